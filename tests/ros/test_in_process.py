"""In-process delivery (ros/in_process.py): with the lockstep executor a robot's sensor messages
and its answers skip DDS while nothing else listens, and go through DDS for a topic as soon as
something does; the run is the same either way."""
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from composed_sim.devices.common import cdr, device
from composed_sim.devices.common.device import Outgoing
from composed_sim.hosts.composed import ComposedHost
from composed_sim.ros import in_process
from composed_sim.ros.controller import SwarmController
from composed_sim.hosting.executors.lockstep import LockstepExecutor
from composed_sim.ros.rcl_graph import GraphChanges
from composed_sim.world.loader import load_world
from listener import Listener

FLOCKING = Path(__file__).resolve().parents[2] / "worlds" / "flocking.yaml"
TICKS = 12


def _run(domain, listen=None):
    """Flocking, 4 robots; with ``listen`` (a Listener), tick 0 starts once the listener is matched
    with bot1's light publisher and its controller's cmd_vel publisher."""
    world = load_world(FLOCKING, robots=4, ticks=TICKS, seed=2)
    with ComposedHost(world, domain_id=domain) as host:
        links = {link.topic: link for link in host.groups.links}
        if listen is not None:
            listen.wait_matched()
            watched = [links["/bot1/light"], links["/bot1/cmd_vel"]]
            deadline = time.monotonic() + 30     # … on the run's side too (discovery is two-way)
            while any(link.matched() < 2 for link in watched) and time.monotonic() < deadline:
                time.sleep(0.01)
        result = host.run()
        if listen is not None:     # the reliable writers' last samples reach it before they go
            for link in watched:
                assert link.publisher.wait_for_all_acked(Duration(seconds=30))
        delivered = {topic: link.in_process for topic, link in links.items()}
    return result.trajectories, delivered


def _count_shortcuts(monkeypatch) -> dict:
    """Counts, per robot, the calls that hand a controller its tick's sensor messages at once
    (``lockstep_batch``) and the readings it took as handed instead of decoding
    (devices/common/handoff.py)."""
    counts = {"batched": Counter(), "handed": Counter()}
    on_sensors, take_reading = SwarmController._on_sensors, device.take_reading

    def batched(node, messages):
        counts["batched"][node.robot] += 1
        return on_sensors(node, messages)

    def taken(data):
        reading = take_reading(data)
        counts["handed"][cdr.stamp_ns(data)] += reading is not None
        return reading
    monkeypatch.setattr(SwarmController, "_on_sensors", batched)
    monkeypatch.setattr(device, "take_reading", taken)
    return counts


def test_an_outside_listener_hears_every_tick_and_the_run_is_the_same(domain_id, monkeypatch):
    counts = _count_shortcuts(monkeypatch)
    alone, delivered = _run(domain_id)
    # Nothing outside listens: every sensor message and answer of the run went in process, each
    # controller got its light and blobs in one call and took both readings as handed.
    assert delivered["/bot1/light"] == delivered["/bot1/cmd_vel"] == delivered["/bot0/blobs"] == TICKS
    assert counts["batched"] == {f"bot{i}": TICKS for i in range(4)}
    assert set(counts["handed"].values()) == {4 * 2}
    counts["batched"].clear()
    counts["handed"].clear()

    listener = Listener(domain_id, ["/bot1/light=sensor_msgs/msg/LaserScan",
                                    "/bot1/cmd_vel=geometry_msgs/msg/TwistStamped"])
    heard_run, delivered = _run(domain_id, listener)
    got = listener.stop()["got"]
    ticks = [t * 100_000_000 for t in range(TICKS)]
    assert [cdr.stamp_ns(bytes.fromhex(m)) for m in got["/bot1/light=sensor_msgs/msg/LaserScan"]] == ticks
    assert [cdr.stamp_ns(bytes.fromhex(m)) for m in got["/bot1/cmd_vel=geometry_msgs/msg/TwistStamped"]] == ticks
    # bot1's two topics went through DDS; the others stayed in process
    assert delivered["/bot1/light"] == delivered["/bot1/cmd_vel"] == 0
    assert delivered["/bot1/blobs"] == delivered["/bot0/light"] == delivered["/bot0/cmd_vel"] == TICKS
    # bot1 took its light from DDS: its messages one by one, that reading decoded
    assert counts["batched"] == {f"bot{i}": TICKS for i in (0, 2, 3)}
    assert set(counts["handed"].values()) == {4 * 2 - 1}

    monkeypatch.setenv(in_process.SWITCH_ENV, "0")
    through_dds, delivered = _run(domain_id)
    assert delivered == {}
    for run in (heard_run, through_dds):
        assert np.array_equal(run.positions, alone.positions) and np.array_equal(run.headings, alone.headings)
        assert np.array_equal(run.led_colors, alone.led_colors)


@pytest.fixture
def node(ros_context):
    node = Node("in_process_test", context=ros_context)
    yield node
    node.destroy_node()


def _spin(executor, times=3):
    for _ in range(times):
        executor.dispatch_ready()


def test_a_link_follows_the_matched_count_and_keeps_the_subscriptions_depth(node):
    publisher = node.create_publisher(String, "chatter", 10)
    got, other = [], []
    sub = node.create_subscription(String, "chatter", got.append, QoSProfile(depth=2))
    links = in_process.link_subscriptions([publisher], [sub])
    executor = LockstepExecutor(context=node.context)
    executor.add_node(node)
    for text in "abc":
        publisher.publish(String(data=text))
    assert links[0].in_process == 3
    _spin(executor)
    assert [m.data for m in got] == ["b", "c"]            # keep-last 2, as its DDS history would
    assert got[0] is not got[1]

    # A second subscription that is not linked matches: DDS carries the messages to both.
    node.create_subscription(String, "chatter", other.append, 10)
    deadline = time.monotonic() + 10
    while publisher.get_subscription_count() < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    got.clear()
    publisher.publish(String(data="d"))
    _spin(executor)
    assert links[0].in_process == 3
    assert [m.data for m in got] == ["d"] and [m.data for m in other] == ["d"]
    executor.shutdown()


def test_what_dds_would_treat_otherwise_is_not_linked(node):
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    best_effort = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    cases = [  # (publisher QoS, subscription QoS, with message info, linked?)
        (10, 10, False, True),
        (10, best_effort, False, True),                  # best effort takes a reliable offer
        (best_effort, 10, False, False),                 # … not the other way round
        (latched, 10, False, False),                     # an outside late joiner expects the history
        (10, QoSProfile(depth=3, history=HistoryPolicy.KEEP_ALL), False, True),
        (10, 10, True, False),                           # its callback wants DDS's message info
    ]
    for k, (offered, requested, with_info, linked) in enumerate(cases):
        publisher = node.create_publisher(String, f"t{k}", offered)
        callback = (lambda msg, info: None) if with_info else (lambda msg: None)
        sub = node.create_subscription(String, f"t{k}", callback, requested)
        assert bool(in_process.link_subscriptions([publisher], [sub])) == linked, k


def test_graph_changes_counts_each_participants_changes_until_closed(domain_id):
    """A thread counts the graph changes of each node's participant: a node's own new endpoint
    is a change of its graph; ``close`` ends the thread at once."""
    import rclpy
    from rclpy.context import Context

    contexts = [Context(), Context()]
    for context in contexts:
        rclpy.init(context=context, domain_id=domain_id)
    nodes = [Node(f"graph_{k}", context=context) for k, context in enumerate(contexts)]
    changes = GraphChanges(nodes)
    changed = [changes.poll(0), changes.poll(1)]
    try:
        assert changed[0]() and changed[1]()         # since the nodes were created
        deadline = time.monotonic() + 30
        while changed[1]() and time.monotonic() < deadline:    # until a look finds no change
            time.sleep(0.05)
        assert time.monotonic() < deadline, "node 1's graph never settled"
        nodes[1].create_publisher(String, "graph_changes", 10)
        deadline = time.monotonic() + 30
        while not changed[1]() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert time.monotonic() < deadline, "node 1's new publisher was never counted"
        started = time.monotonic()
        changes.close()
        assert time.monotonic() - started < 1.0 and not changes._thread.is_alive()
    finally:
        changes.close()
        for node, context in zip(nodes, contexts):
            node.destroy_node()
            rclpy.shutdown(context=context)


def test_a_listener_that_comes_after_the_graph_settled_gets_every_tick_from_then_on(node, domain_id):
    # The link keeps its last answer while the graph is quiet; a subscriber in another process
    # changes the graph, and the links ask DDS again.
    publisher = node.create_publisher(String, "chatter", 10)
    got = []
    sub = node.create_subscription(String, "chatter", got.append, 10)
    links = in_process.link_subscriptions([publisher], [sub])
    changes = GraphChanges([node])
    watch = in_process.GraphWatch(changes.poll(0), links, [in_process.inbox_of(sub)])
    executor = LockstepExecutor(context=node.context)
    executor.add_node(node)
    clock = [0.0]                         # the watch's ticks, on a clock of the test's own

    def tick(text):
        clock[0] += 1.0
        watch.start_tick(clock[0])
        publisher.publish(String(data=text))
        _spin(executor)

    for k in range(4):                    # the graph settles: no more asking
        tick(f"quiet {k}")
    assert not links[0].checking and links[0].in_process == 4

    listener = Listener(domain_id, ["/chatter=std_msgs/msg/String"])     # another process
    listener.wait_matched()
    deadline = time.monotonic() + 20
    while publisher.get_subscription_count() < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert publisher.get_subscription_count() == 2
    for k in range(3):
        tick(f"heard {k}")
    assert publisher.wait_for_all_acked(Duration(seconds=30))
    heard = listener.stop()["got"]["/chatter=std_msgs/msg/String"]
    assert [deserialize_message(bytes.fromhex(m), String).data for m in heard] == ["heard 0", "heard 1", "heard 2"]
    assert links[0].in_process == 4          # the three went through DDS, to both
    assert [m.data for m in got] == [f"quiet {k}" for k in range(4)] + ["heard 0", "heard 1", "heard 2"]
    changes.close()
    executor.shutdown()


def test_a_topic_nobody_read_is_published_once_a_listener_comes_after_the_graph_settled(domain_id):
    # The flocking controllers do not read their proximity rings: the simulator publishes nothing
    # there, and stops asking DDS for readers once the graph is quiet; a listener in another
    # process changes the graph, and from then on it hears every tick.
    world = load_world(FLOCKING, robots=4, ticks=TICKS, seed=2)
    with ComposedHost(world, domain_id=domain_id) as host:
        proximity = next(p for node in host.simulator_nodes for p in node.device_publishers()
                         if p.topic.name == "proximity")
        deadline = time.monotonic() + 30
        while proximity.checking and time.monotonic() < deadline:     # the graph settles
            host.run(1)
        assert not proximity.checking and not any(proximity.wanted(i, _outgoing(4)) for i in range(4))

        listener = Listener(domain_id, ["/bot1/proximity=sensor_msgs/msg/LaserScan"])
        listener.wait_matched()
        deadline = time.monotonic() + 30
        while proximity.pubs[1].get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        host.run(TICKS)
        assert proximity.pubs[1].wait_for_all_acked(Duration(seconds=30))
        assert not proximity.wanted(0, _outgoing(4))     # bot0's ring is still read by nobody
        heard = listener.stop()["got"]["/bot1/proximity=sensor_msgs/msg/LaserScan"]
    stamps = [cdr.stamp_ns(bytes.fromhex(m)) for m in heard]
    assert len(stamps) == TICKS and np.all(np.diff(stamps) == world.tick_ns)


def _outgoing(robots):
    return Outgoing(0, 0, 0, cdr.stamp_bytes(0, 0), [False] * robots, 0)


def test_a_batch_takes_its_subscriptions_messages_in_one_call_only_when_all_wait_in_process(node):
    """``lockstep_batch`` (ros/controller.py): one call with a message of each subscription when
    every one has one waiting in its inbox; otherwise each subscription's own callback, as without
    the batch. An empty batch is no batch."""
    publishers = [node.create_publisher(String, topic, 10) for topic in ("a", "b")]
    one_by_one, batched = [], []
    subs = [node.create_subscription(String, topic, lambda m, t=topic: one_by_one.append((t, m.data)), 10)
            for topic in ("a", "b")]
    in_process.link_subscriptions(publishers, subs)
    node.lockstep_batch = (tuple(subs), lambda messages: batched.append([m.data for m in messages]))
    executor = LockstepExecutor(context=node.context)
    executor.add_node(node)
    try:
        for link_publisher, text in zip(publishers, ("a1", "b1")):
            link_publisher.publish(String(data=text))
        _spin(executor)
        assert batched == [["a1", "b1"]] and one_by_one == []
        publishers[1].publish(String(data="b2"))        # b alone: its own callback
        _spin(executor)
        assert batched == [["a1", "b1"]] and one_by_one == [("b", "b2")]
        node.lockstep_batch = ((), lambda messages: batched.append(messages))
        executor.wake()
        _spin(executor)
        assert batched == [["a1", "b1"]]
    finally:
        executor.shutdown()
