"""The drones' commands of a tick applied to their firmware (core/drone_commands.py): the same as the
firmware's own calls made one by one in the one order, vectorised over the drones that got one;
what the firmware refuses or no drone should be asked comes back as a refusal, changing nothing."""
from __future__ import annotations

import numpy as np
import pytest

from composed_sim.core.drone_commands import ALL, DroneCommand, DroneCommander
from composed_sim.devices.crazyflie import Crazyflies
from composed_sim.devices.crazyflie import polynomials as poly
from tests.hosting.figure_eight import figure_eight

DT = 0.01


def _fleet(n: int) -> Crazyflies:
    positions = np.column_stack([np.arange(n) * 0.5, np.zeros(n), np.zeros(n)])
    return Crazyflies(positions, np.zeros(n), mass_kg=0.027)


def _commander(n: int, robots=None, size=None):
    """A commander of ``n`` drones that are robots ``robots`` of a run (default 0 … n-1)."""
    robots = np.arange(n) if robots is None else np.asarray(robots)
    drone_of = np.full(robots.max() + 2, -1)
    drone_of[robots] = np.arange(n)
    inside = (lambda xy: (np.abs(xy) <= np.asarray(size) / 2).all(axis=1)) if size else \
        (lambda xy: np.ones(len(xy), dtype=bool))
    fleet = _fleet(n)
    return fleet, DroneCommander(fleet, drone_of, inside)


def _fly(fleet, ticks: int, start: int = 0) -> None:
    for k in range(start + 1, start + ticks + 1):
        fleet.advance(k * DT, DT)


def _command(robot, kind, *args, stamp=0, seq=0):
    return DroneCommand(robot, stamp, seq, kind, tuple(args))


def test_a_ticks_commands_fly_the_drones_as_the_firmwares_own_calls_one_by_one():
    """Take-offs, go-tos and streamed positions of several drones, applied in one tick, give what
    the firmware's calls made drone by drone in the same order give."""
    fleet, commander = _commander(4)
    reference = _fleet(4)
    commands = [_command(0, "takeoff", 1.0, 2.5, 0, stamp=5), _command(1, "takeoff", 0.5, 2.0, 0, stamp=1),
                _command(2, "position", 1.0, 0.0, 0.3, 0.0, stamp=2), _command(3, "takeoff", 1.0, 2.5, 0, stamp=3),
                _command(3, "go_to", 1.5, 0.0, 1.0, 0.5, 3.0, False, 0, stamp=4)]
    assert commander.apply(commands, 0.0) == []
    reference.takeoff(0, 0.0, 1.0, 2.5, yaw=0.0)
    reference.takeoff(1, 0.0, 0.5, 2.0, yaw=0.0)
    reference.cmd_position(2, 0.0, [1.0, 0.0, 0.3], 0.0)
    reference.takeoff(3, 0.0, 1.0, 2.5, yaw=0.0)
    reference.go_to(3, 0.0, [1.5, 0.0, 1.0], 0.5, 3.0)
    _fly(fleet, 400)
    _fly(reference, 400)
    np.testing.assert_array_equal(fleet.state.pos, reference.state.pos)
    np.testing.assert_array_equal(fleet.state.yaw, reference.state.yaw)


def test_the_swarms_commands_come_first_then_each_drones_in_arrival_order():
    """all/takeoff (ALL) before a drone's own land, whatever their stamps; a take-off while flying
    is refused by the planner."""
    fleet, commander = _commander(2)
    refused = commander.apply([_command(1, "land", 0.0, 1.0, 0, stamp=1),
                               _command(ALL, "takeoff", 1.0, 2.0, 0, stamp=9)], 0.0)
    assert refused == [], refused                 # the swarm took off first: drone 1 then lands
    _fly(fleet, 300)
    assert fleet.state.pos[0, 2] == pytest.approx(1.0) and fleet.state.pos[1, 2] == pytest.approx(0.0, abs=1e-9)
    refused = commander.apply([_command(0, "takeoff", 1.0, 2.0, 0, stamp=2)], 3.0)
    assert [(r.robot, r.text.split(":")[0]) for r in refused] == [(0, "takeoff")]
    assert "not idle" in refused[0].text


def test_a_group_mask_picks_the_drones_of_its_group():
    fleet, commander = _commander(3)
    commander.apply([_command(0, "set_group_mask", 0b1001), _command(2, "set_group_mask", 0b0010)], 0.0)
    commander.apply([_command(ALL, "takeoff", 0.5, 1.0, 2)], 0.0)           # drone 2 only
    _fly(fleet, 150)
    np.testing.assert_allclose(fleet.state.pos[:, 2], [0.0, 0.0, 0.5], atol=1e-9)
    commander.apply([_command(ALL, "takeoff", 0.5, 1.0, 1)], 1.5)           # drone 0 only (2 is flying)
    _fly(fleet, 150, start=150)
    np.testing.assert_allclose(fleet.state.pos[:, 2], [0.5, 0.0, 0.5], atol=1e-9)


def test_an_uploaded_trajectory_is_flown_piece_by_piece():
    fleet, commander = _commander(1)
    coefficients, durations = figure_eight()
    commander.apply([_command(0, "upload_trajectory", 3, 0, coefficients, durations),
                     _command(0, "takeoff", 1.0, 2.0, 0, stamp=1)], 0.0)
    _fly(fleet, 300)
    start = fleet.state.pos.copy()
    assert commander.apply([_command(0, "start_trajectory", 3, 1.0, False, True, 0)], 3.0) == []
    for k in range(301, 301 + 800):
        fleet.advance(k * DT, DT)
        t = k * DT - 3.0
        piece = min(int(t // 2.0), 3)
        expected = [np.polynomial.polynomial.polyval(t - 2.0 * piece, coefficients[piece, c]) for c in range(3)]
        # (our pieces are least-squares fits: 1e-5 m apart where they meet)
        np.testing.assert_allclose(fleet.state.pos[0], start[0] + expected - coefficients[0, :3, 0], atol=1e-4)


@pytest.mark.parametrize("command, why", [
    (("upload_trajectory", 0, 0, np.zeros((0, 4, 8)), np.zeros(0)), "no pieces"),
    (("upload_trajectory", 0, 0, np.zeros((2, 4, 8)), np.array([1.0, 0.0])), "non-positive duration"),
    (("upload_trajectory", 0, 0, np.zeros((1, 4, 5)), np.array([1.0])), "8 coefficients"),
    (("takeoff", 1.0, 0.0, 0), "duration must be positive"),
    (("go_to", 0.0, 0.0, 1.0, 0.0, -1.0, False, 0), "duration must be positive"),
    (("go_to", 5.0, 0.0, 1.0, 0.0, 2.0, False, 0), "outside the arena"),
    (("go_to", 0.0, 3.0, 0.0, 0.0, 2.0, True, 0), "outside the arena"),       # relative: from where it is
    (("position", 0.0, np.nan, 1.0, 0.0), "must be finite"),
    (("start_trajectory", 7, 1.0, False, True, 0), "no such trajectory defined"),
    (("start_trajectory", 40, 1.0, False, True, 0), "no such trajectory defined"),
    (("upload_trajectory", 40, 0, np.zeros((1, 4, 8)), np.array([1.0])), "ENOEXEC"),
])
def test_what_no_drone_should_be_asked_is_refused_and_changes_nothing(command, why):
    fleet, commander = _commander(2, size=(4.0, 4.0))
    before = (fleet.state.pos.copy(), fleet.high_level.planner.state.copy(), fleet.high_level.memory.defined.copy())
    refused = commander.apply([_command(1, *command)], 0.0)
    assert [r.robot for r in refused] == [1] and why in refused[0].text, refused
    _fly(fleet, 50)
    np.testing.assert_array_equal(fleet.state.pos, before[0])
    np.testing.assert_array_equal(fleet.high_level.planner.state, before[1])
    np.testing.assert_array_equal(fleet.high_level.memory.defined, before[2])


def test_after_an_emergency_stop_everything_is_refused():
    fleet, commander = _commander(1)
    commander.apply([_command(0, "takeoff", 1.0, 1.0, 0), _command(0, "emergency", stamp=1)], 0.0)
    _fly(fleet, 10)
    refused = commander.apply([_command(0, "takeoff", 1.0, 1.0, 0)], 0.1)
    assert refused and "EBUSY" in refused[0].text


def test_a_drones_robot_index_is_not_its_drone_index():
    """Robots 2 and 5 of a run are drones 0 and 1: a command names the robot."""
    fleet, commander = _commander(2, robots=[2, 5])
    commander.apply([_command(5, "takeoff", 0.7, 1.0, 0)], 0.0)
    _fly(fleet, 150)
    np.testing.assert_allclose(fleet.state.pos[:, 2], [0.0, 0.7], atol=1e-9)


def test_a_take_off_follows_the_firmwares_curve():
    fleet, commander = _commander(1)
    commander.apply([_command(0, "takeoff", 1.0, 2.5, 0)], 0.0)
    zero = np.zeros((1, 1))
    curve = poly.plan_7th_order_no_jerk(np.array([2.5]), zero, zero, zero, np.full((1, 1), 1.0), zero, zero)[0, 0]
    for k in range(1, 300):
        fleet.advance(k * DT, DT)
        tau = min(k * DT, 2.5)
        assert fleet.state.pos[0, 2] == pytest.approx(sum(c * tau ** i for i, c in enumerate(curve)), abs=1e-12)
