"""Services, clients, actions and parameters of hosted nodes: a block's services and action
endpoints (``directory.py``), a served service's queue and the responses handed to clients
(``served.py``), where a client's call goes (``clients.py``); calls between places of the run
(``between_places.py``), actions between places (``actions_between_places.py``) and their rounds
across worker processes (``rounds.py``); requests from other processes (``outside.py``); every
node's parameter services (``parameters.py``)."""
