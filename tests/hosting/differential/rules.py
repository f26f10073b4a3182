"""The generator's rules (``strategies.py``'s docstring) checked on a program: what a drawn or
shrunk program must satisfy for rclpy to give it one behaviour. ``problems(program)`` lists what
breaks them (empty: none)."""
from __future__ import annotations

from typing import Iterator

CALLBACKS = ("timer", "scan", "sub", "service", "action_server")
SLOW = ("sleep",)
WAITING = ("block", "timeout", "await")


def _callbacks(node: dict) -> Iterator[dict]:
    """Every entity of ``node`` with a callback, those its statements make included."""
    stack = list(node.get("entities", ()))
    while stack:
        e = stack.pop()
        if e.get("kind") in CALLBACKS:
            yield e
        for st in e.get("body", ()):
            if st.get("do") == "make":
                stack.append(st["entity"])


def problems(program: dict) -> list[str]:
    out = []
    nodes = {n["name"]: n for n in program["nodes"] + program.get("run_wide", [])}
    services = {(n, e["name"]): e for n, node in nodes.items() for e in _callbacks(node) if e["kind"] == "service"}
    for name, node in nodes.items():
        clients = {e["name"]: e for e in node.get("entities", ())}
        me1 = [e["name"] for e in _callbacks(node) if e.get("group") == "me1"]
        if len(me1) > 1:
            out.append(f"{name}: {len(me1)} callbacks in me1 ({', '.join(me1)})")
        for e in _callbacks(node):
            group = e.get("group", "default")
            for st in e.get("body", ()):
                where = f"{name}.{e['name']}"
                if st["do"] in SLOW and (group == "default" or e["kind"] == "service"):
                    out.append(f"{where}: sleeps in {'a service' if e['kind'] == 'service' else 'the default group'}")
                if st["do"] == "call" and st.get("how") in WAITING:
                    out += _waiting_problems(where, e, group, clients.get(st["client"]), services)
    return out


def _waiting_problems(where: str, callback: dict, group: str, client, services) -> list[str]:
    if client is None:
        return [f"{where}: waits on a client it does not have"]
    out = []
    if client.get("group", "default") == "me1" or (client.get("group", "default") == group and group != "re1"):
        out.append(f"{where}: waits through a client of group {client.get('group', 'default')}")
    target = services.get((client["to"]["node"], client["to"].get("name")))
    if target is not None:
        waits = any(s.get("how") in WAITING for s in target.get("body", ()))
        if callback["kind"] == "service" and waits:
            out.append(f"{where}: a handler waits for {client['to']['name']}, which waits itself")
        if group == "default" and (waits or target.get("group", "default") != "re1"):
            out.append(f"{where}: waits in the default group for {client['to']['name']}, which may wait itself")
    return out
