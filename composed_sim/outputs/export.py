"""A run's trajectories as one tidy table (``composed-sim export RESULTS --format csv|parquet``).

One row per (tick, robot), ticks 0 … T in order and robots in the run's order within a tick:

  tick    int64    0 is the initial pose
  time_s  float64  tick · tick_s (sim time)
  robot   string   the robot's name (bot0, fb3, ...)
  group   int64    its group: the index in the world file's ``robots`` list
  model   string   its robot model (foot-bot, e-puck, ...)
  x, y    float64  position in m (world frame)
  yaw     float64  heading in rad, CCW from the x axis
  led_r, led_g, led_b  uint8  its display LED colour (0, 0, 0: no LED lit)

pandas (``read_csv``, ``read_parquet``) and polars read either file as is. The table is built as a
pyarrow Table from the trajectory arrays (no per-row Python), written by pyarrow's CSV or Parquet
writer.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa

from composed_sim.outputs.results import TRAJECTORIES, WORLD, has_trajectories, load_trajectories
from composed_sim.world.loader import WorldFileError, load_world

FORMATS = ("csv", "parquet")


class ExportError(Exception):
    """Results that cannot be exported; the message names the file and the problem."""


def trajectory_table(results: Path) -> pa.Table:
    """The tidy table of a results directory (``--out`` of ``composed-sim run``; of a run that
    goes or was killed, its ticks up to the last checkpoint)."""
    if not has_trajectories(results):
        raise ExportError(f"{results}: no {TRAJECTORIES}; not a results directory of `composed-sim run`")
    try:
        world = load_world(Path(results) / WORLD)
    except WorldFileError as e:
        raise ExportError(str(e)) from None
    traj = load_trajectories(results)
    ticks, n = traj.positions.shape[:2]
    groups = np.asarray(world.group_of_robot(), dtype=np.int64)
    if len(groups) != n:
        raise ExportError(f"{results}/{WORLD}: holds {len(groups)} robots, {TRAJECTORIES} {n}")
    models = np.array([world.robots[g].model for g in groups])
    leds = traj.led_colors if traj.led_colors is not None else np.zeros((ticks, n, 3), np.uint8)
    tick = np.repeat(np.arange(ticks, dtype=np.int64), n)
    return pa.table({
        "tick": tick,
        "time_s": tick * world.tick_s,
        "robot": np.tile(np.asarray(traj.names, dtype=str), ticks),
        "group": np.tile(groups, ticks),
        "model": np.tile(models, ticks),
        "x": traj.positions[..., 0].ravel(),
        "y": traj.positions[..., 1].ravel(),
        "yaw": traj.headings.ravel(),
        "led_r": leds[..., 0].ravel(),
        "led_g": leds[..., 1].ravel(),
        "led_b": leds[..., 2].ravel(),
    })


def export_table(results: Path, out: Path, fmt: str) -> int:
    """Write the table of ``results`` to ``out`` as ``fmt`` (csv or parquet); returns the rows."""
    if fmt not in FORMATS:
        raise ExportError(f"--format {fmt!r}: one of {', '.join(FORMATS)}")
    table = trajectory_table(results)
    try:
        if fmt == "csv":
            import pyarrow.csv
            pyarrow.csv.write_csv(table, out)
        else:
            import pyarrow.parquet
            pyarrow.parquet.write_table(table, out)
    except OSError as e:
        raise ExportError(f"{out}: cannot write it ({e})") from None
    return table.num_rows
