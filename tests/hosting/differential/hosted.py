"""A batch hosted by composed_sim, as a user runs it: ``composed-sim run`` on the batch's world
in one of the host modes, its nodes' events read back from ``OUT/logs/<robot>.log`` (and
``<run-wide node>.log``), each line stamped by the host with its tick."""
from __future__ import annotations

import csv
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from differential.events import RunResult
from differential.spec import write_world

MODES = {
    "workers1": ["--workers", "1"],
    "workers2": ["--workers", "2"],
    "threads": ["--workers", "1", "--executor", "multi-threaded"],
    "processes": ["--mode", "multi-process"],
}
HERE = Path(__file__).resolve().parent
STAMP = re.compile(r"^\[\w+\] \[(?:set-up|sim [-\d.]+ s, tick (-?\d+))\] \[[^\]]*\]: (.*)$")
FAILED_LINE = re.compile(r"callback raised (\w+); (\w+) is failed")
OWNER = re.compile(r"p(\d+)([rw]\d+)")
WATCHDOG_S = 3.0       # only the multi-threaded executor's known stalls wait for it
TAIL = 1500


def run_hosted(programs: list[dict], ticks: int, mode: str, workdir: Path, timeout_s: float = 300.0) -> RunResult:
    workdir.mkdir(parents=True, exist_ok=True)
    world = write_world(programs, ticks, workdir / "world.yaml")
    out = workdir / "out"
    shutil.rmtree(out, ignore_errors=True)             # the node logs append: no run's lines but this one's
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}     # the run claims free domains
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(HERE.parent), os.environ.get("PYTHONPATH")]))
    cmd = [sys.executable, "-m", "composed_sim.cli", "run", str(world), "--out", str(out), "--watchdog",
           str(WATCHDOG_S), "--no-progress", "--no-picture", *MODES[mode]]
    result = RunResult(mode)
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, env=env)
        if done.returncode != 0:
            result.failed = True
            result.notes.append(f"exit status {done.returncode}: {done.stderr[-TAIL:].strip()}")
    except subprocess.TimeoutExpired as e:
        result.failed = True
        err = e.stderr.decode(errors="replace") if isinstance(e.stderr, bytes) else (e.stderr or "")
        result.notes.append(f"still running after {timeout_s:.0f} s, killed: {err[-TAIL:].strip()}")
    read_logs(out / "logs", result)
    read_violations(out / "violations.csv", result)
    return result


def read_logs(folder: Path, result: RunResult) -> None:
    for path in sorted(folder.glob("*.log")) if folder.is_dir() else ():
        for line in path.read_text(errors="replace").splitlines():
            m = STAMP.match(line)
            if m is None:
                continue
            tick = int(m.group(1)) if m.group(1) is not None else -1
            if not result.add_line(m.group(2), tick):
                failed = FAILED_LINE.search(m.group(2))
                owner = OWNER.fullmatch(failed.group(2)) if failed else None
                if owner:
                    result.fail(int(owner.group(1)), owner.group(2), tick, failed.group(1))


def read_violations(path: Path, result: RunResult) -> None:
    """Robots the host failed or whose tick had no answer: a note each (the logs say what ran)."""
    if not path.is_file():
        return
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if rows:
        result.notes.append(f"{len(rows)} violations, the first: {dict(rows[0])}")
    if any("process died" in row.get("reason", "") for row in rows):
        result.failed = True
