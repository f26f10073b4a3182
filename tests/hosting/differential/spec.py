"""A generated program as data, and a batch of them as one run.

A program (``strategies.py`` makes them) is a JSON-able dict::

    {"robots": 1 or 2,             # robots that each run ``nodes``
     "nodes": [node, …],           # a robot's nodes, named n0, n1, … (in their robot's namespace)
     "run_wide": [node, …]}        # run-wide nodes, named w0, w1, …

and a node is ``{"name", "lifecycle": None | "autostart" | "manual", "groups": ["me1", "re1", …],
"params": ["k0", …], "entities": [entity, …], "init": [statement, …], "transitions": {t: [statement,
…]}, "cleanup_destroys": bool}`` (entities and statements: ``entities.py``, ``statements.py``).
An entity that talks to another node names it with ``to``: ``{"node": "n1", "name": "s0"}`` (a
node of the same robot, or a run-wide node ``w0``), from a run-wide node ``{"robot": j, …}``.

A batch puts programs side by side in one world: program ``i``'s robots are ``p{i}r0``, ``p{i}r1``
(a robot group of its own, ``answers: when_published``), its run-wide nodes ``p{i}w0`` …; the
nodes see only resolved names (``compile_node``) and log under their name within the program
(``r0/n1``, ``w0``), so a program's events do not depend on where it stands in a batch.
"""
from __future__ import annotations

import copy
import hashlib
import json
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[3]
INTERFACES = ROOT / "tests" / "user_pkg" / "robot_programs_interfaces"
TICKS_PER_SECOND = 10
TICK_NS = 10**9 // TICKS_PER_SECOND
TICKS = 16                     # every generated program runs this many ticks
STEP_TICKS = 2                 # an action server's slow execute callback sleeps this long between feedbacks
HARNESS_VERSION = 2            # part of every program's hash: bump when what a spec means changes
SERVING = ("service", "action_server")
TARGETING = ("client", "action_client", "param_client", "lifecycle_client")


def class_name(node_spec: dict, name: str) -> str:
    """The class of ``differential.interpreter`` that runs ``node_spec`` as node ``name``."""
    return f"{'Plain' if node_spec.get('lifecycle') is None else 'Lifecycle'}_{name}"


def program_hash(program: dict, ticks: int) -> str:
    text = json.dumps([HARNESS_VERSION, ticks, program], sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def robot_name(index: int, robot: int) -> str:
    return f"p{index}r{robot}"


def run_wide_name(index: int, node: str) -> str:
    return f"p{index}{node}"


def _resolve(entity: dict, index: int, from_robot: bool) -> None:
    """Fill ``ros`` (a server's own name) or ``target`` (the name a client asks for)."""
    if entity["kind"] in SERVING:
        entity["ros"] = f"{entity['owner']}_{entity['name']}"
    if entity["kind"] not in TARGETING:
        return
    to = entity["to"]
    if to["node"].startswith("w"):
        node = "/" + run_wide_name(index, to["node"])
    elif from_robot:
        node = to["node"]                                   # relative: the same robot's node
    else:
        node = f"/{robot_name(index, to.get('robot', 0))}/{to['node']}"
    entity["target"] = f"{node}_{to['name']}" if "name" in to else node


def dicts_in(value):
    """Every dict nested in ``value`` (dicts and lists), outermost first; a dict may be changed
    before its own values are looked at."""
    if isinstance(value, dict):
        yield value
        for v in value.values():
            yield from dicts_in(v)
    elif isinstance(value, list):
        for v in value:
            yield from dicts_in(v)


def compile_node(node: dict, index: int, robot_node: bool) -> dict:
    """The spec a node of program ``index`` is built from: names resolved, its program's prefix
    and the tick length added."""
    compiled = copy.deepcopy(node)
    owner = node["name"] if robot_node else run_wide_name(index, node["name"])

    for entity in dicts_in(compiled):
        if "kind" in entity:
            entity["owner"] = owner
            _resolve(entity, index, robot_node)
    compiled.update(prefix=f"p{index}", tick_ns=TICK_NS)
    return compiled


def node_entry(node: dict, index: int, robot_node: bool) -> dict:
    """The world file's entry of a node."""
    name = node["name"] if robot_node else run_wide_name(index, node["name"])
    entry = {"node": f"differential.interpreter:{class_name(node, name)}",
             "parameters": {"spec": json.dumps(compile_node(node, index, robot_node), sort_keys=True)}}
    if node.get("lifecycle"):
        entry["lifecycle"] = node["lifecycle"]
    return entry


def batch_world(programs: list[dict], ticks: int, name: str = "differential") -> dict:
    """One world running ``programs`` side by side for ``ticks`` ticks (a dict, as YAML reads)."""
    groups = [{"model": "foot-bot", "count": p["robots"], "name_prefix": f"p{i}r", "answers": "when_published",
               "placement": {"method": "grid", "center": [2.0 * i, 0.0], "spacing_m": 0.5},
               "nodes": [node_entry(n, i, True) for n in p["nodes"]]}
              for i, p in enumerate(programs)]
    run_wide = [node_entry(n, i, False) for i, p in enumerate(programs) for n in p.get("run_wide", ())]
    world = {"name": name, "seed": 1, "ticks_per_second": TICKS_PER_SECOND, "length_ticks": ticks,
             "arena": {"center": [0.0, 0.0], "walls": False}, "robots": groups,
             "interfaces": [str(INTERFACES)]}
    if run_wide:
        world["nodes"] = run_wide
    return world


def write_world(programs: list[dict], ticks: int, path: Path) -> Path:
    path.write_text(yaml.safe_dump(batch_world(programs, ticks), sort_keys=False))
    return path


def places(programs: list[dict]) -> list[tuple[str, list[tuple[str, dict, bool]]]]:
    """The batch's processes of its own (the ground truth): each robot, then all run-wide nodes,
    each as (class name, compiled spec, autostart)."""
    out = []
    for i, p in enumerate(programs):
        for j in range(p["robots"]):
            out.append((robot_name(i, j), [(class_name(n, n["name"]), compile_node(n, i, True),
                                             n.get("lifecycle") == "autostart") for n in p["nodes"]]))
    run_wide = [(class_name(n, run_wide_name(i, n["name"])), compile_node(n, i, False), n.get("lifecycle") == "autostart")
                for i, p in enumerate(programs) for n in p.get("run_wide", ())]
    if run_wide:
        out.append(("run_wide", run_wide))
    return out


def ready_targets(node: dict) -> list[str]:
    """The entities of a compiled node whose other side exists from the start: a process of its
    own waits for them to be discovered before the rig starts tick 0 (``plain_process.py``)."""
    return [e["name"] for e in node.get("entities", ()) if e["kind"] in TARGETING and not e.get("configured")
            and not e.get("late")]
