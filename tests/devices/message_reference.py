"""The contract's sensor messages as rclpy message objects, filled and read field by field: the
reference the devices' byte codecs (devices/common/cdr.py, cdr_clouds.py) are checked against in test_cdr.py."""
import array
from types import SimpleNamespace

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState, LaserScan, PointCloud2, PointField

from composed_sim.devices import camera, differential_steering, ground, range_and_bearing
from composed_sim.devices.common import cdr_clouds
from composed_sim.devices.common.topic import WORLD_FRAME, base_link, base_scan, odom_frame, yaw_of


def point_fields(dtype):
    return [PointField(name=n, offset=o, datatype=d, count=k) for n, o, d, k in cdr_clouds.point_fields(dtype)]


def point_cloud(robot, dtype, width=0):
    msg = PointCloud2()
    msg.header.frame_id = base_link(robot)
    msg.height, msg.width = 1, width
    msg.fields = point_fields(dtype)
    msg.is_bigendian = False
    msg.point_step, msg.row_step = dtype.itemsize, dtype.itemsize * width
    msg.is_dense = True
    return msg


def fill_points(msg, stamp, points):
    msg.header.stamp = stamp
    msg.width = len(points)
    msg.row_step = msg.point_step * len(points)
    msg.data = points.tobytes()


def ring_scan(angles, robot, range_max):
    msg = LaserScan()
    msg.header.frame_id = base_link(robot)
    msg.angle_min, msg.angle_max = float(angles[0]), float(angles[-1])
    msg.angle_increment = float(angles[1] - angles[0]) if len(angles) > 1 else 0.0
    msg.range_min, msg.range_max = 0.0, float(range_max)
    return msg


def _f4(values):
    return array.array("f", np.asarray(values, dtype=np.float32).tobytes())


def _scan_fill(msg, stamp, ranges=None, intensities=None):
    msg.header.stamp = stamp
    if ranges is not None:
        msg.ranges = _f4(ranges)
    if intensities is not None:
        msg.intensities = _f4(intensities)


def _lidar_message(lidar, robot, scan_time_s):
    msg = LaserScan()
    msg.header.frame_id = base_scan(robot)
    msg.angle_min, msg.angle_max = float(lidar.angle_min_rad), float(lidar.angle_max_rad)
    msg.angle_increment, msg.scan_time = float(lidar.angle_increment_rad), float(scan_time_s)
    msg.range_min, msg.range_max = float(lidar.min_range_m), float(lidar.max_range_m)
    return msg


def _pose_message():
    msg = PoseStamped()
    msg.header.frame_id = WORLD_FRAME
    return msg


def _pose_fill(msg, stamp, x, y, qz, qw, z=0.0):
    msg.header.stamp = stamp
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
    msg.pose.orientation.z, msg.pose.orientation.w = qz, qw


def _odom_message(robot):
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = odom_frame(robot), base_link(robot)
    return msg


def _odom_fill(msg, stamp, x, y, qz, qw, linear, angular):
    msg.header.stamp = stamp
    p, q, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
    p.x, p.y, q.z, q.w = x, y, qz, qw
    t.linear.x, t.angular.z = linear, angular


def _wheels_message(robot):
    msg = JointState()
    msg.header.frame_id = base_link(robot)
    msg.name = list(differential_steering.WHEEL_JOINTS)
    msg.effort = [0.0] * len(differential_steering.WHEEL_JOINTS)
    return msg


def _wheels_fill(msg, stamp, angles, speeds):
    msg.header.stamp = stamp
    msg.position = array.array("d", np.asarray(angles, dtype=np.float64).tobytes())
    msg.velocity = array.array("d", np.asarray(speeds, dtype=np.float64).tobytes())


def _rab_decode(msg):
    payload = {f.name: f for f in msg.fields}["payload"]
    points = np.frombuffer(msg.data, dtype=range_and_bearing.point_dtype(payload.count), count=msg.width)
    return range_and_bearing.RabMessages(points["range"].astype(float), points["bearing"].astype(float),
                                         points["elevation"].astype(float), points["payload"].copy())


def _blobs_decode(msg):
    points = np.frombuffer(msg.data, dtype=camera._cloud_dtype(tuple((f.name, f.offset, f.datatype) for f in msg.fields),
                                                              msg.point_step), count=msg.width)
    return camera._blobs(points)


proximity = SimpleNamespace(
    message=lambda ring, robot: ring_scan(ring.angles_rad, robot, ring.range_m),
    fill=lambda msg, stamp, distances, readings: _scan_fill(msg, stamp, distances, readings),
    decode=lambda msg: (np.frombuffer(msg.ranges, np.float32).astype(float),
                        np.frombuffer(msg.intensities, np.float32).astype(float)))
light = SimpleNamespace(
    message=lambda ring, robot: ring_scan(ring.angles_rad, robot, 0.0),
    fill=lambda msg, stamp, readings: _scan_fill(msg, stamp, intensities=readings),
    decode=lambda msg: np.frombuffer(msg.intensities, np.float32).astype(float))
lidar = SimpleNamespace(
    message=_lidar_message, fill=lambda msg, stamp, ranges: _scan_fill(msg, stamp, ranges),
    decode=lambda msg: np.frombuffer(msg.ranges, np.float32).astype(float))
positioning = SimpleNamespace(
    message=_pose_message, fill=_pose_fill,
    decode=lambda msg: np.array([msg.pose.position.x, msg.pose.position.y,
                                 yaw_of(msg.pose.orientation.z, msg.pose.orientation.w)]))
odometry = SimpleNamespace(
    message=_odom_message, fill=_odom_fill,
    decode=lambda msg: (np.array([msg.pose.pose.position.x, msg.pose.pose.position.y,
                                  yaw_of(msg.pose.pose.orientation.z, msg.pose.pose.orientation.w)]),
                        np.array([msg.twist.twist.linear.x, msg.twist.twist.angular.z])))
wheels = SimpleNamespace(
    message=_wheels_message, fill=_wheels_fill,
    decode=lambda msg, radius: (np.frombuffer(msg.velocity, np.float64) * radius,
                                np.frombuffer(msg.position, np.float64) * radius))
ground_sensors = SimpleNamespace(
    message=lambda robot, n: point_cloud(robot, ground.GROUND_DTYPE, n),
    fill=lambda msg, stamp, points: (setattr(msg.header, "stamp", stamp), setattr(msg, "data", points.tobytes())),
    decode=lambda msg: np.frombuffer(msg.data, ground.GROUND_DTYPE, count=msg.width)["intensity"].astype(float))
rab = SimpleNamespace(
    message=lambda robot, payload_bytes: point_cloud(robot, range_and_bearing.point_dtype(payload_bytes)),
    fill=fill_points, decode=_rab_decode)
blobs = SimpleNamespace(message=lambda robot: point_cloud(robot, camera.BLOB_DTYPE), fill=fill_points,
                        decode=_blobs_decode)
