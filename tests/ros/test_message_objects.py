"""A plain node's LaserScan built from the bytes (ros/message_objects.py) is the object rclpy's
deserializer gives, for the simulator's scans and for any other publisher's."""
from array import array

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String

from composed_sim.devices import lidar
from composed_sim.world.robot_models import TURTLEBOT3_BURGER
from composed_sim.ros import message_objects


def scan(frame_id: str, n_ranges: int, n_intensities: int, seed: int) -> LaserScan:
    rng = np.random.default_rng(seed)
    msg = LaserScan()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(rng.integers(-5, 10**6)), int(rng.integers(0, 10**9))
    msg.header.frame_id = frame_id
    (msg.angle_min, msg.angle_max, msg.angle_increment, msg.time_increment, msg.scan_time, msg.range_min,
     msg.range_max) = (float(v) for v in rng.normal(size=7).astype(np.float32))
    values = rng.normal(size=n_ranges).astype(np.float32)
    values[::7] = np.inf
    msg.ranges = array("f", values.tobytes())
    msg.intensities = array("f", rng.normal(size=n_intensities).astype(np.float32).tobytes())
    return msg


@pytest.mark.parametrize("frame_id", ["", "a", "ab", "abc", "tb12/base_scan", "bøt/ünïcode"])
@pytest.mark.parametrize("sizes", [(0, 0), (1, 0), (360, 360), (3, 5)])
def test_a_scan_built_from_its_bytes_is_the_deserialized_one(frame_id, sizes):
    data = serialize_message(scan(frame_id, *sizes, seed=len(frame_id) + sizes[0]))
    built = message_objects.builder(LaserScan)(data)
    assert built == deserialize_message(data, LaserScan)      # every field (padding bytes aside)


def test_the_simulators_own_scan_bytes_and_other_types():
    layout = TURTLEBOT3_BURGER.lidar
    ranges = np.linspace(0.1, 3.5, layout.n_rays)
    data = lidar.encoder(layout, "tb0", 0.1).encode(3, 500, np.zeros(0), ranges)
    assert message_objects.builder(LaserScan)(data) == deserialize_message(data, LaserScan)
    assert message_objects.builder(String)(serialize_message(String(data="x"))) == String(data="x")
