"""The physics step alone: ms per tick and µs per robot of the flocking world's swarm, one space,
cells in one process and K regions in worker processes (docs/speed.md, "Physics that scales").

  python -m composed_sim.bench.physics_step --robots 1280,10240,102400 --regions 1,2 --processes 2 --out physics.json

Each size builds its engines from the same start (the shipped flocking world, 5 robots/m²) and
fixed commands (0.1 m/s, each robot its own turn rate), warms them up, then steps them in turn,
one tick each (A B C A B C …) so that the machine's load falls on all alike. A row per engine:
its median ms per tick and µs per robot. The machine is recorded with the rows.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from composed_sim.bench.machine import machine_info
from composed_sim.core.engine import physics_engine
from composed_sim.core.physics import PhysicsWorld
from composed_sim.core.placement import place_robots
from composed_sim.core.seeding import STREAM_PLACEMENT, stream
from composed_sim.world.loader import SHIPPED_WORLDS, load_world
from composed_sim.world.robot_models import get_model


def engines_of(robots: int, regions: list[int], single_space: bool, processes: tuple[int, ...] = ()) -> dict:
    """label → engine, from the flocking world's start for ``robots`` robots; ``processes``: the
    one-region cells also spread over that many processes each (physics.processes)."""
    world = load_world(SHIPPED_WORLDS / "flocking.yaml", robots=robots)
    positions, headings = place_robots(world, stream(world.seed, STREAM_PLACEMENT))
    models = [get_model(world.robots[0].model)] * robots
    out = {}
    if single_space:
        out["one space"] = PhysicsWorld(world, models, positions, headings)
    for k in regions:
        physics = world.physics.model_copy(update={"regions": k, "processes": 1})
        engine = physics_engine(world.model_copy(update={"physics": physics}), models, positions, headings)
        out["cells, one process" if k == 1 else f"{k} regions"] = engine
    for k in processes:
        physics = world.physics.model_copy(update={"regions": 1, "processes": k})
        out[f"cells, {k} processes"] = physics_engine(world.model_copy(update={"physics": physics}), models,
                                                      positions, headings)
    return out


def measure(robots: int, regions: list[int], ticks: int, warmup: int, single_space: bool,
            processes: tuple[int, ...] = ()) -> list[dict]:
    engines = engines_of(robots, regions, single_space, processes)
    rng = np.random.default_rng(0)
    left = np.full(robots, 0.1) - rng.uniform(0.0, 0.02, robots)
    times = {label: [] for label in engines}
    try:
        for engine in engines.values():
            engine.set_wheel_speeds(left, np.full(robots, 0.1))
        for tick in range(warmup + ticks):
            for label, engine in engines.items():
                t0 = time.perf_counter()
                engine.step()
                if tick >= warmup:
                    times[label].append(time.perf_counter() - t0)
    finally:
        for engine in engines.values():
            getattr(engine, "close", lambda: None)()
    rows = []
    for label, engine in engines.items():
        ms = 1e3 * float(np.median(times[label]))
        layout = getattr(engine, "layout", None)
        rows.append({"robots": robots, "engine": label, "cells": layout.n_cells if layout else 1,
                     "regions": layout.n_regions if layout else 1, "ticks": ticks,
                     "ms_per_tick": round(ms, 3), "us_per_robot": round(1e3 * ms / robots, 3)})
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", default="1280,10240,102400", help="sizes, comma-separated")
    p.add_argument("--regions", default="1,2", help="region counts, comma-separated (1: cells in one process)")
    p.add_argument("--processes", default="", help="also the one-region cells in this many processes each "
                                                   "(physics.processes), comma-separated")
    p.add_argument("--ticks", type=int, default=20)
    p.add_argument("--warmup", type=int, default=5)
    p.add_argument("--single-space-up-to", type=int, default=102400,
                   help="also step all robots in one space up to this many robots")
    p.add_argument("--out", type=Path, help="write the machine and the rows here (JSON)")
    args = p.parse_args(argv)
    regions = [int(k) for k in args.regions.split(",")]
    rows = []
    print("| robots | engine | cells | ms per tick | µs per robot |\n|---:|---|---:|---:|---:|")
    for robots in (int(n) for n in args.robots.split(",")):
        for row in measure(robots, regions, args.ticks, args.warmup, robots <= args.single_space_up_to,
                           tuple(int(k) for k in args.processes.split(",") if k)):
            rows.append(row)
            print(f"| {robots} | {row['engine']} | {row['cells']} | {row['ms_per_tick']:.1f} | "
                  f"{row['us_per_robot']:.2f} |", flush=True)
    if args.out:
        args.out.write_text(json.dumps({"machine": machine_info(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
