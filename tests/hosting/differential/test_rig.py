"""The ground-truth rig drives plain rclpy processes tick by tick: what it records is what rcl's
timers and rclpy's executor do on sim time (the facts ``ground_truth.py`` relies on)."""
from __future__ import annotations

from differential.ground_truth import run_ground_truth

TIMERS = {"robots": 1, "nodes": [
    {"name": "n0", "groups": ["re1"], "entities": [
        {"kind": "scan", "name": "scan", "group": "re1", "body": [
            {"do": "call", "client": "c0", "how": "block"}, {"do": "sleep", "how": "clock", "ticks": 2, "at": [3]}]},
        {"kind": "client", "name": "c0", "to": {"node": "n1", "name": "s0"}, "group": "re1"},
        {"kind": "timer", "name": "every", "period": 0.1, "body": []},
        {"kind": "timer", "name": "odd", "period": 0.15, "body": []},
        {"kind": "timer", "name": "fast", "period": 0.05, "body": []},
        {"kind": "cmd_vel", "name": "cmd_vel"}]},
    {"name": "n1", "entities": [{"kind": "service", "name": "s0"}]}], "run_wide": []}


def fired(events, timer: str) -> list[int]:
    return sorted(tick for tick, who, act, seq, kind, *_ in events if act.startswith(f"{timer}#") and kind == "fire")


def test_rclpys_timers_scans_calls_and_sleeps_on_the_rigs_clock(tmp_path):
    from composed_sim.hosts.domain_claim import claim_free_domain, run_identity
    claim, domain = claim_free_domain(1, run_identity("differential rig test"))
    try:
        result = run_ground_truth([TIMERS], 10, tmp_path, domain)
    finally:
        claim.release()
    assert result.notes == []
    events = result.events[0]
    # A timer made when the clock read 0 fires one period later, then every period (the hosts
    # fire it at tick 0 as well: the interpreter's timers ignore a firing at clock 0).
    assert fired(events, "every") == list(range(1, 10))
    assert fired(events, "odd") == [2, 3, 5, 6, 8, 9]             # due at 0.15, 0.30, 0.45 …: the tick at or after
    assert fired(events, "fast") == list(range(1, 10))            # the periods a tick jumps over: once
    scans = sorted((tick, act) for tick, who, act, seq, kind, *_ in events if kind == "scan")
    assert scans == [(t, f"scan@{t}") for t in range(10)]
    answered = {act: tick for tick, who, act, seq, kind, *_ in events if kind == "resp"}
    assert answered == {f"scan@{t}": t for t in range(10)}      # a blocking call, answered within its tick
    woke = [(tick, act) for tick, who, act, seq, kind, *_ in events if kind == "woke"]
    assert woke == [(5, "scan@3")]                                # sleep_for two ticks of sim time
