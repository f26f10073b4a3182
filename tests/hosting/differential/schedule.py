"""The statements whose effect depends on when they run, placed at chosen ticks of a scheduler
(``strategies.py``): parameters set and read, lifecycle transitions, entities made and
destroyed, services made later, goals and their cancels, and calls from constructors."""
from __future__ import annotations

from hypothesis import strategies as st

from differential.bodies import free_body
from differential.spec import STEP_TICKS, TICKS

LAST = TICKS - 2            # the last tick a scheduled statement's effect is still compared at


def scheduler(draw, b, node: str) -> dict:
    """``node``'s scheduler: its scan callback ``sz`` (a robot node) or 1-tick timer ``tz``."""
    name = "sz" if node.startswith("n") else "tz"
    found = b.entity(node, name)
    if found is not None:
        return found
    entity = {"kind": "scan" if name == "sz" else "timer", "name": name,
              "group": draw(st.sampled_from(["default", "re1"])), "body": []}
    if name == "tz":
        entity["period"] = 0.1
    if b.has("await") and draw(st.booleans()):
        entity["async"] = True
    return b.add(node, entity)


def at(entity: dict, statement: dict, tick: int) -> None:
    entity["body"].append({**statement, "at": [tick]})


def scheduled_hows(b, sched: dict, apc: bool = False) -> list[str]:
    out = ["done"]
    if sched["group"] == "re1":
        if sched.get("async"):
            out += ["await"] if b.has("await") else []
        elif not apc:
            out += [h for h in ("block", "timeout") if b.has(h)]
    return out


def callers(b, target: str, setting: bool = False) -> list[str]:
    """Who may set or read ``target``'s parameter: a run-wide node's is set by itself when two
    robots run (both robots setting it in one tick would leave a value rclpy does not define)."""
    if setting and target.startswith("w") and b.program["robots"] > 1:
        return [target]
    return [n for n in b.nodes if n.startswith("n") or not target.startswith("w") or n == target]


def schedule_all(draw, b) -> None:
    schedule_params(draw, b)
    for node in [n for n in b.nodes.values() if n["lifecycle"]]:
        schedule_lifecycle(draw, b, node)
    if b.has("make"):
        schedule_made_timer(draw, b)
    if b.has("late_service") and len(b.robot_nodes()) > 1:
        schedule_late_service(draw, b)
    if b.has("actions") and draw(st.booleans()):
        schedule_goal(draw, b)
    if b.has("init_call"):
        schedule_init_calls(draw, b)


def param_statement(draw, b, node: str, target: str, do: str) -> tuple[dict, dict]:
    """A ``param_set``/``param_get`` of ``target``'s k0 by ``node``: (statement, its scheduler)."""
    sched = scheduler(draw, b, node)
    if node == target:
        return {"do": do, "client": "own", "name": "k0"}, sched
    how_client = draw(st.sampled_from(["raw", "apc"] if b.has("apc") else ["raw"]))
    how = draw(st.sampled_from(scheduled_hows(b, sched, apc=how_client == "apc")))
    group = draw(st.sampled_from(["re1", "cl1"] if how != "done" else ["default", "re1", "cl1"]))
    robot = draw(st.integers(0, b.program["robots"] - 1))
    client = b.client_for(node, b.to(node, target, robot=robot), group, kind="param_client", how=how_client)
    return {"do": do, "client": client, "name": "k0", "how": how}, sched


def schedule_params(draw, b) -> None:
    if not b.has("params") or not draw(st.booleans()):
        return
    target = draw(st.sampled_from(list(b.nodes)))
    b.nodes[target]["params"] = ["k0"]
    set_tick = draw(st.integers(1, LAST - 3))
    statement, sched = param_statement(draw, b, draw(st.sampled_from(callers(b, target, True))), target, "param_set")
    at(sched, statement, set_tick)
    free = [t for t in range(1, LAST) if t not in (set_tick, set_tick + 1)]
    for _ in range(draw(st.integers(1, 2))):
        statement, sched = param_statement(draw, b, draw(st.sampled_from(callers(b, target))), target, "param_get")
        at(sched, statement, draw(st.sampled_from(free)))


def transition_ticks(draw, period: int, steps: int) -> list[int]:
    """Ticks of configure and the ``steps`` transitions after it: two or more apart, none on a
    tick where a timer of ``period`` ticks made at configure fires."""
    ticks = [draw(st.integers(1, 4))]
    for _ in range(steps):
        choices = [t for t in range(ticks[-1] + 2, ticks[-1] + 5) if (t - ticks[0]) % period and t <= LAST]
        if not choices:
            break
        ticks.append(draw(st.sampled_from(choices)))
    return ticks


def configured_entities(draw, b, node: dict) -> int:
    """What ``node`` makes in ``on_configure``: a timer that publishes on a lifecycle publisher
    (heard by a robot node) and drives; ``cmd_vel`` itself, maybe. Returns the timer's period in ticks."""
    name, period = node["name"], draw(st.sampled_from([2, 3]))
    topic = b.fresh("y")
    b.add(name, {"kind": "pub", "name": f"lo_{topic}", "topic": topic, "configured": True})
    listener = draw(st.sampled_from(b.robot_nodes()))
    b.add(listener, {"kind": "sub", "name": f"i_{topic}", "topic": topic, "group": "default", "body": []})
    if b.has("lifecycle_cmd_vel") and draw(st.booleans()) and not any(
            e["kind"] == "cmd_vel" for n in b.nodes.values() for e in n["entities"]):
        b.add(name, {"kind": "cmd_vel", "name": "cmd_vel", "configured": True})
    b.add(name, {"kind": "timer", "name": "tc", "period": period / 10, "group": "default", "configured": True,
                 "body": [{"do": "publish", "pub": f"lo_{topic}"}, {"do": "drive"}]})
    if b.has("cleanup_destroys"):
        node["cleanup_destroys"] = draw(st.booleans())
    node["transitions"] = {"activate": [{"do": "now"}, {"do": "drive"}]}
    return period


def schedule_lifecycle(draw, b, node: dict) -> None:
    period = configured_entities(draw, b, node)
    if node["lifecycle"] == "autostart":
        return
    name = node["name"]
    drivers = ([name] if b.has("lifecycle_self") else []) + \
        ([n for n in b.robot_nodes() if n != name] if b.has("lifecycle_other") else []) + \
        ([n for n in b.nodes if n.startswith("w")] if b.has("lifecycle_run_wide") else [])
    if not drivers:
        return
    driver = draw(st.sampled_from(drivers))
    ticks = transition_ticks(draw, period, draw(st.integers(1, 3)))
    robots = range(b.program["robots"]) if driver.startswith("w") else [None]
    sched = scheduler(draw, b, driver)
    for t, tick in zip(("configure", "activate", "deactivate", "cleanup"), ticks):
        for robot in robots:
            if driver == name:
                at(sched, {"do": "transition", "client": "self", "t": t}, tick)
                continue
            how = draw(st.sampled_from(scheduled_hows(b, sched)))
            group = draw(st.sampled_from(["re1", "cl1"] if how != "done" else ["default", "re1", "cl1"]))
            client = b.client_for(driver, b.to(driver, name, robot=robot or 0), group, kind="lifecycle_client")
            at(sched, {"do": "transition", "client": client, "t": t, "how": how}, tick)


def schedule_made_timer(draw, b) -> None:
    from differential.strategies import Ctx
    node = draw(st.sampled_from(list(b.nodes)))
    period, made = draw(st.integers(1, 3)), draw(st.integers(1, LAST - 4))
    timer = {"kind": "timer", "name": "tm", "period": period / 10, "group": "default",
             "body": draw(free_body(b, Ctx(node, "default", False, "timer"), max_len=2))}
    sched = scheduler(draw, b, node)
    at(sched, {"do": "make", "entity": timer}, made)
    if b.has("destroy") and draw(st.booleans()):
        choices = [t for t in range(made + 1, LAST) if (t - made) % period]
        if choices:
            at(sched, {"do": "destroy", "name": "tm"}, draw(st.sampled_from(choices)))


def schedule_late_service(draw, b) -> None:
    maker, caller = draw(st.permutations(b.robot_nodes()))[:2]
    made = draw(st.integers(1, LAST - 5))
    service = {"kind": "service", "name": b.fresh(f"{maker}_s"), "group": draw(st.sampled_from(["default", "re1"]))}
    b.services.append({"node": maker, "name": service["name"], "group": service["group"], "level": 0,
                       "entity": service, "late": True})
    at(scheduler(draw, b, maker), {"do": "make", "entity": service}, made)
    sched = scheduler(draw, b, caller)
    how = draw(st.sampled_from(scheduled_hows(b, sched)))
    client = b.client_for(caller, b.to(caller, maker, service["name"]),
                          draw(st.sampled_from(["re1", "cl1"] if how != "done" else ["default", "cl1"])), late=True)
    if b.has("ready"):
        at(sched, {"do": "ready", "client": client}, draw(st.sampled_from([t for t in range(1, LAST) if not made <= t <= made + 1])))
    at(sched, {"do": "call", "client": client, "how": how}, draw(st.integers(made + 2, LAST)))


def schedule_goal(draw, b) -> None:
    server, client_node = draw(st.sampled_from(list(b.nodes))), draw(st.sampled_from(list(b.nodes)))
    execute = draw(st.sampled_from(["immediate"] + [s for s, c in (("rate", "sleep_rate"), ("clock", "sleep_clock"))
                                                     if b.has(c)]))
    b.add(server, {"kind": "action_server", "name": "a0", "group": draw(st.sampled_from(["ac1", "re1"])),
                   "execute": execute, "cancel": draw(st.sampled_from(["accept", "reject"]))})
    steps = draw(st.integers(1, 3))
    length = STEP_TICKS * steps if execute != "immediate" else 0
    sent = draw(st.integers(1, max(1, LAST - length - 2)))
    sched = scheduler(draw, b, client_node)
    how = draw(st.sampled_from([h for h in scheduled_hows(b, sched) if h in ("done", "await")]))
    robot = draw(st.integers(0, b.program["robots"] - 1))
    client = b.client_for(client_node, b.to(client_node, server, "a0", robot),
                          draw(st.sampled_from(["default", "re1", "cl1"])), kind="action_client")
    at(sched, {"do": "goal", "client": client, "ticks": steps, "how": how}, sent)
    wakes = [t for t in ([sent + STEP_TICKS * k + 1 for k in range(steps)] if length else [sent + 1]) if t <= LAST]
    if wakes and draw(st.booleans()):
        at(sched, {"do": "cancel", "client": client}, draw(st.sampled_from(wakes)))


def schedule_init_calls(draw, b) -> None:
    robot = b.robot_nodes()
    for i, name in enumerate(robot):
        targets = [s for s in b.services if not s.get("late") and (s["node"] in robot[:i] or s["node"].startswith("w"))]
        if not targets or not draw(st.booleans()):
            continue
        s = draw(st.sampled_from(targets))
        client = b.client_for(name, b.to(name, s["node"], s["name"]), draw(st.sampled_from(["default", "re1", "cl1"])))
        b.nodes[name]["init"] = [{"do": "wait_service", "client": client}, {"do": "call", "client": client, "how": "done"}]
