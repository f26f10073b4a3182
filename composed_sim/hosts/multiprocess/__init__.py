"""Multi-process mode: every robot's controller in its own OS process, as in the paper. The
simulator's side (``multiprocess_host.py``), one controller's process (``controller_process.py``) and how the
robots are spread over ROS domains (``domains.py``).

Nothing is imported here: a controller process imports only what it needs, when it needs it."""
