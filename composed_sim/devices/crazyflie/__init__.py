"""The Crazyflie's firmware for a swarm, ROS-free, in numpy arrays over the drones.

What Bitcraze's firmware does between a command and a setpoint, each module one part of it, the
same curves and the same answers (checked against the firmware compiled from its own sources:
tools/crazyflie/, tests/devices/crazyflie/):

- ``polynomials``: the degree-7 pieces, their evaluation and the body rates from flatness;
- ``memory``: each drone's trajectory memory (31 pieces) and its 31 trajectory definitions;
- ``planner``: the planner's state machine and the trajectory it follows;
- ``high_level``: the high-level commander (group masks, what it refuses, its last setpoint);
- ``commander``: priorities between it and streamed setpoints, and the supervisor's part;
- ``motion``: how the drones move under their setpoints;
- ``fleet``: ``Crazyflies``, all of it for a swarm: what the simulation steps and a ROS layer calls.

Not a device module (no ``DEVICE``): the core moves the drones with it (core/flight.py).
"""
from composed_sim.devices.crazyflie.commander import KIND_NAMES, Setpoints
from composed_sim.devices.crazyflie.fleet import Crazyflies
from composed_sim.devices.crazyflie.motion import Tracking

__all__ = ["Crazyflies", "KIND_NAMES", "Setpoints", "Tracking"]
