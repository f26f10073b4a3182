"""DDS below the hosted nodes: a process's participants that ignore one another and what dead runs
left in shared memory (``participants.py``); whether the simulator's and the nodes' endpoints are
matched (``matching.py``)."""
