"""How controller shards and the simulator find each other: one latched announcement per shard.

A shard (``composed-sim host``) publishes, once its controllers' contract endpoints are matched
with the simulator's, a ``std_msgs/String`` on ``/composed_sim/shards`` holding JSON: who it is,
which robots it hosts, which contract topics each of them uses, the GIDs of each one's cmd_vel
publishers and a fingerprint of the world it was built from. The topic is transient-local, so a simulator that starts after the shards still
gets every announcement. This is host plumbing next to the topic contract, not part of it:
controllers never see it.

The simulator uses the announcements to start tick 0 only once every robot is hosted by exactly
one ready shard of the same world, and to name what is missing when that does not happen.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from composed_sim.hosts.shards.robot_ranges import format_ranges, parse_ranges
from composed_sim.ros.robot_settings import quiet_node_options
from composed_sim.world.schema import World

SHARDS_TOPIC = "/composed_sim/shards"
# Latched per writer (one writer per shard). The reader keeps many: the topic has no key, so
# keep-last on the reader counts all shards' samples together.
ANNOUNCE_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST)
REGISTRY_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST)


def world_fingerprint(world: World) -> str:
    """What a hosted controller's behaviour depends on (robot names, models, controllers and
    their params, the seed), hashed: the simulator refuses a shard built from another world.
    Run length, watchdog, physics and obstacles are the simulator's alone and do not count."""
    groups = [g.model_dump(include={"model", "count", "name_prefix", "controller", "params"}) for g in world.robots]
    text = json.dumps({"seed": world.seed, "robots": groups}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass
class ShardInfo:
    shard: str                          # "<hostname>:<pid>", for messages
    robots: list[int]                   # robot indices it hosts
    world: str                          # world_fingerprint of its world
    topics: dict[int, list[str]] = field(default_factory=dict)   # robot → contract topics it uses
    gids: dict[int, list[bytes]] = field(default_factory=dict)    # robot → its cmd_vel publishers' GIDs

    def encode(self) -> String:
        by_topics: dict[str, list[int]] = {}
        for robot, names in self.topics.items():
            by_topics.setdefault(",".join(sorted(names)), []).append(robot)
        return String(data=json.dumps({
            "shard": self.shard, "robots": format_ranges(self.robots), "world": self.world,
            "topics": {names: format_ranges(robots) for names, robots in by_topics.items()},
            "cmd_vel_gids": {str(robot): [gid.hex() for gid in gids] for robot, gids in self.gids.items()}}))

    @classmethod
    def decode(cls, msg: String, n_robots: int) -> "ShardInfo":
        d = json.loads(msg.data)
        topics = {robot: names.split(",") if names else []
                  for names, ranges in d["topics"].items() for robot in parse_ranges(ranges, n_robots)}
        gids = {int(robot): [bytes.fromhex(g) for g in hexes] for robot, hexes in d["cmd_vel_gids"].items()}
        return cls(d["shard"], parse_ranges(d["robots"], n_robots), d["world"], topics, gids)


class ShardAnnouncer:
    """The shard's side: one latched announcement."""

    def __init__(self, context: Context, node_name: str):
        self.node = Node(node_name, context=context, **quiet_node_options())
        self._pub = self.node.create_publisher(String, SHARDS_TOPIC, ANNOUNCE_QOS)

    def announce(self, info: ShardInfo) -> None:
        self._pub.publish(info.encode())

    def destroy(self) -> None:
        self.node.destroy_node()


class ShardRegistry:
    """The simulator's side: the announcements heard so far, by shard. Its node is never added
    to an executor; ``poll`` takes what has arrived, from the calling thread."""

    def __init__(self, context: Context, n_robots: int):
        self.node = Node("composed_sim_shards", context=context, **quiet_node_options())
        self._sub = self.node.create_subscription(String, SHARDS_TOPIC, lambda msg: None, REGISTRY_QOS)
        self._n = n_robots
        self.shards: dict[str, ShardInfo] = {}
        self.malformed: list[str] = []

    def poll(self) -> dict[str, ShardInfo]:
        sub = self._sub
        while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
            try:
                info = ShardInfo.decode(taken[0], self._n)
            except (ValueError, KeyError, TypeError, AttributeError) as e:
                self.malformed.append(f"{taken[0].data[:80]!r}: {e}")
                continue
            self.shards[info.shard] = info
        return self.shards

    def destroy(self) -> None:
        self.node.destroy_node()
