"""The benchmark's distributed row (``composed-sim bench --machines M``, as root): per swarm size,
the simulator and M machines in network namespaces of this machine (composed_sim/bench/netns.py),
each machine ``join``-ed with ``--workers`` worker processes, against one machine with the same
number of worker processes and with ``--workers auto``, run after one another ``--trials`` times.

Per run: the whole command's wall time, set-up and ticks, the simulator's serial part per tick
(summary.json's phases: what more machines cannot share), violations, and for the distributed run
the state's payload per tick (``state_bytes_per_tick``) and the bytes through the simulator's link
per tick while the ticks ran (both ways, Dask's framing and TCP included). The namespaces share
this machine's cores: the ratio to one machine measures the overhead of going through the
network, not a speed-up (docs/speed.md, "Across machines", models the speed-up).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from composed_sim.bench.netns import Netns

RUN = [sys.executable, "-m", "composed_sim.cli", "run"]


def _summary(stdout: str) -> dict:
    return json.loads(stdout[stdout.index("{"):]) if "{" in stdout else {}


def _row(kind: str, robots: int, wall_s: float, summary: dict, **extra) -> dict:
    phases = summary.get("phases_per_tick_ms") or {}
    return {"run": kind, "Robots": robots, "whole_s": round(wall_s, 2), "setup_s": summary.get("setup_s"),
            "ticks_wall_s": summary.get("ticks_wall_s"), "serial_ms": phases.get("serial"),
            "physics_ms": phases.get("physics"), "sending_frames_ms": phases.get("sending_frames"),
            "gathering_answers_ms": phases.get("gathering_answers"), "violations": summary.get("violations"),
            "main_cpu_ms": summary.get("main_process_cpu_per_tick_ms"), "cpu_ms": summary.get("cpu_per_tick_ms"),
            "workers": summary.get("workers"), "ticks": summary.get("ticks"), **extra}


def one_machine(world: Path, robots: int, ticks: int, workers: str, env: dict, out: Path) -> dict:
    t0 = time.perf_counter()
    done = subprocess.run([*RUN, str(world), "--robots", str(robots), "--ticks", str(ticks), "--workers", workers,
                           "--out", str(out), "--json", "--no-progress", "--no-picture"],
                          capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"--workers {workers}: {done.stderr[-600:]}")
    return _row(f"one machine, --workers {workers}", robots, wall, _summary(done.stdout))


def machines(world: Path, robots: int, ticks: int, count: int, workers: str, env: dict, out: Path) -> dict:
    """The simulator and ``count`` machines, each in a network namespace of its own."""
    names = [f"m{i}" for i in range(count)]
    with Netns(["sim", *names]) as nets, tempfile.TemporaryDirectory() as logs:
        log = Path(logs) / "sim.log"
        t0 = time.perf_counter()
        with open(log, "wb") as err:
            sim = subprocess.Popen(nets.exec("sim", [
                *RUN, str(world), "--robots", str(robots), "--ticks", str(ticks), "--machines",
                ",".join(nets.address[m] for m in names), "--listen", f"{nets.address['sim']}:0", "--out", str(out),
                "--json", "--no-progress", "--no-picture"]), stdout=subprocess.PIPE, stderr=err, text=True, env=env)
        command = _wait_for(log, "on each: ", sim).split("on each: ", 1)[1].split()
        joins = [subprocess.Popen(nets.exec(m, [sys.executable, "-m", "composed_sim.cli", *command[1:], "--workers",
                                                workers]), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  env=env) for m in names]
        _wait_for(log, "robots on ", sim)            # set-up done: the ticks' traffic from here
        before = nets.counters("sim")
        stdout, _ = sim.communicate()
        after = nets.counters("sim")
        wall = time.perf_counter() - t0
        for join in joins:
            join.wait(timeout=60)
        if sim.returncode != 0:
            raise RuntimeError(f"--machines {count}: {log.read_text()[-600:]}")
    summary = _summary(stdout)
    wire = sum(after[k] - before[k] for k in after) / max(summary.get("ticks") or 1, 1)
    return _row(f"{count} machines × --workers {workers}", robots, wall, summary,
                state_bytes_per_tick=summary.get("state_bytes_per_tick"), wire_bytes_per_tick=round(wire))


def _wait_for(log: Path, text: str, process: subprocess.Popen, timeout_s: float = 600) -> str:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for line in log.read_text(errors="replace").splitlines():
            if text in line:
                return line
        if process.poll() is not None:
            raise RuntimeError(f"the simulator ended before saying {text!r}: {log.read_text()[-600:]}")
        time.sleep(0.05)
    raise RuntimeError(f"the simulator did not say {text!r} within {timeout_s:g} s")


def run_distributed(world: Path, sizes, ticks: int, count: int, workers: str, trials: int, out: Path,
                    machine: dict) -> list[dict]:
    """The rows, alternated per trial: one machine with the same worker processes, ``--workers
    auto``, then the machines; written with ``machine`` (what ran them) to distributed.json."""
    env = dict(os.environ, MPLBACKEND="Agg")
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    baselines = [str(count * int(workers)), "auto"] if workers.isdigit() else ["auto"]
    for robots in sizes:
        for trial in range(trials):
            with tempfile.TemporaryDirectory() as tmp:
                runs = [lambda k=k: one_machine(world, robots, ticks, k, env, Path(tmp) / k) for k in baselines]    # noqa: B023 - run within this iteration
                runs.append(lambda: machines(world, robots, ticks, count, workers, env, Path(tmp) / "machines"))    # noqa: B023 - run within this iteration
                for measured in runs:
                    rows.append({**measured(), "trial": trial})
                    print(json.dumps(rows[-1]), flush=True)
    (out / "distributed.json").write_text(json.dumps({"machine": machine, "rows": rows}, indent=1))
    return rows
