"""Publishing the devices beyond the flocking set (ground, LiDAR, range and bearing, pose, odometry,
wheels, tf): one method each, called only for the robot groups that run the device. A part of
``SimulatorNode``, which holds the publishers, the reused messages and the robots' state."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from composed_sim.ros import cdr, contract as c
from composed_sim.ros.frames import frame_pairs, moving_frames
from composed_sim.world.robot_models import (DIFFERENTIAL_STEERING, GROUND, LIDAR, ODOMETRY, POSITIONING,
                                            RANGE_AND_BEARING, TF, RobotModel)
if TYPE_CHECKING:
    from composed_sim.core.simulation import SensorFrame


@dataclass
class GroupPlan:
    """This node's robots of one robot group, for publishing from ``frame.groups[group]``."""
    group: int
    pairs: list[tuple[int, int]]   # (index among this node's robots, row in the group's arrays)
    rows: np.ndarray               # [k] their simulation rows
    local: np.ndarray              # [k] their indices among this node's robots
    within: np.ndarray             # [k] their rows in the group's arrays
    devices: frozenset[str]        # what the group runs (the same for all its robots)


class DevicePublishing:
    """Mixed into SimulatorNode."""

    def _create_device_publishers(self, i: int, name: str, model: RobotModel, has: frozenset[str]) -> None:
        """Publishers and reused messages of robot i's devices beyond the proximity/light/camera set."""
        def add(topic: c.Topic, msg) -> None:
            self._device_pubs[topic.name][i] = self._publisher(name, topic)
            self._device_msgs[topic.name][i] = msg
        if GROUND in has:
            add(c.GROUND_SENSORS, c.ground_cloud(name, len(model.ground.offsets_m)))
        if LIDAR in has:
            add(c.SCAN, c.lidar_scan_message(model.lidar, name, self._tick_ns * 1e-9))
        if RANGE_AND_BEARING in has:
            add(c.RAB_RX, c.rab_cloud(name, self._rab_payload_bytes))
        if POSITIONING in has:
            add(c.POSE, c.pose_stamped(name))
        if ODOMETRY in has:
            add(c.ODOM, c.odometry_message(name))
        if DIFFERENTIAL_STEERING in has:
            add(c.WHEELS, c.joint_state(name))
        if TF in has and self._frames.per_robot[i]:
            add(c.TF, cdr.TransformsEncoder(frame_pairs(name)))

    def _publish_devices(self, plan: GroupPlan, frame: SensorFrame, stamp, stamp_ns: int) -> None:
        has = plan.devices
        if GROUND in has:
            self._publish_ground(plan, frame.groups[plan.group].ground, stamp, stamp_ns)
        if LIDAR in has:
            self._publish_scan(plan, frame.groups[plan.group].lidar, stamp, stamp_ns)
        if RANGE_AND_BEARING in has:
            self._publish_rab(plan, frame.range_and_bearing, stamp, stamp_ns)
        if POSITIONING in has:
            self._publish_pose(plan, frame, stamp, stamp_ns)
        if ODOMETRY in has:
            self._publish_odometry(plan, frame, stamp, stamp_ns)
        if DIFFERENTIAL_STEERING in has:
            self._publish_wheels(plan, frame, stamp, stamp_ns)
        if TF in has:
            self._publish_frames(plan, frame, stamp, stamp_ns)

    def _send(self, topic: c.Topic, i: int, msg, stamp_ns: int) -> None:
        """Publish a device message; the caller asked ``_wanted`` before filling it."""
        self._device_pubs[topic.name][i].publish(msg)
        self._tap_message(topic, i, msg, stamp_ns)

    def _publish_ground(self, plan: GroupPlan, ground: np.ndarray, stamp, stamp_ns: int) -> None:
        offsets = self._models[plan.local[0]].ground.offsets_m
        points = c.ground_points(offsets, ground[plan.within])     # [k, s], built once per group
        msgs = self._device_msgs[c.GROUND_SENSORS.name]
        for k, (i, _) in enumerate(plan.pairs):
            if not self.failed[i] and self._wanted(c.GROUND_SENSORS, i):
                c.fill_ground(msgs[i], stamp, points[k])
                self._send(c.GROUND_SENSORS, i, msgs[i], stamp_ns)

    def _publish_scan(self, plan: GroupPlan, lidar: np.ndarray, stamp, stamp_ns: int) -> None:
        ranges = lidar[plan.within].astype(np.float32)             # [k, r], cast once per group
        msgs = self._device_msgs[c.SCAN.name]
        for k, (i, _) in enumerate(plan.pairs):
            if not self.failed[i] and self._wanted(c.SCAN, i):
                c.fill_scan(msgs[i], stamp, ranges[k])
                self._send(c.SCAN, i, msgs[i], stamp_ns)

    def _publish_rab(self, plan: GroupPlan, rab, stamp, stamp_ns: int) -> None:
        take, offsets = csr_take(rab.offsets, plan.rows)
        points = c.rab_points(rab.ranges[take], rab.horizontal_bearings[take], rab.vertical_bearings[take],
                              rab.payloads[take])
        offsets = offsets.tolist()
        msgs = self._device_msgs[c.RAB_RX.name]
        for k, i in enumerate(plan.local.tolist()):
            if not self.failed[i] and self._wanted(c.RAB_RX, i):
                c.fill_rab(msgs[i], stamp, points[offsets[k]:offsets[k + 1]])
                self._send(c.RAB_RX, i, msgs[i], stamp_ns)

    def _publish_pose(self, plan: GroupPlan, frame: SensorFrame, stamp, stamp_ns: int) -> None:
        xy = frame.pose.positions[plan.rows, :2].tolist()
        q = frame.pose.quaternions[plan.rows].tolist()          # (x, y, z, w)
        msgs = self._device_msgs[c.POSE.name]
        for k, i in enumerate(plan.local.tolist()):
            if not self.failed[i] and self._wanted(c.POSE, i):
                c.fill_pose(msgs[i], stamp, xy[k][0], xy[k][1], q[k][2], q[k][3])
                self._send(c.POSE, i, msgs[i], stamp_ns)

    def _publish_odometry(self, plan: GroupPlan, frame: SensorFrame, stamp, stamp_ns: int) -> None:
        pose = frame.odometry[plan.rows]
        qz, qw = c.half_yaw(pose[:, 2])
        values = np.column_stack([pose[:, 0], pose[:, 1], qz, qw, frame.odometry_twist[plan.rows]]).tolist()
        msgs = self._device_msgs[c.ODOM.name]
        for k, i in enumerate(plan.local.tolist()):
            if not self.failed[i] and self._wanted(c.ODOM, i):
                c.fill_odometry(msgs[i], stamp, *values[k])
                self._send(c.ODOM, i, msgs[i], stamp_ns)

    def _publish_wheels(self, plan: GroupPlan, frame: SensorFrame, stamp, stamp_ns: int) -> None:
        radius = self._models[plan.local[0]].wheel_radius_m
        self._wheel_angles[plan.local] += frame.wheels.distances_m[plan.rows] / radius
        angles = self._wheel_angles[plan.local]
        velocities = frame.wheels.velocities_mps[plan.rows] / radius
        msgs = self._device_msgs[c.WHEELS.name]
        for k, i in enumerate(plan.local.tolist()):
            if not self.failed[i] and self._wanted(c.WHEELS, i):
                c.fill_wheels(msgs[i], stamp, angles[k], velocities[k])
                self._send(c.WHEELS, i, msgs[i], stamp_ns)

    def _publish_frames(self, plan: GroupPlan, frame: SensorFrame, stamp, stamp_ns: int) -> None:
        """tf: world → odom → base_link of each robot, on its own /<r>/tf or gathered for /tf."""
        poses = moving_frames(frame, plan.rows)                      # [k, 2, 7]
        encoders = self._device_msgs[c.TF.name]
        for k, i in enumerate(plan.local.tolist()):
            if self.failed[i]:
                continue
            if not self._frames.per_robot[i]:
                self._frames.gather(i, poses[k])
            elif self._wanted(c.TF, i):
                self._send(c.TF, i, encoders[i].encode(stamp.sec, stamp.nanosec, poses[k]), stamp_ns)


def csr_take(offsets: np.ndarray, rows: np.ndarray):
    """The entries of CSR rows ``rows`` [k] (ascending) of entry arrays with row offsets
    ``offsets``: (what to take from the entry arrays, [k+1] offsets into what is taken).

    A simulator node serves a shard or a domain of the swarm: converting every robot's entries
    (blobs, range-and-bearing messages) in every node would cost (number of nodes) × the work."""
    starts, ends = offsets[rows], offsets[rows + 1]
    counts = ends - starts
    local = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(counts, out=local[1:])
    if len(rows) and rows[-1] - rows[0] + 1 == len(rows):     # contiguous rows: a slice
        return slice(int(starts[0]), int(ends[-1])), local
    return np.arange(local[-1]) + np.repeat(starts - local[:-1], counts), local
