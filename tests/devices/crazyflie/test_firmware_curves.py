"""Our Crazyflie firmware against the firmware itself: every scenario of the transcripts
(transcript.py; tools/crazyflie/regenerate.py made them from the firmware's C sources) replayed
through ``Crazyflies``, all scenarios at once, one drone each: the same return codes, the same
planner states, priorities and setpoint kinds at every step, and the same setpoints — within
1e-6 (m, m/s, m/s², rad) of the firmware compiled in double precision, and within the float
rounding of the firmware as it flies (float32)."""
from __future__ import annotations

import numpy as np
import pytest

from composed_sim.devices.crazyflie import Crazyflies
from composed_sim.devices.crazyflie.commander import FULL_STATE, HIGH_LEVEL, HOVER, OFF, POSITION
from .transcript import FIXTURES, STEP_HEADER, follow, read

# Setpoint kind → the firmware's (mode x, mode z, mode yaw): disable 0, absolute 1, velocity 2.
MODES = {OFF: (0, 0, 0), HIGH_LEVEL: (1, 1, 1), POSITION: (1, 1, 1), FULL_STATE: (1, 1, 1), HOVER: (2, 1, 2)}
# Largest difference allowed (positions in m; everything: m, m/s, m/s², rad, rad/s), per precision.
# The double build is the same arithmetic (measured: positions 4.9e-11, the transcript's 11
# digits; body rates 2.3e-7, its gravity a float 9.81); the float build rounds every coefficient
# and product to float (measured: positions 1.25e-5 m, a take-off to 1 m ends 2.9e-6 m above it;
# accelerations and rates 5.2e-5).
POSITION_TOLERANCE = {"f64": 1e-9, "f32": 2e-5}
TOLERANCE = {"f64": 1e-6, "f32": 1e-4}
DT = 0.1


def _ticks(rows):
    """A scenario's rows → its start state [7] and its ticks [(t, commands, step result)]."""
    start, ticks, pending = None, [], []
    for op, args, result in rows:
        if op == "state":
            start = np.array(args)
        elif op == "step":
            ticks.append((args[0], pending, result))
            pending = []
        else:
            pending.append((op, args, result))
    return start, ticks


def _command(fleet: Crazyflies, d: int, t: float, op: str, a: list[float]):
    """One transcript command sent to drone ``d`` → its code (None for those without)."""
    hl = fleet.high_level
    yaw = (lambda use_current, value: None if use_current else value)
    if op in ("takeoff", "land"):
        call = fleet.takeoff if op == "takeoff" else fleet.land
        return call(d, t, a[1], a[4], yaw=yaw(a[3], a[2]), group_mask=int(a[0]))[0]
    if op in ("takeoffv", "landv"):
        call = fleet.takeoff_with_velocity if op == "takeoffv" else fleet.land_with_velocity
        return call(d, t, a[1], a[5], relative=bool(a[2]), yaw=yaw(a[4], a[3]), group_mask=int(a[0]))[0]
    if op == "goto":
        return fleet.go_to(d, t, a[3:6], a[6], a[7], relative=bool(a[1]), linear=bool(a[2]), group_mask=int(a[0]))[0]
    if op == "stop":
        return fleet.stop(d, group_mask=int(a[0]))[0]
    if op == "piece":
        return hl.memory.write(np.array([d]), int(a[0]), np.reshape(a[2:], (1, 4, 8)), [a[1]])[0]
    if op == "define":
        return hl.memory.define(np.array([d]), int(a[0]), int(a[1]), int(a[2]))[0]
    if op == "start":
        return fleet.start_trajectory(d, t, int(a[1]), timescale=a[2], reversed=bool(a[3]), relative=bool(a[4]),
                                      relative_yaw=bool(a[5]), group_mask=int(a[0]))[0]
    streams = {"position": lambda: fleet.cmd_position(d, t, a[0:3], a[3]),
               "fullstate": lambda: fleet.cmd_full_state(d, t, a[0:3], a[3:6], a[6:9], a[9], np.zeros(3)),
               "hover": lambda: fleet.cmd_hover(d, t, a[0], a[1], a[2], a[3]),
               "notify": lambda: fleet.notify_setpoints_stop(d),
               "mask": lambda: fleet.set_group_mask(d, int(a[0])),
               "block": lambda: hl.block(np.array([d]), bool(a[0]))}
    streams[op]()
    return None


def _ours(fleet: Crazyflies, d: int) -> np.ndarray:
    """Drone ``d``'s step as the transcript writes it (given, priority, planner state, modes, values)."""
    sp, commander = fleet.commander.current, fleet.commander
    kind = int(sp.kind[d])
    yaw_rate = sp.yaw_rate[d] if kind == HOVER else sp.omega[d, 2]
    values = np.concatenate([sp.pos[d], sp.vel[d], sp.acc[d], [sp.yaw[d]], sp.omega[d, :2], [yaw_rate]])
    if kind == OFF:
        values[:] = 0.0
    header = [float(commander.last_high_level.given[d]), commander.priority[d],
              fleet.high_level.planner.state[d], *MODES[kind]]
    return np.concatenate([header, values])


def replay(precision: str):
    """Every scenario replayed → {scenario: [(t, firmware step, our step)]} and the code mismatches."""
    scenarios = {name: _ticks(rows) for name, rows in read(FIXTURES[precision]).items()}
    names = list(scenarios)
    starts = np.array([scenarios[s][0] for s in names])
    fleet = Crazyflies(starts[:, 0:3], starts[:, 6], mass_kg=0.027)
    states = starts.copy()
    compared = {name: [] for name in names}
    code_mismatches = []
    for i in range(max(len(scenarios[s][1]) for s in names)):
        t = round(i * DT, 10)
        for d, name in enumerate(names):
            ticks = scenarios[name][1]
            if i < len(ticks):
                assert ticks[i][0] == pytest.approx(t)
                for op, args, result in ticks[i][1]:
                    code = _command(fleet, d, t, op, args)
                    if result and code != result[0]:
                        code_mismatches.append((name, t, op, args[:3], result[0], code))
        fleet.commander.step(t, states[:, 0:3].copy(), states[:, 3:6].copy(), states[:, 6].copy())
        for d, name in enumerate(names):
            ticks = scenarios[name][1]
            if i < len(ticks):
                theirs = np.array(ticks[i][2])
                compared[name].append((t, theirs, _ours(fleet, d)))
                states[d] = follow(states[d], theirs, DT)
    return compared, code_mismatches


@pytest.fixture(scope="module", params=["f64", "f32"])
def replayed(request):
    return request.param, *replay(request.param)


def test_same_return_codes(replayed):
    _, _, mismatches = replayed
    assert mismatches == []


def test_same_states_priorities_and_kinds(replayed):
    """Planner state, priority and setpoint kind at every step: the same durations, hand-overs,
    refusals and ends of landings."""
    _, compared, _ = replayed
    wrong = [(name, t, theirs[:STEP_HEADER].tolist(), ours[:STEP_HEADER].tolist())
             for name, steps in compared.items() for t, theirs, ours in steps
             if not np.array_equal(theirs[:STEP_HEADER], ours[:STEP_HEADER])]
    assert wrong == []


def _worst(compared, columns: slice) -> dict[str, float]:
    return {name: max(np.abs(theirs[columns] - ours[columns]).max() for _, theirs, ours in steps)
            for name, steps in compared.items()}


def test_same_curves(replayed):
    precision, compared, _ = replayed
    positions = _worst(compared, slice(STEP_HEADER, STEP_HEADER + 3))
    assert max(positions.values()) <= POSITION_TOLERANCE[precision], positions
    everything = _worst(compared, slice(STEP_HEADER, None))
    assert max(everything.values()) <= TOLERANCE[precision], everything


def test_the_transcripts_cover_every_scenario_kind():
    """The scenarios the checks above rest on are in the data (a regenerated transcript that lost
    one would otherwise pass unnoticed)."""
    names = set(read(FIXTURES["f64"]))
    assert {"takeoff", "takeoff_yaw_land", "goto_absolute", "goto_relative", "goto_replan", "goto_linear",
            "goto_from_idle", "figure_eight", "figure_eight_absolute_slow", "figure_eight_reversed_fast",
            "turn_relative_yaw", "odd_durations", "group_mask", "streams_and_handover", "blocked"} <= names
    assert {"takeoff", "goto_replan", "figure_eight_reversed_fast", "streams_and_handover",
            "memory_full"} <= set(read(FIXTURES["f32"]))
