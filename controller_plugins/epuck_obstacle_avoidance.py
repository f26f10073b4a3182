"""The ARGoS e-puck obstacle avoidance example (argos3-examples, epuck_obstacleavoidance).

Of the four front proximity sensors (indices 0 and 1 on the left, 6 and 7 on the right, as the
e-puck's ring counts them) the one with the highest reading decides: nothing seen → both wheels
at ``speed_mps``; the strongest on the left → turn right (right wheel stopped); on the right →
turn left. ARGoS checks them in the order 0, 1, 7, 6 and keeps the first maximum; so does this.
"""
from __future__ import annotations

import numpy as np

from composed_sim.plugins import ArgosPort
from composed_sim.ros.contract import twist_of_wheels
from composed_sim.ros.controller import SwarmController, Tick

FRONT_SENSORS = (0, 1, 7, 6)      # ARGoS's order of comparison
LEFT_SENSORS = (0, 1)


def avoidance_wheels(readings: np.ndarray, speed: float) -> tuple[float, float]:
    """(left, right) wheel speeds for the e-puck's 8 proximity readings."""
    best, value = FRONT_SENSORS[0], readings[FRONT_SENSORS[0]]
    for index in FRONT_SENSORS[1:]:
        if value < readings[index]:
            best, value = index, readings[index]
    if value <= 0.0:
        return speed, speed
    return (speed, 0.0) if best in LEFT_SENSORS else (0.0, speed)


class EpuckObstacleAvoidanceController(SwarmController):
    """Go straight; turn away from the strongest of the four front proximity readings."""

    sensors = ("proximity",)
    # ARGoS: velocity in cm/s (default 2.5).
    argos = ArgosPort("epuck_obstacleavoidance_controller", {"velocity": ("speed_mps", 0.01)})

    def __init__(self, **node_kwargs):
        super().__init__("epuck_obstacle_avoidance", **node_kwargs)
        if len(self.proximity_angles) < 8:
            raise ValueError(f"epuck-obstacle-avoidance needs the e-puck's 8 proximity sensors; "
                             f"the {self.model.name} has {len(self.proximity_angles)}")
        speed = float(self.declare_parameter("speed_mps", 0.025).value)
        self.speed = min(speed, self.model.max_wheel_speed_mps)

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        return twist_of_wheels(*avoidance_wheels(tick.proximity, self.speed), self.model)
