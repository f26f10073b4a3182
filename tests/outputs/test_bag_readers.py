"""A bag recorded with every device on, every topic recorded, reads back with both independent
ROS 2 readers: rosbags' AnyReader and the mcap ROS 2 decoder."""
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

ROOT = Path(__file__).resolve().parents[2]

# Foot-bots with every device (ground, range and bearing and the topic-switched three on top of
# their proximity, light and camera), and TurtleBot 3s (LiDAR) whose node answers with a Twist.
EVERY_DEVICE = """
name: every_device
seed: 3
length_ticks: 5
arena: {center: [0, 0], size: [4, 4], walls: true}
lights: [{position: [1.5, 1.5]}]
robots:
  - model: foot-bot
    count: 2
    controller: flocking
    placement: {method: uniform, center: [-1, 0], size: [1.5, 1.5]}
    devices: {ground: {}, range_and_bearing: {}, positioning: {}, odometry: {}, differential_steering: {}}
  - model: turtlebot3-burger
    count: 2
    name_prefix: tb
    controller: obstacle-avoidance
    placement: {method: uniform, center: [1, 0], size: [1.5, 1.5]}
    devices: {positioning: {}, odometry: {}, differential_steering: {}}
"""


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("every_device")
    (tmp / "world.yaml").write_text(EVERY_DEVICE)
    run = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", tmp / "world.yaml", "--out", tmp / "out",
                          "--record", tmp / "bag", "--record-topics", "/**", "--markers", "--no-progress"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    return tmp / "bag"


def test_rosbags_and_the_mcap_reader_decode_every_message_of_every_topic(bag):
    by_rosbags: dict[str, int] = {}
    types: dict[str, str] = {}
    with AnyReader([bag]) as reader:
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)          # raises on any message it cannot read
            by_rosbags[connection.topic] = by_rosbags.get(connection.topic, 0) + 1
            types[connection.topic] = connection.msgtype
    by_mcap: dict[str, int] = {}
    for file in bag.glob("*.mcap"):
        with file.open("rb") as f:
            for _, channel, _, decoded in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                assert decoded is not None
                by_mcap[channel.topic] = by_mcap.get(channel.topic, 0) + 1
    assert by_mcap == by_rosbags
    for robot in ("bot0", "bot1"):
        for topic in ("proximity", "light", "blobs", "ground", "rab_rx", "pose", "odom", "wheels", "cmd_vel", "leds"):
            assert by_rosbags.get(f"/{robot}/{topic}", 0) >= 1, (robot, topic)
    for robot in ("tb0", "tb1"):
        for topic in ("scan", "pose", "odom", "wheels"):
            assert by_rosbags[f"/{robot}/{topic}"] == 5, (robot, topic)
        # Their controller answers from a 0.1 s timer, first due at tick 1 (as rclpy's on sim time).
        assert by_rosbags[f"/{robot}/cmd_vel"] == 4, robot
    assert types["/tb0/cmd_vel"] == "geometry_msgs/msg/Twist"
    assert types["/bot0/cmd_vel"] == "geometry_msgs/msg/TwistStamped"
    assert types["/bot0/wheels"] == "sensor_msgs/msg/JointState"
