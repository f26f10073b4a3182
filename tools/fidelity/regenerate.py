#!/usr/bin/env python3
"""Regenerate the fidelity suite's reference data (tests/fidelity/data/) from ARGoS's own runs.

Needs an ARGoS 3 that is already built and installed, with the controllers the experiments name
already built (this script builds neither; see tools/fidelity/README.md):

  --argos BIN              the ``argos3`` launcher (its plugins found through ARGOS_PLUGIN_PATH,
                           or the installation's default)
  --include DIR ...        where ``<argos3/...>`` headers are (an installation's PREFIX/include)
  --lib DIR ...            where ``libargos3core_simulator`` and ``libargos3plugin_simulator_entities`` are
  --controllers DIR        the built example controllers: DIR/footbot_flocking/libfootbot_flocking.so, …
  --kheperaiv-controller LIB   the Khepera IV plugin's built ``kheperaiv_diffusion`` controller

It compiles ``pose_logger.cpp`` (ours) with the C++ compiler, runs every experiment of
``tools/fidelity/experiments/`` for each seed, reads the poses the logger wrote and stores, per
experiment, one small ``.npz`` (tests/fidelity/reference.py says what is in it).
"""
from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
from tests.fidelity.reference import EXPERIMENTS, pack, seeds_of  # noqa: E402 - after the checkout is put on sys.path


def compile_logger(args, out_dir: Path) -> Path:
    lib = out_dir / "libpose_logger.so"
    cmd = [os.environ.get("CXX", "g++"), "-O2", "-fPIC", "-shared", "-std=c++17", "-DARGOS_simulator_BUILD",
           *(f"-I{d}" for d in args.include), str(HERE / "pose_logger" / "pose_logger.cpp"),
           *(f"-L{d}" for d in args.lib), "-largos3core_simulator", "-largos3plugin_simulator_entities",
           "-o", str(lib)]
    subprocess.run(cmd, check=True)
    return lib


def read_log(path: Path) -> dict:
    """The logger's CSV → robot poses per tick, and the objects of tick 0."""
    robots: dict[int, list] = {}
    boxes, cylinders = [], []
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            tick = int(row["tick"])
            x, y, yaw = float(row["x"]), float(row["y"]), float(row["yaw"])
            a, b, c = float(row["a"]), float(row["b"]), float(row["c"])
            if row["kind"] == "robot":
                robots.setdefault(tick, []).append((x, y, yaw))
            elif tick == 0 and row["kind"] == "box":
                boxes.append((x, y, yaw, a, b, c))
            elif tick == 0 and row["kind"] == "cylinder":
                cylinders.append((x, y, a, b))
    ticks = sorted(robots)
    return {"poses": np.array([robots[t] for t in ticks]), "boxes": np.array(boxes).reshape(-1, 6),
            "cylinders": np.array(cylinders).reshape(-1, 4)}


def run(args, logger: Path, experiment: str, seed: int, work: Path) -> dict:
    text = (HERE / "experiments" / f"{experiment}.argos").read_text()
    output = work / f"{experiment}_{seed}.csv"
    text = (text.replace("@SEED@", str(seed)).replace("@OUTPUT@", str(output))
            .replace("@LOGGER@", str(logger.with_suffix("")))
            .replace("@CONTROLLERS@", str(args.controllers))
            .replace("@KHEPERAIV_CONTROLLER@", str(args.kheperaiv_controller or "")))
    conf = work / f"{experiment}_{seed}.argos"
    conf.write_text(text)
    subprocess.run([args.argos, "-n", "-c", str(conf)], check=True, stdout=subprocess.DEVNULL)
    return read_log(output)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--argos", required=True)
    p.add_argument("--include", nargs="+", required=True)
    p.add_argument("--lib", nargs="+", required=True)
    p.add_argument("--controllers", required=True)
    p.add_argument("--kheperaiv-controller")
    p.add_argument("--only", nargs="*", help="experiments to regenerate (default: all)")
    p.add_argument("--out", default=str(ROOT / "tests" / "fidelity" / "data"))
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        logger = compile_logger(args, work)
        for experiment in args.only or EXPERIMENTS:
            if experiment.startswith("kheperaiv") and not args.kheperaiv_controller:
                print(f"{experiment}: skipped (no --kheperaiv-controller)")
                continue
            seeds = seeds_of(experiment)
            runs = [run(args, logger, experiment, seed, work) for seed in seeds]
            pack(out / f"{experiment}.npz", seeds, runs)
            print(f"{experiment}: {len(seeds)} seeds, {runs[0]['poses'].shape[1]} robots, "
                  f"{runs[0]['poses'].shape[0] - 1} ticks → {out / (experiment + '.npz')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
