"""Shrinking a mismatching program to a minimal one that still mismatches the same way.

Hypothesis's own shrinker would rerun rclpy and a host for each of hundreds of attempts; a
program's parts are few and each attempt costs seconds, so this one removes parts greedily
(delta debugging): a node, an entity, a statement, a second robot, an ``async`` flag, keeping a
removal while the program still mismatches with the same ``signature`` in the same mode. What a
removal leaves dangling (a client of a removed service, a statement on a removed client) goes
with it, so every candidate is a program the generator could have drawn, minus parts: the rules
that keep the ground truth defined hold for it too.

``python -m differential.shrink MODE PROGRAM.json`` prints the minimal program.
"""
from __future__ import annotations

import copy
import json
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Iterator, Optional

from differential.check import FILLER
from differential.events import compare
from differential.hosted import run_hosted
from differential.spec import TICKS
from differential.truth import truths

ERROR = re.compile(r"\b(\w*(?:Error|Exception|InvalidHandle))\b")


def signature(mode: str, diffs, notes: list[str]) -> tuple:
    """What makes two mismatches the same: the mode, the error a run ended with (or its refusal
    to start), else which kinds of event the first differing tick lacks and has too many of."""
    errors = sorted({m.group(1) for n in notes for m in ERROR.finditer(n)} |
                    {"refused" for n in notes if n.startswith("exit status 2")})
    if errors:
        return mode, tuple(errors)
    first = diffs[0]
    return mode, tuple(sorted({("rclpy", e[3]) for e in first.only_truth} | {("hosted", e[3]) for e in first.only_hosted}))


def outcome(program: dict, mode: str, ticks: int, workdir: Path) -> Optional[tuple]:
    """The program's mismatch signature in ``mode`` (None: it matches, or rclpy is not defined for it)."""
    record = truths([program], ticks, workdir)[0]
    if not record["stable"]:
        return None
    hosted = run_hosted([program] + ([FILLER] if program["robots"] < 2 else []), ticks, mode, workdir / mode)
    diffs = compare(record["events"], hosted.events.get(0, []), ticks)
    return signature(mode, diffs, hosted.notes) if diffs else None


# --- candidates ---------------------------------------------------------------------------------

def _paths(value, path=()) -> Iterator[tuple]:
    """Every list element's path (deepest last), each a removal candidate."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, path + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            if isinstance(v, dict):
                yield path + (i,)
            yield from _paths(v, path + (i,))


def _without(program: dict, path: tuple) -> dict:
    out = copy.deepcopy(program)
    parent = out
    for k in path[:-1]:
        parent = parent[k]
    del parent[path[-1]]
    return repair(out)


def repair(program: dict) -> dict:
    """Drop what refers to something no longer there, until nothing does."""
    while True:
        nodes = {n["name"]: n for n in program["nodes"] + program.get("run_wide", [])}
        names = {(n, e["name"]) for n, node in nodes.items() for e in _all_entities(node)}
        changed = False
        for node in nodes.values():
            own = {e["name"] for e in _all_entities(node)}
            kept = [e for e in node["entities"] if "to" not in e or (e["to"]["node"] in nodes and (
                "name" not in e["to"] or (e["to"]["node"], e["to"]["name"]) in names))]
            changed |= len(kept) != len(node["entities"])
            node["entities"] = kept
            changed |= _prune(node, own | {"own", "self", "cmd_vel"})
        if not changed:
            for node in nodes.values():           # the groups still used
                used = {e.get("group", "default") for e in _all_entities(node)}
                node["groups"] = sorted(used - {"default"})
            return program


def _all_entities(node: dict) -> list[dict]:
    """A node's entities, with those its statements make."""
    found = []

    def walk(v):
        if isinstance(v, dict):
            if "kind" in v and "name" in v:
                found.append(v)
            for x in v.values():
                walk(x)
        elif isinstance(v, list):
            for x in v:
                walk(x)
    walk(node)
    return found


def _prune(value, names: set) -> bool:
    changed = False
    if isinstance(value, dict):
        for v in value.values():
            changed |= _prune(v, names)
    elif isinstance(value, list):
        keep = [v for v in value if not (isinstance(v, dict) and "do" in v and (
            v.get("client", "own") not in names or v.get("pub", "cmd_vel") not in names))]
        if len(keep) != len(value):
            value[:] = keep
            changed = True
        for v in value:
            changed |= _prune(v, names)
    return changed


def wiring(program: dict) -> tuple[bool, bool]:
    """Has a robot node a scan subscription and a cmd_vel publisher from its constructor? (What
    the hosts require of every robot, by design: a shrink keeps them.)"""
    entities = [e for n in program["nodes"] for e in n["entities"] if not e.get("configured")]
    return any(e["kind"] == "scan" for e in entities), any(e["kind"] == "cmd_vel" for e in entities)


def candidates(program: dict) -> Iterator[dict]:
    wired = wiring(program)
    for candidate in _candidates(program):
        if all(now or not before for now, before in zip(wiring(candidate), wired)):
            yield candidate


def _candidates(program: dict) -> Iterator[dict]:
    if program["robots"] > 1:
        yield {**copy.deepcopy(program), "robots": 1}
    for path in _paths(program):
        if path[:1] == ("nodes",) and len(path) == 2 and path[1] == 0:
            continue                                        # n0 stays: the robot's node
        yield _without(program, path)
    for path in _paths(program):
        target = program
        for k in path:
            target = target[k]
        if target.get("async"):
            out = copy.deepcopy(program)
            node = out
            for k in path:
                node = node[k]
            del node["async"]
            yield out


def minimize(program: dict, mode: str, ticks: int, workdir: Path, budget_s: float = 1800.0,
             log: Callable[[str], None] = print) -> dict:
    """The smallest program found that mismatches in ``mode`` as ``program`` does."""
    goal = outcome(program, mode, ticks, workdir)
    if goal is None:
        raise ValueError(f"the program matches rclpy in {mode}: nothing to shrink")
    current, deadline, tried = program, time.monotonic() + budget_s, set()
    improved = True
    while improved and time.monotonic() < deadline:
        improved = False
        for candidate in candidates(current):
            key = json.dumps(candidate, sort_keys=True)
            if key in tried or time.monotonic() > deadline:
                continue
            tried.add(key)
            if outcome(candidate, mode, ticks, workdir) == goal:
                current, improved = candidate, True
                log(f"shrunk to {len(key)} characters")
                break
    return current


def main(argv: list[str]) -> None:
    mode, program = argv[0], json.loads(Path(argv[1]).read_text())
    with tempfile.TemporaryDirectory() as tmp:
        print(json.dumps(minimize(program, mode, TICKS, Path(tmp), log=lambda s: print(s, file=sys.stderr)), indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
