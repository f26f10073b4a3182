"""Remote workers (``composed-sim run WORLD --machines N``, ``composed-sim join``): the worker host's
blocks on other machines. The simulator's side (``remote_host.py``), each machine's agent that
forks that machine's workers (``agent.py``), and the Dask cluster that carries their messages
(``cluster.py``)."""
