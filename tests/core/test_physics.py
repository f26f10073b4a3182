"""PhysicsWorld: the ARGoS dynamics2d differential drive on pymunk, without ROS.

Timing used throughout: 10 ticks/s and 10 sub-steps, so a sub-step is DT = 0.01 s.
Chipmunk integrates positions before it solves velocities, so a new command moves the
body one sub-step late; tolerances below are "one or two sub-steps of motion" for that.
"""
import dataclasses
import math
import subprocess
import sys

import numpy as np
import pytest

from composed_sim.core.physics import PhysicsWorld
from composed_sim.world.robot_models import FOOTBOT
from composed_sim.world.schema import World

R = FOOTBOT.body_radius_m
L = FOOTBOT.wheel_separation_m
DT = 0.01          # sub-step, s
TICK = 0.1         # s
V = 0.1            # m/s, the foot-bot's usual top speed


def make_world(n: int, **kw) -> World:
    return World(robots=[dict(count=n, controller="none")], ticks_per_second=10,
                 physics=dict(substeps=10, iterations=10), **kw)


def make(positions, headings, models=None, **world_kw) -> PhysicsWorld:
    positions = np.asarray(positions, dtype=float)
    n = len(positions)
    return PhysicsWorld(make_world(n, **world_kw), models or [FOOTBOT] * n, positions,
                        np.asarray(headings, dtype=float))


def drive(pw: PhysicsWorld, left, right, ticks: int):
    """Command constant wheel speeds and step; returns positions [ticks, n, 2]."""
    pw.set_wheel_speeds(np.broadcast_to(np.asarray(left, float), (pw.n,)),
                        np.broadcast_to(np.asarray(right, float), (pw.n,)))
    out = []
    for _ in range(ticks):
        pw.step()
        out.append(pw.poses()[0])
    return np.array(out)


def test_core_does_not_import_ros_or_plotting():
    code = ("import sys, composed_sim.core.physics; "
            "bad = [m for m in ('rclpy', 'matplotlib') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_initial_poses_round_trip_and_wrap():
    pw = make([[1.0, 2.0], [-3.0, 0.5]], [0.25, 4.0])
    p, h = pw.poses()
    assert p.dtype == np.float64 and h.dtype == np.float64
    np.testing.assert_array_equal(p, [[1.0, 2.0], [-3.0, 0.5]])
    np.testing.assert_allclose(h, [0.25, 4.0 - 2 * math.pi], atol=1e-12)
    v, w = pw.velocities()
    assert v.shape == (2, 2) and w.shape == (2,) and not v.any() and not w.any()


def test_straight_line():
    heading = 0.3
    pw = make([[0.0, 0.0]], [heading])
    drive(pw, V, V, 50)
    p, h = pw.poses()
    along = p[0] @ [math.cos(heading), math.sin(heading)]
    across = p[0] @ [-math.sin(heading), math.cos(heading)]
    # v*t minus the start-up lag, which is under two sub-steps of motion: one sub-step
    # integrates the old (zero) velocity, and the 15 N pivot cap gives 1.6 kg at most
    # 0.09375 m/s in the next. A wrong speed formula would be off by centimetres.
    assert V * 5.0 - 2 * V * DT <= along <= V * 5.0
    assert abs(across) < 1e-12
    assert h[0] == pytest.approx(heading, abs=1e-12)
    v, w = pw.velocities()
    np.testing.assert_allclose(v[0], [V * math.cos(heading), V * math.sin(heading)], atol=1e-12)
    assert abs(w[0]) < 1e-12


def test_turning_in_place():
    wheel = 0.05
    omega = 2 * wheel / L                       # (vr - vl) / L
    pw = make([[0.3, -0.2]], [0.0])
    drive(pw, -wheel, wheel, 20)
    p, h = pw.poses()
    # The 150 N m gear cap reaches omega within the first solved sub-step, so the heading
    # lags omega*t by exactly one sub-step (tolerance: a tenth of that).
    assert h[0] == pytest.approx(omega * (2.0 - DT), abs=0.1 * omega * DT)
    np.testing.assert_allclose(p[0], [0.3, -0.2], atol=1e-12)
    assert pw.velocities()[1][0] == pytest.approx(omega)


def test_velocity_follows_heading_at_start_of_tick():
    # ARGoS sets the control body's velocity once per tick from the heading at that moment;
    # re-aiming every sub-step would point the velocity ~omega*tick/2 further round.
    pw = make([[0.0, 0.0]], [0.4])
    pw.set_wheel_speeds(np.array([0.05]), np.array([0.1]))
    pw.step()
    heading_at_start = pw.poses()[1][0]
    pw.step()
    v, _ = pw.velocities()
    heading_at_end = pw.poses()[1][0]
    assert heading_at_end - heading_at_start == pytest.approx(0.05 / L * TICK, rel=1e-9)
    assert math.atan2(v[0, 1], v[0, 0]) == pytest.approx(heading_at_start, abs=1e-9)
    assert np.hypot(*v[0]) == pytest.approx(0.075, rel=1e-9)


def test_head_on_robots_never_overlap():
    pw = make([[-0.5, 0.0], [0.5, 0.0]], [0.0, math.pi])
    traj = drive(pw, V, V, 200)
    gaps = np.linalg.norm(traj[:, 0] - traj[:, 1], axis=1) - 2 * R
    # Discrete collision detection lets them overlap by at most one sub-step of closing
    # motion (2 V DT = 2 mm); Chipmunk's slop (0.1, ARGoS's default) leaves it there but
    # the contact stops any further approach, however long they keep pushing.
    assert gaps.min() >= -2 * V * DT - 1e-9
    assert gaps[-1] < 1e-3                                   # they did meet ...
    np.testing.assert_allclose(gaps[-50:], gaps[-1], atol=1e-9)   # ... and stay put
    assert np.abs(traj[:, :, 1]).max() < 1e-9


def _obstacle_case(kind):
    """(world kwargs, start, heading): a robot 0.5 m from a static obstacle, facing it."""
    if kind == "wall":        # arena 2.2 x 2.2, walls 0.1 thick inside it: inner face at x = 1
        return dict(arena=dict(size=(2.2, 2.2), walls=True)), [1.0 - R - 0.5, 0.0], 0.0
    if kind == "box":         # a 0.4 x 0.4 box turned 45 deg: a corner points at the robot
        return dict(obstacles=[dict(type="box", position=(1.0, 0.0), size=(0.4, 0.4),
                                    yaw_rad=math.pi / 4)]), [1.0 - 0.2 * math.sqrt(2) - R - 0.5, 0.0], 0.0
    if kind == "cylinder":
        return dict(obstacles=[dict(type="cylinder", position=(0.0, 1.0), radius_m=0.15)]), \
            [0.0, 1.0 - 0.15 - R - 0.5], math.pi / 2
    raise ValueError(kind)


@pytest.mark.parametrize("kind", ["wall", "box", "cylinder"])
def test_robot_cannot_penetrate_or_move_static_obstacles(kind):
    world_kw, start, heading = _obstacle_case(kind)
    pw = make([start], [heading], **world_kw)
    static = pw.space.static_body
    shapes = list(static.shapes)
    bbs = [s.bb for s in shapes]
    traj = drive(pw, V, V, 100)          # 10 s: 0.5 m to the contact, then 5 s of pushing
    clearance = np.array([min(s.point_query(tuple(p)).distance for s in shapes) - R
                          for p in traj[:, 0]])
    # At most one sub-step of approach (V DT = 1 mm) inside the surface, never through it.
    assert clearance.min() >= -V * DT - 1e-9
    assert clearance[-1] < 1e-3                              # it reached the obstacle
    along = (traj[:, 0] - start) @ [math.cos(heading), math.sin(heading)]
    assert along[-1] == pytest.approx(0.5, abs=V * DT + 1e-6)   # stopped at the surface
    assert along.max() - along[-50] < 1e-3                   # pushing got it no further
    assert static.position == (0, 0) and static.angle == 0 and static.velocity == (0, 0)
    assert [s.bb for s in shapes] == bbs


def test_force_cap_limits_pushing_a_braked_robot():
    gap = 0.05
    ticks = 50
    start = np.array([[0.0, 0.0], [2 * R + gap, 0.0]])
    uncapped = dataclasses.replace(FOOTBOT, max_force_n=1e4)
    pushed = {}
    for name, pusher in (("capped", FOOTBOT), ("uncapped", uncapped)):
        pw = make(start, [0.0, 0.0], models=[pusher, FOOTBOT])
        pw.set_wheel_speeds(np.array([V, 0.0]), np.array([V, 0.0]))   # robot 1 brakes
        for _ in range(ticks):
            pw.step()
        pushed[name] = pw.poses()[0][1, 0] - start[1, 0]
    full_speed = V * (ticks * TICK - gap / V)      # shoved at V from contact on
    # With no cap on the drive the braked robot (15 N brake) is shoved at full speed.
    assert pushed["uncapped"] == pytest.approx(full_speed, rel=0.02)
    # With the foot-bot's 15 N drive against its 15 N brake the forces cancel: after the
    # (inelastic, equal-mass) impact the pair coasts at V/2 — half the uncapped push.
    assert pushed["capped"] == pytest.approx(full_speed / 2, rel=0.05)


def _random_world(seed):
    rng = np.random.default_rng(seed)
    n = 60
    ij = np.array([(i, j) for i in range(8) for j in range(8)][:n], float)
    pos = ij * 0.45 - 1.6 + rng.uniform(-0.05, 0.05, (n, 2))
    pw = make(pos, rng.uniform(-math.pi, math.pi, n), arena=dict(size=(4.0, 4.0), walls=True),
              obstacles=[dict(type="box", position=(0.1, 0.1), size=(0.2, 0.5), yaw_rad=0.3),
                         dict(type="cylinder", position=(-0.8, 0.9), radius_m=0.1)])
    return pw, rng


def test_same_inputs_give_bit_identical_poses():
    (a, rng_a), (b, rng_b) = _random_world(7), _random_world(7)
    for _ in range(100):
        for pw, rng in ((a, rng_a), (b, rng_b)):
            pw.set_wheel_speeds(rng.uniform(-V, V, pw.n), rng.uniform(-V, V, pw.n))
            pw.step()
        (pa, ha), (pb, hb) = a.poses(), b.poses()
        assert np.array_equal(pa, pb) and np.array_equal(ha, hb)
        assert all(np.array_equal(x, y) for x, y in zip(a.velocities(), b.velocities()))
    assert np.abs(pa - _random_world(7)[0].poses()[0]).max() > 0.1    # they did move


def test_shape_errors_are_value_errors():
    with pytest.raises(ValueError, match="positions"):
        PhysicsWorld(make_world(2), [FOOTBOT] * 2, np.zeros((3, 2)), np.zeros(2))
    with pytest.raises(ValueError, match="headings"):
        PhysicsWorld(make_world(2), [FOOTBOT] * 2, np.zeros((2, 2)), np.zeros(3))
    pw = make([[0.0, 0.0], [1.0, 0.0]], [0.0, 0.0])
    with pytest.raises(ValueError, match="left_mps"):
        pw.set_wheel_speeds(np.zeros(3), np.zeros(2))
    with pytest.raises(ValueError, match="right_mps"):
        pw.set_wheel_speeds(np.zeros(2), np.array([0.0, np.nan]))


def test_zero_wheels_brake():
    pw = make([[0.0, 0.0]], [1.0])
    drive(pw, V, V, 10)
    stopped_at = drive(pw, 0.0, 0.0, 1)[-1]
    # Control velocity zero; the 15 N pivot stops 1.6 kg at 0.1 m/s in two sub-steps.
    v, w = pw.velocities()
    assert not v.any() and not w.any()
    np.testing.assert_array_equal(drive(pw, 0.0, 0.0, 5)[-1], stopped_at)
