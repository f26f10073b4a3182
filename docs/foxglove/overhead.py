"""The per-tick cost of --foxglove with no viewer connected, measured two ways in one invocation:

1. alternated whole runs of one world, with and without the server: each pair's tick time and
   the median ratio (on a shared machine this is mostly noise: the cost is far below it);
2. in this process, each tick's physics and sensing (``Simulation.step``) and the server's
   ``on_tick`` after it, timed apart: (step + on_tick) / step. A run's tick also holds the ROS
   exchange, so this ratio over-states the server's share of a real tick.

    .venv/bin/python docs/foxglove/overhead.py [PAIRS] [ROBOTS] [TICKS]
"""
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def ticks_wall_s(robots: int, ticks: int, foxglove: bool) -> float:
    with tempfile.TemporaryDirectory() as out:
        args = [sys.executable, "-m", "composed_sim.cli", "run", str(ROOT / "worlds" / "flocking.yaml"),
                "--robots", str(robots), "--ticks", str(ticks), "--workers", "1", "--out", out,
                "--no-progress", "--no-picture", "--json"] + (["--foxglove", "127.0.0.1:0"] if foxglove else [])
        r = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, check=True)
        return json.loads(r.stdout)["ticks_wall_s"]


def in_process_ratio(robots: int, ticks: int) -> float:
    """(step + on_tick) / step over ``ticks`` ticks, each part timed on its own."""
    from composed_sim.core.simulation import Simulation
    from composed_sim.live.foxglove_server import FoxgloveServer
    from composed_sim.live.observers import Scene
    from composed_sim.world.loader import load_world
    world = load_world(ROOT / "worlds" / "flocking.yaml", robots=robots)
    sim = Simulation(world)
    server = FoxgloveServer(Scene(sim, world.tick_ns), ("127.0.0.1", 0), {})
    step_s = observe_s = 0.0
    try:
        for _ in range(ticks):
            t0 = time.perf_counter()
            sim.step()
            t1 = time.perf_counter()
            server.on_tick(sim)
            t2 = time.perf_counter()
            step_s, observe_s = step_s + t1 - t0, observe_s + t2 - t1
    finally:
        server.close()
    return (step_s + observe_s) / step_s


def main(pairs: int = 4, robots: int = 40, ticks: int = 300) -> None:
    ratios = []
    for i in range(pairs):
        order = (False, True) if i % 2 == 0 else (True, False)     # alternate who goes first
        times = {on: ticks_wall_s(robots, ticks, on) for on in order}
        ratios.append(times[True] / times[False])
        print(f"pair {i}: without {times[False]:.3f} s, with {times[True]:.3f} s, ratio {ratios[-1]:.4f}")
    print(f"{robots} robots x {ticks} ticks, {pairs} pairs: median ratio with/without {statistics.median(ratios):.4f}")
    print(f"in process, {ticks} ticks: (Simulation.step + on_tick) / Simulation.step = "
          f"{in_process_ratio(robots, ticks):.5f}")


if __name__ == "__main__":
    main(*map(int, sys.argv[1:]))
