"""Initial robot poses: draw each group's positions and headings without overlaps.

Like ARGoS's ``<distribute>``, a robot whose draw overlaps another robot, a static obstacle
or the walls is re-drawn, up to ``placement.max_trials`` times. The draws are batched:
each round draws one candidate for every robot still unplaced, checks all of them at once
with KD-trees, keeps the ones that fit and re-draws the rest. So each robot gets at most
max_trials draws, as in ARGoS, and 10,000 robots take milliseconds, not minutes.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from composed_sim.devices.common.poses import wrap_angle
from composed_sim.world.robot_models import get_model
from composed_sim.world.schema import Box, Cylinder, Placement, RobotGroup, World

# Gap kept between a robot and anything else at the start. Chipmunk (pymunk) treats shapes
# that touch as colliding and pushes them apart with a contact impulse on the first step,
# and a pose that merely touches can overlap after float rounding; 1 cm is far below the
# flocking distances (0.75 m) and about where the IR sensor saturates (0.0099 m).
CLEARANCE_M = 0.01


class PlacementError(ValueError):
    """Some robots of a group could not be placed without overlapping."""

    def __init__(self, message: str, *, group_index: int, model: str, unplaced: int,
                 trials: int):
        super().__init__(message)
        self.group_index, self.model, self.unplaced, self.trials = (
            group_index, model, unplaced, trials)


def place_robots(world: World, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Start poses of all robots, in ``world.robot_names()`` order.

    Returns positions [n, 2] (m) and headings [n] (rad, in (-pi, pi]). Groups are placed in
    order; a group avoids the robots of the groups before it. Deterministic for the state of
    ``rng``. Raises PlacementError when a group does not fit.
    """
    n = world.robot_count
    positions = np.empty((n, 2))
    headings = np.empty(n)
    radii = np.empty(n)
    statics = Statics.of_world(world)
    start = 0
    for gi, group in enumerate(world.robots):
        end = start + group.count
        radius = get_model(group.model).body_radius_m
        positions[start:end] = _place_group(gi, group, radius, positions[:start],
                                            radii[:start], statics, rng)
        radii[start:end] = radius
        headings[start:end] = _draw_headings(group, rng)
        start = end
    return positions, headings


# --- positions -----------------------------------------------------------------------

def _place_group(gi: int, group: RobotGroup, radius: float, others: np.ndarray,
                 other_radii: np.ndarray, statics: Statics,
                 rng: np.random.Generator) -> np.ndarray:
    """[count, 2] positions of one group, clear of ``others`` [m, 2] and of the statics."""
    p = group.placement
    out = np.empty((group.count, 2))
    todo = np.arange(group.count)       # indices of the robots not placed yet
    fixed = _fixed_layout(p, group.count)
    # Grid and explicit layouts give the same positions on every draw: one trial says all.
    trials = 1 if fixed is not None else p.max_trials
    # Explicit poses are taken as given (e.g. another simulator's, whose bodies may touch): only
    # a real overlap is refused. Drawn ones keep a margin.
    clearance = 0.0 if p.method == "explicit" else CLEARANCE_M
    placed, placed_radii = others, other_radii
    for _ in range(trials):
        if todo.size == 0:
            break
        cand = fixed[todo] if fixed is not None else _draw(p, group.count, todo.size, rng)
        fits = statics.clear(cand, radius + clearance)
        fits &= ~_overlaps(cand, radius, placed, placed_radii, clearance)
        fits &= _first_of_each_clash(cand, radius, fits, clearance)
        out[todo[fits]] = cand[fits]
        placed = np.concatenate([placed, cand[fits]])
        placed_radii = np.concatenate([placed_radii, np.full(fits.sum(), radius)])
        todo = todo[~fits]
    if todo.size:
        raise PlacementError(
            f"robots[{gi}] ({group.model}, {group.name_prefix}*): could not place {todo.size} "
            f"of {group.count} robots in {trials} trial{'s' if trials > 1 else ''} each "
            f"({_describe(p, group.count)}): they overlap other robots, obstacles or the "
            f"walls; {_advice(p)}",
            group_index=gi, model=group.model, unplaced=int(todo.size), trials=trials)
    return out


def _fixed_layout(p: Placement, count: int) -> np.ndarray | None:
    """[count, 2] grid or explicit positions; None for the random methods."""
    if p.method == "explicit":
        return np.asarray(p.positions, dtype=float).reshape(-1, 2)
    if p.method != "grid":
        return None
    cols = max(1, math.ceil(math.sqrt(count)))
    rows = max(1, math.ceil(count / cols))
    i = np.arange(count)
    # Row-major from the lower-left; the whole block is centred at p.center.
    return np.column_stack([(i % cols - (cols - 1) / 2) * p.spacing_m + p.center[0],
                            (i // cols - (rows - 1) / 2) * p.spacing_m + p.center[1]])


def uniform_size(p: Placement, count: int) -> tuple[float, float]:
    """Side lengths (m) of a uniform placement's rectangle for a group of ``count``."""
    if p.size is not None:
        return p.size
    side = math.sqrt(count / p.density)     # count robots at `density` per m^2
    return side, side


def _draw(p: Placement, count: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """[k, 2] random candidates for a group of ``count``."""
    center = np.asarray(p.center)
    if p.method == "gaussian":
        return rng.normal(center, p.std_m, size=(k, 2))
    half = np.asarray(uniform_size(p, count)) / 2
    return rng.uniform(center - half, center + half, size=(k, 2))


def _overlaps(cand: np.ndarray, radius: float, placed: np.ndarray,
              placed_radii: np.ndarray, clearance: float = CLEARANCE_M) -> np.ndarray:
    """[k] bool: candidate closer than radius + r_j + clearance to some placed robot j."""
    hit = np.zeros(len(cand), dtype=bool)
    if len(cand) == 0 or len(placed) == 0:
        return hit
    reach = radius + placed_radii.max() + clearance
    pairs = cKDTree(cand).sparse_distance_matrix(cKDTree(placed), reach, output_type="ndarray")
    # Exact per-pair test: the tree used the largest radius, robots may differ in size.
    close = pairs["v"] < radius + placed_radii[pairs["j"]] + clearance
    hit[pairs["i"][close]] = True
    return hit


def _first_of_each_clash(cand: np.ndarray, radius: float, fits: np.ndarray,
                         clearance: float = CLEARANCE_M) -> np.ndarray:
    """[k] bool: False for a fitting candidate that clashes with an earlier kept one.

    Keeping the earlier of each clashing pair, as placing one robot after the other does.
    The Python loop runs over clashing pairs only (about n/4 at 5 robots/m^2).
    """
    keep = fits.copy()
    idx = np.flatnonzero(fits)
    if idx.size < 2:
        return keep
    reach = 2 * radius + clearance
    pairs = cKDTree(cand[idx]).query_pairs(reach, output_type="ndarray")    # i < j
    if pairs.size == 0:
        return keep
    d = np.linalg.norm(cand[idx[pairs[:, 0]]] - cand[idx[pairs[:, 1]]], axis=1)
    pairs = pairs[d < reach]
    # In order of the later robot: by then the earlier one's fate is settled.
    for a, b in pairs[np.lexsort((pairs[:, 0], pairs[:, 1]))]:
        if keep[idx[a]]:
            keep[idx[b]] = False
    return keep


class Statics:
    """Static obstacles (and the walls' inner faces) as arrays, for vectorised clearance tests.
    The ARGoS importer grows one while it distributes obstacles (``add``), as ARGoS checks a
    new entity against everything already in the space."""

    def __init__(self, obstacles: list = (), inner: tuple | None = None):
        self.box_center = np.empty((0, 2))    # [b, 2]
        self.box_half = np.empty((0, 2))      # [b, 2]
        self.box_yaw = np.empty(0)            # [b]
        self.cyl_center = np.empty((0, 2))    # [c, 2] (cylinders, and discs such as robots)
        self.cyl_radius = np.empty(0)         # [c]
        self.inner = inner                    # the walls' inner faces, or None
        for obstacle in obstacles:
            self.add(obstacle)

    @classmethod
    def of_world(cls, world: World) -> Statics:
        return cls(world.obstacles, world.arena.inner_bounds())

    def add(self, obstacle: Box | Cylinder) -> None:
        if isinstance(obstacle, Box):
            self.box_center = np.vstack([self.box_center, obstacle.position])
            self.box_half = np.vstack([self.box_half, np.asarray(obstacle.size) / 2])
            self.box_yaw = np.append(self.box_yaw, obstacle.yaw_rad)
        else:
            self.add_disc(obstacle.position, obstacle.radius_m)

    def add_disc(self, center, radius: float) -> None:
        self.cyl_center = np.vstack([self.cyl_center, center])
        self.cyl_radius = np.append(self.cyl_radius, radius)

    def obstacle_fits(self, obstacle: Box | Cylinder) -> bool:
        """The obstacle, taken as its bounding disc (a box's half diagonal), touches nothing here."""
        reach = (math.hypot(*obstacle.size) / 2 if isinstance(obstacle, Box) else obstacle.radius_m)
        return bool(self.clear(np.asarray([obstacle.position], dtype=float), reach)[0])

    def clear(self, points: np.ndarray, reach: float) -> np.ndarray:
        """[k] bool: a disc of radius ``reach`` at each point [k, 2] touches nothing static.

        Memory is [k, obstacles]: fine for the tens of obstacles a world file holds.
        """
        ok = np.ones(len(points), dtype=bool)
        if self.inner is not None:
            x0, y0, x1, y1 = self.inner
            ok &= ((points[:, 0] - reach >= x0) & (points[:, 0] + reach <= x1)
                   & (points[:, 1] - reach >= y0) & (points[:, 1] + reach <= y1))
        if len(self.cyl_radius):
            d = np.linalg.norm(points[:, None, :] - self.cyl_center[None], axis=2)  # [k, c]
            ok &= (d >= self.cyl_radius + reach).all(axis=1)
        if len(self.box_yaw):
            rel = points[:, None, :] - self.box_center[None]                          # [k, b, 2]
            cos, sin = np.cos(self.box_yaw), np.sin(self.box_yaw)
            local = np.stack([cos * rel[..., 0] + sin * rel[..., 1],                 # rotate by -yaw
                              -sin * rel[..., 0] + cos * rel[..., 1]], axis=-1)
            # Distance from the point to the rectangle: 0 inside it.
            outside = np.maximum(np.abs(local) - self.box_half[None], 0.0)
            ok &= (np.linalg.norm(outside, axis=2) >= reach).all(axis=1)
        return ok


def _describe(p: Placement, count: int) -> str:
    c = f"({p.center[0]:g}, {p.center[1]:g})"
    if p.method == "uniform":
        sx, sy = uniform_size(p, count)
        return f"uniform in {sx:.3g} x {sy:.3g} m at {c}"
    if p.method == "gaussian":
        return f"gaussian, std {p.std_m:g} m around {c}"
    if p.method == "grid":
        return f"grid, spacing {p.spacing_m:g} m at {c}"
    return "explicit positions"


def _advice(p: Placement) -> str:
    if p.method == "uniform":
        return "enlarge placement.size, lower placement.density or raise placement.max_trials"
    if p.method == "gaussian":
        return "raise placement.std_m or placement.max_trials"
    if p.method == "grid":
        return "raise placement.spacing_m or move placement.center (grid cells are not re-drawn)"
    return "move the listed positions apart (explicit positions are not re-drawn)"


# --- headings ------------------------------------------------------------------------

def _draw_headings(group: RobotGroup, rng: np.random.Generator) -> np.ndarray:
    """[count] headings in (-pi, pi]."""
    h, k = group.heading, group.count
    if h.method == "uniform" and h.range_rad is not None:
        return wrap_angle(rng.uniform(*h.range_rad, size=k))
    if h.method == "uniform":
        return np.pi - rng.uniform(0.0, 2 * np.pi, size=k)     # uniform in (-pi, pi]
    if h.method == "gaussian":
        return wrap_angle(rng.normal(h.value_rad, h.std_rad, size=k))
    if h.method == "explicit":
        return wrap_angle(np.asarray(h.values_rad, dtype=np.float64))
    return wrap_angle(np.full(k, h.value_rad))


