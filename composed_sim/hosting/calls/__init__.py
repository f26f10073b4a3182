"""Services, clients, actions and parameters of hosted nodes: served in process (``directory.py``),
between places of the run (``between_places.py``) and in rounds across worker processes
(``rounds.py``), from other processes (``outside.py``); every node's parameter services
(``parameters.py``)."""
