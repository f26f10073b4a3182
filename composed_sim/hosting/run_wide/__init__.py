"""Run-wide topics: the topics outside every robot's namespace. The relay in each process
(``relay.py``), its link across controller processes (``link.py``) and the world's run-wide nodes
(``nodes.py``)."""
