"""Differential steering: the wheels' speeds and travel (readings: core/odometry.differential_steering).

``/<r>/wheels``, sensor_msgs/JointState: joints wheel_left_joint and wheel_right_joint (TurtleBot 3's
names); position = the wheel's angle since the start (rad), velocity = its speed (rad/s). Published
and taken as bytes.
"""
from __future__ import annotations

import array

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import JointState

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher
from composed_sim.ros.topic import Topic, base_link
from composed_sim.world.robot_models import DIFFERENTIAL_STEERING, RobotModel

TOPIC = Topic("wheels", JointState, "sensor",
              "differential steering sensor: joints wheel_left_joint, wheel_right_joint; position = "
              "wheel angle since the start (rad), velocity = wheel speed (rad/s)")
WHEEL_JOINTS = ("wheel_left_joint", "wheel_right_joint")


def message(robot: str) -> JointState:
    msg = JointState()
    msg.header.frame_id = base_link(robot)
    msg.name = list(WHEEL_JOINTS)
    # Not simulated, so zero, as a TurtleBot 3 reports it. Not empty: Fast CDR pads an empty
    # float64 sequence at the message's end to 8 bytes, and rosbags refuses such a message.
    msg.effort = [0.0] * len(WHEEL_JOINTS)
    return msg


def encoder(robot: str) -> cdr.FixedEncoder:
    """Its ``encode(stamp, left angle, right angle, left speed, right speed)``."""
    template = message(robot)
    template.position = template.velocity = [0.0] * len(WHEEL_JOINTS)
    return cdr.FixedEncoder(template, lambda data: sum(cdr.joint_state_f64_at(data), []))


def fill(msg: JointState, stamp: Time, angles_rad: np.ndarray, velocities_radps: np.ndarray) -> None:
    """[2] (left, right) wheel angles since the start and wheel speeds, of one robot."""
    msg.header.stamp = stamp
    msg.position = array.array("d", angles_rad.astype(np.float64, copy=False).tobytes())
    msg.velocity = array.array("d", velocities_radps.astype(np.float64, copy=False).tobytes())


def decode(msg: JointState, wheel_radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """→ (left, right) wheel speeds [2] m/s, and wheel travel since the start [2] m."""
    return (np.frombuffer(msg.velocity, dtype=np.float64) * wheel_radius_m,
            np.frombuffer(msg.position, dtype=np.float64) * wheel_radius_m)


def decode_cdr(data: bytes, wheel_radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    angles, speeds = cdr.decode_joint_state(data)
    return speeds * wheel_radius_m, angles * wheel_radius_m


class Publisher(DevicePublisher):
    topic, device = TOPIC, DIFFERENTIAL_STEERING

    def __init__(self, node, robots):
        super().__init__(node, robots)
        self._angles = np.zeros((len(robots.names), 2))     # [n, 2] rad since the start

    def template(self, robots, i):
        return encoder(robots.names[i])

    def publish(self, plan, frame, out):
        radius = plan.model.wheel_radius_m
        self._angles[plan.local] += frame.wheels.distances_m[plan.rows] / radius
        angles, speeds = self._angles[plan.local], frame.wheels.velocities_mps[plan.rows] / radius
        self.encode_and_send(plan, out, *(column.tolist() for column in
                                          (angles[:, 0], angles[:, 1], speeds[:, 0], speeds[:, 1])))


def reader(model: RobotModel):
    travelled = np.zeros(2)       # at the last tick, m: the sensor gives the travel since the start

    def read(data: bytes, tick) -> None:
        nonlocal travelled
        tick.wheel_speeds, travel = decode_cdr(data, model.wheel_radius_m)
        tick.wheel_distances = travel - travelled
        travelled = travel
    return read


DEVICE = Device(DIFFERENTIAL_STEERING, (TOPIC,), Publisher, reader)
