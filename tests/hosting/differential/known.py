"""The known differences between the hosts and rclpy, as the differential test found them, each
with the construct, the modes, and why (docs/contract.md says the same for users). A mismatch of a
program that uses a known construct, in a mode the difference is known for, is explained; every
other mismatch fails the test. Fix one, and its entry goes.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Iterator

HERE = Path(__file__).resolve().parent
FIXED = HERE / "fixed_programs.json"


def fixed_programs() -> list[dict]:
    return json.loads(FIXED.read_text())


def _entities(program: dict, nodes: str) -> Iterator[dict]:
    """The entities of a program's robot nodes (``nodes="robot"``) or run-wide nodes, with those
    its statements make."""
    stack = [e for n in program.get("nodes" if nodes == "robot" else "run_wide", ()) for e in n.get("entities", ())]
    while stack:
        e = stack.pop()
        yield e
        stack += [s["entity"] for s in e.get("body", ()) if s.get("do") == "make"]


def action_between_places(program: dict) -> bool:
    """An action client of one place (a robot, the run-wide nodes) and its server in another."""
    robot = [e for e in _entities(program, "robot") if e["kind"] == "action_client" and e["to"]["node"].startswith("w")]
    run_wide = [e for e in _entities(program, "run_wide") if e["kind"] == "action_client" and "robot" in e["to"]]
    return bool(robot or run_wide)


def sleeps_on_sim_time(program: dict) -> bool:
    """A callback sleeps on the node's clock (a rate, ``sleep_for``) or an action server's execute
    callback paces its feedback so."""
    def sleeps(e):
        return e.get("execute") in ("rate", "clock") or any(s.get("do") == "sleep" for s in e.get("body", ()))
    return any(sleeps(e) for part in ("robot", "run_wide") for e in _entities(program, part))


def cleanup_destroys(program: dict) -> bool:
    """A node whose on_cleanup destroys what on_configure made is cleaned up at some tick."""
    nodes = (*program.get("nodes", ()), *program.get("run_wide", ()))
    return any(n.get("cleanup_destroys") for n in nodes) and '"t": "cleanup"' in json.dumps(program)


def makes_a_timer(program: dict) -> bool:
    return any(e["kind"] == "timer" for part in ("robot", "run_wide") for e in _made(program, part))


def _made(program: dict, part: str) -> list[dict]:
    return [s["entity"] for e in _entities(program, part) for s in e.get("body", ()) if s.get("do") == "make"]


KNOWN: list[dict] = [
    {"construct": "a callback sleeps on sim time (a rate, sleep_for, a slow action execute callback)",
     "modes": ("threads",), "uses": sleeps_on_sim_time,
     "why": "rclpy's multi-threaded executor (kept for comparison) runs rclpy's own sleep in one of its threads, "
            "which wakes when the node's clock reaches a later tick; the host closes a tick only once its "
            "callbacks have returned, so the tick waits for the watchdog and the robot is failed as hung "
            "(the default executor sets the callback aside instead, and matches)"},
    {"construct": "an action between a robot's node and a run-wide node",
     "modes": ("threads",), "uses": action_between_places,
     "why": "rclpy's multi-threaded executor (kept for comparison) is not walked by the host: an action between "
            "places stays rclpy's, through DDS, outside the rounds of calls between places, and what one "
            "place sends in tick k the other takes as tick k + 1 starts (rclpy: in tick k). The default "
            "executor relays it in the rounds, and matches"},
    {"construct": "a timer made in a callback",
     "modes": ("threads",), "uses": makes_a_timer,
     "why": "under rclpy's multi-threaded executor (kept for comparison) a timer made in a callback may miss "
            "a firing (a tick late, then on time) when the machine is loaded: its threads and the host's "
            "check that a tick is done race over a timer that just became ready. Not deterministic: the "
            "same programs run again matched"},
    {"construct": "a lifecycle node's on_cleanup destroys its timer and publishers",
     "modes": ("workers1", "workers2", "threads", "processes"), "uses": cleanup_destroys,
     "why": "in its own process rclpy's executor may raise InvalidHandle (a destroyed timer still in its wait "
            "set) and the process ends; hosted, destroying an entity from a callback or a transition is safe "
            "on purpose, and the node runs on"},
]


SHARED_EXECUTOR = ("a program of the same batch stalls rclpy's multi-threaded executor (a known difference above): "
                   "its robots share that executor with the batch's other robots, whose ticks it holds up too")


def explained(program: dict, mode: str, batch: list[dict] = ()) -> list[str]:
    """The known differences that explain a mismatch of ``program`` in ``mode`` (empty: none),
    run in one world with ``batch``."""
    own = [k["construct"] for k in KNOWN if mode in k["modes"] and k["uses"](program)]
    if own or mode != "threads":
        return own
    neighbours = any(k["uses"](p) for p in batch if p is not program for k in KNOWN if mode in k["modes"])
    return [SHARED_EXECUTOR] if neighbours else []
