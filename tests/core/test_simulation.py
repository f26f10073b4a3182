"""The Simulation with the full device set: heterogeneous swarms, range-and-bearing timing and
reach, movable objects, per-group evaluation, determinism. No ROS."""
from __future__ import annotations

import math

import numpy as np
import pytest

from composed_sim.world.robot_models import EPUCK, FOOTBOT, THYMIO2, TURTLEBOT3_BURGER
from composed_sim.core.simulation import Simulation
from composed_sim.world.loader import load_world
from composed_sim.world.schema import World

HETEROGENEOUS_YAML = """
name: mixed
seed: 7
arena: {size: [8, 8], walls: true}
floor:
  color: [0, 0, 0]
  shapes:
    - {type: circle, position: [0, 0], radius_m: 1.5, color: [255, 255, 255]}
range_and_bearing: {mode: local, payload_bytes: 4}
lights:
  - {position: [0, 3], intensity: 2}
  - {position: [0, -3], intensity: 1}
obstacles:
  - {type: box, position: [2.5, 2.5], size: [0.4, 0.4], movable: true, mass_kg: 0.5}
  - {type: cylinder, position: [-2.5, 2.5], radius_m: 0.2, movable: true}
  - {type: cylinder, position: [-2.5, -2.5], radius_m: 0.3}
robots:
  - {model: foot-bot, count: 6, controller: none, placement: {center: [-1, 0], size: [1.5, 3]},
     devices: {range_and_bearing: {}, ground: {}}}
  - {model: e-puck, count: 6, controller: none, name_prefix: epuck,
     placement: {center: [1, 0], size: [1.5, 3]}, devices: {range_and_bearing: {range_m: 2.0}}}
  - {model: turtlebot3-burger, count: 3, controller: none, name_prefix: tb,
     placement: {center: [0, 2.5], size: [3, 1]}}
  - {model: thymio2, count: 3, controller: none, name_prefix: thymio,
     placement: {center: [0, -2.5], size: [3, 1]}}
"""


def test_heterogeneous_world_loads_and_steps_with_each_models_devices(tmp_path):
    path = tmp_path / "mixed.yaml"
    path.write_text(HETEROGENEOUS_YAML)
    sim = Simulation(load_world(path))
    assert [m.name for m in sim.models] == ["foot-bot"] * 6 + ["e-puck"] * 6 + ["turtlebot3-burger"] * 3 \
        + ["thymio2"] * 3
    np.testing.assert_array_equal(sim.radii[[0, 6, 12, 15]], [FOOTBOT.body_radius_m, EPUCK.body_radius_m,
                                                              TURTLEBOT3_BURGER.body_radius_m, THYMIO2.body_radius_m])
    assert sim.led_colors.shape == (18, 13, 3)
    for _ in range(5):
        sim.set_velocity_commands(np.full(sim.n, 0.05), np.full(sim.n, 0.3))
        frame = sim.step()
    fb, ep, tb, th = frame.groups
    assert (fb.robots, ep.robots, tb.robots, th.robots) == (slice(0, 6), slice(6, 12), slice(12, 15), slice(15, 18))
    assert fb.proximity.shape == (6, 24) and fb.light.shape == (6, 24) and fb.ground.shape == (6, 4)
    assert len(fb.blobs.offsets) == 7 and fb.lidar is None
    assert ep.proximity.shape == (6, 8) and ep.ground.shape == (6, 3) and ep.light is None and ep.blobs is None
    assert tb.lidar.shape == (3, 360) and tb.proximity is None and tb.ground is None
    assert th.proximity.shape == (3, 7) and th.ground.shape == (3, 2)
    assert frame.pose.positions.shape == (18, 3) and frame.wheels.velocities_mps.shape == (18, 2)
    assert frame.odometry.shape == (18, 3) and frame.odometry_twist.shape == (18, 2)
    rab = frame.range_and_bearing
    assert len(rab.offsets) == 19 and rab.payloads.shape[1] == 4
    assert np.all(rab.offsets[13:] == rab.offsets[12])       # burgers and Thymios have no RAB
    assert set(rab.senders.tolist()) <= set(range(12))
    # the ground sensors read the white disc or the black floor, nothing else
    # (white is 0.299 + 0.587 + 0.114 in floating point: 1 within an ulp)
    assert np.all(np.isclose(fb.ground, 0.0) | np.isclose(fb.ground, 1.0))
    with pytest.raises(ValueError, match="groups"):
        frame.proximity


def explicit_world(groups, **kw) -> World:
    return World(robots=[dict(controller="none", count=len(g["positions"]), name_prefix=f"g{i}_",
                              placement=dict(method="explicit", positions=g.pop("positions")),
                              heading=dict(method="constant", value_rad=g.pop("heading", 0.0)), **g)
                         for i, g in enumerate(groups)], **kw)


def test_a_payload_sent_at_tick_k_is_received_at_tick_k_plus_1_by_exactly_the_robots_in_range_and_sight():
    # Robot 0 at the origin; foot-bot range 3 m. 1: in range; 2: hidden behind 1;
    # 3: out of range; 4: in range, behind a wall segment; 5: in range, clear.
    positions = [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (0.0, 3.5), (0.0, -1.5), (-2.0, 1.0)]
    world = explicit_world([dict(positions=positions, devices=dict(range_and_bearing={}))],
                           obstacles=[dict(type="box", position=(0.0, -0.75), size=(0.6, 0.1))],
                           range_and_bearing=dict(payload_bytes=3))
    sim = Simulation(world)
    for robot in range(sim.n):
        sim.set_rab_payload(robot, bytes([robot, 0, 0]))
    frame0 = sim.step()                       # tick 1: payloads set before it are on the air
    for robot in range(sim.n):
        sim.set_rab_payload(robot, bytes([robot, 1, 0]))
    frame1 = sim.step()                       # tick 2
    for frame, version in ((frame0, 0), (frame1, 1)):
        senders, ranges, hb, _, data = frame.range_and_bearing.of(0)
        assert senders.tolist() == [1, 5]
        np.testing.assert_allclose(ranges, [1.0, math.hypot(2.0, 1.0)])
        np.testing.assert_allclose(hb, [0.0, math.atan2(1.0, -2.0)])
        assert data.tolist() == [[1, version, 0], [5, version, 0]]
    # robot 4: the wall hides 0, 1 and 2 pass beside the wall's end, 3 and 5 are out of range
    assert frame1.range_and_bearing.of(4)[0].tolist() == [1, 2]
    assert frame0.tick == 1 and frame1.tick == 2


def test_nothing_is_heard_before_the_first_step():
    sim = Simulation(explicit_world([dict(positions=[(0, 0), (1, 0)], devices=dict(range_and_bearing={}))]))
    assert sim.sense().range_and_bearing.of(0)[0].tolist() == []
    assert sim.step().range_and_bearing.of(0)[0].tolist() == [1]


def test_payload_size_is_checked():
    sim = Simulation(explicit_world([dict(positions=[(0, 0), (1, 0)], devices=dict(range_and_bearing={}))]))
    with pytest.raises(ValueError, match="10 bytes"):
        sim.set_rab_payload(0, b"abc")


def test_global_mode_reaches_everyone_at_any_distance():
    world = explicit_world([dict(positions=[(0, 0), (1, 0), (40, 0)], devices=dict(range_and_bearing={}))],
                           range_and_bearing=dict(mode="global"))
    frame = Simulation(world).step()
    assert [frame.range_and_bearing.of(i)[0].tolist() for i in range(3)] == [[1, 2], [0, 2], [0, 1]]


def pushing_world(movable=True, mass=0.5):
    return explicit_world([dict(positions=[(0.0, 0.0)])],
                          obstacles=[dict(type="box", position=(0.4, 0.0), size=(0.3, 0.3), movable=movable,
                                          mass_kg=mass)])


def test_a_movable_box_is_pushed_and_stops_by_friction():
    sim = Simulation(pushing_world())
    start = sim.physics.movable_poses()[0][0].copy()
    for _ in range(40):                       # 4 s at 0.1 m/s: contact after about 1.6 s
        sim.set_velocity_commands(np.array([0.1]), np.array([0.0]))
        sim.step()
    pushed = sim.physics.movable_poses()[0][0]
    assert pushed[0] - start[0] > 0.15 and abs(pushed[1] - start[1]) < 0.02
    # the robot stays behind the box it pushes
    assert sim.positions[0, 0] < pushed[0] - 0.15
    sim.set_velocity_commands(np.array([-0.1]), np.array([0.0]))   # back off
    sim.step()
    sim.set_velocity_commands(np.array([0.0]), np.array([0.0]))
    for _ in range(3):
        sim.step()
    before = sim.physics.movable_poses()[0][0].copy()
    for _ in range(10):
        sim.step()
    np.testing.assert_allclose(sim.physics.movable_poses()[0][0], before, atol=1e-9)   # friction held it


def test_a_static_box_is_not_pushed_and_sensors_see_the_movable_box_where_it_is():
    sim = Simulation(pushing_world(movable=False))
    for _ in range(40):
        sim.set_velocity_commands(np.array([0.1]), np.array([0.0]))
        sim.step()
    assert sim.positions[0, 0] == pytest.approx(0.25 - FOOTBOT.body_radius_m, abs=0.01)
    sim = Simulation(pushing_world())
    for _ in range(40):
        sim.set_velocity_commands(np.array([0.1]), np.array([0.0]))
        sim.step()
    for _ in range(3):                        # back off a few cm, then stand
        sim.set_velocity_commands(np.array([-0.1]), np.array([0.0]))
        sim.step()
    sim.set_velocity_commands(np.array([0.0]), np.array([0.0]))
    frame = sim.step()
    # the proximity rays at ±7.5° see the box's face, which moved with it
    face = sim.physics.movable_poses()[0][0][0] - 0.15
    rim = sim.positions[0, 0] + FOOTBOT.body_radius_m * math.cos(math.radians(7.5))
    assert face > 0.25 + 0.1 and frame.proximity_distances[0, 0] > 0.01
    assert frame.proximity_distances[0, 0] == pytest.approx((face - rim) / math.cos(math.radians(7.5)), abs=1e-6)


def test_groups_of_one_model_give_the_readings_of_one_group():
    rng = np.random.default_rng(0)
    xy = [tuple(p) for p in (rng.permutation(64)[:30, None] // [8, 1] % 8 * 0.6 - 2.1)]
    one = explicit_world([dict(positions=xy)], lights=[dict(position=(0, 3))])
    two = explicit_world([dict(positions=xy[:12]), dict(positions=xy[12:])], lights=[dict(position=(0, 3))])
    a, b = Simulation(one), Simulation(two)
    for sim in (a, b):
        sim.led_colors[:, 12] = (255, 0, 0)
        sim.set_velocity_commands(np.full(30, 0.05), np.linspace(-1, 1, 30))
    fa, fb = a.step(), b.step()
    np.testing.assert_array_equal(a.positions, b.positions)
    for device in ("proximity", "light"):
        np.testing.assert_array_equal(getattr(fa, device),
                                      np.concatenate([getattr(g, device) for g in fb.groups]))
    blobs = fa.blobs
    for i in range(30):
        g, row = (fb.groups[0], i) if i < 12 else (fb.groups[1], i - 12)
        for x, y in zip(blobs.of(i), g.blobs.of(row)):
            np.testing.assert_array_equal(x, y)
    assert blobs.offsets[-1] > 30           # the swarm does see itself


def test_switching_devices_and_noise_is_deterministic_per_seed():
    def run(seed):
        world = World(seed=seed, robots=[dict(count=8, controller="none", devices=dict(
            proximity=dict(noise=0.05), light=dict(enabled=False), ground=dict(noise=0.1),
            positioning=dict(position_noise_m=0.01)))], lights=[dict(position=(0, 3))])
        sim = Simulation(world)
        frames = [sim.step() for _ in range(3)]
        return frames[-1]
    a, b, c = run(1), run(1), run(2)
    assert a.groups[0].light is None and a.groups[0].ground.shape == (8, 4)
    np.testing.assert_array_equal(a.groups[0].proximity, b.groups[0].proximity)
    np.testing.assert_array_equal(a.pose.positions, b.pose.positions)
    assert not np.array_equal(a.groups[0].ground, c.groups[0].ground)


def test_the_device_modules_import_neither_ros_nor_plotting_nor_imageio():
    import subprocess
    import sys
    code = ("import sys, composed_sim.core.simulation; "
            "bad = [m for m in ('rclpy', 'matplotlib', 'imageio') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("start, stop", [(0, 18), (0, 4), (4, 13), (12, 18), (17, 18)])
def test_a_block_of_robots_reads_exactly_their_readings_in_the_whole_frame(tmp_path, start, stop):
    """What a worker process reads (core/senses.py, hosts/workers/worker_host.py): every reading of robots
    start … stop-1, the groups cut and renumbered, the CSR rows (blobs, range and bearing) intact."""
    path = tmp_path / "mixed.yaml"
    path.write_text(HETEROGENEOUS_YAML)
    sim = Simulation(load_world(path))
    sim.set_led_colors(1, np.full((13, 3), 200, dtype=np.uint8))
    for robot in range(sim.n):
        sim.set_rab_payload(robot, bytes([robot, 1, 2, 3]))
    for _ in range(3):
        sim.set_velocity_commands(np.full(sim.n, 0.05), np.full(sim.n, 0.3))
        frame = sim.step()
    cut = sim.senses.frame(sim.sensing_inputs(), sim.robot_rows(start, stop), slice(start, stop))
    assert cut.tick == frame.tick and len(cut.groups) == len(frame.groups)
    for robot in range(start, stop):
        local = robot - start
        for g, c in zip(frame.groups, cut.groups):
            assert (c.robots.start <= local < c.robots.stop) == (g.robots.start <= robot < g.robots.stop)
            if not g.robots.start <= robot < g.robots.stop:
                continue
            i, j = robot - g.robots.start, local - c.robots.start
            for field in ("proximity_distances", "proximity", "light", "ground", "lidar"):
                if getattr(g, field) is not None:
                    np.testing.assert_array_equal(getattr(c, field)[j], getattr(g, field)[i])
            if g.blobs is not None:
                for a, b in zip(c.blobs.of(j), g.blobs.of(i)):
                    np.testing.assert_array_equal(a, b)
        for a, b in zip(cut.range_and_bearing.of(local), frame.range_and_bearing.of(robot)):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(cut.pose.positions[local], frame.pose.positions[robot])
        np.testing.assert_array_equal(cut.wheels.distances_m[local], frame.wheels.distances_m[robot])
        np.testing.assert_array_equal(cut.odometry[local], frame.odometry[robot])
    assert sum(len(c.blobs.offsets) - 1 for c in cut.groups if c.blobs is not None) == \
        sum(max(0, min(c.robots.stop, stop - start) - c.robots.start) for c, g in zip(cut.groups, frame.groups)
            if g.blobs is not None)
    assert len(cut.range_and_bearing.offsets) == stop - start + 1
    assert frame.range_and_bearing.of(6)[0].size > 0      # the world really has messages to cut


def test_readings_are_read_on_first_use_and_are_those_of_their_tick(tmp_path, monkeypatch):
    """A device's readings are computed when first used (a sensor topic nobody subscribes to costs
    no sensing), once, and a frame read after the world moved on still gives its own tick's."""
    import gc
    import weakref

    import composed_sim.core.senses as senses

    calls = []
    for device, read in list(senses.GROUP_READERS.items()):
        monkeypatch.setitem(senses.GROUP_READERS, device,
                            lambda s, g, out, device=device, read=read: (calls.append((device, g.index)), read(s, g, out)))
    path = tmp_path / "mixed.yaml"
    path.write_text(HETEROGENEOUS_YAML)

    def stepped(sim: Simulation, ticks: int):
        sim.set_led_colors(1, np.full((13, 3), 200, dtype=np.uint8))
        for _ in range(ticks):
            sim.set_velocity_commands(np.full(sim.n, 0.1), np.full(sim.n, 0.5))
            sim.step()
        return sim.frame

    def moved_on(sim: Simulation) -> None:
        for _ in range(5):
            sim.set_velocity_commands(np.full(sim.n, 0.3), np.full(sim.n, -0.5))
            sim.step()

    sim = Simulation(load_world(path))
    eager = stepped(sim, 3)
    fields = ("proximity_distances", "proximity", "light", "ground", "lidar", "blobs")
    values = {(gi, field): getattr(g, field) for gi, g in enumerate(eager.groups) for field in fields}
    assert sorted(set(calls)) == sorted({(d, g.index) for g in sim.groups for d in g.running
                                         if d in senses.GROUP_READERS})
    calls.clear()
    late_sim = Simulation(load_world(path))
    late = stepped(late_sim, 3)
    moved_on(late_sim)                                 # the world moves on, then the old frame is read
    assert calls == []                                 # nothing read yet: nobody used a reading
    late.groups[0].proximity                           # the foot-bots' ring: both its fields, one read
    late.groups[0].proximity_distances
    assert calls == [("proximity", 0)]
    # A frame goes as soon as nothing refers to it (no reference cycle waits for the collector):
    # a large swarm's readings and their snapshot are not kept for later ticks.
    gone = weakref.ref(late_sim.frame.groups[0])
    gc.disable()
    try:
        late_sim.step()
        assert gone() is None
    finally:
        gc.enable()
    for (gi, field), value in values.items():
        got = getattr(late.groups[gi], field)
        if value is None:
            assert got is None
        elif field == "blobs":
            assert value.offsets.size > 1
            for a, b in zip((got.offsets, got.angles, got.distances, got.colors),
                            (value.offsets, value.angles, value.distances, value.colors)):
                np.testing.assert_array_equal(a, b)
        else:
            np.testing.assert_array_equal(got, value)
