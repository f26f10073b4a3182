"""2D rigid-body physics of the robots and static obstacles (pymunk / Chipmunk).

A faithful copy of the ARGoS 3 ``dynamics2d`` engine's differential drive
(ilpincy/argos3, ``plugins/simulator/physics_engines/dynamics2d`` and
``plugins/robots/foot-bot/simulator/dynamics2d_footbot_model.cpp``): each robot is a
dynamic circle dragged by an infinite-mass "control body" through velocity-only
pivot and gear joints whose forces are capped, so a robot follows its wheel speeds
in free space but can push, and be pushed by, other bodies only within those caps.

State crosses the pymunk boundary in batch: every tick the control bodies' velocities
are written, and the poses and velocities read, with ``pymunk.batch``; no Python runs per
robot.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import pymunk
import pymunk.batch
from composed_sim.devices.common.poses import wrap_angle
from composed_sim.world.robot_models import RobotModel
from composed_sim.world.schema import Box, Cylinder, World

# ARGoS static box/cylinder models: "e = 0.0; u = 0.1 // Little contact friction to help sliding away"
STATIC_FRICTION = 0.1
# ARGoS movable box/cylinder models: "u = 0.7 // Lots of friction", like the robots.
MOVABLE_FRICTION = 0.7
# dynamics2d engine defaults (box/cylinder linear and angular friction, docs/architecture.md):
# the caps of the velocity-only pivot and gear joints that tie a movable body to the ground.
MOVABLE_GROUND_FORCE_N = 1.49
MOVABLE_GROUND_TORQUE_NM = 1.49

_FIELDS = (pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE
           | pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY)
_N_FIELDS = 6   # x, y, angle, vx, vy, w — the order cpSpaceEachBody's batch writer uses
_SET_FIELDS = pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY


def checked_wheel_speeds(left_mps, right_mps, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Copies of wheel speeds [n] each (m/s) as float64; a wrong shape or a non-finite value is a
    ValueError naming the argument."""
    left = np.asarray(left_mps, dtype=np.float64)
    right = np.asarray(right_mps, dtype=np.float64)
    for name, a in (("left_mps", left), ("right_mps", right)):
        if a.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"{name} must be finite, got {a}")
    return left.copy(), right.copy()


class PhysicsWorld:
    """pymunk (Chipmunk) space: differential-drive robots, static obstacles and movable objects.

    The space's bodies, in the order ``pymunk.batch`` lists them: the n robots, their n
    control bodies and the movable objects (insertion order), then the space's static body,
    which holds the obstacles. ``space`` is exposed for queries (ray casts, tests); callers
    must not add to it or step it.
    """

    n: int
    space: pymunk.Space

    def __init__(self, world: World, models: Sequence[RobotModel], positions: np.ndarray,
                 headings: np.ndarray):
        positions = np.asarray(positions, dtype=np.float64)
        headings = np.asarray(headings, dtype=np.float64)
        n = len(models)
        if positions.shape != (n, 2):
            raise ValueError(f"positions must have shape ({n}, 2), got {positions.shape}")
        if headings.shape != (n,):
            raise ValueError(f"headings must have shape ({n},), got {headings.shape}")
        if not (np.isfinite(positions).all() and np.isfinite(headings).all()):
            raise ValueError("positions and headings must be finite")
        self.n = n
        self._substeps = world.physics.substeps
        self._dt = world.tick_s / self._substeps   # ARGoS: GetPhysicsClockTick() = tick / iterations

        self.space = new_space(world)

        self._wheel_separation_m = np.array([m.wheel_separation_m for m in models], dtype=np.float64)
        self._left_mps = np.zeros(n)
        self._right_mps = np.zeros(n)
        controls = []
        for model, (x, y), a in zip(models, positions.tolist(), headings.tolist()):
            body, shape, control, pivot, gear = robot_bodies(model, x, y, a)
            self.space.add(body, shape, pivot, gear)
            controls.append(control)
        self.space.add(*controls)

        # Added after the robots and their control bodies, and so are later ones (add_movable).
        self.movable = [ob for ob in world.obstacles if ob.movable]
        self._movable_bodies: list[pymunk.Body] = []
        self._add_movable_objects(self.movable)

        self._buffer = pymunk.batch.Buffer()
        self._velocity_buffer = pymunk.batch.Buffer()
        self._state = np.zeros((n, _N_FIELDS))   # [n, 6] x, y, angle, vx, vy, w after the last step
        self._movable_state = np.zeros((len(self.movable), _N_FIELDS))   # [k, 6] the same for movables
        self._read_state()
        if not (np.array_equal(self._state[:, 0:2], positions)
                and np.array_equal(self._state[:, 2], headings)):
            raise RuntimeError("pymunk.batch did not return the robots in insertion order")

    def _add_movable_objects(self, objects) -> None:
        """Dynamic boxes/cylinders held by ground friction (ARGoS dynamics2d_box_model.cpp and
        dynamics2d_cylinder_model.cpp): velocity-only pivot and gear joints to a static body,
        capped, so a push stronger than the caps slides the object and friction stops it."""
        ground = self.space.static_body
        for ob in objects:
            if isinstance(ob, Box):
                body = pymunk.Body(ob.mass_kg, pymunk.moment_for_box(ob.mass_kg, ob.size))
                shape = _box_shape(body, (0.0, 0.0), ob.size, 0.0)
                body.angle = ob.yaw_rad
            else:
                body = pymunk.Body(ob.mass_kg, pymunk.moment_for_circle(ob.mass_kg, 0.0, ob.radius_m))
                shape = pymunk.Circle(body, ob.radius_m)
            body.position = ob.position
            shape.elasticity = 0.0
            shape.friction = MOVABLE_FRICTION
            linear = pymunk.PivotJoint(ground, body, (0.0, 0.0), (0.0, 0.0))
            linear.max_bias = 0.0
            linear.max_force = MOVABLE_GROUND_FORCE_N
            angular = pymunk.GearJoint(ground, body, 0.0, 1.0)
            angular.max_bias = 0.0
            angular.max_force = MOVABLE_GROUND_TORQUE_NM
            self.space.add(body, shape, linear, angular)
            self._movable_bodies.append(body)

    def set_wheel_speeds(self, left_mps: np.ndarray, right_mps: np.ndarray) -> None:
        """Store wheel speeds [n] each (m/s); they act from the start of the next step()."""
        self._left_mps, self._right_mps = checked_wheel_speeds(left_mps, right_mps, self.n)

    def step(self) -> None:
        """One tick: set the control velocities (act), then ``substeps`` physics steps."""
        # batch sets the velocities of every body it lists, one row each: all but the control
        # bodies get back what they have (read after the last step or placement).
        velocities = self._velocities
        velocities[self.n:2 * self.n] = control_velocities(self._left_mps, self._right_mps,
                                                           self._wheel_separation_m, self._state[:, 2])
        self._velocity_buffer.set_float_buf(velocities)
        pymunk.batch.set_space_bodies(self.space, _SET_FIELDS, self._velocity_buffer)
        step, dt = self.space.step, self._dt
        for _ in range(self._substeps):   # dynamics2d_engine.cpp Update(): `iterations` cpSpaceSteps
            step(dt)
        self._read_state()

    def _read_state(self) -> None:
        self._buffer.clear()
        pymunk.batch.get_space_bodies(self.space, _FIELDS, self._buffer)
        # One row per body batch lists: robots, control bodies, movable objects, then the static
        # bodies (the space's, which holds the obstacles).
        rows = np.frombuffer(self._buffer.float_buf(), dtype=np.float64).reshape(-1, _N_FIELDS)
        self._state[:] = rows[:self.n]
        self._movable_state[:] = rows[2 * self.n:2 * self.n + len(self.movable)]
        self._velocities = rows[:, 3:6].copy()   # C-contiguous, as set_float_buf needs

    def place_movable(self, index: int, position, yaw_rad: float) -> None:
        """Put movable object ``index`` at rest at a new pose (between steps)."""
        body = self._movable_bodies[index]
        body.position, body.angle = (float(position[0]), float(position[1])), float(yaw_rad)
        body.velocity, body.angular_velocity = (0.0, 0.0), 0.0
        self.space.reindex_shapes_for_body(body)
        self._read_state()

    def add_movable(self, obstacle) -> int:
        """Add a movable object (after the others: the batch rows stay robots, then movables)."""
        self._add_movable_objects([obstacle])
        self.movable.append(obstacle)
        self._movable_state = np.zeros((len(self.movable), _N_FIELDS))
        self._read_state()
        return len(self.movable) - 1

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions [n, 2] (m) and headings [n] (rad, wrapped to (-pi, pi])."""
        return self._state[:, 0:2].copy(), wrap_angle(self._state[:, 2])

    def wheel_speeds(self) -> tuple[np.ndarray, np.ndarray]:
        """The left and right wheel speeds [n] each (m/s) that the next step() applies."""
        return self._left_mps, self._right_mps

    def movable_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions [k, 2] (m) and yaws [k] (rad, wrapped) of the movable objects, world order."""
        return self._movable_state[:, 0:2].copy(), wrap_angle(self._movable_state[:, 2])

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        """Linear velocities [n, 2] (m/s, world frame) and angular velocities [n] (rad/s)."""
        return self._state[:, 3:5].copy(), self._state[:, 5].copy()


def new_space(world: World) -> pymunk.Space:
    """An empty space with the world's solver settings and its static obstacles."""
    # ARGoS's cpSpaceNew() defaults are Chipmunk 7's too (slop 0.1, bias 0.9^60,
    # damping 1, no gravity, no sleeping), so only the iteration count is set.
    # Default bounding-box tree: measured faster than use_spatial_hash (cell 0.17-0.5 m)
    # at 80-1280 robots. Not threaded=True: cpHastySpace's parallel solver is not
    # bit-reproducible.
    space = pymunk.Space()
    space.iterations = world.physics.iterations
    static = space.static_body
    shapes: list[pymunk.Shape] = []
    # The schema owns the wall geometry (inside the arena rectangle); they are boxes too.
    for ob in [*world.arena.wall_boxes(), *(ob for ob in world.obstacles if not ob.movable)]:
        if isinstance(ob, Box):
            shapes.append(_box_shape(static, ob.position, ob.size, ob.yaw_rad))
        elif isinstance(ob, Cylinder):
            shapes.append(pymunk.Circle(static, ob.radius_m, offset=ob.position))
        else:
            raise ValueError(f"unsupported obstacle {ob!r}")
    for s in shapes:
        s.elasticity = 0.0
        s.friction = STATIC_FRICTION
    space.add(*shapes)
    return space


def robot_bodies(model: RobotModel, x: float, y: float, angle: float):
    """One robot's body, its circle, its control body and the two joints between them (not added)."""
    # dynamics2d_footbot_model.cpp: cpBodyNew(m, cpMomentForCircle(m, 0, R + R, 0)) —
    # ARGoS passes the diameter as the radius, so I = 2 m R^2; copied as is.
    # A carried body (the foot-bot's gripper) is rigidly tied to it: its mass and moment add.
    body = pymunk.Body(model.mass_kg + model.carried_mass_kg,
                       pymunk.moment_for_circle(model.mass_kg, 0.0, 2.0 * model.body_radius_m)
                       + model.carried_moment_kg_m2)
    body.position = (x, y)
    body.angle = angle
    shape = pymunk.Circle(body, model.body_radius_m)
    shape.elasticity = 0.0              # footbot model: e = 0 "No elasticity"
    shape.friction = model.friction     # footbot model: u = 0.7
    # dynamics2d_velocity_control.cpp: control body = cpBodyNew(INFINITY, INFINITY),
    # never added to the space; Chipmunk 7 calls such a body KINEMATIC. Here it is in
    # the space, so that batch can set its velocity: a kinematic body there only has
    # its pose integrated, which these velocity-only joints do not read (their anchors
    # sit at its origin and their correction is off), and no shape to collide.
    control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    pivot = pymunk.PivotJoint(body, control, (0.0, 0.0), (0.0, 0.0))
    pivot.max_bias = 0.0                # "disable joint correction": velocity-only
    pivot.max_force = model.max_force_n   # "limit the dragging force"
    gear = pymunk.GearJoint(body, control, 0.0, 1.0)
    gear.max_bias = 0.0
    gear.max_force = model.max_torque_nm  # "limit the torque"
    return body, shape, control, pivot, gear


def control_velocities(left_mps: np.ndarray, right_mps: np.ndarray, wheel_separation_m: np.ndarray,
                       angle: np.ndarray) -> np.ndarray:
    """[n, 3] the control bodies' vx, vy (m/s) and w (rad/s) for wheel speeds [n] each and body angles [n]."""
    # dynamics2d_differentialsteering_control.cpp: w = (Vr - Vl) / b, v = (Vr + Vl) / 2
    # along the body angle at the time of the call (start of the tick). Both wheels
    # at 0 give exactly 0, which is what ARGoS's Reset() sets (the robot brakes).
    v = 0.5 * (left_mps + right_mps)
    out = np.empty((len(angle), 3))
    out[:, 0], out[:, 1], out[:, 2] = v * np.cos(angle), v * np.sin(angle), (right_mps - left_mps) / wheel_separation_m
    return out


def _box_shape(body: pymunk.Body, center: tuple[float, float], size: tuple[float, float],
               yaw_rad: float) -> pymunk.Poly:
    """A static box: its own x/y sides ``size``, rotated by ``yaw_rad`` about ``center``."""
    hx, hy = size[0] / 2, size[1] / 2
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    corners = [(center[0] + c * px - s * py, center[1] + s * px + c * py)
               for px, py in ((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy))]
    return pymunk.Poly(body, corners, radius=0.0)
