"""The statements a callback runs at each of its activations (the unscheduled ones: their
effect does not depend on the order of callbacks within a tick). Which may run where follows the
rules in ``strategies.py``'s docstring."""
from __future__ import annotations

from hypothesis import strategies as st

WAITING = ("block", "timeout", "await")


def reachable(caller: str, target: str) -> bool:
    """Robot nodes call their own robot's nodes and the run-wide ones; run-wide nodes call both."""
    return True if caller.startswith("w") else target.startswith(("n", "w"))


def call_targets(b, ctx, waiting: bool) -> list[dict]:
    out = []
    for s in b.services:
        if s.get("late") or not reachable(ctx.node, s["node"]):
            continue
        if ctx.kind == "service" and s["level"] != 0:      # a handler calls only level 0: no loop of calls
            continue
        if waiting:
            terminal = s["level"] == 0 and s["group"] == "re1"
            if (ctx.group == "default" and not terminal) or (ctx.kind == "service" and s["level"] != 0):
                continue
        out.append(s)
    return out


def can_wait(ctx) -> bool:
    return ctx.kind in ("timer", "scan", "sub") or (ctx.kind == "service" and ctx.level == 1)


def hows(b, ctx) -> list[str]:
    out = ["done"] if b.has("done") else []
    if can_wait(ctx):
        out += ["await"] if ctx.is_async and b.has("await") else \
            [h for h in ("block", "timeout") if not ctx.is_async and b.has(h)]
    return out


def draw_target(draw, b, ctx, waiting: bool) -> dict:
    s = draw(st.sampled_from(call_targets(b, ctx, waiting)))
    robot = draw(st.integers(0, b.program["robots"] - 1))
    return b.to(ctx.node, s["node"], s["name"], robot)


def draw_call(draw, b, ctx):
    how = draw(st.sampled_from([h for h in hows(b, ctx) if call_targets(b, ctx, h in WAITING)]))
    waiting = how in WAITING
    to = draw_target(draw, b, ctx, waiting)
    if waiting:
        groups = ["re1", "cl1"] + (["default"] if ctx.group != "default" and ctx.kind != "service" else [])
    else:
        groups = ["default", "re1", "cl1"]
    client = b.client_for(ctx.node, to, draw(st.sampled_from(groups)))
    return {"do": "call", "client": client, "how": how}


def draw_ready(draw, b, ctx):
    to = draw_target(draw, b, ctx, False)
    return {"do": "ready", "client": b.client_for(ctx.node, to, draw(st.sampled_from(["default", "re1", "cl1"])))}


def draw_publish(draw, b, ctx):
    pubs = [e["name"] for e in b.nodes[ctx.node]["entities"] if e["kind"] == "pub" and not e.get("configured")]
    return {"do": "publish", "pub": draw(st.sampled_from(pubs))}


def draw_sleep(draw, b, ctx):
    kinds = (["rate", "rate_destroy"] if b.has("sleep_rate") else []) + (["clock"] if b.has("sleep_clock") else [])
    return {"do": "sleep", "how": draw(st.sampled_from(kinds)), "ticks": draw(st.integers(1, 2))}


def available(b, ctx) -> list[str]:
    out = ["now"]
    if any(call_targets(b, ctx, h in WAITING) for h in hows(b, ctx)):
        out.append("call")
    if b.has("ready") and call_targets(b, ctx, False):
        out.append("ready")
    robot = ctx.node.startswith("n")
    # Only timers and scans publish: a subscriber or a handler that published would call itself.
    if robot and ctx.kind in ("timer", "scan") and any(e["kind"] == "pub" and not e.get("configured") for e in b.nodes[ctx.node]["entities"]):
        out.append("publish")
    if robot:
        out.append("drive")
    if ctx.group in ("me1", "re1") and ctx.kind in ("timer", "scan", "sub") and (b.has("sleep_rate") or b.has("sleep_clock")):
        out.append("sleep")
    return out


DRAWERS = {"call": draw_call, "ready": draw_ready, "publish": draw_publish, "sleep": draw_sleep,
           "now": lambda draw, b, ctx: {"do": "now"}, "drive": lambda draw, b, ctx: {"do": "drive"}}


@st.composite
def free_body(draw, b, ctx, max_len: int = 3) -> list[dict]:
    body = []
    for _ in range(draw(st.integers(0, max_len))):
        body.append(DRAWERS[draw(st.sampled_from(available(b, ctx)))](draw, b, ctx))
    return body
