"""Who runs the controllers, and the tick loop they share.

``lockstep.py`` is the one tick loop; ``host.py`` the interface every host offers the command
line (``Host``, ``HostBase``); ``composed.py`` the one-process host; a folder per mode:
``workers/`` (composed mode over worker processes), ``multiprocess/`` (a process per robot),
``distributed/`` (controllers in shards, possibly on other machines). ``settings.py`` types a
run's choices of host, ``make.py`` builds the host they ask for in ROS domains of the run's own
(``domain_claim.py``); ``processes.py`` keeps child processes from outliving the run. The nodes
themselves are hosted by ``composed_sim.hosting``, below.

Nothing is imported here: a child process imports only what it needs.
"""
