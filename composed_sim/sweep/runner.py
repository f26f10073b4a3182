"""One run of a sweep in a child process, and the runners that spread runs over cores or a cluster.

Each run is a child ``composed-sim run`` in its own folder: its own process, its own ROS domain
(the run claims a free one itself), its own results. Its row comes back to the sweep, never its
exception: a failed run is a row with its error. A run whose folder holds a finished result with
the same spec hash (the resolved world, the run's options, the version) is not run again.
"""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Iterable, Iterator

from composed_sim.sweep.grid import RunSpec

SPEC = "spec.sha256"       # written once the run ended well: what a resumed sweep compares
INPUT = "input.yaml"       # the world the child runs (the overrides applied)
LOG = "run.log"            # the child's stdout and stderr
# One process per run: runs share cores. Written out: these words are part of each run's spec hash
# (a resumed sweep reruns a run whose hash changed).
RUN_ARGS = ["--workers", "1", "--no-progress", "--no-picture"]
ERROR_TAIL = 2000          # characters of a failed run's log kept in its row


def run_one(spec: RunSpec, out_dir: str, timeout_s: float | None = None) -> dict:
    """Run one spec in a child process (or reuse its finished result); the row of the runs table,
    with the per-tick metrics under "_metrics"."""
    folder = Path(out_dir) / spec.name
    folder.mkdir(parents=True, exist_ok=True)
    digest = spec.spec_hash(RUN_ARGS)
    row: dict = {"run": spec.name, **spec.values}
    if (folder / SPEC).exists() and (folder / SPEC).read_text().strip() == digest:
        return {**row, **_results(folder), "status": "ok", "exit_code": 0, "error": "", "reused": True}
    (folder / SPEC).unlink(missing_ok=True)
    (folder / INPUT).write_text(spec.world_text())
    command = [sys.executable, "-m", "composed_sim.cli", "run", str(folder / INPUT), "--out", str(folder), *RUN_ARGS]
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}    # the run claims a free domain
    t0 = time.perf_counter()
    with open(folder / LOG, "w") as log:
        try:
            code = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, env=env, timeout=timeout_s).returncode
        except subprocess.TimeoutExpired:
            code = -9
    row["wall_s"] = round(time.perf_counter() - t0, 3)
    row["exit_code"] = code
    if code == 0:
        (folder / SPEC).write_text(digest + "\n")
        return {**row, **_results(folder), "status": "ok", "error": "", "reused": False}
    text = (folder / LOG).read_text(errors="replace")
    results = _results(folder) if (folder / "summary.json").exists() else {}
    return {**row, **results, "status": "timeout" if code == -9 else "failed", "error": text[-ERROR_TAIL:],
            "reused": False}


def _results(folder: Path) -> dict:
    """The figures of a run's summary.json and its metrics.csv rows."""
    s = json.loads((folder / "summary.json").read_text())
    final = (s.get("metrics") or {}).get("final", {})
    ended_by_loop_functions = s.get("ended_by_loop_functions", s.get("finished", False))   # older summaries
    out = {"robots_run": s["robots"], "ticks": s["ticks"], "ended_by_loop_functions": ended_by_loop_functions,
           "finished": ended_by_loop_functions,        # deprecated column, as in summary.json
           "setup_s": s["setup_s"], "ticks_wall_s": s["ticks_wall_s"], "real_time_factor": s["real_time_factor"],
           "violations": s["violations"], **{f"final_{k}": v for k, v in final.items() if k != "tick"}}
    out["_metrics"] = []
    if (folder / "metrics.csv").exists():
        with open(folder / "metrics.csv", newline="") as f:
            out["_metrics"] = [{k: _number(v) for k, v in r.items()} for r in csv.DictReader(f)]
    return out


def _number(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def local_pool(specs: list[RunSpec], out_dir: str, jobs: int) -> Iterator[dict]:
    """Rows as runs end, ``jobs`` at a time. Each run is its own child process; a thread per job
    slot only waits for it."""
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        yield from _as_done(pool.submit(run_one, spec, out_dir) for spec in specs)


def _as_done(futures: Iterable[Future]) -> Iterator[dict]:
    from concurrent.futures import as_completed
    for future in as_completed(list(futures)):
        yield future.result()


def dask_cluster(specs: list[RunSpec], out_dir: str, address: str, security=None) -> Iterator[dict]:
    """Rows as runs end on a Dask distributed cluster (``tls://scheduler:8786``, or a Client's
    cluster object): every worker needs composed_sim installed and ``out_dir`` on a shared file
    system. Each task is one run, retried by Dask if its worker dies. ``security``: Dask's
    ``Security`` of the cluster's TLS; None takes Dask's own configuration (its config file's
    ``distributed.comm.tls``), as any Dask client does."""
    from distributed import Client
    # now, not at the first row: a bad address is an error before any run
    client = Client(address) if security is None else Client(address, security=security)
    return _cluster_rows(client, specs, out_dir)


def _cluster_rows(client, specs: list[RunSpec], out_dir: str) -> Iterator[dict]:
    from distributed import as_completed
    with client:
        futures = [client.submit(run_one, spec, str(Path(out_dir).resolve()), key=f"run-{spec.name}", pure=False)
                   for spec in specs]
        for future in as_completed(futures):
            yield future.result()

