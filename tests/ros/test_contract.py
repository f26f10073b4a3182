"""The topic contract: encoders and decoders agree, and docs/contract.md lists exactly the code's topics."""
import re
from pathlib import Path

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import LaserScan, PointCloud2
from std_msgs.msg import UInt8MultiArray

from composed_sim.world.robot_models import FOOTBOT
from composed_sim.ros import contract as c, decoding
from composed_sim.devices import camera, light, proximity

DOC = Path(__file__).resolve().parents[2] / "docs" / "contract.md"


def ros_type_name(msg_type) -> str:
    pkg = msg_type.__module__.split(".")[0]
    return f"{pkg}/msg/{msg_type.__name__}"


def test_every_topic_is_documented_with_its_type_and_nothing_else():
    doc = DOC.read_text()
    rows = dict(re.findall(r"^\| `(/[^`]+)` \| `([^`]+)` \|", doc, flags=re.M))
    expected = {f"/<robot>/{t.name}": ros_type_name(c.msg_type(t)) for t in c.TOPICS.values()}
    expected[c.CLOCK_TOPIC] = ros_type_name(c.CLOCK_TYPE)
    expected[c.SWARM_STATE_TOPIC] = "sensor_msgs/msg/PointCloud2"
    expected[c.SWARM_MARKERS_TOPIC] = "visualization_msgs/msg/MarkerArray"
    assert rows == expected


def test_stamps_are_exact_integer_nanoseconds():
    tick_ns = 100_000_000
    stamp = c.stamp_of(12345, tick_ns)
    assert (stamp.sec, stamp.nanosec) == (1234, 500_000_000)
    assert c.stamp_key(stamp) == 12345 * tick_ns


def test_proximity_and_light_round_trip():
    """A ring's bytes are a LaserScan in the robot's base_link at the ring's angles, and decode back."""
    k = len(FOOTBOT.proximity.angles_rad)
    rng = np.random.default_rng(0)
    dist = np.where(rng.random(k) < 0.5, np.inf, rng.random(k) * 0.1)
    read = rng.random(k)
    data = proximity.encoder(FOOTBOT.proximity, "bot3").encode(1, 10, read, dist)
    msg = deserialize_message(data, LaserScan)
    assert msg.header.frame_id == "bot3/base_link" and (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 10)
    np.testing.assert_allclose(msg.angle_min + msg.angle_increment * np.arange(k), FOOTBOT.proximity.angles_rad,
                               atol=1e-6)
    d2, r2 = proximity.decode(data)
    np.testing.assert_allclose(d2, dist.astype(np.float32))
    np.testing.assert_allclose(r2, read.astype(np.float32))
    data = light.encoder(FOOTBOT.light, "bot3").encode(1, 10, read)
    assert len(deserialize_message(data, LaserScan).ranges) == 0
    np.testing.assert_allclose(light.decode(data), read.astype(np.float32))


def test_blobs_round_trip_bearing_distance_colour():
    angles = np.array([0.0, 1.0, -2.5, 3.0])
    dists = np.array([0.2, 1.0, 1.5, 0.75])
    colors = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [10, 20, 30]], dtype=np.uint8)
    encoder = camera.encoder("bot0")
    points = camera.points_of(angles, dists, colors)
    data = encoder.encode(2, 10, points.tobytes(), len(points))
    msg = deserialize_message(data, PointCloud2)
    assert msg.width == 4 and msg.row_step == 4 * msg.point_step
    blobs = camera.decode(data)
    np.testing.assert_allclose(blobs.angles, angles, atol=1e-6)
    np.testing.assert_allclose(blobs.distances, dists, atol=1e-6)
    np.testing.assert_array_equal(blobs.colors, colors)
    red = blobs.of_color((255, 0, 0))
    assert len(red) == 1 and red.distances[0] == pytest.approx(0.2, abs=1e-6)
    assert len(camera.decode(encoder.encode(3, 10, b"", 0))) == 0


def test_leds_round_trip_and_wrong_size_is_rejected():
    colors = np.zeros((FOOTBOT.n_leds, 3), dtype=np.uint8)
    colors[12] = (255, 0, 0)
    # A controller's bytes are the message's; the simulator decodes any layout's bytes.
    sent = c.led_encoder(FOOTBOT.n_leds).encode(colors.tobytes())
    assert deserialize_message(sent, UInt8MultiArray) == c.led_message(colors)
    for data in (sent, serialize_message(c.led_message(colors)), serialize_message(UInt8MultiArray(data=colors.tobytes()))):
        np.testing.assert_array_equal(decoding.decode_leds(data, FOOTBOT.n_leds), colors)
    with pytest.raises(ValueError, match="expected 39"):
        decoding.decode_leds(serialize_message(c.led_message(colors[:5])), FOOTBOT.n_leds)


def test_twist_and_wheels_are_inverse():
    v, w = c.twist_of_wheels(0.03, 0.1, FOOTBOT)
    assert c.wheel_speeds(v, w, FOOTBOT) == pytest.approx((0.03, 0.1))
    msg = c.twist_stamped(c.stamp_of(5, 100), v, w)
    assert (msg.twist.linear.x, msg.twist.angular.z) == pytest.approx((v, w))
