"""The world file's ``flight`` section: how drones (models that fly, world/robot_models.py) move
and when two of them are too close (core/flight.py)."""
from __future__ import annotations

from typing import Annotated, Literal, Optional

from pydantic import Field

from composed_sim.devices.common.settings import PositiveFloat, Strict


class Tracking(Strict):
    """A lag between a drone and its position setpoint, instead of perfect tracking: first order
    (each coordinate approaches the setpoint with this time constant) or second order (a
    critically damped spring of natural frequency 1 / time constant)."""
    order: Literal[1, 2] = 1
    time_constant_s: PositiveFloat = 0.1


class Flight(Strict):
    # A near miss: two drones, one of them off the floor, inside each other's tall ellipsoid of
    # this horizontal radius and ``near_miss_height_ratio`` times it vertically (downwash reaches
    # further down than a propeller reaches sideways). docs/devices.md says why 0.15 m and 3.
    near_miss_radius_m: PositiveFloat = 0.15
    near_miss_height_ratio: Annotated[float, Field(ge=1.0, le=10.0)] = 3.0
    # None: the drones are where their setpoints say (Crazyswarm2's ``none`` backend).
    tracking: Optional[Tracking] = None
