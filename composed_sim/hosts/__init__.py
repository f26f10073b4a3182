"""Who runs the controllers, and the tick loop they share.

``tick_loop.py`` is the one tick loop; ``base.py`` the interface every host offers the command
line (``Host``, ``HostBase``); ``composed.py`` the one-process host; a folder per mode:
``workers/`` (composed mode over worker processes on this machine), ``machines/`` (the same over
worker processes on other machines, ``--machines``), ``multiprocess/`` (a process per robot, as in
the paper); ``outside_controllers.py`` (the simulator alone, its robots driven by processes outside
the run, ``--external-controllers``). ``settings.py`` types a run's choices of host, ``make.py`` builds the
host they ask for in ROS domains of the run's own (``domain_claim.py``), with the DDS discovery
they ask for (``discovery.py``); ``processes.py`` keeps child processes from outliving the run.
The nodes themselves are hosted by ``composed_sim.hosting``, below.

Nothing is imported here: a child process imports only what it needs.
"""
