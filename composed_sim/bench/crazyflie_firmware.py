"""The Crazyflie firmware alone: µs per drone and tick of ``Crazyflies.advance`` (every drone's
high-level commander, commander and motion) at 100 Hz, in the situations a swarm flies.

  python -m composed_sim.bench.crazyflie_firmware --drones 16,256,1024 --out firmware.json

Per size and situation a fleet on a grid (0.5 m apart) is brought there, warmed up, then stepped
``--ticks`` times: hovering (every take-off's plan ended), going to (a go-to half done), the figure
eight (a 6-piece uploaded trajectory, started relative), streaming (a position setpoint per drone
and tick, as ``cmd_position``), on the floor (idle: motors off). A row each: the median ms per
tick and µs per drone and tick. The machine is recorded with the rows.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from composed_sim.bench.machine import machine_info
from composed_sim.devices.crazyflie import Crazyflies

TICK_S = 0.01
MASS_KG = 0.027


def _eight() -> tuple[np.ndarray, np.ndarray]:
    """Six pieces of a figure eight (x, y) at constant height, each a plan the firmware makes."""
    from composed_sim.devices.crazyflie.polynomials import plan_pieces
    knots = np.linspace(0.0, 6.0, 7)
    w = 2 * np.pi / 6.0
    pos = np.column_stack([0.6 * np.sin(w * knots), 0.3 * np.sin(2 * w * knots), np.zeros(7)])
    vel = np.column_stack([0.6 * w * np.cos(w * knots), 0.6 * w * np.cos(2 * w * knots), np.zeros(7)])
    acc = np.column_stack([-0.6 * w * w * np.sin(w * knots), -1.2 * w * w * np.sin(2 * w * knots), np.zeros(7)])
    zero = np.zeros(6)
    pieces = plan_pieces(np.diff(knots), pos[:-1], zero, vel[:-1], zero, acc[:-1], pos[1:], zero, vel[1:], zero,
                         acc[1:])
    return pieces, np.diff(knots)


def fleet_in(situation: str, drones: int) -> tuple[Crazyflies, float, callable]:
    """A fleet brought into ``situation`` → (fleet, time, what to do each tick before advancing)."""
    side = int(np.ceil(np.sqrt(drones)))
    grid = np.column_stack([np.arange(drones) % side * 0.5, np.arange(drones) // side * 0.5, np.zeros(drones)])
    fleet = Crazyflies(grid, np.zeros(drones), mass_kg=MASS_KG)
    t = 0.0

    def run(seconds: float) -> None:
        nonlocal t
        for _ in range(int(round(seconds / TICK_S))):
            t += TICK_S
            fleet.advance(t, TICK_S)

    def nothing(t):
        return None
    if situation == "on the floor":
        return fleet, t, nothing
    fleet.takeoff(None, t, 1.0, 2.0)
    run(2.5)
    if situation == "going to":
        fleet.go_to(None, t, grid + [0.25, 0.25, 1.2], 0.5, 4.0)
        run(2.0)
    elif situation == "figure eight":
        fleet.upload_trajectory(None, 1, 0, *_eight())
        fleet.start_trajectory(None, t, 1, relative=True)
        run(2.0)
    elif situation == "streaming":
        return fleet, t, (lambda now: fleet.cmd_position(None, now, grid + [0.0, 0.0, 1.0], 0.0))
    return fleet, t, nothing


def measure(drones: int, ticks: int, warmup: int) -> list[dict]:
    rows = []
    for situation in ("hovering", "going to", "figure eight", "streaming", "on the floor"):
        fleet, t, before = fleet_in(situation, drones)
        times = []
        for tick in range(warmup + ticks):
            t += TICK_S
            t0 = time.perf_counter()
            before(t)
            fleet.advance(t, TICK_S)
            if tick >= warmup:
                times.append(time.perf_counter() - t0)
        median = float(np.median(times))
        rows.append({"drones": drones, "situation": situation, "ms_per_tick": 1e3 * median,
                     "us_per_drone_tick": 1e6 * median / drones})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--drones", default="16,256,1024", help="fleet sizes, comma-separated")
    parser.add_argument("--ticks", type=int, default=200)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument("--out", type=Path, default=None, help="write the rows and the machine as JSON")
    args = parser.parse_args(argv)
    rows = [row for n in (int(v) for v in args.drones.split(",")) for row in measure(n, args.ticks, args.warmup)]
    for row in rows:
        print(f"{row['drones']:6d} drones  {row['situation']:13s} {row['ms_per_tick']:8.3f} ms/tick "
              f"{row['us_per_drone_tick']:7.2f} µs per drone-tick")
    if args.out:
        args.out.write_text(json.dumps({"machine": machine_info(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
