"""Crazyswarm2's interface of the drones, from a process of its own as its scripts use it
(tests/hosting/crazyswarm_tool.py, which talks as crazyflie_py does): the drones found by their
services, the crazyflie_server's parameters, take-off, an uploaded figure eight, streamed
setpoints, group masks, landings; each drone's path checked against what was commanded, tick by
tick; what no drone should be asked is a logged warning, never a hang or a crash; in every host mode."""
from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from composed_sim.devices.crazyflie import polynomials as poly
from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.schema import World
from tests.hosting.figure_eight import figure_eight

ROOT = Path(__file__).resolve().parents[2]
INTERFACES = ROOT / "tests" / "user_pkg" / "crazyflie_interfaces"
TOOL = Path(__file__).with_name("crazyswarm_tool.py")
TICK_S = 0.01
CM = 0.02


@pytest.fixture(scope="module", autouse=True)
def crazyflie_interfaces():
    """The tests' crazyflie_interfaces built and importable, here and in the tool's process."""
    from composed_sim.interfaces import activate
    activate([str(INTERFACES)])


def drone_world(count: int = 2, **extra) -> World:
    return World.model_validate({
        "ticks_per_second": 100, "length_ticks": 100_000, "interfaces": [str(INTERFACES)],
        "arena": {"size": [6.0, 6.0]},
        "robots": [{"model": "crazyflie", "count": count, "name_prefix": "cf",
                    "crazyflie": {"ids": [231, 5, 7, 9][:count]},
                    "placement": {"method": "grid", "spacing_m": 1.0}, "heading": {"method": "constant"}}],
        **extra})


def host_for(mode: str, world: World, domain: int, logs=None):
    if mode == "workers":
        from composed_sim.hosts.workers.worker_host import WorkerHost
        return WorkerHost(world, workers=2, domain_id=domain, logs=logs)
    if mode == "multi-process":
        from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
        # One domain for the drones: a script sees the drones of its own domain only.
        return MultiProcessHost(world, domain_id=domain, robots_per_domain=len(world.robot_names()), logs=logs)
    return ComposedHost(world, domain_id=domain, logs=logs)


def node_logs(tmp_path, world):
    from composed_sim.hosting import WARN, Console, LogSettings, NodeLogs
    return NodeLogs(LogSettings(str(tmp_path / "logs"), WARN), world.tick_ns, console=Console(io.StringIO()))


def fly(scenario: str, world: World, domain: int, mode: str = "composed", logs=None):
    """The run, while the tool plays ``scenario`` against it: (result, what the tool reported)."""
    # Started once the host is set up, as a script is run once the crazyflie_server is up: its
    # discovery wait then measures discovery, not the host's set-up on a loaded machine.
    with host_for(mode, world, domain, logs) as host:
        tool = subprocess.Popen([sys.executable, str(TOOL), str(domain), scenario], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        try:
            result = host.run(should_stop=lambda: tool.poll() is not None)
        finally:
            out, err = tool.communicate(timeout=60)
    assert tool.returncode == 0, err[-3000:]
    # Its report is its last line: Fast DDS writes its own log lines on stdout too (a shared-memory
    # port that another participant of the machine held a moment, in a parallel test run).
    return result, json.loads(out.strip().splitlines()[-1])


def take_off_curve(height: float, duration: float):
    zero = np.zeros((1, 1))
    c = poly.plan_7th_order_no_jerk(np.array([duration]), zero, zero, zero, np.full((1, 1), height), zero, zero)[0, 0]
    return lambda t: np.polynomial.polynomial.polyval(np.clip(t, 0.0, duration), c)


def first_tick(moving: np.ndarray) -> int:
    """The tick before the first one of ``moving``: the tick whose close took the command."""
    return int(np.flatnonzero(moving)[0]) - 1


def check_flight(result, report) -> None:
    names = result.trajectories.names
    z, xy = result.trajectories.altitudes, result.trajectories.positions
    first, second = (names.index(n) for n in report["drones"][:2])
    # Take-off to 1.0 m in 2.5 s: the firmware's curve at every tick, within 2 cm.
    start = first_tick(z[:, first] > 0)
    ticks = np.arange(start, start + 300)
    assert np.abs(z[ticks, first] - take_off_curve(1.0, 2.5)((ticks - start) * TICK_S)).max() < CM
    # The figure eight, relative to where it starts: within 2 cm of its polynomial at every tick.
    hover = xy[start + 300, first]
    begin = first_tick(np.linalg.norm(xy[:, first] - hover, axis=1) > 1e-9)
    coefficients, durations = figure_eight()
    t = (np.arange(begin, begin + 800) - begin) * TICK_S
    piece = np.minimum((t // durations[0]).astype(int), len(durations) - 1)
    local = t - piece * durations[0]
    want = np.stack([[np.polynomial.polynomial.polyval(local[i], coefficients[piece[i], c]) for c in range(2)]
                     for i in range(len(t))]) - coefficients[0, :2, 0] + hover
    assert np.abs(xy[begin:begin + 800, first] - want).max() < CM
    # The streamed circle: every tick of it at a setpoint sent, in the order sent.
    sent = np.array(report["streamed"])
    on_circle = np.flatnonzero(np.linalg.norm(xy[:, second] - report["initial"][names[second]][:2], axis=1) > 1e-6)
    assert len(on_circle) > 50
    streaming = on_circle[z[on_circle, second] > 0.49]
    matches = [int(np.argmin(np.linalg.norm(sent[:, :2] - xy[k, second], axis=1))) for k in streaming]
    assert all(np.linalg.norm(sent[m, :2] - xy[k, second]) < 1e-6 for m, k in zip(matches, streaming))
    assert matches == sorted(matches)
    # Landed at the end (a landing at 0.03 m, then motors off: on the floor).
    assert z[-1, first] < 0.05 and z[-1, second] < 0.05


def test_a_script_finds_the_drones_and_flies_them_as_commanded(domain_id):
    """As Crazyswarm2's hello_world, figure8 and cmd_full_state scripts: each path follows what was commanded."""
    world = drone_world()
    result, report = fly("flight", world, domain_id)
    assert report["drones"] == ["cf231", "cf5"]
    assert report["uri"] == {"cf231": "radio://0/80/2M/E7E7E7E7E7", "cf5": "radio://0/80/2M/E7E7E7E705"}
    assert report["initial"] == {"cf231": [-0.5, 0.0, 0.0], "cf5": [0.5, 0.0, 0.0]}
    assert report["params"]["cf231.params.hlCommander.groupmask"] == 2          # an integer parameter
    assert report["params"]["all.params.hlCommander.vtoff"] == 3                # a double one
    assert result.violations == []
    check_flight(result, report)


@pytest.mark.parametrize("mode", ["workers", "multi-process"])
def test_a_script_flies_the_drones_in_every_host_mode(domain_id, mp_domain, mode):
    world = drone_world()
    result, report = fly("flight", world, mp_domain if mode == "multi-process" else domain_id, mode)
    assert result.violations == []
    check_flight(result, report)


def test_group_masks_set_as_parameters_pick_who_takes_off(domain_id, tmp_path):
    """As Crazyswarm2's group_mask script: the masks set through the crazyflie_server's parameters; a take-off for a
    group no drone is in moves none and is a warning; all.params sets every drone's."""
    world = drone_world()
    logs = node_logs(tmp_path, world)
    result, report = fly("masks", world, domain_id, logs=logs)
    assert report["set"] == [True, True, True]
    z = result.trajectories.altitudes
    first_up, all_up, answered = (round(t / TICK_S) for _, t in report["marks"])
    assert z[:first_up - 1].max() == 0.0                        # mask 4: nobody
    assert z[all_up - 1, 0] == pytest.approx(0.5) and z[all_up - 1, 1] == 0.0      # mask 1: cf231 only
    # then both: up 1 s after the take-off was answered at the latest, landing 1.5 s after that
    assert z[answered + 110:answered + 150, 1].min() == pytest.approx(0.5)
    assert z[-1].max() < 1e-9
    logs.flush()
    text = (tmp_path / "logs" / "crazyflie_server.log").read_text()
    assert "all/takeoff: group mask 4: no drone is in it" in text


def test_what_no_drone_should_be_asked_is_a_warning_and_the_run_goes_on(domain_id, tmp_path):
    world = drone_world()
    logs = node_logs(tmp_path, world)
    result, report = fly("bad", world, domain_id, logs=logs)
    assert report["cf99"] is False and report["set cf99"] is False
    logs.flush()
    text = (tmp_path / "logs" / "cf231.log").read_text()
    for warning in ("takeoff: refused by the planner: a take-off while the planner is not idle",
                    "upload_trajectory: a trajectory with no pieces: refused",
                    "upload_trajectory: a piece of non-positive duration (0 s): refused",
                    "go_to: the goal (50.000, 0.000, 1.000) m is outside the arena: refused",
                    "start_trajectory: ignored: the drone has no such trajectory defined",
                    "takeoff: refused: the drone is locked after an emergency stop (EBUSY)"):
        assert warning in text, text
    z = result.trajectories.altitudes[:, 0]
    assert z.max() == pytest.approx(1.0) and z[-1] == 0.0        # stayed at 1 m, then fell when stopped
    assert result.violations == []
