"""The worker host: the controller nodes in K worker processes, the physics in the main process
(``worker_host.py``); the launcher that forks the workers (``launcher.py``), a worker's life
(``serving.py``), what they say to each other (``messages.py``), the world's state they share in
memory (``shared_state.py``) and the tick's exchange with them (``exchange.py``). Workers on other
machines: ``hosts/machines/``.

Nothing is imported here: a worker's launcher imports only what it needs, when it needs it."""
