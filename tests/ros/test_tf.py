"""tf, opt-in per robot group: /<r>/tf and /<r>/tf_static (or /tf and /tf_static), received by a
listener in another process as tf2_msgs/msg/TFMessage, and consistent with the trajectories."""
import math
import time

import pytest
from rosbags.typesys import Stores, get_typestore

from composed_sim.hosts.composed import ComposedHost
from composed_sim.ros import contract as c
from composed_sim.world.loader import load_world
from listener import Listener

TYPES = get_typestore(Stores.ROS2_JAZZY)

WORLD = """
name: frames
seed: 5
length_ticks: {ticks}
arena: {{center: [0, 0], size: [4, 4], walls: true}}
lights: [{{position: [1.5, 1.5]}}]
robots:
  - model: foot-bot
    count: 2
    controller: flocking
    placement: {{method: uniform, center: [-1, 0], size: [1.5, 1.5]}}
    devices: {{wheels: {{distance_noise_m: 0.001}}, {tf}}}
  - model: turtlebot3-burger
    count: 2
    name_prefix: tb
    controller: obstacle-avoidance
    placement: {{method: uniform, center: [1, 0], size: [1.5, 1.5]}}
    devices: {{ {tf} }}
"""

def run_with_listener(tmp_path, domain, ticks, tf, topics):
    """Run the world with a listener process on ``topics``; tick 0 starts once the listener is
    matched on every one of them that the run publishes."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "world.yaml").write_text(WORLD.format(ticks=ticks, tf=tf))
    world = load_world(tmp_path / "world.yaml")
    listener = Listener(domain, topics)
    with ComposedHost(world, executor="lockstep", domain_id=domain) as host:
        ours = [p for node in host.simulator_nodes for p in node.publishers if p.topic_name in topics]
        deadline = time.monotonic() + 30
        while not all(p.get_subscription_count() > 0 for p in ours) and time.monotonic() < deadline:
            time.sleep(0.01)
        result = host.run()
    heard = listener.stop()
    return heard, result.trajectories.positions, result.trajectories.headings


def transforms(hex_data):
    return TYPES.deserialize_cdr(bytes.fromhex(hex_data), "tf2_msgs/msg/TFMessage").transforms


def yaw(q):
    return 2 * math.atan2(q.z, q.w)


def test_per_robot_tf_chains_world_to_base_link_as_the_robot_moved(tmp_path, domain_id):
    heard, positions, headings = run_with_listener(tmp_path, domain_id, 60, "tf: {}",
                                                   ["/bot0/tf", "/tb1/tf", "/tb1/tf_static", "/bot0/tf_static"])
    assert len(heard["got"]["/bot0/tf"]) == 60 and len(heard["got"]["/tb1/tf"]) == 60     # every tick
    tick_ns = 100_000_000
    for topic, robot, row in (("/bot0/tf", "bot0", 0), ("/tb1/tf", "tb1", 3)):
        for data in heard["got"][topic]:
            world_odom, odom_base = transforms(data)
            assert (world_odom.header.frame_id, world_odom.child_frame_id) == ("world", f"{robot}/odom")
            assert (odom_base.header.frame_id, odom_base.child_frame_id) == (f"{robot}/odom", f"{robot}/base_link")
            stamp = world_odom.header.stamp
            tick = (stamp.sec * 1_000_000_000 + stamp.nanosec) // tick_ns
            # world → base_link = (world → odom) · (odom → base_link): the robot's pose at that tick.
            a, b = yaw(world_odom.transform.rotation), odom_base.transform.translation
            x = world_odom.transform.translation.x + math.cos(a) * b.x - math.sin(a) * b.y
            y = world_odom.transform.translation.y + math.sin(a) * b.x + math.cos(a) * b.y
            assert (x, y) == pytest.approx(tuple(positions[tick, row]), abs=1e-9)
            assert math.remainder(a + yaw(odom_base.transform.rotation) - headings[tick, row], math.tau) \
                == pytest.approx(0, abs=1e-9)
    # The LiDAR's mount, once, to a listener that came before; foot-bots have no such frame.
    [static] = heard["got"]["/tb1/tf_static"]
    [mount] = transforms(static)
    assert (mount.header.frame_id, mount.child_frame_id) == ("tb1/base_link", "tb1/base_scan")
    assert (mount.transform.translation.x, mount.transform.translation.z) == (-0.064, 0.122)
    assert heard["got"]["/bot0/tf_static"] == []
    assert "/tf" not in heard["seen"] and "/tb1/tf" in heard["seen"]


def test_global_tf_carries_every_robot_in_one_message_and_tf_is_absent_when_off(tmp_path, domain_id):
    heard, _, _ = run_with_listener(tmp_path, domain_id, 40, "tf: {topics: global}", ["/tf", "/tf_static"])
    assert len(heard["got"]["/tf"]) == 40
    children = [t.child_frame_id for t in transforms(heard["got"]["/tf"][-1])]
    assert children == ["bot0/odom", "bot0/base_link", "bot1/odom", "bot1/base_link",
                        "tb0/odom", "tb0/base_link", "tb1/odom", "tb1/base_link"]
    assert [t.child_frame_id for t in transforms(heard["got"]["/tf_static"][0])] == ["tb0/base_scan", "tb1/base_scan"]
    assert "/bot0/tf" not in heard["seen"]
    off, _, _ = run_with_listener(tmp_path / "off", domain_id, 20, "odometry: {}", ["/tf"])
    assert off["got"]["/tf"] == [] and not any(t.endswith("tf") for t in off["seen"])


def test_tf_type_hash_is_tf2_msgs_own():
    assert TYPES.hash_rihs01("tf2_msgs/msg/TFMessage") == \
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
    assert c.type_name(c.TF_MESSAGE) == "tf2_msgs/msg/TFMessage"
