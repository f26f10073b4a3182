#!/usr/bin/env python3
"""Regenerate the Crazyflie firmware transcripts (tests/devices/crazyflie/data/) from the firmware itself.

Needs a checkout of Bitcraze's crazyflie-firmware (any place; nothing of it is copied here) and a
C compiler:

  python tools/crazyflie/regenerate.py --firmware <crazyflie-firmware checkout> [--cc gcc] [--out DIR]

It compiles ``firmware_harness.c`` (ours) with the firmware's own
``src/modules/src/{crtp_commander_high_level,planner,pptraj,pptraj_compressed,commander}.c``,
against the few header stand-ins of ``stubs.py``, twice: as the firmware is (float) and with
every float a double (the same arithmetic without float rounding). It then runs the scenarios
below through both, one line per command, moving the drone between steps as
``tests/devices/crazyflie/transcript.py``'s ``follow`` does, and writes every line with the
firmware's answer to ``firmware_f32.csv`` and ``firmware_f64.csv``. The data in the repository
came from the firmware's master of 2026-08-21 (commit 2a18fc29).

The scenarios' trajectories are ours: degree-7 Hermite pieces through a figure eight and a
climbing turn (``hermite_pieces``), their coefficients rounded to float as the firmware stores them.
"""
from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
from stubs import DOUBLE_PRELUDE, HEADERS  # noqa: E402 - after the checkout is put on sys.path
from tests.devices.crazyflie.transcript import FIXTURES, follow  # noqa: E402 - after the checkout is put on sys.path

SOURCES = ("commander.c",)     # its own translation unit; the others are included by the harness
INCLUDES = ("src/modules/src", "src/modules/interface", "src/hal/interface", "src/utils/interface/lighthouse",
            "src/utils/interface")
DT = 0.1


def build(firmware: Path, work: Path, cc: str, double: bool) -> Path:
    stubs = work / "stubs"
    stubs.mkdir(exist_ok=True)
    for name, text in HEADERS.items():
        (stubs / name).write_text(text)
    (work / "prelude_double.h").write_text(DOUBLE_PRELUDE)
    out = work / ("harness_f64" if double else "harness_f32")
    cmd = [cc, "-O2", "-std=gnu11", "-w", *(["-include", str(work / "prelude_double.h")] if double else []),
           f"-I{stubs}", *(f"-I{firmware / d}" for d in INCLUDES), str(HERE / "firmware_harness.c"),
           *(str(firmware / "src/modules/src" / s) for s in SOURCES), "-lm", "-o", str(out)]
    subprocess.run(cmd, check=True)
    return out


def hermite_pieces(curve, knots) -> tuple[np.ndarray, np.ndarray]:
    """Degree-7 pieces [p, 4, 8] matching ``curve(t)`` → [4 derivatives, 4 axes] at each knot, and
    their durations [p], the coefficients rounded to float."""
    pieces, durations = [], []
    for t0, t1 in zip(knots[:-1], knots[1:]):
        T = t1 - t0
        rows = []
        for tau in (0.0, T):
            for k in range(4):
                rows.append([0.0 if i < k else np.prod(range(i - k + 1, i + 1)) * tau ** (i - k) for i in range(8)])
        a, b = curve(t0), curve(t1)
        rhs = np.vstack([a, b])                     # [8, 4]: value, 1st..3rd derivative at each end
        pieces.append(np.linalg.solve(np.array(rows), rhs).T)
        durations.append(T)
    return np.asarray(pieces, dtype=np.float32).astype(np.float64), np.asarray(durations)


def figure_eight(t):
    w = 2 * np.pi / 6.0
    x = [0.6 * w ** k * np.sin(w * t + k * np.pi / 2) for k in range(4)]
    y = [0.3 * (2 * w) ** k * np.sin(2 * w * t + k * np.pi / 2) for k in range(4)]
    z = [1.0 + 0.1 * w ** k * np.sin(w * t + k * np.pi / 2) if k == 0 else 0.1 * w ** k * np.sin(w * t + k * np.pi / 2)
         for k in range(4)]
    yaw = [0.4 * w ** k * np.sin(w * t + k * np.pi / 2) for k in range(4)]
    return np.array([x, y, z, yaw]).T


def climbing_turn(t):
    x = [0.5 * np.cos(t + k * np.pi / 2) - (0.5 if k == 0 else 0.0) for k in range(4)]
    y = [0.5 * np.sin(t + k * np.pi / 2) for k in range(4)]
    z = [0.5 + 0.1 * t, 0.1, 0.0, 0.0]
    yaw = [1.5 * t, 1.5, 0.0, 0.0]
    return np.array([x, y, z, yaw]).T


EIGHT = hermite_pieces(figure_eight, [0.0, 0.9, 2.1, 3.0, 3.9, 5.1, 6.0])
TURN = hermite_pieces(climbing_turn, [0.0, 0.7, 2.0, 3.0, 4.5])
# The turn's pieces with durations the firmware takes as they are: one of 0 s, one negative (the
# other ends off the steps' times: at a piece's end the float build's rounding picks either side).
ODD = (TURN[0], np.array([0.73, 0.0, -0.5, 1.45]))


def upload(pieces, offset: int, trajectory_id: int) -> list[str]:
    coefficients, durations = pieces
    lines = [f"piece {offset + i} {float(d)!r} " + " ".join(repr(float(c)) for c in coefficients[i].reshape(-1))
             for i, d in enumerate(durations)]
    return lines + [f"define {trajectory_id} {offset} {len(durations)}"]


def floor(x=0.0, y=0.0, yaw=0.0) -> str:
    return f"state {x} {y} 0 0 0 0 {yaw}"


# name → (start state, {time: commands}, end time); times are multiples of DT, the steps' spacing.
TAKEOFF = "takeoff 0 1.0 0 1 1.5"
SCENARIOS = {
    "takeoff": (floor(0.5, -0.3, 0.3), {0.5: ["takeoff 0 1.0 0 1 2.5"], 3.5: ["takeoff 0 1.0 0 1 2.0"]}, 4.0),
    "takeoff_yaw_land": (floor(-1.0, 2.0, -2.9), {0.2: ["takeoff 0 0.5 2.8 0 1.5"], 2.0: ["land 0 0.03 0 1 2.0"],
                                                  2.5: ["land 0 0.03 0 1 2.0"], 4.5: ["land 0 0.03 0 1 1.0"]}, 6.0),
    "takeoff_land_velocity": (floor(0.2, 0.2), {0.2: ["takeoffv 0 0.8 0 0 1 0.4"],
                                                2.5: ["landv 0 0.5 1 1.0 0 0.5"], 4.0: ["landv 0 0.03 0 0 1 0"]}, 5.5),
    "goto_absolute": (floor(), {0.2: [TAKEOFF], 2.0: ["goto 0 0 0 1.5 -0.5 1.2 1.0 2.5"],
                                5.0: ["goto 0 0 0 1.5 -0.5 1.2 -3.0 1.0"]}, 6.5),
    "goto_relative": (floor(1.0, 1.0, 0.5), {0.2: [TAKEOFF], 2.0: ["goto 0 1 0 0.5 0.5 -0.2 0.5 2.0"],
                                             4.5: ["goto 0 1 0 -1.0 0 0 3.0 1.5"]}, 6.5),
    "goto_replan": (floor(), {0.2: [TAKEOFF], 0.8: ["goto 0 0 0 0.5 0.5 1.0 0 2.0"],
                              1.9: ["goto 0 1 0 0 -1.0 0.3 0.7 1.5"]}, 4.5),
    "goto_linear": (floor(), {0.2: [TAKEOFF], 2.0: ["goto 0 0 1 1.0 1.0 1.0 1.0 2.0"],
                              3.0: ["goto 0 1 1 -0.5 0 0.2 -1.0 1.5"]}, 5.5),
    "goto_from_idle": (floor(0.3, 0.3), {0.2: ["goto 0 0 0 0.3 0.3 0.5 0.2 2.0"], 3.0: ["stop 0"],
                                         3.5: ["goto 0 1 0 0 0 1.0 0 1.0"], 5.0: ["land 0 0.03 0 1 1.0"]}, 6.5),
    "figure_eight": (floor(), {0.0: upload(EIGHT, 0, 1), 0.2: [TAKEOFF], 2.0: ["start 0 1 1.0 0 1 0"]}, 9.0),
    "figure_eight_absolute_slow": (floor(), {0.0: upload(EIGHT, 0, 1), 0.2: [TAKEOFF],
                                             2.0: ["start 0 1 2.0 0 0 0"]}, 15.0),
    "figure_eight_reversed_fast": (floor(0.5, 0.0), {0.0: upload(EIGHT, 0, 1), 0.2: [TAKEOFF],
                                                     2.0: ["start 0 1 0.5 1 1 0"]}, 6.0),
    "turn_relative_yaw": (floor(0.0, 0.0, 2.0), {0.0: upload(EIGHT, 0, 1) + upload(TURN, 6, 2),
                                                 0.2: ["takeoff 0 0.5 0 1 1.5"], 2.0: ["start 0 2 1.0 0 1 1"],
                                                 7.0: ["start 0 2 1.5 1 1 1"]}, 14.5),
    "trajectory_refusals": (floor(), {0.0: upload(TURN, 0, 3) + ["define 31 0 2", "define 40 0 2"],
                                      0.2: [TAKEOFF, "start 0 7 1.0 0 1 0", "start 0 40 1.0 0 1 0"],
                                      2.0: ["start 0 5 1.0 0 1 0", "start 0 3 1.0 0 1 0"]}, 3.0),
    "odd_durations": (floor(), {0.0: upload(ODD, 0, 4), 0.2: [TAKEOFF], 2.0: ["start 0 4 1.0 0 1 0"],
                                4.5: ["start 0 4 1.0 1 1 0"]}, 6.5),
    "group_mask": (floor(), {0.0: ["mask 5"], 0.2: ["takeoff 2 1.0 0 1 1.5"], 0.5: ["takeoff 4 1.0 0 1 1.5"],
                             2.2: ["goto 2 1 0 1 0 0 0 1"], 2.5: ["goto 1 1 0 0 1 0 0 1"],
                             4.0: ["land 0 0.03 0 1 1.5"]}, 6.0),
    "stop_and_again": (floor(), {0.2: [TAKEOFF], 2.0: ["stop 0"], 3.0: ["takeoff 0 0.7 0 1 1.0"]}, 4.5),
    "blocked": (floor(), {0.2: [TAKEOFF], 2.0: ["block 1", "goto 0 0 0 1 1 1 0 1", "stop 0"],
                          2.5: ["block 0", "takeoff 0 1 0 1 1.5"]}, 4.5),
    "streams_and_handover": (floor(), {0.2: [TAKEOFF], **{round(2.0 + i * DT, 2): [f"position 0.1 {0.04 * i} 1.0 0.5"]
                                                          for i in range(5)},
                                       2.6: ["goto 0 0 0 0.5 0.5 1.0 0 1.0"],
                                       3.0: ["notify"], 3.2: ["notify", "goto 0 0 0 0 0 1.0 0 1.5"],
                                       **{round(5.0 + i * DT, 2): ["hover 0.2 0.0 0.5 0.8"] for i in range(5)},
                                       **{round(5.5 + i * DT, 2): [f"fullstate 0 {0.1 * i} 0.8 0 1 0 0 0 0 0.1"]
                                          for i in range(3)},
                                       5.8: ["notify", "land 0 0.03 0 1 2.0"]}, 8.5),
}
# The float build's transcript: these scenarios (its rounding is the same in the others).
FLOAT_SCENARIOS = ("takeoff", "takeoff_yaw_land", "goto_replan", "goto_linear", "figure_eight_reversed_fast",
                   "turn_relative_yaw", "odd_durations", "streams_and_handover")
# The firmware's memory holds 31 pieces of float: 15 of double, so these are the float build's only.
FLOAT_ONLY = {
    "memory_full": (floor(), {0.0: [f"piece 30 1.0 {' '.join(['0'] * 32)}", f"piece 31 1.0 {' '.join(['0'] * 32)}",
                                    "define 30 30 1", "define 3 29 3"]}, 0.1),
}


class Harness:
    def __init__(self, binary: Path):
        self.process = subprocess.Popen([str(binary)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                        bufsize=1)

    def send(self, line: str) -> None:
        self.process.stdin.write(line + "\n")

    def ask(self, line: str) -> list[float]:
        self.send(line)
        self.process.stdin.flush()
        return [float(v) for v in self.process.stdout.readline().split()[1:]]

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait()


QUIET = {"state", "time", "mask", "block", "notify", "position", "fullstate", "hover", "reset"}


def run_scenario(harness: Harness, name: str, scenario, digits: int) -> list[list[str]]:
    start, commands, end = scenario
    rows: list[list[str]] = []

    def record(line: str, result=()):
        op, *args = line.split()
        rows.append([name, op, " ".join(args), " ".join(f"{v:.{digits}g}" for v in result)])

    harness.send("reset")
    state = np.array(start.split()[1:], dtype=np.float64)
    harness.send(start)
    record(start)
    for i in range(int(round(end / DT)) + 1):
        t = round(i * DT, 10)
        harness.send(f"time {t}")
        for line in commands.get(round(t, 2), []):
            if line.split()[0] in QUIET:
                harness.send(line)
                record(line)
            else:
                record(line, harness.ask(line))
        harness.send("state " + " ".join(repr(float(v)) for v in state))
        result = harness.ask("step")
        record(f"step {t}", result)
        result = [float(f"{v:.{digits}g}") for v in result]
        state = follow(state, result, DT)
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--firmware", type=Path, required=True, help="a crazyflie-firmware checkout")
    parser.add_argument("--cc", default="gcc")
    parser.add_argument("--out", type=Path, default=None, help="folder for the two CSVs (default: the tests' data)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as work:
        for precision, double, digits in (("f64", True, 11), ("f32", False, 8)):
            harness = Harness(build(args.firmware, Path(work), args.cc, double))
            scenarios = SCENARIOS if double else {**{k: SCENARIOS[k] for k in FLOAT_SCENARIOS}, **FLOAT_ONLY}
            rows = [row for name, s in scenarios.items() for row in run_scenario(harness, name, s, digits)]
            harness.close()
            path = (args.out / FIXTURES[precision].name) if args.out else FIXTURES[precision]
            with open(path, "w", newline="") as f:
                writer = csv.writer(f, lineterminator="\n")
                writer.writerow(["scenario", "op", "args", "result"])
                writer.writerows(rows)
            print(f"{path}: {len(rows)} rows")


if __name__ == "__main__":
    main()
