"""DDS below the hosted nodes: a process's participants that ignore one another
(``participants.py``); what processes that are gone left in /dev/shm, removed by owner
(``shared_memory.py``); whether the simulator's and the nodes' endpoints are matched
(``matching.py``)."""
