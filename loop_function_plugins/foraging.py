"""Foraging (ARGoS's foraging.argos): food items are black spots on the floor; a robot that carries
nothing and whose ground sensors read a spot picks it up, and the spot moves to a free random
place; a carrying robot whose sensors read the grey nest delivers it and scores.

Carrying is decided from the same readings the controllers get (``sim.frame``, with the same rule,
composed_sim.devices.common.floor.ground_zone), so the score and the robots agree without the controllers
knowing of these loop functions.
"""
from __future__ import annotations

import numpy as np

from composed_sim.devices.common.floor import FOOD, NEST, ground_zone
from composed_sim.core.seeding import stream
from composed_sim.loop_functions import LoopFunctions
from composed_sim.world.schema import FloorCircle

STREAM_FOOD = 0xF00D     # the food's own random stream: it never shifts the placement's draws


class ForagingLoopFunctions(LoopFunctions):
    """``items`` food spots of ``radius_m`` drawn uniformly in the rectangle ``food_area``
    ([x_min, x_max, y_min, y_max]); the thresholds are the controllers' (their params of the same
    names); ``target_score``: end the run once this many items were delivered (None: never)."""

    def __init__(self, items: int = 15, radius_m: float = 0.05,
                 food_area: tuple[float, float, float, float] = (-1.0, 2.0, -2.0, 2.0),
                 food_below: float = 0.25, nest_below: float = 0.75, target_score: int | None = None):
        if items < 1 or radius_m <= 0:
            raise ValueError(f"items must be >= 1 and radius_m > 0 (got {items}, {radius_m})")
        if len(food_area) != 4 or food_area[0] >= food_area[1] or food_area[2] >= food_area[3]:
            raise ValueError(f"food_area must be [x_min, x_max, y_min, y_max] (got {list(food_area)})")
        self.items, self.radius = int(items), float(radius_m)
        self.area = tuple(float(v) for v in food_area)
        self.food_below, self.nest_below = float(food_below), float(nest_below)
        self.target = target_score
        self.score = 0

    def init(self, world, sim) -> None:
        self.rng = stream(world.seed, STREAM_FOOD)
        self.carrying = np.zeros(sim.n, dtype=bool)
        self.shapes = [sim.add_floor_shape(FloorCircle(position=self._free_spot(sim), radius_m=self.radius,
                                                       color=(0, 0, 0))) for _ in range(self.items)]

    def _free_spot(self, sim) -> tuple[float, float]:
        """A random place in the food area with no robot on it (so no robot finds food it never saw)."""
        for _ in range(100):
            spot = (self.rng.uniform(*self.area[:2]), self.rng.uniform(*self.area[2:]))
            if sim.n == 0 or np.min(np.linalg.norm(sim.positions - spot, axis=1)) > 2 * self.radius + 0.2:
                return float(spot[0]), float(spot[1])
        return float(spot[0]), float(spot[1])

    def post_step(self, sim) -> None:
        picked: set[int] = set()
        for group in sim.frame.groups:
            if group.ground is None:
                continue
            zones = ground_zone(group.ground, self.food_below, self.nest_below)
            robots = np.arange(group.robots.start, group.robots.stop)
            pickers = robots[(zones == FOOD) & ~self.carrying[robots]]
            picked.update(self._item_under(sim, robot) for robot in pickers)
            self.carrying[pickers] = True
            delivered = robots[(zones == NEST) & self.carrying[robots]]
            self.carrying[delivered] = False
            self.score += len(delivered)
        # Moved once all robots were looked at: two robots on one spot both picked it up, as
        # their own readings say, and it moves once.
        for shape in sorted(picked):
            sim.set_floor_shape(shape, position=self._free_spot(sim))

    def _item_under(self, sim, robot: int) -> int:
        """The floor shape of the food spot nearest the robot."""
        shapes = sim.world.floor.shapes
        centres = np.array([shapes[i].position for i in self.shapes])
        return self.shapes[int(np.argmin(np.linalg.norm(centres - sim.positions[robot], axis=1)))]

    def is_finished(self, sim) -> bool:
        return self.target is not None and self.score >= self.target

    def metrics(self, sim) -> dict:
        return {"score": self.score, "carrying": int(self.carrying.sum())}

    @staticmethod
    def describe(initial: dict, final: dict) -> list[str]:
        return [f"  foraging: {final.get('score', 0)} items delivered, {final.get('carrying', 0)} carried at the end"]
