"""The firmware transcripts (data/firmware_f64.csv, data/firmware_f32.csv): what they hold and how
the drone moves between their steps.

tools/crazyflie/regenerate.py drives the Crazyflie firmware's high-level commander, planner and
commander (compiled from the firmware's sources, once as the firmware runs, in float, and once
with every float a double) through scenarios and writes every line it sent, with the firmware's
answer, as one CSV row: ``scenario, op, args, result``. ``args`` and ``result`` are numbers
separated by spaces. The ops:

- ``state x y z vx vy vz yaw``: the drone placed (the state estimate the firmware reads);
- ``time t``: the clock (s);
- ``mask m``, ``block b``: the drone's group mask; the supervisor blocking it;
- ``takeoff``, ``land``, ``takeoffv``, ``landv``, ``goto``, ``stop``, ``piece``, ``define``,
  ``start``: high-level commands (tools/crazyflie/firmware_harness.c lists their arguments), result
  the firmware's return code;
- ``position``, ``fullstate``, ``hover``, ``notify``: streamed setpoints and notify-setpoints-stop;
- ``step``: one stabilizer tick; result: high-level setpoint given (0/1), the commander's active
  priority, the planner's state, the setpoint's x, z and yaw modes, then position, velocity,
  acceleration (3 each), yaw and body rates (3) of the setpoint that flies the drone.

Between steps the drone moves as Crazyswarm2's ``none`` backend moves it (``follow``), so the
state the firmware reads at the next step is known from the transcript alone.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

DATA = Path(__file__).parent / "data"
FIXTURES = {"f64": DATA / "firmware_f64.csv", "f32": DATA / "firmware_f32.csv"}
STEP_HEADER = 6           # given, priority, planner state, mode x, mode z, mode yaw
MODE_DISABLE, MODE_ABS, MODE_VELOCITY = 0, 1, 2


def read(path: Path) -> dict[str, list[tuple[str, list[float], list[float]]]]:
    """scenario → its rows (op, args, result) in order."""
    scenarios: dict[str, list] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            numbers = [[float(v) for v in row[k].split()] for k in ("args", "result")]
            scenarios.setdefault(row["scenario"], []).append((row["op"], *numbers))
    return scenarios


def follow(state: np.ndarray, result, dt: float) -> np.ndarray:
    """The drone's state [7] (x, y, z, vx, vy, vz, yaw) after a step answered ``result``, ``dt``
    s later: at a position setpoint exactly there; under a hover setpoint its body velocities and
    yaw rate integrated at the height; motors off on the floor below."""
    mode_x, mode_z = result[3], result[4]
    values = result[STEP_HEADER:]
    pos, vel, yaw, yaw_rate = values[0:3], values[3:6], values[9], values[12]
    out = np.array(state, dtype=np.float64)
    if mode_x == MODE_ABS:
        out[0:3], out[3:6], out[6] = pos, vel, yaw
    elif mode_x == MODE_VELOCITY:
        c, s = math.cos(out[6]), math.sin(out[6])
        world = (c * vel[0] - s * vel[1], s * vel[0] + c * vel[1])
        out[0] += world[0] * dt
        out[1] += world[1] * dt
        out[2] = pos[2] if mode_z == MODE_ABS else out[2]
        out[3:6] = (world[0], world[1], 0.0)
        out[6] += yaw_rate * dt
    else:
        out[2], out[3:6] = 0.0, 0.0
    return out
