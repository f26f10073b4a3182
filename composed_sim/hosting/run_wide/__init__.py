"""Run-wide topics: the topics outside every robot's namespace. The relay in each process
(``relay.py``) and its link across controller processes (``link.py``). The world's run-wide nodes
themselves are hosted by ``hosting/run_wide_nodes.py``."""
