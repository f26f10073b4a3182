"""The physics in cells and regions (core/cell_layout.py, core/cells.py, core/engine.py, core/regions.py).

What the design guarantees, and is checked here:
- a robot with no contact across a border moves bit for bit as in one space, also when it crosses
  cells' and regions' borders (its state goes with it);
- the regions' worker processes give the run of the same cells stepped in this process, tick for tick;
- a contact across a border is resolved with ghosts (no overlap) and not seen with ``ignore``;
- bad region settings are refused with the file, the field and the value; no process outlives an engine.
"""
import math
import os
import signal
import textwrap

import numpy as np
import pytest

from composed_sim.core.cell_layout import plan_layout
from composed_sim.core.cell_engine import TiledPhysics
from composed_sim.core.engine import layout_of, physics_engine
from composed_sim.core.physics import PhysicsWorld
from composed_sim.core.regions import RegionError, RegionPhysics
from composed_sim.core.simulation import Simulation
from composed_sim.world import WorldFileError, load_world
from composed_sim.world.robot_models import FOOTBOT
from composed_sim.world.schema import World

R = FOOTBOT.body_radius_m


def world_of(n: int, **physics) -> World:
    return World(robots=[dict(count=n, controller="none")], physics=physics)


def engines(world: World, positions, headings, **kw):
    models = [FOOTBOT] * len(positions)
    return physics_engine(world, models, np.asarray(positions, float), np.asarray(headings, float), **kw)


def children_alive(pids) -> list[int]:
    return [p for p in pids if os.path.exists(f"/proc/{p}")]


# --- the layout -----------------------------------------------------------------------------------

def test_every_robot_has_one_owner_and_ghosts_within_the_margin():
    rng = np.random.default_rng(3)
    positions = rng.uniform(-10, 10, (2000, 2))
    layout = plan_layout(positions, regions=2, robots_per_cell=300, margin_m=0.5, ignore_other_regions=False)
    assert layout.n_regions == 2 and layout.n_cells >= 6
    owner = layout.owners(positions)
    cell, robot = layout.members(positions, owner)
    pairs = set(zip(cell.tolist(), robot.tolist()))
    assert all((o, r) in pairs for r, o in enumerate(owner.tolist()))          # every robot is in its cell
    moved = layout.owners(positions + 0.5 * np.sign(rng.uniform(-1, 1, positions.shape)))
    shifted = layout.owners(positions + rng.uniform(-0.5, 0.5, positions.shape))
    for r in range(len(positions)):        # a cell it may touch within 0.5 m along each axis holds it
        assert (shifted[r], r) in pairs
        assert moved[r] == owner[r] or (moved[r], r) in pairs
    counts = np.bincount(owner, minlength=layout.n_cells)
    assert counts.max() <= 1.5 * counts.mean()     # about as many robots in each cell


def test_ignore_takes_no_ghost_from_another_region():
    positions = np.array([[-0.1, 0.0], [0.1, 0.0], [5.0, 0.0]])
    for ignore, expected in ((False, {(0, 0), (0, 1), (1, 0), (1, 1), (1, 2)}), (True, {(0, 0), (1, 1), (1, 2)})):
        layout = plan_layout(positions, cuts=(0.0,), robots_per_cell=0, margin_m=0.4, ignore_other_regions=ignore)
        cell, robot = layout.members(positions, layout.owners(positions))
        assert set(zip(cell.tolist(), robot.tolist())) == expected


# --- trajectories ---------------------------------------------------------------------------------

def _parallel_swarm():
    """64 robots on a grid, all heading the same way and driving at the same speeds: no contacts."""
    ij = np.array([(i, j) for i in range(8) for j in range(8)], float)
    return ij * 0.5 - 1.75, np.full(64, 0.3)


@pytest.mark.parametrize("physics", [dict(regions=dict(x_m=[-0.6, 0.3]), robots_per_cell=0),
                                     dict(regions=dict(y_m=[0.1]), robots_per_cell=20),
                                     dict(robots_per_cell=10, processes=1),
                                     dict(robots_per_cell=10, processes=3)])
def test_without_contacts_across_borders_cells_and_regions_move_robots_as_one_space(physics):
    positions, headings = _parallel_swarm()
    world = world_of(64, **physics)
    one = PhysicsWorld(world_of(64), [FOOTBOT] * 64, positions, headings)
    cut = engines(world, positions, headings)
    assert isinstance(cut, RegionPhysics if "regions" in physics or physics.get("processes", 1) > 1 else TiledPhysics)
    try:
        for tick in range(80):     # 0.8 m along the heading: many robots cross a border
            speeds = np.full(64, 0.1 + 0.02 * math.sin(tick)), np.full(64, 0.11)
            for engine in (one, cut):
                engine.set_wheel_speeds(*speeds)
                engine.step()
            assert all(np.array_equal(a, b) for a, b in zip(one.poses(), cut.poses())), tick
            assert all(np.array_equal(a, b) for a, b in zip(one.velocities(), cut.velocities())), tick
        owners_then = cut.layout.owners(positions)
        assert (cut.layout.owners(cut.poses()[0]) != owners_then).sum() >= 8   # robots changed cells
    finally:
        cut.close()


def _crowd(seed: int, n: int = 150):
    rng = np.random.default_rng(seed)
    ij = np.array([(i, j) for i in range(13) for j in range(13)][:n], float)
    return ij * 0.3 - 1.8 + rng.uniform(-0.03, 0.03, (n, 2)), rng.uniform(-math.pi, math.pi, n), rng


def test_regions_in_processes_give_the_run_of_their_cells_in_this_process_every_time():
    positions, headings, rng = _crowd(5)
    world = world_of(len(positions), regions=3, robots_per_cell=25)
    serial = engines(world, positions, headings, processes=False)
    runs = [engines(world, positions, headings) for _ in range(2)]
    try:
        left, right = rng.uniform(-0.1, 0.1, len(positions)), rng.uniform(-0.1, 0.1, len(positions))
        for _ in range(30):     # each robot on its own circle: they bump into one another
            for engine in (serial, *runs):
                engine.set_wheel_speeds(left, right)
                engine.step()
            assert np.array_equal(serial.state(), runs[0].state())
            assert np.array_equal(serial.state(), runs[1].state())
        assert np.abs(serial.poses()[0] - positions).max() > 0.1
    finally:
        for engine in runs:
            engine.close()


def test_the_cells_of_one_region_give_the_same_run_in_any_number_of_processes():
    """physics.processes spreads a one-region world's cells over processes: the cells, and so the
    run, are the same as in one process, contacts included, bit for bit."""
    positions, headings, rng = _crowd(7)
    world = world_of(len(positions), robots_per_cell=25, processes=1)
    serial = engines(world, positions, headings)
    assert isinstance(serial, TiledPhysics) and serial.layout.n_cells == 6
    spread = [engines(world_of(len(positions), robots_per_cell=25, processes=k), positions, headings) for k in (2, 6)]
    assert [len(e.pids) for e in spread] == [2, 6]
    try:
        left, right = rng.uniform(-0.1, 0.1, len(positions)), rng.uniform(-0.1, 0.1, len(positions))
        for _ in range(30):
            for engine in (serial, *spread):
                engine.set_wheel_speeds(left, right)
                engine.step()
            assert all(np.array_equal(serial.state(), e.state()) for e in spread)
        assert np.abs(serial.poses()[0] - positions).max() > 0.1
    finally:
        for engine in spread:
            engine.close()


def test_auto_processes_are_one_per_usable_core_up_to_the_cells(monkeypatch):
    from composed_sim.core.engine import cell_processes
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(16)))
    assert [cell_processes(world_of(10), cells) for cells in (1, 6, 10, 40)] == [1, 6, 10, 16]
    assert cell_processes(world_of(10, processes=4), 40) == 4 and cell_processes(world_of(10, processes=4), 3) == 3


def _head_on(border_contacts: str):
    """Two robots driving at each other across the border x = 0 of two regions."""
    world = world_of(2, regions=dict(x_m=[0.0]), border_contacts=border_contacts)
    engine = engines(world, [[-0.3, 0.0], [0.3, 0.0]], [0.0, math.pi])
    try:
        gaps = []
        for _ in range(60):
            engine.set_wheel_speeds(np.full(2, 0.1), np.full(2, 0.1))
            engine.step()
            p = engine.poses()[0]
            gaps.append(np.linalg.norm(p[0] - p[1]))
        return np.array(gaps), engine.poses()[0]
    finally:
        engine.close()


def test_a_contact_across_a_border_is_resolved_with_ghosts_and_not_seen_with_ignore():
    one = PhysicsWorld(world_of(2), [FOOTBOT] * 2, np.array([[-0.3, 0.0], [0.3, 0.0]]), np.array([0.0, math.pi]))
    one_gaps = []
    for _ in range(60):
        one.set_wheel_speeds(np.full(2, 0.1), np.full(2, 0.1))
        one.step()
        one_gaps.append(np.linalg.norm(np.subtract(*one.poses()[0])))
    ghosts, ghost_end = _head_on("ghosts")
    assert ghosts.min() > 2 * R - 0.005                       # they push, as in one space
    np.testing.assert_allclose(ghosts, one_gaps, atol=1e-9)
    ignored, ignored_end = _head_on("ignore")
    assert ignored.min() < 0.02                               # they drive through each other (ARGoS)
    assert ignored_end[0, 0] > 0.2 and ignored_end[1, 0] < -0.2


# --- settings and processes -----------------------------------------------------------------------

BASE = """\
robots: [{count: 4, controller: none}]
obstacles: [{type: box, position: [5, 5], size: [1, 1], movable: %s}]
physics:
  regions: %s
"""


@pytest.mark.parametrize("regions, movable, expected", [
    ("0", "false", "w.yaml:4: physics.regions: must be >= 1 (got 0)"),
    ("65", "false", "w.yaml:4: physics.regions: must be <= 64 (got 65)"),
    ("{x_m: [1.0, 0.5]}", "false", "w.yaml:4: physics.regions.x_m: the cuts must increase (got [1.0, 0.5])"),
    ("{x_m: [1.0], y_m: [2.0]}", "false", "physics.regions: give the cuts between the regions along one axis"),
    ("{z_m: [1.0]}", "false", "physics.regions.z_m: unknown field"),
    ("auto", "false", 'w.yaml:4: physics.regions: a count of regions (1 to 64) or the cuts between them '
     '({x_m: [...]} or {y_m: [...]}) (got "auto")'),
    ("2", "true", "w.yaml:4: physics.regions: regions need a world without movable objects "
     "(obstacles[0] is movable): give physics.regions: 1 (got 2)"),
])
def test_bad_region_settings_name_the_file_the_field_and_the_value(tmp_path, regions, movable, expected):
    path = tmp_path / "w.yaml"
    path.write_text(BASE % (movable, regions))
    with pytest.raises(WorldFileError) as info:
        load_world(path)
    assert expected in str(info.value)


def test_a_world_file_names_its_regions(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text(textwrap.dedent("""\
        robots: [{count: 200, controller: none, placement: {method: uniform, density: 5.0}}]
        physics: {regions: {y_m: [0.5]}, border_contacts: ignore, ghost_margin_m: 0.3, robots_per_cell: 50}
        """))
    world = load_world(path)
    with Simulation(world) as sim:
        layout = sim.physics.layout
        assert (layout.axis, layout.n_regions, layout.ignore_other_regions, layout.margin_m) == (1, 2, True, 0.3)
        assert 0.5 in layout.band_cuts and layout.n_cells >= 4
        pids = list(sim.physics.pids)
        sim.advance()
    assert len(pids) == 2 and not children_alive(pids)


def test_no_worker_outlives_its_engine_whatever_ends_it():
    positions, headings, rng = _crowd(1, 60)
    world = world_of(60, regions=2)
    closed = engines(world, positions, headings)
    pids = list(closed.pids)
    closed.step()
    closed.close()
    closed.close()
    assert not children_alive(pids)
    with pytest.raises(RegionError, match="closed"):
        closed.step()

    dropped = engines(world, positions, headings)          # garbage: its finalizer ends them
    pids = list(dropped.pids)
    del dropped
    assert not children_alive(pids)

    killed = engines(world, positions, headings)           # a worker dies: the step fails, the rest end
    pids = list(killed.pids)
    os.kill(pids[1], signal.SIGKILL)
    with pytest.raises(RegionError, match="region 1"):
        killed.step()
    assert not children_alive(pids)


def test_a_layout_that_needs_one_cell_is_the_one_space():
    positions, headings, _ = _crowd(2, 30)
    assert isinstance(engines(world_of(30), positions, headings), PhysicsWorld)
    assert layout_of(world_of(3000), np.zeros((0, 2))).n_cells == 1


def test_ctrl_c_during_a_tick_ends_the_workers(monkeypatch):
    positions, headings, _ = _crowd(4, 60)
    engine = engines(world_of(60, regions=2), positions, headings)
    pids = list(engine.pids)

    def interrupted():
        raise KeyboardInterrupt
    monkeypatch.setattr(engine, "_wait_all", interrupted)   # as if Ctrl-C came while the workers step
    with pytest.raises(KeyboardInterrupt):
        engine.step()
    assert not children_alive(pids)
