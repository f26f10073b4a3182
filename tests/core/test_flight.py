"""Drones in the simulation (core/flight.py): they fly by their firmware beside robots on wheels,
their altitude is part of the state, the sensors and the results; near misses are counted."""
from __future__ import annotations

import numpy as np
import pytest

from composed_sim.core.near_misses import NearMisses
from composed_sim.core.simulation import Simulation
from composed_sim.devices.crazyflie import polynomials as poly
from composed_sim.hosts.tick_loop import LoopResult, LoopTimes, Trajectories
from composed_sim.outputs.results import load_trajectories, write_results
from composed_sim.world.loader import WorldFileError, load_world
from composed_sim.world.schema import World

TICKS_PER_SECOND = 100


def _world(*groups, **extra) -> World:
    return World.model_validate({"ticks_per_second": TICKS_PER_SECOND, "robots": list(groups), **extra})


def _drones(count, spacing=0.5, **group):
    return {"model": "crazyflie", "count": count, "controller": "none", "name_prefix": "cf",
            "placement": {"method": "grid", "spacing_m": spacing}, "heading": {"method": "constant"}, **group}


def _footbots(count):
    return {"model": "foot-bot", "count": count, "controller": "none",
            "placement": {"method": "grid", "center": [3.0, 3.0]}}


def _takeoff_curve(height, duration):
    zero = np.zeros((1, 1))
    return poly.plan_7th_order_no_jerk(np.array([duration]), zero, zero, zero, np.full((1, 1), height), zero,
                                       zero)[0, 0]


def test_a_take_off_is_the_firmware_curve_at_every_tick_beside_robots_on_wheels():
    with Simulation(_world(_footbots(3), _drones(4))) as sim:
        drones = sim.drones
        assert list(drones.robots) == [3, 4, 5, 6] and list(sim.wheeled) == [0, 1, 2]
        sim.set_velocity_commands(np.full(7, 0.1), np.zeros(7))      # the drones' part does nothing
        for _ in range(50):
            sim.advance()
        assert (sim.altitudes == 0.0).all()                            # on the floor before take-off
        start, start_xy = drones.now, sim.positions[3:].copy()
        drones.fleet.takeoff(drones.of_robots([3, 4, 5, 6]), drones.now, 1.0, 2.5)
        curve = _takeoff_curve(1.0, 2.5)
        for _ in range(300):
            sim.advance()
            tau = min(drones.now - start, 2.5)
            want = sum(c * tau ** i for i, c in enumerate(curve))
            assert np.allclose(sim.altitudes[3:], want, atol=1e-12) and (sim.altitudes[:3] == 0.0).all()
        assert np.array_equal(sim.positions[3:], start_xy)
        assert sim.positions[0, 0] > sim.initial_positions[0, 0] + 0.2      # the foot-bots drove on
        frame = sim.frame
        assert np.allclose(frame.pose.positions[3:, 2], 1.0) and (frame.pose.positions[:3, 2] == 0.0).all()


def test_a_robot_that_does_not_fly_is_no_drone():
    with Simulation(_world(_footbots(2), _drones(2))) as sim:
        with pytest.raises(IndexError, match=r"robots \[1\] do not fly"):
            sim.drones.of_robots([1, 2])
    with Simulation(_world(_footbots(2))) as sim:
        assert sim.drones is None and (sim.altitudes == 0.0).all()


def test_range_and_bearing_between_drones_is_three_dimensional():
    world = _world(_drones(2, spacing=1.0, devices={"range_and_bearing": {}}))
    with Simulation(world) as sim:
        sim.drones.fleet.takeoff(0, 0.0, 1.5, 1.0)
        sim.drones.fleet.takeoff(1, 0.0, 0.5, 1.0)
        for _ in range(150):
            sim.advance()
        rab = sim.frame.range_and_bearing
        assert rab.ranges[0] == pytest.approx(np.hypot(1.0, 1.0))
        assert abs(rab.vertical_bearings[0]) == pytest.approx(np.pi / 4)


def test_a_swap_that_passes_too_close_is_a_near_miss_and_one_that_keeps_apart_is_not():
    """Crazyswarm2's swap: two drones trade places 0.4 m apart, one 0.1 m above the other (a near
    miss: the downwash ellipsoid reaches 0.45 m down), then again 1 m above it (none)."""
    with Simulation(_world(_drones(2, spacing=0.4))) as sim:
        fleet, drones = sim.drones.fleet, sim.drones
        fleet.takeoff(0, 0.0, 0.4, 2.0)
        fleet.takeoff(1, 0.0, 0.5, 2.0)
        for _ in range(250):
            sim.advance()
        assert drones.near_misses.events == []
        a, b = sim.positions[0].copy(), sim.positions[1].copy()
        fleet.go_to(0, drones.now, [*b, 0.4], 0.0, 3.0)
        fleet.go_to(1, drones.now, [*a, 0.5], 0.0, 3.0)
        for _ in range(350):
            sim.advance()
        events = drones.near_misses.events
        assert len(events) == 1 and (events[0].first, events[0].second) == (0, 1)
        assert events[0].distance_m == pytest.approx(0.1, abs=1e-6)
        fleet.go_to(1, drones.now, [*b, 1.5], 0.0, 2.0)
        for _ in range(250):
            sim.advance()
        fleet.go_to(0, drones.now, [*a, 0.4], 0.0, 3.0)
        for _ in range(350):
            sim.advance()
        assert len(drones.near_misses.events) == 1


def test_near_misses_are_vectorised_pairs_of_the_ellipsoid():
    near = NearMisses(np.array([4, 7, 9]), radius_m=0.15, height_ratio=3.0)
    xy = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.12]])
    near.check(1, xy, np.array([0.0, 0.0, 0.0]))                    # all on the floor: none
    assert near.events == []
    # 4 and 7: 0.1 m apart; 4 and 9: 0.12 m across, 0.4 m up (0.12²/0.15² + 0.4²/0.45² > 1)
    near.check(2, xy, np.array([1.0, 1.0, 1.4]))
    assert [(e.tick, e.first, e.second) for e in near.events] == [(2, 4, 7)]
    near.check(3, xy * 0.5, np.array([1.0, 1.0, 1.5]))             # closer: the same event, its closest updated
    assert [(e.tick, e.first, e.second) for e in near.events] == [(2, 4, 7)]
    assert near.events[0].distance_m == pytest.approx(0.05)
    near.check(4, xy * 0.5, np.array([1.0, 1.0, 1.3]))             # 9 comes down within reach of both
    near.check(5, xy * 4, np.array([1.0, 1.0, 1.3]))               # all apart: the next approach is new
    near.check(6, xy, np.array([1.0, 1.0, 1.0]))                   # 7 and 9: 0.156 m apart, outside
    assert [(e.tick, e.first, e.second) for e in near.events] == [(2, 4, 7), (4, 4, 9), (4, 7, 9), (6, 4, 7),
                                                                 (6, 4, 9)]
    summary = near.summary(["r%d" % i for i in range(10)])
    assert summary["count"] == 5 and summary["pairs"] == ["r4-r7", "r4-r9", "r7-r9"] and summary["closest_m"] == 0.05


def test_the_altitudes_are_in_the_trajectories_and_the_results(tmp_path):
    with Simulation(_world(_footbots(1), _drones(2, spacing=0.12))) as sim:
        traj = Trajectories.allocate(sim, 60)
        sim.drones.fleet.takeoff(None, 0.0, 0.3, 0.5)
        for _ in range(60):
            sim.advance()
            traj.record(sim)
        result = LoopResult(traj.filled(), [], LoopTimes())
        events = sim.drones.near_misses.events
        assert len(events) == 1
        files = write_results(tmp_path, sim.world, result, {}, picture=False, near_misses=events)
    assert "near_misses.csv" in files
    rows = (tmp_path / "near_misses.csv").read_text().splitlines()
    assert rows[0] == "tick,first,second,distance_m" and rows[1].split(",")[1:3] == ["cf0", "cf1"]
    loaded = load_trajectories(tmp_path / "trajectories.npz")
    assert loaded.altitudes.shape == (61, 3) and loaded.altitudes[-1, 1] == pytest.approx(0.3)
    assert (loaded.altitudes[:, 0] == 0.0).all()


def test_a_drone_has_no_wheels_to_count(tmp_path):
    path = tmp_path / "drones.yaml"
    path.write_text("ticks_per_second: 100\nrobots:\n  - model: crazyflie\n    count: 2\n    controller: none\n"
                    "    devices: {odometry: {}}\n")
    with pytest.raises(WorldFileError, match=r"drones.yaml:6.*devices.odometry.*crazyflie flies: it has no wheels"):
        load_world(path)
