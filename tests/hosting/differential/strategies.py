"""Hypothesis strategies for small robots' programs (``spec.py``'s format), from the constructs of
docs/contract.md's table "What a node may do".

Every program drawn has one behaviour under rclpy, whatever its executor's threads do, because
the generator keeps to these rules (each says what would otherwise be undefined or a deadlock in a
process of its own):

- callback groups: a node's default group (mutually exclusive) holds only prompt callbacks (they
  wait, if at all, only for a terminal service: one in a reentrant group whose handler waits for
  nothing), so it is free between ticks (rclpy's /clock subscription is in it); ``me1`` holds one
  callback, the only one that may sleep (two in one group would take turns in an order rclpy does
  not define); ``re1`` is reentrant; ``cl1`` holds only clients; ``ac1`` one action server;
- services live in the default or ``re1`` group; level-1 services (``re1``) wait for level-0
  ones, which wait for nothing; a callback waits (``Client.call``, ``await``) only through a
  client of ``re1`` or ``cl1``, or of the default group when it is not in it;
- what depends on the order within a tick is scheduled apart: a parameter is set once and read
  two ticks or more after (or before) it; a lifecycle node has one driver, whose transitions are
  two ticks or more apart and never on a tick where the node's timer fires; a made timer is
  destroyed on a tick where it does not fire; a goal's cancel comes on a tick where its execute
  callback (two ticks per step) does not wake; a service made later is asked for two ticks after;
- scheduled statements run in a scheduler: a robot node's scan callback ``sz`` (its index is the
  tick) or a run-wide node's 1-tick timer ``tz`` (index = tick).

``programs(constructs)`` draws one program using only ``constructs`` (``ALL`` by default).
"""
from __future__ import annotations

from dataclasses import dataclass

from hypothesis import strategies as st

from differential.bodies import free_body
from differential.schedule import schedule_all
from differential.spec import dicts_in

CONSTRUCTS = ("block", "timeout", "done", "await", "async_service", "sleep_rate", "sleep_clock", "odd_periods",
              "pubsub", "run_wide", "two_robots", "nested", "ready", "init_call", "actions", "params", "apc",
              "lifecycle_autostart", "lifecycle_self", "lifecycle_other", "lifecycle_run_wide",
              "lifecycle_cmd_vel", "cleanup_destroys", "make", "destroy", "late_service")
ALL = frozenset(CONSTRUCTS)


@dataclass
class Ctx:
    """Where a body runs: which node, group, whether ``async def``, what kind of callback."""
    node: str
    group: str
    is_async: bool
    kind: str                 # timer, scan, sub, service, init
    level: int = 2            # a service's level (0: waits for nothing)


class Builder:
    """A program being drawn: its nodes, their servers, and the clients made for them."""

    def __init__(self, constructs: frozenset):
        self.c = constructs
        self.program = {"robots": 1, "nodes": [], "run_wide": []}
        self.nodes: dict[str, dict] = {}
        self.services: list[dict] = []      # {node, name, group, level}
        self.counters: dict[str, int] = {}

    def has(self, construct: str) -> bool:
        return construct in self.c

    def fresh(self, prefix: str) -> str:
        self.counters[prefix] = self.counters.get(prefix, -1) + 1
        return f"{prefix}{self.counters[prefix]}"

    def add_node(self, name: str, lifecycle=None) -> dict:
        node = {"name": name, "lifecycle": lifecycle, "groups": [], "entities": []}
        self.nodes[name] = node
        (self.program["nodes"] if name.startswith("n") else self.program["run_wide"]).append(node)
        return node

    def add(self, node: str, entity: dict) -> dict:
        self.nodes[node]["entities"].append(entity)
        return entity

    def entity(self, node: str, name: str):
        return next((e for e in self.nodes[node]["entities"] if e["name"] == name), None)

    def robot_nodes(self) -> list[str]:
        return [n["name"] for n in self.program["nodes"]]

    def client_for(self, node: str, to: dict, group: str, kind: str = "client", late: bool = False, **extra) -> str:
        """A client of ``node`` for ``to`` in ``group`` (one per target and group)."""
        for e in self.nodes[node]["entities"]:
            if e["kind"] == kind and e["to"] == to and e.get("group", "default") == group and e.get("how") == extra.get("how"):
                return e["name"]
        entity = {"kind": kind, "name": self.fresh(f"{node}_{ {'client': 'c', 'action_client': 'ac', 'param_client': 'pc', 'lifecycle_client': 'lc'}[kind] }"),
                  "to": to, "group": group, **extra}
        if late:
            entity["late"] = True
        self.add(node, entity)
        return entity["name"]

    def to(self, caller: str, target: str, name: str | None = None, robot: int = 0) -> dict:
        """How ``caller`` names ``target``'s entity (a run-wide caller names a robot)."""
        out = {"node": target}
        if name is not None:
            out["name"] = name
        if caller.startswith("w") and target.startswith("n"):
            out["robot"] = robot
        return out

    def finish(self) -> dict:
        for node in self.nodes.values():
            used = {d["group"] for d in dicts_in(node) if "group" in d}
            node["groups"] = sorted(used - {"default"})
            for key in ("init", "transitions"):
                if not node.get(key):
                    node.pop(key, None)
            if node["lifecycle"] is None:
                node.pop("lifecycle")
        return self.program


@st.composite
def programs(draw, constructs: frozenset = ALL) -> dict:
    b = Builder(frozenset(constructs))
    if b.has("two_robots"):
        b.program["robots"] = draw(st.integers(1, 2))
    for i in range(draw(st.integers(1, 3))):
        lifecycle = None
        if i > 0:
            kinds = [None] + (["autostart"] if b.has("lifecycle_autostart") else []) + \
                (["manual"] if any(b.has(x) for x in LIFECYCLE_DRIVERS) else [])
            lifecycle = draw(st.sampled_from(kinds))
        b.add_node(f"n{i}", lifecycle)
    if b.has("run_wide") and draw(st.booleans()):
        b.add_node("w0")
    draw_servers(draw, b)
    draw_callbacks(draw, b)
    schedule_all(draw, b)
    if not any(e["kind"] == "cmd_vel" for n in b.nodes.values() for e in n["entities"]):
        b.add("n0", {"kind": "cmd_vel", "name": "cmd_vel"})
    return b.finish()


LIFECYCLE_DRIVERS = ("lifecycle_self", "lifecycle_other", "lifecycle_run_wide")


def draw_servers(draw, b: Builder) -> None:
    for name in list(b.nodes):
        for _ in range(draw(st.integers(0, 2))):
            group = draw(st.sampled_from(["default", "re1"]))
            service = {"kind": "service", "name": b.fresh(f"{name}_s"), "group": group}
            if b.has("async_service") and draw(st.booleans()):
                service["async"] = True
            b.add(name, service)
            b.services.append({"node": name, "name": service["name"], "group": group, "level": 0, "entity": service})
    nested = [s for s in b.services if s["group"] == "re1"]
    if b.has("nested") and nested and draw(st.booleans()):
        upper = draw(st.sampled_from(nested))
        upper["level"] = 1
        ctx = Ctx(upper["node"], "re1", bool(upper["entity"].get("async")), "service", level=1)
        upper["entity"]["body"] = draw(free_body(b, ctx, max_len=2))


def draw_callbacks(draw, b: Builder) -> None:
    robot = b.robot_nodes()
    scan_node = draw(st.sampled_from(robot))
    groups = ["default", "me1", "re1"]
    for name in list(b.nodes):
        callbacks = []
        if name == scan_node:
            callbacks.append(("scan", "scan"))
        callbacks += [("timer", b.fresh(f"{name}_t")) for _ in range(draw(st.integers(0, 2)))]
        if name in robot and b.has("pubsub") and draw(st.booleans()):
            topic = b.fresh("x")
            b.add(draw(st.sampled_from(robot)), {"kind": "pub", "name": f"o_{topic}", "topic": topic})
            callbacks.append(("sub", f"i_{topic}"))
        used_me1 = False
        for kind, cb in callbacks:
            group = draw(st.sampled_from([g for g in groups if not (g == "me1" and used_me1)]))
            used_me1 |= group == "me1"
            is_async = draw(st.booleans()) if b.has("await") else False
            entity = {"kind": kind, "name": cb, "group": group}
            if is_async:
                entity["async"] = True
            if kind == "timer":
                periods = [0.1, 0.2, 0.3] + ([0.05, 0.15, 0.25] if b.has("odd_periods") else [])
                entity["period"] = draw(st.sampled_from(periods))
            if kind == "sub":
                entity["topic"] = cb[2:]
            entity["body"] = draw(free_body(b, Ctx(name, group, is_async, kind)))
            b.add(name, entity)


def draw_programs(count: int, seed: int, constructs: frozenset = ALL) -> list[dict]:
    """``count`` distinct programs drawn from ``programs(constructs)`` with a fixed seed (the same
    ones every time with this version of hypothesis). Hypothesis starts every seed with the
    simplest program: it is left out, so that batches of different seeds do not share it."""
    import json
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as seeded
    drawn: dict[str, dict] = {}
    first: list[str] = []

    @settings(max_examples=3 * count + 1, database=None, phases=[Phase.generate], deadline=None,
              suppress_health_check=list(HealthCheck))
    @seeded(seed)
    @given(programs(constructs))
    def collect(program):
        key = json.dumps(program, sort_keys=True)
        if not first:
            first.append(key)
        elif key not in drawn and len(drawn) < count:
            drawn[key] = program
    collect()
    return list(drawn.values())
