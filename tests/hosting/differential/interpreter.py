"""The generated programs' one Node class: a node whose entities and callbacks a JSON spec says
(the ``spec`` parameter), loaded unchanged by the composed_sim hosts and by a plain rclpy process.

``differential.interpreter:Plain_n0`` is a plain ``Node`` named ``n0``, ``…:Lifecycle_p3w0`` a
``LifecycleNode`` named ``p3w0``: the classes are made on first use (the module's ``__getattr__``),
as a world file names a node by ``module:Class`` and a class names its node.

Everything a node observes is logged, one line per event, through its own logger:
``EV <program> <who> [activation, seq, kind, payload…]``: ``program`` is its program's place in
a batch (``p3``), ``who`` the node's name within its program (``r0/n1``, ``w0``); an activation is one run of one callback (a timer's 3rd firing ``t0#3``, the
scan of tick 4 ``scan@4``, the request with value 17 to service ``s0`` ``s0<17``, a done callback
``t0#3/1``), and ``seq`` counts the events within it, so that the events of one activation keep
their order in any comparison while activations are compared as sets (see ``events.py``).
The statements a callback runs are in ``statements.py``.
"""
from __future__ import annotations

import json
import zlib

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node

from differential.entities import Entities
from differential.statements import Statements

EVENT_MARK = "EV"


def value_of(*parts) -> int:
    """A request's or message's value: the same wherever the program runs, and distinct per
    place, activation and statement (the activation ids of the receiver are made from it)."""
    return zlib.crc32("|".join(map(str, parts)).encode()) % 1_000_003


class Activation:
    """One run of one callback: its id, its index (a timer's firing, a scan's tick) and its events."""

    def __init__(self, program: "Program", ident: str, index: int = 0):
        self.program, self.id, self.index, self.seq = program, ident, index, 0

    def log(self, kind: str, *payload) -> None:
        self.program.emit(self.id, self.seq, kind, payload)
        self.seq += 1

    def due(self, statement: dict) -> bool:
        """A statement with ``at`` runs only at those indices of its callback."""
        at = statement.get("at")
        return at is None or self.index in at

    def child(self, suffix: str, index: int = 0) -> "Activation":
        return Activation(self.program, f"{self.id}/{suffix}", index)


class Program(Statements, Entities):
    """One node's part of a generated program: its groups, entities, and callbacks' bodies."""

    def __init__(self, node: Node, spec: dict):
        self.node, self.spec = node, spec
        self.tick_ns = spec["tick_ns"]
        fqn = node.get_fully_qualified_name()
        self.who = fqn[len(spec["prefix"]) + 1:] if fqn.startswith("/" + spec["prefix"]) else fqn
        self.groups = {"default": node.default_callback_group}
        for name in spec.get("groups", ()):
            self.groups[name] = ReentrantCallbackGroup() if name.startswith("re") else MutuallyExclusiveCallbackGroup()
        self.entities: dict = {}
        self.goal_handles: dict = {}
        self.counters: dict = {}

    def emit(self, act: str, seq: int, kind: str, payload: tuple) -> None:
        line = json.dumps([act, seq, kind, *payload], separators=(",", ":"))
        self.node.get_logger().info(f"{EVENT_MARK} {self.spec['prefix']} {self.who} {line}")

    def tick(self) -> int:
        return round(self.node.get_clock().now().nanoseconds / self.tick_ns)

    def next_index(self, name: str) -> int:
        self.counters[name] = self.counters.get(name, 0) + 1
        return self.counters[name]

    def construct(self) -> None:
        for p in self.spec.get("params", ()):
            self.node.declare_parameter(p, 0)
        if self.spec.get("params"):
            self.node.add_on_set_parameters_callback(self.on_set_parameters)
        if self.spec.get("lifecycle") is None:
            self.make_all(self.spec.get("entities", ()))
        else:
            self.make_all(e for e in self.spec.get("entities", ()) if not e.get("configured"))
        self.run(Activation(self, "init"), self.spec.get("init", ()))

    def on_set_parameters(self, parameters):
        from rcl_interfaces.msg import SetParametersResult
        for p in parameters:
            Activation(self, f"set<{p.name}={p.value}").log("param_set", p.name, p.value)
        return SetParametersResult(successful=True)

    def transition(self, name: str) -> TransitionCallbackReturn:
        """A lifecycle callback's body; ``on_configure`` makes the entities marked ``configured``
        first, ``on_cleanup`` destroys them when the spec says so."""
        act = Activation(self, f"{name}#{self.next_index(name)}")
        act.log("transition", name)
        configured = [e for e in self.spec.get("entities", ()) if e.get("configured")]
        if name == "configure":
            self.make_all(configured)
        if name == "cleanup" and self.spec.get("cleanup_destroys"):
            for e in configured:
                self.destroy(e["name"])
        self.run(act, self.spec.get("transitions", {}).get(name, ()))
        return TransitionCallbackReturn.SUCCESS


class ProgramNode(Node):
    NODE_NAME = "n"

    def __init__(self, **kwargs):
        super().__init__(self.NODE_NAME, **kwargs)
        self.program = Program(self, json.loads(self.declare_parameter("spec", "{}").value))
        self.program.construct()


class LifecycleProgramNode(LifecycleNode):
    NODE_NAME = "n"

    def __init__(self, **kwargs):
        super().__init__(self.NODE_NAME, **kwargs)
        self.program = Program(self, json.loads(self.declare_parameter("spec", "{}").value))
        self.program.construct()

    def on_configure(self, state):
        super().on_configure(state)
        return self.program.transition("configure")

    def on_activate(self, state):
        super().on_activate(state)          # activates the lifecycle publishers
        return self.program.transition("activate")

    def on_deactivate(self, state):
        super().on_deactivate(state)
        return self.program.transition("deactivate")

    def on_cleanup(self, state):
        super().on_cleanup(state)
        return self.program.transition("cleanup")


KINDS = {"Plain": ProgramNode, "Lifecycle": LifecycleProgramNode}


def __getattr__(name: str):
    kind, _, node_name = name.partition("_")
    if kind not in KINDS or not node_name:
        raise AttributeError(name)
    cls = type(name, (KINDS[kind],), {"NODE_NAME": node_name, "__module__": __name__, "__qualname__": name})
    globals()[name] = cls
    return cls

