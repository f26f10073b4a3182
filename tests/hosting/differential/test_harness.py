"""The differential harness itself, without ROS: the comparison, the names a batch gives, the
generator's rules."""
from __future__ import annotations

import copy
import json

from hypothesis import HealthCheck, given, settings

from differential.events import compare
from differential.rules import problems
from differential.spec import TICKS, batch_world, compile_node, program_hash
from differential.strategies import programs

CALL = {"robots": 1, "nodes": [
    {"name": "n0", "groups": ["re1"], "entities": [
        {"kind": "scan", "name": "scan", "group": "re1", "body": [{"do": "call", "client": "c0", "how": "block"}]},
        {"kind": "client", "name": "c0", "to": {"node": "w0", "name": "s0"}, "group": "re1"},
        {"kind": "cmd_vel", "name": "cmd_vel"}]}],
    "run_wide": [{"name": "w0", "entities": [{"kind": "service", "name": "s0"}],
                  "init": [], "groups": []}]}


def test_callbacks_of_a_tick_compare_as_a_set_and_one_callbacks_events_in_order():
    a = [(1, "r0/n0", "t0#1", 0, "fire", 1), (1, "r0/n0", "t0#1", 1, "now", 1), (1, "r0/n0", "scan@1", 0, "scan", 1)]
    other_order = [a[2], a[0], a[1]]
    assert compare(a, other_order, 16) == []
    swapped = [(1, "r0/n0", "t0#1", 0, "now", 1), (1, "r0/n0", "t0#1", 1, "fire", 1), a[2]]
    assert [d.tick for d in compare(a, swapped, 16)] == [1]
    later = [a[0], a[1], (2, "r0/n0", "scan@1", 0, "scan", 1)]
    assert [d.tick for d in compare(a, later, 16)] == [1, 2]


def test_what_happens_before_tick_0_compares_with_tick_0_and_ticks_past_the_run_are_left_out():
    setup = [(-1, "r0/n1", "init/1", 0, "resp", "c0", 5, 5, 9)]
    assert compare(setup, [(0, *setup[0][1:])], 16) == []
    assert compare([], [(16, "w0", "tz#16", 0, "fire", 16)], 16) == []


def test_a_batch_names_each_programs_places_and_resolves_their_names():
    node = compile_node(CALL["nodes"][0], 3, robot_node=True)
    client = next(e for e in node["entities"] if e["kind"] == "client")
    assert client["target"] == "/p3w0_s0" and node["prefix"] == "p3"
    service = compile_node(CALL["run_wide"][0], 3, robot_node=False)["entities"][0]
    assert service["ros"] == "p3w0_s0"
    world = batch_world([CALL, CALL], 16)
    assert [g["name_prefix"] for g in world["robots"]] == ["p0r", "p1r"]
    assert [n["node"] for n in world["nodes"]] == ["differential.interpreter:Plain_p0w0",
                                                   "differential.interpreter:Plain_p1w0"]
    assert all(g["answers"] == "when_published" for g in world["robots"])


def test_a_programs_hash_is_its_content():
    assert program_hash(CALL, 16) == program_hash(json.loads(json.dumps(CALL)), 16) != program_hash(CALL, 17)


@settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
@given(programs())
def test_generated_programs_keep_the_rules_that_make_rclpys_behaviour_defined(program):
    assert problems(program) == []
    json.dumps(program)


def test_a_rule_broken_is_named():
    sleeping = copy.deepcopy(CALL)
    sleeping["nodes"][0]["entities"][0].update(group="default", body=[{"do": "sleep", "how": "clock", "ticks": 1}])
    assert problems(sleeping) == ["n0.scan: sleeps in the default group"]
    waiting = copy.deepcopy(CALL)
    waiting["nodes"][0]["entities"][0]["group"] = "default"
    assert problems(waiting) == ["n0.scan: waits in the default group for s0, which may wait itself"]


def test_a_fixed_program_whose_text_changed_has_no_recorded_truth_and_starts_no_rclpy(tmp_path):
    import pytest

    from differential.known import fixed_programs
    from differential.truth import truths
    programs = fixed_programs()
    assert all(r["stable"] for r in truths(programs, TICKS, tmp_path, recorded_only=True))
    changed = copy.deepcopy(programs[0])
    changed["nodes"][0]["entities"].append({"kind": "timer", "name": "extra", "period": 0.1, "body": []})
    with pytest.raises(AssertionError, match="no recorded rclpy run"):
        truths([changed], TICKS, tmp_path, recorded_only=True)
