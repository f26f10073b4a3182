"""The fidelity suite's reference data: ARGoS's own runs of tools/fidelity/experiments/, one
``.npz`` per experiment in tests/fidelity/data/ (written by tools/fidelity/regenerate.py).

Each file holds, for its seeds in order:
  seeds        [S] int           ARGoS's random_seed of each run
  initial      [S, n, 3] f64     every robot's pose at tick 0 (x, y, yaw), ARGoS's entity order
  boxes        [S, b, 6] f64     every box at tick 0 (walls included): x, y, yaw, size x, y, z
  cylinders    [S, c, 4] f64     every cylinder at tick 0: x, y, radius, height
  track_ticks  [T] int, track [R, T, n, 2] f32   positions at the first ticks (robot for robot),
                                                 for the first R = len(TRACK_SEEDS) seeds only
  coarse_ticks [K] int, coarse [S, K, n, 2] i2   positions at the metrics' ticks and 10 ticks
                                                 before each, in mm (tests/fidelity/metrics.py)
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent / "data"
EXPERIMENTS_DIR = Path(__file__).resolve().parents[2] / "tools" / "fidelity" / "experiments"

# The suite: each must be within 1 pooled standard deviation of ARGoS on every metric.
MAIN = ("flocking_10", "flocking_30", "diffusion_10", "diffusion_30", "epuck_50", "kheperaiv_20")
# Held out (not looked at while the models were fixed): other variants of the same set-ups.
VARIANTS = ("diffusion_20_fast", "epuck_30", "epuck_50_fast", "kheperaiv_40")
EXPERIMENTS = MAIN + VARIANTS
# The gap is in pooled standard deviations of single runs: with 5 runs a side, two samples of
# the very same model differ by more than 1 in about one comparison in seven; with 20, in about
# one in 300. Hence 20 seeds for the suite.
SEEDS = tuple(range(1, 21))
# More seeds of the main experiments, held out likewise; the variants' own seeds.
HELD_OUT = {name: tuple(range(21, 31)) for name in MAIN}
VARIANT_SEEDS = tuple(range(1, 11))
TRACK_SEEDS = (1, 2, 3, 4, 5)

TRACK_TICKS = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 15, 20, 30, 50, 100)
COARSE_TICKS = (90, 100, 290, 300, 590, 600)


def seeds_of(name: str) -> tuple[int, ...]:
    """Every seed ARGoS ran ``name`` with, in the file's order."""
    return VARIANT_SEEDS if name in VARIANTS else SEEDS + HELD_OUT[name]


def pack(path: Path, seeds, runs: list[dict]) -> None:
    """ARGoS's runs (poses [ticks + 1, n, 3] per run, tick 0 first; its boxes and cylinders) → ``path``."""
    poses = np.stack([r["poses"] for r in runs])                                     # [S, t+1, n, 3]
    tracked = [i for i, seed in enumerate(seeds) if seed in TRACK_SEEDS]
    np.savez_compressed(
        path, seeds=np.asarray(seeds), initial=poses[:, 0],
        boxes=np.stack([r["boxes"] for r in runs]), cylinders=np.stack([r["cylinders"] for r in runs]),
        track_ticks=np.asarray(TRACK_TICKS),
        track=poses[tracked][:, list(TRACK_TICKS), :, :2].astype(np.float32),
        coarse_ticks=np.asarray(COARSE_TICKS),
        coarse=np.round(poses[:, list(COARSE_TICKS), :, :2] * 1000.0).astype(np.int16))


def load(name: str) -> dict:
    with np.load(DATA / f"{name}.npz") as f:
        out = {k: f[k] for k in f.files}
    out["coarse_m"] = out["coarse"].astype(np.float64) / 1000.0
    return out
