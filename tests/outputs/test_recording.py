"""Recording a run as rosbag2/MCAP, read back with rosbags' own reader; live swarm markers."""
import json

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import TwistStamped
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from visualization_msgs.msg import Marker, MarkerArray

from composed_sim.outputs.recording import (CLOCK_TOPIC, FRAME_ID, STATE_DTYPE, SWARM_STATE_TOPIC,
                                    BagRecorder, RecordingError, display_colors, read_recording,
                                    read_swarm_states)
from composed_sim.ros.contract import led_message, stamp_of, twist_stamped
from composed_sim.live.markers import swarm_markers, swarm_markers_cdr
from composed_sim.world.loader import world_from_dict

NAMES = ["bot0", "bot1", "bot2"]
TICKS = 20
TICK_S = 0.1
TICK_NS = 100_000_000


def synthetic_run(n=3, ticks=TICKS, seed=0):
    """positions [T+1, n, 2], headings [T+1, n], LEDs [T+1, n, 13, 3] with varied colours."""
    rng = np.random.default_rng(seed)
    positions = np.cumsum(rng.normal(0, 0.01, (ticks + 1, n, 2)), axis=0) + rng.uniform(-1, 1, (n, 2))
    headings = rng.uniform(-np.pi, np.pi, (ticks + 1, n))
    leds = np.zeros((ticks + 1, n, 13, 3), dtype=np.uint8)
    leds[1:, 0:1, 12] = (255, 0, 0)         # bot0: red beacon from tick 1
    leds[:, 1:2, 4] = (0, 0, 255)           # bot1: one blue ring LED, beacon off
    leds[10:, 2:3, 12] = (0, 255, 0)        # bot2: dark until tick 10, then a green beacon
    return positions, headings, leds


def record(path, positions, headings, leds, *, ticks=None, globs=("/bot1*/cmd_vel", "/*/leds"),
           world=None):
    """Write ticks 0..ticks (all by default) plus every robot's cmd_vel and leds each tick."""
    last = len(positions) - 1 if ticks is None else ticks
    with BagRecorder(path, robot_names=NAMES, tick_s=TICK_S, topics_globs=list(globs),
                     world=world) as rec:
        for k in range(last + 1):
            ns = k * TICK_NS
            rec.write_clock(k)
            rec.write_swarm_state(ns, positions[k], headings[k], leds[k])
            for i, name in enumerate(NAMES):
                for topic, msg in ((f"/{name}/cmd_vel", twist_stamped(stamp_of(k, TICK_NS), 0.1 * i, 0.5)),
                                   (f"/{name}/leds", led_message(leds[k, i]))):
                    if rec.wants(topic):
                        assert rec.write_message(topic, msg, ns)
    return rec


@pytest.fixture(scope="module")
def run():
    return synthetic_run()


@pytest.fixture(scope="module")
def bag(tmp_path_factory, run):
    path = tmp_path_factory.mktemp("rec") / "run_bag"
    record(path, *run)
    return path


def read_all(path):
    """{topic: [(timestamp_ns, message)]} and {topic: msgtype}, decoded by rosbags."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    out, types = {}, {}
    with Reader(path) as reader:
        for conn in reader.connections:
            types[conn.topic] = conn.msgtype
        for conn, ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((ns, typestore.deserialize_cdr(raw, conn.msgtype)))
    return out, types


def test_bag_directory_is_rosbag2_with_mcap(bag):
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap"
    assert meta["relative_file_paths"] == ["run_bag.mcap"]
    data = (bag / "run_bag.mcap").read_bytes()
    assert data[:8] == b"\x89MCAP0\r\n" and data[-8:] == b"\x89MCAP0\r\n"   # header and footer magic
    custom = meta["custom_data"]
    assert json.loads(custom["composed_sim.robot_names"]) == NAMES
    assert float(custom["composed_sim.tick_s"]) == TICK_S
    assert int(custom["composed_sim.ticks"]) == TICKS     # the ticks simulated, as summary.json counts them
    # Sim time: the bag starts at tick 0 = 0 ns and lasts TICKS ticks.
    assert meta["starting_time"]["nanoseconds_since_epoch"] == 0
    assert meta["duration"]["nanoseconds"] == TICKS * TICK_NS


def test_topics_types_counts_and_sim_time_stamps(bag):
    messages, types = read_all(bag)
    assert types == {
        CLOCK_TOPIC: "rosgraph_msgs/msg/Clock",
        SWARM_STATE_TOPIC: "sensor_msgs/msg/PointCloud2",
        "/bot1/cmd_vel": "geometry_msgs/msg/TwistStamped",   # the glob /bot1*/cmd_vel only
        "/bot0/leds": "std_msgs/msg/UInt8MultiArray",
        "/bot1/leds": "std_msgs/msg/UInt8MultiArray",
        "/bot2/leds": "std_msgs/msg/UInt8MultiArray",
    }
    expected_ns = [k * TICK_NS for k in range(TICKS + 1)]
    for topic, rows in messages.items():
        assert [ns for ns, _ in rows] == expected_ns, topic
    for ns, clock in messages[CLOCK_TOPIC]:
        assert clock.clock.sec * 1_000_000_000 + clock.clock.nanosec == ns
    for ns, state in messages[SWARM_STATE_TOPIC]:
        assert state.header.stamp.sec * 1_000_000_000 + state.header.stamp.nanosec == ns
        assert state.header.frame_id == FRAME_ID
        assert state.width == len(NAMES) and state.point_step == STATE_DTYPE.itemsize
        assert [f.name for f in state.fields] == ["x", "y", "z", "yaw", "rgb", "id"]
    for ns, cmd in messages["/bot1/cmd_vel"]:
        assert cmd.header.stamp.sec * 1_000_000_000 + cmd.header.stamp.nanosec == ns
        assert cmd.twist.linear.x == pytest.approx(0.1) and cmd.twist.angular.z == 0.5


def test_swarm_state_reads_back_exactly(bag, run):
    positions, headings, leds = run
    stamps, pos, head, colors = read_swarm_states(bag)
    np.testing.assert_array_equal(stamps, np.arange(TICKS + 1) * TICK_NS)
    np.testing.assert_array_equal(pos, positions)          # float64 on the wire: bit-identical
    np.testing.assert_array_equal(head, headings)
    np.testing.assert_array_equal(colors, np.stack([display_colors(f) for f in leds]))
    assert tuple(colors[0, 0]) == (0, 0, 0) and tuple(colors[5, 0]) == (255, 0, 0)
    assert tuple(colors[5, 1]) == (0, 0, 255)
    assert tuple(colors[9, 2]) == (0, 0, 0) and tuple(colors[10, 2]) == (0, 255, 0)


def test_swarm_state_is_a_pointcloud_rclpy_decodes(bag):
    """The PointCloud2 is a plain message: rclpy (as RViz/Foxglove would) reads the points."""
    with Reader(bag) as reader:
        conn = next(c for c in reader.connections if c.topic == SWARM_STATE_TOPIC)
        raw = next(raw for _, _, raw in reader.messages(connections=[conn]))
    from sensor_msgs.msg import PointCloud2
    msg = deserialize_message(bytes(raw), PointCloud2)
    points = np.frombuffer(bytes(msg.data), dtype=STATE_DTYPE)
    np.testing.assert_array_equal(points["id"], np.arange(len(NAMES)))
    assert np.all(points["z"] == 0)


def test_recording_keeps_the_world_for_replay(tmp_path, run):
    world = world_from_dict({"name": "rec-test", "robots": [{"count": 3, "controller": "flocking"}],
                             "lights": [{"position": [0, 10]}]})
    record(tmp_path / "bag", *run, world=world, ticks=3)
    rec = read_recording(tmp_path / "bag")
    assert rec.world == world
    assert rec.names == NAMES and rec.tick_s == TICK_S
    assert rec.ticks.tolist() == [0, 1, 2, 3] and rec.ticks_done == 3


def test_interrupted_run_leaves_a_readable_bag(tmp_path, run):
    positions, headings, leds = run
    path = tmp_path / "interrupted"
    with pytest.raises(KeyboardInterrupt):
        with BagRecorder(path, robot_names=NAMES, tick_s=TICK_S) as rec:
            for k in range(8):
                rec.write_clock(k)
                rec.write_swarm_state(k * TICK_NS, positions[k], headings[k], leds[k])
            raise KeyboardInterrupt        # Ctrl-C in the middle of the run
    stamps, pos, _, _ = read_swarm_states(path)
    assert len(stamps) == 8
    np.testing.assert_array_equal(pos, positions[:8])
    messages, _ = read_all(path)
    assert len(messages[CLOCK_TOPIC]) == 8


def test_closed_mid_run_is_readable_and_refuses_more(tmp_path, run):
    positions, headings, leds = run
    rec = record(tmp_path / "partial", positions, headings, leds, ticks=4)   # 5 of 21 ticks
    assert rec.closed
    rec.close()                           # idempotent
    with pytest.raises(RecordingError, match="closed"):
        rec.write_clock(5)
    assert read_recording(tmp_path / "partial").ticks_done == 4


def test_wants_matches_globs_across_slashes(tmp_path):
    with BagRecorder(tmp_path / "g", robot_names=NAMES, tick_s=TICK_S,
                     topics_globs=["/bot1*/cmd_vel", "/*/leds"]) as rec:
        assert rec.wants("/bot1/cmd_vel") and rec.wants("/bot12/cmd_vel")
        assert not rec.wants("/bot2/cmd_vel") and not rec.wants("/bot1/cmd_vel/x")
        assert rec.wants("/bot0/leds") and rec.wants("/ns/bot0/leds")   # * also spans /
        assert rec.wants("/bot1/cmd_vel") is True                       # cached answer
        assert rec.write_message("/bot0/cmd_vel", TwistStamped(), 0) is False
    with BagRecorder(tmp_path / "none", robot_names=NAMES, tick_s=TICK_S) as rec:
        assert not rec.wants("/bot0/cmd_vel")


def test_type_missing_from_rosbags_typestore_is_loaded_from_its_msg_file(tmp_path):
    """nav_msgs/msg/Goals is not in rosbags' Jazzy store: its definition comes from the .msg."""
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Goals
    goals = Goals()
    pose = PoseStamped()
    pose.pose.position.x = 1.5
    goals.goals = [pose]
    with BagRecorder(tmp_path / "goals", robot_names=NAMES, tick_s=TICK_S,
                     topics_globs=["/*/goals"]) as rec:
        assert rec.write_message("/bot0/goals", goals, 7)
    typestore = get_typestore(Stores.ROS2_JAZZY)
    with Reader(tmp_path / "goals") as reader:
        conn = next(c for c in reader.connections if c.topic == "/bot0/goals")
        assert conn.msgtype == "nav_msgs/msg/Goals"
        typestore.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))   # the stored schema
        (_, ns, raw), = list(reader.messages(connections=[conn]))
    assert ns == 7 and typestore.deserialize_cdr(raw, conn.msgtype).goals[0].pose.position.x == 1.5


def test_recorder_refuses_existing_directory_and_bad_input(tmp_path):
    (tmp_path / "exists").mkdir()
    with pytest.raises(RecordingError, match="already exists"):
        BagRecorder(tmp_path / "exists", robot_names=NAMES, tick_s=TICK_S)
    with pytest.raises(ValueError, match="tick_s"):
        BagRecorder(tmp_path / "b", robot_names=NAMES, tick_s=0)
    with BagRecorder(tmp_path / "c", robot_names=NAMES, tick_s=TICK_S) as rec:
        with pytest.raises(ValueError, match=r"positions must be \[3, 2\]"):
            rec.write_swarm_state(0, np.zeros((2, 2)), np.zeros(3))
        with pytest.raises(ValueError, match=r"headings must be \[3\]"):
            rec.write_swarm_state(0, np.zeros((3, 2)), np.zeros(2))
        rec.write_swarm_state(0, np.zeros((3, 2)), np.zeros(3))      # still usable; no LEDs: dark
    assert read_swarm_states(tmp_path / "c")[3].tolist() == [[[0, 0, 0]] * 3]


def test_display_colors_prefers_the_beacon_then_the_first_lit_ring_led():
    leds = np.zeros((4, 13, 3), dtype=np.uint8)
    leds[0, 12] = (255, 0, 0)
    leds[0, 3] = (0, 255, 0)            # beacon wins
    leds[1, 5] = (0, 0, 255)
    leds[1, 7] = (9, 9, 9)              # the first lit ring LED
    leds[3, 0] = (1, 2, 3)
    assert display_colors(leds).tolist() == [[255, 0, 0], [0, 0, 255], [0, 0, 0], [1, 2, 3]]
    assert display_colors(leds[:, 12]).tolist() == leds[:, 12].tolist()   # [n, 3] passes through
    with pytest.raises(ValueError):
        display_colors(np.zeros((3, 4)))


# --- /swarm/markers ---------------------------------------------------------------------

def test_swarm_markers_one_list_for_all_robots(run):
    positions, headings, leds = run
    msg = swarm_markers(NAMES, positions[5], headings[5], leds[5], 0.085, stamp_of(5, TICK_NS))
    assert isinstance(msg, MarkerArray) and len(msg.markers) == 2
    bodies, lines = msg.markers
    assert bodies.type == Marker.SPHERE_LIST and lines.type == Marker.LINE_LIST
    assert bodies.header.frame_id == FRAME_ID and bodies.header.stamp == stamp_of(5, TICK_NS)
    assert len(bodies.points) == 3 and len(bodies.colors) == 3 and len(lines.points) == 6
    assert bodies.scale.x == pytest.approx(0.17)
    assert (bodies.colors[0].r, bodies.colors[0].g) == (1.0, 0.0)          # red beacon
    assert bodies.colors[2].b == pytest.approx(0.71, abs=1e-6)            # dark: default blue
    tip = np.array([lines.points[1].x, lines.points[1].y]) - positions[5, 0]
    np.testing.assert_allclose(np.arctan2(tip[1], tip[0]), headings[5, 0], atol=1e-9)


@pytest.mark.parametrize("n", [0, 1, 3, 40])
def test_swarm_markers_cdr_is_the_same_message(n):
    positions, headings, leds = synthetic_run(n=n, ticks=1, seed=n)
    names = [f"r{i}" for i in range(n)]
    args = (names, positions[1], headings[1], leds[1], 0.085, stamp_of(1, TICK_NS))
    fast = deserialize_message(swarm_markers_cdr(*args), MarkerArray)
    assert fast == swarm_markers(*args)


def test_marker_bytes_go_into_the_bag(tmp_path, run):
    positions, headings, leds = run
    with BagRecorder(tmp_path / "m", robot_names=NAMES, tick_s=TICK_S,
                     topics_globs=["/swarm/markers"]) as rec:
        data = swarm_markers_cdr(NAMES, positions[0], headings[0], leds[0], 0.085, stamp_of(0, TICK_NS))
        assert rec.write_serialized("/swarm/markers", "visualization_msgs/msg/MarkerArray", data, 0)
    messages, types = read_all(tmp_path / "m")
    assert types["/swarm/markers"] == "visualization_msgs/msg/MarkerArray"
    (_, markers), = messages["/swarm/markers"]
    assert len(markers.markers[0].points) == 3


def test_close_if_idle_for_a_hard_exit(tmp_path, run):
    """A second Ctrl-C ends the process at once: the handler closes the bag first if it can."""
    positions, headings, leds = run
    rec = BagRecorder(tmp_path / "hard", robot_names=NAMES, tick_s=np.float64(0.1))
    rec.write_clock(0)
    rec.write_swarm_state(0, positions[0], headings[0], leds[0])
    rec._busy = True                       # as if the signal arrived in the middle of a write
    assert rec.close_if_idle() is False and not rec.closed
    rec._busy = False
    assert rec.close_if_idle() is True and rec.closed
    assert len(read_swarm_states(tmp_path / "hard")[0]) == 1
