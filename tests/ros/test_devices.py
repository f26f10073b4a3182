"""The devices over ROS: each new message round-trips, a robot has exactly its devices' topics,
and range-and-bearing messages reach exactly the robots in range one tick later."""
import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState, LaserScan, PointCloud2
from std_msgs.msg import UInt8MultiArray

from composed_sim.world.robot_models import FOOTBOT, TURTLEBOT3_BURGER
from composed_sim.devices import (differential_steering, ground, lidar, odometry, positioning, proximity,
                                  range_and_bearing)
from composed_sim.devices.common import cdr
from composed_sim.ros import contract as c, decoding
from composed_sim.world.schema import World


STAMP = c.stamp_of(7, 100_000_000)
STAMP_CDR = cdr.stamp_bytes(STAMP.sec, STAMP.nanosec)


def test_ground_round_trip_keeps_sensor_positions_and_readings():
    offsets = np.asarray(FOOTBOT.ground.offsets_m)
    readings = np.array([[0.0, 0.25, 0.5, 1.0], [1.0, 1.0, 0.0, 0.0]])
    points = ground.points_of(offsets, readings)
    data = ground.encoder("bot1").encode(STAMP.sec, STAMP.nanosec, points[1].tobytes(), len(points[1]))
    msg = deserialize_message(data, PointCloud2)
    assert (msg.width, msg.point_step, msg.header.frame_id) == (4, 16, "bot1/base_link")
    np.testing.assert_array_equal(ground.decode(data), readings[1])
    cloud = np.frombuffer(msg.data, dtype=ground.GROUND_DTYPE)
    np.testing.assert_allclose(np.column_stack([cloud["x"], cloud["y"]]), offsets, atol=1e-7)


def test_scan_round_trip_keeps_rep117_infinities_and_ray_angles():
    layout = TURTLEBOT3_BURGER.lidar
    ranges = np.linspace(0.2, 3.0, layout.n_rays)
    ranges[[0, 5]] = np.inf
    ranges[7] = -np.inf
    data = lidar.encoder(layout, "tb0", 0.1).encode(STAMP.sec, STAMP.nanosec, np.zeros(0), ranges)
    msg = deserialize_message(data, LaserScan)
    assert msg.header.frame_id == "tb0/base_scan" and (msg.range_min, msg.range_max) == pytest.approx((0.12, 3.5))
    np.testing.assert_allclose(lidar.decode(data), ranges.astype(np.float32))
    angles = msg.angle_min + msg.angle_increment * np.arange(len(msg.ranges))
    np.testing.assert_allclose(angles, layout.angles_array(), atol=1e-6)
    assert angles[90] == pytest.approx(math.pi / 2, abs=1e-6)


def test_rab_round_trip_range_bearing_elevation_and_payload_bytes():
    rng = np.random.default_rng(1)
    m, b = 5, 10
    ranges, bearings, elevations = rng.uniform(0.1, 3, m), rng.uniform(-3, 3, m), rng.uniform(-0.2, 0.2, m)
    payloads = rng.integers(0, 256, (m, b), dtype=np.uint8)
    points = range_and_bearing.points_of(ranges, bearings, elevations, payloads)
    encoder = range_and_bearing.encoder("bot0", b)
    data = encoder.encode(STAMP.sec, STAMP.nanosec, points[1:4].tobytes(), 3)
    msg = deserialize_message(data, PointCloud2)
    assert msg.point_step == 24 + b and msg.width == 3
    got = range_and_bearing.decode(data)
    assert len(got) == 3
    np.testing.assert_allclose(got.ranges, ranges[1:4], rtol=1e-6)
    np.testing.assert_allclose(got.bearings, bearings[1:4], rtol=1e-6)
    np.testing.assert_allclose(got.elevations, elevations[1:4], rtol=1e-6)
    np.testing.assert_array_equal(got.payloads, payloads[1:4])
    xyz = np.frombuffer(msg.data, dtype=range_and_bearing.point_dtype(b))
    np.testing.assert_allclose(np.hypot(np.hypot(xyz["x"], xyz["y"]), xyz["z"]), ranges[1:4], rtol=1e-5)
    np.testing.assert_allclose(np.arctan2(xyz["y"], xyz["x"]), bearings[1:4], atol=1e-5)
    assert len(range_and_bearing.decode(encoder.encode(STAMP.sec, STAMP.nanosec, b"", 0))) == 0


def test_rab_tx_round_trip_and_wrong_size_names_the_setting():
    payload = bytes(range(10))
    sent = c.payload_encoder(10).encode(payload)
    assert deserialize_message(sent, UInt8MultiArray) == c.payload_message(payload)
    for data in (sent, serialize_message(c.payload_message(payload))):
        np.testing.assert_array_equal(decoding.decode_payload(data, 10), np.arange(10))
    with pytest.raises(ValueError, match=r"has 3 bytes, expected 10 \(range_and_bearing.payload_bytes"):
        decoding.decode_payload(serialize_message(c.payload_message([1, 2, 3])), 10)
    for cut in (6, 20, len(sent) - 3):           # bytes that end inside the message
        with pytest.raises(ValueError):
            decoding.decode_payload(sent[:cut], 10)


def test_pose_odometry_and_wheels_round_trip():
    qz, qw = c.half_yaw(np.array([2.5]))
    data = positioning.encoder().encode(STAMP_CDR, 1.5, -2.0, 0.0, float(qz[0]), float(qw[0]))
    assert deserialize_message(data, PoseStamped).header.frame_id == "world"
    np.testing.assert_allclose(positioning.decode(data), [1.5, -2.0, 2.5])
    qz, qw = c.half_yaw(np.array([-3.0]))
    data = odometry.encoder("bot2").encode(STAMP_CDR, 0.3, 0.4, float(qz[0]), float(qw[0]), 0.05, -0.2)
    odom = deserialize_message(data, Odometry)
    assert (odom.header.frame_id, odom.child_frame_id) == ("bot2/odom", "bot2/base_link")
    p, t = odometry.decode(data)
    np.testing.assert_allclose(p, [0.3, 0.4, -3.0])
    np.testing.assert_allclose(t, [0.05, -0.2])
    r = FOOTBOT.wheel_radius_m
    data = differential_steering.encoder("bot2").encode(STAMP_CDR, *(np.array([1.0, 2.0]) / r),
                                                        *(np.array([0.05, 0.1]) / r))
    assert list(deserialize_message(data, JointState).name) == ["wheel_left_joint", "wheel_right_joint"]
    speeds, travel = differential_steering.decode(data, r)
    np.testing.assert_allclose(speeds, [0.05, 0.1])
    np.testing.assert_allclose(travel, [1.0, 2.0])


def world_with(groups: list[dict], **extra) -> World:
    return World.model_validate({"name": "t", "seed": 3, "arena": {"size": [6.0, 6.0]},
                                 "robots": groups, **extra})


def test_a_robot_has_the_topics_of_the_devices_it_runs():
    from composed_sim.ros.robot_settings import robot_devices
    world = world_with([
        {"model": "foot-bot", "count": 1, "controller": "x"},
        {"model": "e-puck", "count": 1, "name_prefix": "ep", "controller": "x",
         "devices": {"range_and_bearing": {}, "odometry": {}}},
        {"model": "turtlebot3-burger", "count": 1, "name_prefix": "tb", "controller": "x",
         "devices": {"positioning": {}, "differential_steering": {"enabled": False}}},
    ])
    names = [[t.name for t in c.robot_topics(d)] for d in robot_devices(world)]
    assert names == [["proximity", "light", "blobs", "cmd_vel", "leds"],
                     ["proximity", "ground", "rab_rx", "odom", "cmd_vel", "leds", "rab_tx"],
                     ["scan", "pose", "cmd_vel", "leds"]]


POSITIONS = [(0.0, 0.0), (0.7, 0.3), (2.0, 0.0), (0.0, 0.9), (3.5, 0.0)]
RAB_RANGE_M = 1.0


def test_rab_messages_reach_exactly_the_robots_in_range_one_tick_later(rab_echo_plugin, domain_id):
    from composed_sim.hosts.composed import ComposedHost
    world = world_with([{
        "model": "foot-bot", "count": len(POSITIONS), "controller": rab_echo_plugin,
        "placement": {"method": "explicit", "positions": POSITIONS},
        "heading": {"method": "constant", "value_rad": 0.0},
        "devices": {"light": {"enabled": False}, "camera": {"enabled": False},
                    "range_and_bearing": {"range_m": RAB_RANGE_M}, "positioning": {}}}],
        length_ticks=6)
    with ComposedHost(world, executor="lockstep", domain_id=domain_id) as host:
        result = host.run()
        heard = [node.heard for node in host.controllers]
        poses = [node.poses for node in host.controllers]
    assert result.violations == []
    p = np.asarray(POSITIONS)
    dist = np.linalg.norm(p[:, None] - p[None], axis=2)
    in_range = [[j for j in range(len(p)) if j != i and dist[i, j] < RAB_RANGE_M] for i in range(len(p))]
    assert in_range == [[1, 3], [0, 3], [], [0, 1], []]    # the layout tests both sides of the range
    for i in range(len(p)):
        assert heard[i][0] == []                               # nothing was sent before tick 0
        np.testing.assert_allclose(poses[i][3], [*p[i], 0.0], atol=1e-9)   # still: pose = placement
        for k in range(1, 6):
            got = heard[i][k]
            # Each neighbour in range, once, with the payload it set one tick earlier.
            assert [(s, t) for s, t, _, _ in got] == [(j, k - 1) for j in in_range[i]], (i, k, got)
            for (j, _, r, b) in got:
                assert r == pytest.approx(dist[i, j], abs=1e-5)
                assert b == pytest.approx(math.atan2(*(p[j] - p[i])[::-1]), abs=1e-5)


def take(sub):
    """The message waiting on a subscription (delivery inside one context is synchronous)."""
    taken = sub.handle.take_message(sub.msg_type, sub.raw)
    assert taken is not None, f"nothing on {sub.topic_name}"
    return taken[0]


def test_a_node_serving_some_rows_of_a_mixed_swarm_publishes_each_robot_its_own_readings(ros_context):
    """As a multi-process domain does: rows from three groups; each topic carries that robot's row
    of its group's arrays, and a robot has no topic of a device it does not run."""
    from rclpy.node import Node
    from composed_sim.core.simulation import Simulation
    from composed_sim.ros.robot_settings import robot_devices
    from composed_sim.ros.simulator_node import SimulatorNode
    world = world_with([
        {"model": "foot-bot", "count": 3, "controller": "x", "devices": {"ground": {}, "odometry": {}}},
        {"model": "e-puck", "count": 3, "name_prefix": "ep", "controller": "x",
         "devices": {"range_and_bearing": {}, "positioning": {}}},
        {"model": "turtlebot3-burger", "count": 2, "name_prefix": "tb", "controller": "x",
         "devices": {"differential_steering": {}}},
    ], floor={"shapes": [{"type": "circle", "position": [0.0, 0.0], "radius_m": 1.0, "color": [0, 0, 0]}]},
        range_and_bearing={"mode": "global"})
    sim = Simulation(world)
    sim.set_wheel_speeds(np.full(sim.n, 0.05), np.full(sim.n, 0.07))
    for i in range(sim.n):
        sim.set_rab_payload(i, bytes([i] * 10))
    frame = sim.step()
    rows = np.array([1, 4, 5, 7])                      # bot1, ep1, ep2, tb1
    devices = robot_devices(world)
    node = SimulatorNode([sim.names[r] for r in rows], [sim.models[r] for r in rows], context=ros_context,
                         tick_ns=world.tick_ns, rows=rows, devices=[devices[r] for r in rows])
    listener = Node("listener", context=ros_context)
    subs = {(robot, t.name): listener.create_subscription(c.msg_type(t), c.topic_name(robot, t), lambda m: None, c.QOS,
                                                          raw=True)
            for robot in ("bot1", "ep1", "ep2", "tb1") for t in c.SENSOR_TOPICS}
    try:
        published = {(robot, t) for (robot, t), sub in subs.items() if sub.get_publisher_count() > 0}
        assert published == {("bot1", "proximity"), ("bot1", "light"), ("bot1", "blobs"), ("bot1", "ground"),
                              ("bot1", "odom"), ("ep1", "proximity"), ("ep1", "ground"), ("ep1", "rab_rx"),
                              ("ep1", "pose"), ("ep2", "proximity"), ("ep2", "ground"), ("ep2", "rab_rx"),
                              ("ep2", "pose"), ("tb1", "scan"), ("tb1", "wheels")}
        node.publish_tick(frame)
        fb, ep, tb = frame.groups
        np.testing.assert_allclose(ground.decode(take(subs["bot1", "ground"])), fb.ground[1], atol=1e-6)
        np.testing.assert_allclose(proximity.decode(take(subs["bot1", "proximity"]))[1], fb.proximity[1], atol=1e-6)
        odom, twist = odometry.decode(take(subs["bot1", "odom"]))
        np.testing.assert_allclose(odom, frame.odometry[1], atol=1e-12)
        np.testing.assert_allclose(twist, frame.odometry_twist[1], atol=1e-12)
        for robot, row in (("ep1", 4), ("ep2", 5)):
            np.testing.assert_allclose(ground.decode(take(subs[robot, "ground"])), ep.ground[row - 3], atol=1e-6)
            np.testing.assert_allclose(positioning.decode(take(subs[robot, "pose"])),
                                       [*frame.pose.positions[row, :2], frame.pose.yaws[row]], atol=1e-9)
            heard = range_and_bearing.decode(take(subs[robot, "rab_rx"]))
            senders = frame.range_and_bearing.of(row)[0]
            # Global medium: the other e-pucks, payload = the sender's index set before the step.
            assert sorted(senders.tolist()) == [3, 4, 5][:row - 3] + [3, 4, 5][row - 2:]
            assert sorted(heard.payloads[:, 0].tolist()) == sorted(senders.tolist())
        np.testing.assert_allclose(lidar.decode(take(subs["tb1", "scan"])), tb.lidar[1], rtol=1e-6)
        speeds, travel = differential_steering.decode(take(subs["tb1", "wheels"]), TURTLEBOT3_BURGER.wheel_radius_m)
        np.testing.assert_allclose(speeds, [0.05, 0.07])
        np.testing.assert_allclose(travel, frame.wheels.distances_m[7])
    finally:
        listener.destroy_node()
        node.destroy_node()


def test_a_rab_payload_of_the_wrong_size_is_a_violation_naming_the_setting(ros_context):
    from rclpy.node import Node
    from composed_sim.ros.simulator_node import SimulatorNode
    node = SimulatorNode(["bot0", "bot1"], [FOOTBOT, FOOTBOT], context=ros_context, tick_ns=100_000_000,
                         devices=[{"range_and_bearing"}, {"range_and_bearing"}], rab_payload_bytes=4)
    sender = Node("sender", context=ros_context)
    try:
        good = sender.create_publisher(c.msg_type(c.RAB_TX), "/bot0/rab_tx", c.QOS)
        bad = sender.create_publisher(c.msg_type(c.RAB_TX), "/bot1/rab_tx", c.QOS)
        good.publish(c.payload_message(b"\x01\x02\x03\x04"))
        good.publish(c.payload_message(b"\x05\x06\x07\x08"))          # the latest counts
        bad.publish(c.payload_message(b"\x01\x02\x03"))
        payloads = node.take_rab_payloads()
        assert list(payloads) == [0] and payloads[0].tolist() == [5, 6, 7, 8]
        assert [(v.robot, v.reason) for v in node.violations] == [
            ("bot1", "rab_tx: rab_tx message has 3 bytes, expected 4 (range_and_bearing.payload_bytes of the world file)")]
    finally:
        sender.destroy_node()
        node.destroy_node()


def test_a_controller_needing_a_sensor_its_robot_lacks_is_a_clear_error(domain_id):
    from composed_sim import plugins
    from composed_sim.hosts.composed import ComposedHost
    world = world_with([{"model": "turtlebot3-burger", "count": 1, "name_prefix": "tb", "controller": "diffusion"}])
    with pytest.raises(plugins.PluginError, match=r"failed to construct for tb0: ValueError: DiffusionController "
                       r"needs the sensor topic\(s\) proximity, which tb0 \(a turtlebot3-burger\) does not have; "
                       r"its sensor topics: scan\. Switch the device on"):
        with ComposedHost(world, domain_id=domain_id):
            pass


def test_a_sensor_topic_goes_out_from_the_tick_after_its_first_subscriber(ros_context):
    """A topic nobody reads costs a matched-count query, not a message; a subscriber that comes
    gets every tick from then on. The writer's sequence numbers show what was published."""
    from rclpy.node import Node
    from composed_sim.core.simulation import Simulation
    from composed_sim.ros.simulator_node import SimulatorNode
    world = world_with([{"model": "foot-bot", "count": 2, "controller": "x"}])
    sim = Simulation(world)
    node = SimulatorNode(sim.names, sim.models, context=ros_context, tick_ns=world.tick_ns)
    listener = Node("listener", context=ros_context)
    light_sub = listener.create_subscription(c.msg_type(c.LIGHT), c.topic_name("bot1", c.LIGHT), lambda m: None, c.QOS)
    frame = sim.sense()
    node.publish_tick(frame)                                   # tick 0: bot1's light is read, its proximity not
    assert take(light_sub).header.stamp == c.stamp_of(0, world.tick_ns)
    proximity_sub = listener.create_subscription(c.msg_type(c.PROXIMITY), c.topic_name("bot1", c.PROXIMITY),
                                                 lambda m: None, c.QOS)
    for tick in (1, 2, 3):
        frame = sim.step()
        node.publish_tick(frame)
        for sub, sequence in ((light_sub, tick + 1), (proximity_sub, tick)):
            msg, info = sub.handle.take_message(sub.msg_type, sub.raw)
            assert c.stamp_key(msg.header.stamp) == tick * world.tick_ns
            assert info["publication_sequence_number"] == sequence, (sub.topic_name, tick)
    np.testing.assert_allclose(proximity.decode(serialize_message(msg))[1], frame.groups[0].proximity[1], atol=1e-6)
    node.destroy_node()
    listener.destroy_node()


def test_a_node_converts_exactly_its_robots_entries_of_csr_readings():
    """Blobs and range-and-bearing messages are CSR by robot; a node takes its robots' entries,
    as a slice for contiguous rows (a shard) and gathered otherwise (explicit domains)."""
    from composed_sim.devices.common.device import csr_take
    counts = np.array([2, 0, 3, 1, 4, 0, 2])
    offsets = np.concatenate([[0], np.cumsum(counts)])
    entries = np.arange(offsets[-1]) * 10
    for rows in ([0, 1, 2], [2, 3, 4], [0, 2, 6], [1, 5], [6], [3, 4, 5, 6]):
        rows = np.array(rows)
        take, local = csr_take(offsets, rows)
        got = entries[take]
        assert local.tolist() == [0, *np.cumsum(counts[rows]).tolist()]
        for k, r in enumerate(rows):
            assert got[local[k]:local[k + 1]].tolist() == entries[offsets[r]:offsets[r + 1]].tolist()


def test_a_reading_handed_beside_its_message_is_the_one_its_reader_decodes_bit_for_bit(ros_context, monkeypatch):
    """In process, the simulator hands each sensor message's reading beside its bytes
    (devices/common/handoff.py): for every device that does, the reading equals the reader's decode
    of the bytes bit for bit (values, dtype, shape), the first reader takes it and any other
    decodes its own; without in-process delivery nothing is handed."""
    from composed_sim.core.simulation import Simulation
    from composed_sim.devices import BY_SENSOR_TOPIC
    from composed_sim.devices.common.device import DevicePublisher
    from composed_sim.devices.common import handoff
    from composed_sim.devices.common.handoff import take_reading
    from composed_sim.ros.controller import Tick
    from composed_sim.ros.robot_settings import robot_devices
    from composed_sim.ros.simulator_node import SimulatorNode
    world = world_with([
        {"model": "foot-bot", "count": 12, "controller": "x", "devices": {"ground": {}},
         "placement": {"method": "grid", "spacing_m": 0.4}},
        {"model": "turtlebot3-burger", "count": 3, "name_prefix": "tb", "controller": "x"},
        {"model": "e-puck", "count": 4, "name_prefix": "ep", "controller": "x", "devices": {"range_and_bearing": {}}},
    ], floor={"shapes": [{"type": "circle", "position": [0.0, 0.0], "radius_m": 1.0, "color": [0, 0, 0]}]},
        range_and_bearing={"mode": "global"})
    sim = Simulation(world)
    for i in range(15, 19):
        sim.set_rab_payload(i, bytes([i] * 10))
    for i in range(0, 12, 2):          # some beacons lit: clouds of several blobs, and empty ones
        colors = np.zeros((sim.models[i].n_leds, 3), dtype=np.uint8)
        colors[-1] = (255, 0, 0)
        sim.set_led_colors(i, colors)
    sim.set_wheel_speeds(np.full(sim.n, 0.05), np.full(sim.n, 0.07))
    frames = [sim.step(), sim.step()]
    sent = []
    original = DevicePublisher.send_all
    monkeypatch.setattr(DevicePublisher, "send_all", lambda self, rows, messages, out:
                        (sent.extend((self.topic.name, self.node.robots[i], m) for i, m in zip(rows, messages)),
                         original(self, rows, messages, out)))
    node = SimulatorNode(sim.names, sim.models, context=ros_context, tick_ns=world.tick_ns,
                         devices=robot_devices(world))
    try:
        for publisher in node.device_publishers():     # as if each topic had a reader
            publisher._read = [p is not None for p in publisher.pubs]
            publisher.checking = False
        node.publish_tick(frames[0])
        assert sent and all(take_reading(m) is None for _, _, m in sent)
        sent.clear()
        for publisher in node.device_publishers():
            publisher.hands_readings = True
        node.publish_tick(frames[1])
    finally:
        node.destroy_node()
    readers = {(topic, robot): BY_SENSOR_TOPIC[topic].reader(sim.models[sim.names.index(robot)]) for topic, robot, _ in sent}
    handed, blobs_seen, heard = set(), 0, 0
    for topic, robot, message in sent:
        read = readers[topic, robot]
        if id(message) in handoff._places:
            handed.add(topic)
        taken, second, decoded = Tick.at(0, 0), Tick.at(0, 0), Tick.at(0, 0)
        read(bytes(bytearray(message)), decoded)      # another object of the same bytes: decoded
        read(message, taken)                          # the reading handed with the message …
        read(message, second)                         # … taken once: decoded
        for field in BY_SENSOR_TOPIC[topic].tick_fields:
            for tick in (taken, second):
                a, b = getattr(decoded, field), getattr(tick, field)
                if field == "blobs":
                    blobs_seen += len(a)
                    a, b = (a.angles, a.distances, a.rgb), (b.angles, b.distances, b.rgb)
                elif field == "rab":
                    heard += len(a)
                    a, b = (a.ranges, a.bearings, a.elevations, a.payloads), (b.ranges, b.bearings, b.elevations, b.payloads)
                else:
                    a, b = (a,), (b,)
                for x, y in zip(a, b):
                    assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), (topic, robot, field)
    assert blobs_seen > 0 and heard > 0 and handed == {"proximity", "light", "blobs", "ground", "scan", "rab_rx"}
