"""One experiment of the fidelity suite compared with ARGoS's runs: behaviour metrics (the gap in
pooled standard deviations) and robot-for-robot positions at the first ticks."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from composed_sim.core.placement import Statics

from composed_sim.world.robot_models import get_model
from tests.fidelity import driver, reference
from tests.fidelity.metrics import METRICS, TICKS, gap, metrics_at


@dataclass
class Comparison:
    name: str
    seeds: list[int]
    ours: dict = field(default_factory=dict)      # (tick, metric) → [runs]
    argos: dict = field(default_factory=dict)
    track_error_m: list = field(default_factory=list)   # per run: [T] largest robot distance
    first_contact: list = field(default_factory=list)   # per run: our first tick with a contact (None: none)

    def gap(self, tick: int, metric: str) -> float:
        return gap(np.array(self.ours[tick, metric]), np.array(self.argos[tick, metric]))

    def worst(self) -> tuple[float, int, str]:
        return max((self.gap(t, m), t, m) for t in TICKS for m in METRICS)

    def rows(self):
        for t in TICKS:
            for m in METRICS:
                yield t, m, float(np.mean(self.argos[t, m])), float(np.mean(self.ours[t, m])), self.gap(t, m)


CONTACT_M = 0.001     # bodies closer than this count as touching


def first_contact(world, positions: np.ndarray):
    """The first tick at which a robot touches another robot, an obstacle or a wall (None: never)."""
    radius = get_model(world.robots[0].model).body_radius_m
    statics = Statics.of_world(world)
    for t, p in enumerate(positions):
        pairs = cKDTree(p).query_pairs(2 * radius + CONTACT_M)
        if pairs or not statics.clear(p, radius + CONTACT_M).all():
            return t
    return None


def compare(name: str, seeds, *, ticks: int = 600, edit=lambda world: world, **exchange) -> Comparison:
    """Runs ``name`` from ARGoS's start of each of ``seeds`` and compares."""
    ref = reference.load(name)
    out = Comparison(name, list(seeds))
    ct = ref["coarse_ticks"]
    for seed in seeds:
        run = int(np.flatnonzero(ref["seeds"] == seed)[0])
        world = driver.world_from_argos(name, ref, run, edit=edit)
        positions = driver.run(world, ticks, **exchange)
        radius = get_model(world.robots[0].model).body_radius_m
        target = world.lights[0].position if world.lights else (0.0, 0.0)
        for t in TICKS:
            if t > ticks:
                continue
            for source, store in ((positions[ct[ct <= ticks]], out.ours), (ref["coarse_m"][run], out.argos)):
                values = metrics_at(source, ct, t, radius=radius, target=target, pen=not world.lights)
                for m, v in values.items():
                    store.setdefault((t, m), []).append(v)
        if seed in reference.TRACK_SEEDS:
            row = [s for s in ref["seeds"] if s in reference.TRACK_SEEDS].index(seed)
            out.first_contact.append(first_contact(world, positions))
            track = ref["track_ticks"][ref["track_ticks"] <= ticks]
            out.track_error_m.append(np.linalg.norm(positions[track] - ref["track"][row][:len(track)],
                                                    axis=-1).max(axis=1))
    return out
