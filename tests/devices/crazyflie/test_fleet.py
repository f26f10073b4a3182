"""Crazyflies as a swarm: batched exactly as drone by drone, the plans' boundary conditions, and
how drones move (perfect tracking, the floor, falling, hover, the supervisor's watchdog and lock)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from composed_sim.devices.crazyflie import Crazyflies, Tracking
from composed_sim.devices.crazyflie import polynomials as poly
from composed_sim.devices.crazyflie.commander import HIGH_LEVEL, LEVEL_OUT, OFF, POSITION
from composed_sim.devices.crazyflie.high_level import EBUSY
from composed_sim.devices.crazyflie.planner import FLYING, IDLE

MASS = 0.027
DT = 0.01
finite = st.floats(-3.0, 3.0, allow_nan=False)


def _fleet(n, spacing=1.0):
    return Crazyflies(np.column_stack([np.arange(n) * spacing, np.zeros(n), np.zeros(n)]), np.zeros(n),
                      mass_kg=MASS)


def _run(fleet, t, seconds):
    for _ in range(int(round(seconds / DT))):
        t = round(t + DT, 10)
        fleet.advance(t, DT)
    return t


# --- batched = drone by drone -----------------------------------------------------------------

command = st.one_of(
    st.tuples(st.just("takeoff"), st.floats(0.2, 2.0), st.floats(0.3, 3.0), st.none() | finite),
    st.tuples(st.just("land"), st.floats(0.0, 0.1), st.floats(0.3, 3.0), st.none() | finite),
    st.tuples(st.just("go_to"), st.tuples(finite, finite, st.floats(0.2, 2.0)), finite, st.floats(0.3, 3.0),
              st.booleans(), st.booleans()),
    st.tuples(st.just("start"), st.floats(0.5, 2.0), st.booleans(), st.booleans(), st.booleans()),
    st.tuples(st.just("position"), st.tuples(finite, finite, st.floats(0.2, 2.0)), finite),
    st.tuples(st.just("hover"), finite, finite, finite, st.floats(0.2, 2.0)),
    st.tuples(st.just("notify")), st.tuples(st.just("stop")), st.tuples(st.just("emergency")),
    st.tuples(st.just("mask"), st.integers(0, 7)))


def _send(fleet, drone, t, cmd, group_mask):
    op, *a = cmd
    if op == "takeoff":
        return fleet.takeoff(drone, t, a[0], a[1], yaw=a[2], group_mask=group_mask)
    if op == "land":
        return fleet.land(drone, t, a[0], a[1], yaw=a[2], group_mask=group_mask)
    if op == "go_to":
        return fleet.go_to(drone, t, a[0], a[1], a[2], relative=a[3], linear=a[4], group_mask=group_mask)
    if op == "start":
        return fleet.start_trajectory(drone, t, 1, timescale=a[0], reversed=a[1], relative=a[2], relative_yaw=a[3],
                                      group_mask=group_mask)
    actions = {"position": lambda: fleet.cmd_position(drone, t, a[0], a[1]),
               "hover": lambda: fleet.cmd_hover(drone, t, *a),
               "notify": lambda: fleet.notify_setpoints_stop(drone),
               "stop": lambda: fleet.stop(drone, group_mask=group_mask),
               "emergency": lambda: fleet.emergency(drone),
               "mask": lambda: fleet.set_group_mask(drone, a[0])}
    return actions[op]()


def _upload(fleet):
    knots = np.array([0.0, 0.8, 2.0])
    pos = np.array([[0.0, 0.0, 1.0], [0.3, 0.2, 1.1], [0.0, 0.5, 1.0]])
    zero = np.zeros(2)
    pieces = poly.plan_pieces(np.diff(knots), pos[:-1], zero, np.zeros((2, 3)), zero, np.zeros((2, 3)),
                              pos[1:], np.array([0.5, 1.0]), np.zeros((2, 3)), zero, np.zeros((2, 3)))
    assert (fleet.upload_trajectory(None, 1, 0, pieces, np.diff(knots)) == 0).all()


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 60), st.integers(0, 3), st.integers(0, 3), command), max_size=12))
def test_a_swarm_flies_as_its_drones_would_alone(script):
    """Each drone of a fleet of 4 does what a fleet of that one drone does, command for command and
    tick for tick: the batch never mixes drones (state, setpoint, codes)."""
    n, ticks = 4, 70
    swarm, alone = _fleet(n), [Crazyflies([[d * 1.0, 0.0, 0.0]], [0.0], mass_kg=MASS) for d in range(n)]
    for fleet in (swarm, *alone):
        _upload(fleet)
    for tick in range(ticks):
        t = tick * 0.05
        for when, drone, group_mask, cmd in script:
            if when == tick:
                codes = _send(swarm, drone, t, cmd, group_mask)
                single = _send(alone[drone], 0, t, cmd, group_mask)
                assert (codes is None and single is None) or list(codes) == list(single)
        swarm.advance(t, 0.05)
        for d, fleet in enumerate(alone):
            fleet.advance(t, 0.05)
            assert np.array_equal(swarm.state.pos[d], fleet.state.pos[0])
            assert np.array_equal(swarm.setpoints.values[d], fleet.setpoints.values[0], equal_nan=True)
            assert swarm.setpoints.kind[d] == fleet.setpoints.kind[0]


# --- the plans ------------------------------------------------------------------------------

def _scalar_value(coefficients, t, k):
    """The k-th derivative of one polynomial at t, term by term (a plain reference)."""
    total = 0.0
    for i, c in enumerate(coefficients):
        if i >= k:
            total += c * np.prod(range(i - k + 1, i + 1)) * t ** (i - k)
    return total


@settings(max_examples=60, deadline=None)
@given(st.floats(0.2, 5.0), st.lists(finite, min_size=6, max_size=6))
def test_a_plan_meets_its_ends_with_no_jerk(duration, ends):
    x0, v0, a0, x1, v1, a1 = ends
    c = poly.plan_7th_order_no_jerk(np.array([duration]), *(np.array([[v]]) for v in ends))[0, 0]
    for t, (x, v, a) in ((0.0, (x0, v0, a0)), (duration, (x1, v1, a1))):
        for k, want in enumerate((x, v, a, 0.0)):
            assert _scalar_value(c, t, k) == pytest.approx(want, abs=1e-9 * (1 + abs(want)) / min(duration, 1) ** 3)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=32, max_size=32), st.floats(0.0, 3.0))
def test_evaluation_matches_a_term_by_term_sum(coefficients, t):
    c = np.reshape(coefficients, (1, 4, 8))
    ev = poly.evaluate(c, np.array([t]))
    for axis in range(3):
        for k, field in enumerate((ev.pos, ev.vel, ev.acc, ev.jerk)):
            want = _scalar_value(c[0, axis], t, k)
            assert field[0, axis] == pytest.approx(want, rel=1e-9, abs=1e-9 * 3 ** 7)
    assert ev.yaw[0] == pytest.approx(_scalar_value(c[0, 3], t, 0), rel=1e-9, abs=1e-9 * 3 ** 7)


# --- how the drones move ----------------------------------------------------------------------

def test_take_off_follows_the_plan_exactly_and_starts_and_ends_on_the_floor():
    fleet = _fleet(3)
    t = _run(fleet, 0.0, 0.5)
    assert (fleet.state.pos[:, 2] == 0.0).all() and (fleet.setpoints.kind == OFF).all()
    t_cmd = t
    assert list(fleet.takeoff(None, t, 1.0, 2.5)) == [0, 0, 0]
    plan = poly.plan_7th_order_no_jerk(np.array([2.5]), np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)),
                                       np.ones((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)))[0, 0]
    for _ in range(300):
        t = round(t + DT, 10)
        fleet.advance(t, DT)
        want = _scalar_value(plan, min(t - t_cmd, 2.5), 0)
        assert np.allclose(fleet.state.pos[:, 2], want, atol=1e-12)
    assert list(fleet.takeoff(None, t, 1.0, 2.5)) == [1, 1, 1]       # flying: refused
    fleet.land(None, t, 0.03, 2.0)
    t = _run(fleet, t, 1.99)
    assert np.allclose(fleet.state.pos[:, 2], 0.03, atol=1e-6)
    t = _run(fleet, t, 0.2)              # the landing's end: planner idle, motors off, it drops
    assert (fleet.state.pos[:, 2] == 0.0).all() and (fleet.planner_states() == IDLE).all()
    assert (fleet.setpoints.kind == OFF).all()


def test_emergency_drops_a_drone_and_locks_it():
    fleet = _fleet(2)
    fleet.takeoff(None, 0.0, 1.0, 1.0)
    t = _run(fleet, 0.0, 1.5)
    fleet.emergency(0)
    t = _run(fleet, t, 0.3)
    assert 0.0 < fleet.state.pos[0, 2] < 1.0 - 0.5 * 9.81 * 0.25 ** 2    # falling
    t = _run(fleet, t, 0.5)
    assert fleet.state.pos[0, 2] == 0.0 and fleet.state.pos[1, 2] == pytest.approx(1.0)
    assert list(fleet.takeoff(None, t, 1.0, 1.0)) == [EBUSY, 1]
    assert list(fleet.go_to(None, t, [0, 0, 1], 0, 1)) == [EBUSY, 0]
    fleet.cmd_position(0, t, [0, 0, 1], 0.0)
    _run(fleet, t, 0.2)
    assert fleet.state.pos[0, 2] == 0.0 and fleet.supervisor_info()[0] & 64


def test_a_stream_takes_over_and_the_high_level_commander_comes_back_after_notify():
    fleet = _fleet(1)
    fleet.takeoff(0, 0.0, 1.0, 1.0)
    t = _run(fleet, 0.0, 1.2)
    for _ in range(20):
        t = round(t + DT, 10)
        fleet.cmd_position(0, t, [0.5, 0.0, 1.2], 0.3)
        fleet.advance(t, DT)
    assert fleet.setpoints.kind[0] == POSITION and np.allclose(fleet.state.pos[0], [0.5, 0.0, 1.2])
    assert fleet.go_to(0, t, [0, 0, 1], 0, 1.0)[0] == 0              # taken, but refused by priority
    t = _run(fleet, t, 0.3)
    assert fleet.setpoints.kind[0] == POSITION
    fleet.notify_setpoints_stop(0)
    fleet.land(0, t, 0.03, 1.0)
    t = _run(fleet, t, 0.05)
    assert fleet.setpoints.kind[0] == HIGH_LEVEL and fleet.planner_states()[0] != IDLE


def test_a_stream_that_stops_levels_out_then_locks():
    fleet = _fleet(1)
    t = 0.0
    for _ in range(100):
        t = round(t + DT, 10)
        fleet.cmd_position(0, t, [0.0, 0.0, 0.8], 0.0)
        fleet.advance(t, DT)
    t = _run(fleet, t, 0.45)
    assert fleet.setpoints.kind[0] == POSITION
    t = _run(fleet, t, 0.1)
    assert fleet.setpoints.kind[0] == LEVEL_OUT and fleet.state.pos[0, 2] == pytest.approx(0.8)
    t = _run(fleet, t, 1.5)
    assert fleet.commander.locked[0] and fleet.state.pos[0, 2] < 0.8


def test_hover_integrates_body_velocities_and_yaw_rate_at_its_height():
    fleet = _fleet(1)
    t, yaw_rate, speed = 0.0, 0.5, 0.2
    for _ in range(200):
        t = round(t + DT, 10)
        fleet.cmd_hover(0, t, speed, 0.0, yaw_rate, 0.6)
        fleet.advance(t, DT)
    # Forward at 0.2 m/s while turning at 0.5 rad/s: an arc of radius 0.4 m.
    yaw = yaw_rate * 2.0
    assert fleet.state.yaw[0] == pytest.approx(yaw)
    assert fleet.state.pos[0, 2] == 0.6
    assert np.allclose(fleet.state.pos[0, :2], [0.4 * np.sin(yaw), 0.4 * (1 - np.cos(yaw))], atol=2e-3)


@pytest.mark.parametrize("order", [1, 2])
def test_tracking_lags_behind_and_settles(order):
    fleet = Crazyflies([[0.0, 0.0, 0.0]], [0.0], mass_kg=MASS, tracking=Tracking(order, 0.1))
    fleet.takeoff(0, 0.0, 1.0, 1.0)
    t = _run(fleet, 0.0, 0.5)
    assert fleet.state.pos[0, 2] < fleet.setpoints.pos[0, 2]
    _run(fleet, t, 2.0)
    assert fleet.state.pos[0, 2] == pytest.approx(1.0, abs=1e-3)


def test_group_masks_address_some_drones():
    fleet = _fleet(3)
    fleet.set_group_mask(0, 0b01)
    fleet.set_group_mask(1, 0b10)
    assert list(fleet.takeoff(None, 0.0, 1.0, 1.0, group_mask=0b10)) == [0, 0, 0]
    assert list(fleet.planner_states()) == [IDLE, FLYING, IDLE]       # drone 2 is in no group: ignores it
    fleet.takeoff(None, 0.0, 1.0, 1.0)                                # mask 0: everyone
    assert list(fleet.planner_states()) == [FLYING, FLYING, FLYING]


# --- bad input: answered, never a crash -------------------------------------------------------

def test_bad_numbers_are_refused_by_name_before_any_drone_is_touched():
    fleet = _fleet(2)
    with pytest.raises(ValueError, match="height must be finite"):
        fleet.takeoff(None, 0.0, float("nan"), 1.0)
    with pytest.raises(ValueError, match="goal must be finite"):
        fleet.go_to(0, 0.0, [0.0, float("inf"), 1.0], 0.0, 1.0)
    with pytest.raises(ValueError, match="durations must be finite"):
        fleet.upload_trajectory(0, 1, 0, np.zeros((1, 4, 8)), [float("nan")])
    with pytest.raises(IndexError, match=r"drone index out of range 0..1: \[2\]"):
        fleet.takeoff(2, 0.0, 1.0, 1.0)
    assert list(fleet.planner_states()) == [IDLE, IDLE]


def test_a_trajectory_of_no_pieces_or_past_the_memory_is_never_started():
    fleet = _fleet(1)
    fleet.takeoff(0, 0.0, 1.0, 1.0)
    t = _run(fleet, 0.0, 1.5)
    assert fleet.upload_trajectory(0, 2, 0, np.zeros((0, 4, 8)), [])[0] == 0      # as the firmware: taken
    assert fleet.start_trajectory(0, t, 2)[0] == 0                                # …and ignored
    assert fleet.upload_trajectory(0, 3, 30, np.zeros((2, 4, 8)), [1.0, 1.0])[0] == 1   # past the memory
    assert fleet.start_trajectory(0, t, 3)[0] == 0
    t = _run(fleet, t, 0.5)
    assert fleet.state.pos[0, 2] == pytest.approx(1.0) and fleet.setpoints.kind[0] == HIGH_LEVEL


def test_in_group_says_who_obeys_a_mask():
    fleet = _fleet(3)
    fleet.set_group_mask([0, 1], 0b100)
    assert list(fleet.in_group(None, 0b100)) == [True, True, False]
    assert list(fleet.in_group(None, 0b010)) == [False, False, False]       # a mask no drone has
    assert list(fleet.in_group(None, 0)) == [True, True, True]
