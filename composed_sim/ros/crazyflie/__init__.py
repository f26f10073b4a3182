"""Crazyswarm2's ROS interface of the drones, on the simulator's side (docs/crazyflie.md).

- ``messages``: Crazyswarm2's services and setpoint topics (``crazyflie_interfaces``, a package the
  user builds from Crazyswarm2's source) and what each request or message asks of the firmware,
  as a ``DroneCommand`` (core/drone_commands.py);
- ``outbox``: a process's commands of the tick, as they arrive;
- ``endpoints``: the per-drone endpoints of a block of drones, beside its simulator node: the
  services ``/<cf>/takeoff`` … ``/<cf>/arm``, the setpoint subscriptions ``/<cf>/cmd_*`` and the
  ``/<cf>/status`` publisher (the ``pose`` is the positioning device's topic);
- ``server``: the run-wide ``crazyflie_server`` node: the robots and their firmware parameters as
  its parameters, and the ``all/*`` services.
"""
