"""Differential steering: the wheels' speeds and travel (its readings, for every robot:
core/odometry.differential_steering; the wheels' actuator noise: core/odometry.WheelActuator).

``/<r>/wheels``, sensor_msgs/JointState: joints wheel_left_joint and wheel_right_joint (TurtleBot 3's
names); position = the wheel's angle since the start (rad), velocity = its speed (rad/s). A
controller's Tick: ``wheel_speeds`` and ``wheel_distances``. Every model has the device; a world
file switches its topic on, and sets the wheels' noise (``devices.wheels``).
"""
from __future__ import annotations

import numpy as np

from composed_sim.devices.common import cdr
from composed_sim.devices.common.device import Device, DevicePublisher
from composed_sim.devices.common.settings import NonNegativeFloat, Strict
from composed_sim.devices.common.topic import Topic, base_link

NAME = "differential_steering"


class WheelsConfig(Strict):
    """Actuator noise (speed · factor + bias) and differential steering sensor noise."""
    bias_mean_mps: float = 0.0
    bias_std_mps: NonNegativeFloat = 0.0
    factor_mean: float = 1.0
    factor_std: NonNegativeFloat = 0.0
    velocity_noise_mps: NonNegativeFloat = 0.0   # sensor: uniform on the reported speeds
    distance_noise_m: NonNegativeFloat = 0.0     # sensor: uniform on the reported distances


TOPIC = Topic("wheels", "sensor_msgs/msg/JointState", "sensor",
              "differential steering sensor: joints wheel_left_joint, wheel_right_joint; position = "
              "wheel angle since the start (rad), velocity = wheel speed (rad/s)")
WHEEL_JOINTS = ("wheel_left_joint", "wheel_right_joint")


def encoder(robot: str) -> cdr.FixedEncoder:
    """Its ``encode(stamp, left angle, right angle, left speed, right speed)``. The effort is not
    simulated, so zero, as a TurtleBot 3 reports it; not empty: Fast CDR pads an empty float64
    sequence at the message's end to 8 bytes, and rosbags refuses such a message."""
    return cdr.FixedEncoder(cdr.joint_state_bytes(base_link(robot), WHEEL_JOINTS, [0.0] * len(WHEEL_JOINTS)),
                            lambda data: sum(cdr.joint_state_f64_at(data), []))


def decode(data: bytes, wheel_radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """JointState bytes → (left, right) wheel speeds [2] m/s, and wheel travel since the start [2] m."""
    angles, speeds = cdr.decode_joint_state(data)
    return speeds * wheel_radius_m, angles * wheel_radius_m


class Publisher(DevicePublisher):
    topic, device = TOPIC, NAME

    def __init__(self, node, robots):
        super().__init__(node, robots)
        self._angles = np.zeros((len(robots.names), 2))     # [n, 2] rad since the start

    def template(self, robots, i):
        return encoder(robots.names[i])

    def publish(self, plan, frame, out):
        radius = plan.model.wheel_radius_m
        self._angles[plan.local] += frame.wheels.distances_m[plan.rows] / radius
        angles, speeds = self._angles[plan.local], frame.wheels.velocities_mps[plan.rows] / radius
        self.encode_and_send(*self.to_send(plan, out), out, *(column.tolist() for column in
                                          (angles[:, 0], angles[:, 1], speeds[:, 0], speeds[:, 1])))


def reader(model):
    travelled = np.zeros(2)       # at the last tick, m: the sensor gives the travel since the start

    def read(data: bytes, tick) -> None:
        nonlocal travelled
        tick.wheel_speeds, travel = decode(data, model.wheel_radius_m)
        tick.wheel_distances = travel - travelled
        travelled = travel
    return read


DEVICE = Device(NAME, (TOPIC,), Publisher, reader, tick_fields=("wheel_speeds", "wheel_distances"))
