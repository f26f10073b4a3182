"""``composed-sim bench``: sweep swarm sizes, host modes and executors; measure each run's whole
process tree; write CSV, JSON, figures and a markdown report side by side with the paper's results.

Each run is its own ``composed-sim run ... --json`` subprocess on a ROS domain (a block of domains
in multi-process mode) that the previous run did not use, watched with psutil every ``SAMPLE_S``:

WallTime(s)  spawn to exit of the run's root process: interpreter start, imports, setup, the ticks,
             writing the results; what the paper timed.
CPU(%)       core-seconds of the whole tree / WallTime × 100 (% of one core, the paper's convention).
MaxMem(kB)   peak over the samples of the summed RSS of every process of the tree (pages shared
             between processes count once per process: an upper bound with many processes).
MaxPss(kB)   peak over the samples of the summed PSS of every process of the tree (each shared page
             split among the processes that map it: the tree's real footprint), sampled at most
             every PSS_SAMPLE_S.
setup_s, ticks_wall_s, real_time_factor, violations …  from the run's own JSON summary.

Outputs in --out: runs.csv (one row per run; the paper's nine columns first, then ours), runs.json
(the same rows, the machine, the exact command, the memory estimate of the skip rule), and
wall_time.png, cpu.png, memory.png (log-log against N, with the paper's means and the real-time
line, like the paper's Figure 5). ``--report FILE.md`` also writes the report, its figures and
raw rows in ``FILE's folder/figures/``. ``--replot runs.json`` redraws all that from stored rows.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import shlex
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Optional

from composed_sim.world.schema import MAX_DOMAIN, ROBOTS_PER_DOMAIN

PAPER_SIZES = (3, 5, 10, 20, 40, 80, 160, 320, 640, 1280)
# Display order of modes and executors; the choices themselves are the hosts' (hosts.composed).
MODES = ("composed", "multi-process")
EXECUTORS = ("lockstep", "events", "single-threaded", "multi-threaded")

# The paper's CSV columns, in its order, filled with our measurements (see the module docstring).
# ArgosCPU/ArgosMem: the run's root process (the simulator); Ros2CPU/Ros2Mem: every other process
# of its tree (the controllers). Only filled in multi-process mode: in composed mode one process
# is both sides and cannot be split.
PAPER_COLUMNS = ("Robots", "Repetition", "WallTime(s)", "CPU(%)", "MaxMem(kB)",
                 "ArgosCPU(%)", "Ros2CPU(%)", "ArgosMem(kB)", "Ros2Mem(kB)")
OUR_COLUMNS = ("mode", "workers", "workers_used", "executor", "status", "ticks", "setup_s", "ticks_wall_s", "total_wall_s",
               "cpu_core_s", "real_time_factor", "per_robot_tick_us", "violations",
               "physics_s", "sensing_s", "ros_exchange_s", "processes", "other_load_cores", "domain_id",
               "exit_code", "reason", "MaxPss(kB)", "Ros2Pss(kB)")
COLUMNS = PAPER_COLUMNS + OUR_COLUMNS
# workers: composed mode's --workers as asked ("1", "auto", "4"), empty in multi-process mode;
# workers_used: what the run used (auto's choice). Ros2Pss(kB): the PSS of every process but the root.
# status: ok | skipped | failed (non-zero exit or no summary) | timeout | interrupted
# other_load_cores: cores kept busy by everything outside the run's tree during it, on average (the
# machine is shared: a run next to a busy neighbour is slower, and this says so).

PAPER_VARIANTS = {          # key: (file, label)
    "single": ("flocking.csv", "paper: ARGoS + ROS 2, 1 thread"),
    "multi": ("flocking_mt.csv", "paper: ARGoS + ROS 2, 12 threads"),
}

SAMPLE_S = 0.15             # psutil sampling period of a run's process tree
PSS_SAMPLE_S = 1.0          # PSS reads each process's smaps: sampled less often
TERM_GRACE_S = 15.0         # after SIGTERM (timeout), time to stop at a tick and write, then SIGKILL
LEFTOVER_GRACE_S = 10.0     # time a run's descendants get to exit after its root did
STDERR_TAIL_CHARS = 600
DEFAULT_TIMEOUT_S = 3600.0
DEFAULT_MEMORY_FRACTION = 0.8
FALLBACK_PROCESS_MB = 70.0       # docs/architecture.md: one rclpy process with a node, until measured
CALIBRATION_ROBOTS = 3           # dedicated multi-process run measuring the per-process cost …
CALIBRATION_ABOVE = 10           # … when the sweep's first multi-process size is larger than this
SAFE_DOMAIN_MAX = 101            # ROS 2 on Linux: domains 0..101 never reach the ephemeral ports

FIGURES = {"wall_time": "wall_time.png", "cpu": "cpu.png", "memory": "memory.png"}


# ---------------------------------------------------------------------------------------------
# Command-line options

def _size_list(text: str) -> tuple[int, ...]:
    sizes = []
    for part in text.split(","):
        part = part.strip()
        try:
            value = int(part)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected whole numbers separated by commas, got {part!r}") from None
        if value < 1:
            raise argparse.ArgumentTypeError(f"swarm sizes must be >= 1 (got {value})")
        sizes.append(value)
    return tuple(sorted(set(sizes)))


def _choice_list(allowed: tuple[str, ...]) -> Callable[[str], tuple[str, ...]]:
    def parse(text: str) -> tuple[str, ...]:
        items = [p.strip() for p in text.split(",") if p.strip()]
        bad = [p for p in items if p not in allowed]
        if bad or not items:
            raise argparse.ArgumentTypeError(f"{', '.join(map(repr, bad)) or 'nothing'} given; "
                                             f"choose from {', '.join(allowed)} (comma separated)")
        return tuple(dict.fromkeys(items))
    return parse


def _workers_list(text: str) -> tuple[str, ...]:
    values = tuple(v.strip() for v in text.split(",") if v.strip())
    bad = [v for v in values if v != "auto" and not (v.isdigit() and int(v) >= 1)]
    if not values or bad:
        raise argparse.ArgumentTypeError(f"expected whole numbers >= 1 or auto, comma-separated, got {text!r}")
    return values


def _positive(kind: type) -> Callable[[str], float]:
    from composed_sim.command_line import number_arg
    return number_arg(kind, minimum=0, inclusive=False)


def _fraction(text: str) -> float:
    value = _positive(float)(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"must be within (0, 1] (got {text})")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from composed_sim.hosts.choices import EXECUTORS as executors, MODES as modes
    join = ",".join
    parser.add_argument("--sizes", type=_size_list, default=PAPER_SIZES, metavar="N,N,…",
                        help=f"swarm sizes (default: the paper's {join(map(str, PAPER_SIZES))})")
    parser.add_argument("--modes", type=_choice_list(tuple(modes)), default=tuple(modes), metavar="MODE,…",
                        help=f"host modes among {join(modes)} (default: all)")
    parser.add_argument("--executors", type=_choice_list(tuple(executors)), default=tuple(executors),
                        metavar="EXECUTOR,…", help=f"executors among {join(executors)} (default: all)")
    parser.add_argument("--workers", type=_workers_list, default=("auto",), metavar="K|auto,…",
                        help="composed mode: the --workers values to sweep, e.g. 1,auto (default: auto)")
    parser.add_argument("--trials", type=_positive(int), default=3, help="runs per size, mode and executor (default: %(default)s)")
    parser.add_argument("--ticks", type=_positive(int), default=600,
                        help="ticks per run (default: %(default)s, one simulated minute as in the paper)")
    parser.add_argument("--world", type=Path, default=None,
                        help="world file (default: the shipped worlds/flocking.yaml, the paper's experiment)")
    parser.add_argument("--out", type=Path, default=Path("bench-results"),
                        help="folder for runs.csv, runs.json and the figures (default: %(default)s)")
    parser.add_argument("--timeout", type=_positive(float), default=DEFAULT_TIMEOUT_S, metavar="SECONDS",
                        help="wall-time limit of one run; a run over it is stopped and recorded as timeout "
                             "(default: %(default)g)")
    parser.add_argument("--report", type=Path, default=None, metavar="FILE.md",
                        help="also write a markdown report there, its figures and raw rows in figures/ beside it")
    parser.add_argument("--domain-id", type=int, default=None,
                        help="first ROS domain: each run gets a domain (a block of them in multi-process "
                             "mode) from here on, never one the previous run had (default: $ROS_DOMAIN_ID or 0)")
    parser.add_argument("--robots-per-domain", type=_positive(int), default=None,
                        help="multi-process mode: passed on to each run (default: the run's own default, "
                             f"{ROBOTS_PER_DOMAIN})")
    parser.add_argument("--memory-fraction", type=_fraction, default=DEFAULT_MEMORY_FRACTION,
                        help="multi-process runs whose predicted memory exceeds this fraction of the "
                             "available memory are skipped (default: %(default)s)")
    parser.add_argument("--replot", type=Path, default=None, metavar="RUNS.json",
                        help="run nothing: redraw the figures (into --out) and the --report from a "
                             "runs.json written by an earlier sweep")


def command_line(args) -> str:
    """The ``composed-sim bench`` command that reproduces this sweep (what was given, spelled out)."""
    parts = ["composed-sim", "bench",
             "--sizes", ",".join(map(str, args.sizes)), "--modes", ",".join(args.modes),
             "--executors", ",".join(args.executors), "--workers", ",".join(args.workers),
             "--trials", str(args.trials), "--ticks", str(args.ticks)]
    if args.world is not None:
        parts += ["--world", str(args.world)]
    if args.timeout != DEFAULT_TIMEOUT_S:
        parts += ["--timeout", f"{args.timeout:g}"]
    if args.domain_id is not None:
        parts += ["--domain-id", str(args.domain_id)]
    if args.robots_per_domain is not None:
        parts += ["--robots-per-domain", str(args.robots_per_domain)]
    if args.memory_fraction != DEFAULT_MEMORY_FRACTION:
        parts += ["--memory-fraction", f"{args.memory_fraction:g}"]
    parts += ["--out", str(args.out)]
    if args.report is not None:
        parts += ["--report", str(args.report)]
    return shlex.join(parts)


# ---------------------------------------------------------------------------------------------
# Pure pieces: paper results, skip rule, domains, aggregation

def paper_results_dir() -> Path:
    from importlib.resources import files
    return Path(str(files("composed_sim") / "data" / "paper_results"))


def load_paper_results(filename: str = "flocking.csv") -> dict[int, dict[str, float]]:
    """Mean over the paper's repetitions of every numeric column, per swarm size (column names as
    in the paper's CSV, plus ``trials``)."""
    path = paper_results_dir() / filename
    groups: dict[int, list[dict[str, float]]] = {}
    with open(path, newline="") as f:
        for rec in csv.DictReader(f):
            groups.setdefault(int(rec["Robots"]), []).append(
                {k: float(v) for k, v in rec.items() if k not in ("Robots", "Repetition")})
    return {n: {**{k: statistics.fmean(r[k] for r in recs) for k in recs[0]}, "trials": len(recs)}
            for n, recs in sorted(groups.items())}


def skip_reason(per_process_mb: float, robots: int, available_mb: float, *, base_mb: float = 0.0,
                fraction: float = DEFAULT_MEMORY_FRACTION, source: str = "") -> Optional[str]:
    """Why a multi-process run of ``robots`` controller processes must not start, or None.

    Predicted tree memory = base_mb (the simulator's process) + robots × per_process_mb; the run
    is skipped when that exceeds ``fraction`` of ``available_mb``."""
    if per_process_mb < 0 or robots < 1 or available_mb < 0 or not 0 < fraction <= 1:
        raise ValueError(f"skip_reason: bad input per_process_mb={per_process_mb}, robots={robots}, "
                         f"available_mb={available_mb}, fraction={fraction}")
    predicted = base_mb + robots * per_process_mb
    budget = fraction * available_mb
    if predicted <= budget:
        return None
    return (f"predicted {predicted:.0f} MB = {base_mb:.0f} MB simulator + {robots} controller processes × "
            f"{per_process_mb:.1f} MB{f' ({source})' if source else ''} exceeds {fraction:.0%} of the "
            f"{available_mb:.0f} MB available ({budget:.0f} MB)")


def domains_needed(mode: str, robots: int, robots_per_domain: Optional[int]) -> int:
    if mode != "multi-process":
        return 1
    return math.ceil(robots / (robots_per_domain or ROBOTS_PER_DOMAIN))


class DomainAllocator:
    """Hands each run a block of consecutive ROS domains disjoint from the previous run's, so a run
    never meets processes of the one before still closing: a block starts at the base unless that
    overlaps the previous block, then right after it; so the sweep's footprint stays about two
    blocks wide (other users of this machine's domains are not swept over)."""

    def __init__(self, base: int):
        if not 0 <= base <= MAX_DOMAIN:
            raise ValueError(f"--domain-id: must be within 0..{MAX_DOMAIN} (got {base})")
        self.base = base
        self.top = SAFE_DOMAIN_MAX if base <= SAFE_DOMAIN_MAX else MAX_DOMAIN
        self._previous: Optional[range] = None

    def take(self, width: int) -> Optional[int]:
        """First domain of a block of ``width``, or None if base..top cannot hold it."""
        if width < 1:
            raise ValueError(f"width must be >= 1 (got {width})")
        if self.base + width - 1 > self.top:
            return None
        start = self.base
        prev = self._previous
        overlaps = prev is not None and start < prev.stop and prev.start < start + width
        if overlaps and prev.stop + width - 1 <= self.top:
            start = prev.stop
        # else: the base block is disjoint from the previous one, or nothing else fits (the previous
        # run's processes are gone anyway: a run ends when its whole tree has exited)
        self._previous = range(start, start + width)
        return start


def _num(v) -> Optional[float]:
    if v is None or v == "":
        return None
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


MEDIAN_FIELDS = ("WallTime(s)", "CPU(%)", "MaxMem(kB)", "MaxPss(kB)", "workers_used", "setup_s", "ticks_wall_s", "total_wall_s",
                 "cpu_core_s", "real_time_factor", "per_robot_tick_us", "processes", "other_load_cores")


def aggregate(rows: Iterable[dict]) -> list[dict]:
    """One record per (Robots, mode, workers, executor): medians over the ok trials, counts of all trials."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        workers = "" if r.get("workers") is None else str(r["workers"])
        groups.setdefault((int(r["Robots"]), r["mode"], workers, r["executor"]), []).append(r)
    out = []
    def order(key: tuple) -> tuple:
        n, mode, workers, executor = key
        return (n, MODES.index(mode) if mode in MODES else len(MODES),
                (0, int(workers)) if workers.isdigit() else (1, 0),
                EXECUTORS.index(executor) if executor in EXECUTORS else len(EXECUTORS), executor)

    for (n, mode, workers, executor), recs in sorted(groups.items(), key=lambda kv: order(kv[0])):
        ok = [r for r in recs if r["status"] == "ok"]
        agg = {"Robots": n, "mode": mode, "workers": workers, "executor": executor, "trials": len(recs), "ok": len(ok),
               "statuses": sorted({r["status"] for r in recs})}
        for k in MEDIAN_FIELDS:
            vals = [x for x in (_num(r.get(k)) for r in ok) if x is not None]
            agg[k] = statistics.median(vals) if vals else None
        viol = [_num(r.get("violations")) for r in ok]
        agg["violations"] = int(max(v for v in viol if v is not None)) if any(v is not None for v in viol) else None
        out.append(agg)
    return out


def host_label(rec: dict) -> str:
    """How a row's or record's controllers were hosted: "composed, 1 process", "composed, workers
    auto (8)", "multi-process"."""
    if rec["mode"] != "composed":
        return rec["mode"]
    workers, used = str(rec.get("workers") or "1"), _num(rec.get("workers_used"))
    if workers == "1":
        return "composed, 1 process"
    return f"composed, workers {workers}" + (f" ({used:.0f})" if workers == "auto" and used else "")


# ---------------------------------------------------------------------------------------------
# Measuring one process tree

@dataclass
class TreeMeasurement:
    exit_code: Optional[int]
    wall_s: float
    cpu_core_s: float                 # the whole tree, see measure_tree
    root_cpu_s: float                 # the root process alone
    peak_tree_rss_kb: int             # peak of the summed RSS of the tree
    peak_root_rss_kb: int
    peak_others_rss_kb: int           # peak of the summed RSS of every process but the root
    max_processes: int                # most processes alive in the tree at one sample
    stdout: str
    stderr: str
    peak_tree_pss_kb: int = 0         # peak of the summed PSS of the tree (sampled every PSS_SAMPLE_S)
    peak_others_pss_kb: int = 0
    timed_out: bool = False
    interrupted: bool = False
    leftovers_killed: int = 0         # descendants still alive LEFTOVER_GRACE_S after the root exited
    other_cores: Optional[float] = None  # machine-wide busy CPU outside the tree / wall


class _Tracked:
    __slots__ = ("proc", "cpu_s")

    def __init__(self, proc):
        self.proc = proc
        self.cpu_s = 0.0


def measure_tree(cmd: list[str], *, env: dict, timeout_s: float, sample_s: float = SAMPLE_S,
                 leftover_grace_s: float = LEFTOVER_GRACE_S) -> TreeMeasurement:
    """Run ``cmd`` and watch its process tree until it and every descendant are gone.

    CPU: each process's last sampled user+system time is kept (so processes that exit between
    samples still count up to their last sample); the root is detected at exit without being
    reaped (waitid WNOWAIT), its final own and reaped-children times read, then it is reaped with
    wait4. cpu_core_s = max(root's own + reaped descendants' exact times + last samples of
    descendants that outlived it, sum of last samples of everything): both are lower bounds of
    the truth, the first exact unless some descendant was never waited for by its parent."""
    import psutil

    tracked: dict[int, _Tracked] = {}
    retired: list[_Tracked] = []      # processes whose pid was reused by a later one
    peak_tree = peak_root = peak_others = 0
    peak_pss = peak_others_pss = 0
    next_pss = 0.0
    max_processes = 0

    def sample(root_alive: bool) -> None:
        nonlocal peak_tree, peak_root, peak_others, max_processes, peak_pss, peak_others_pss, next_pss
        with_pss = time.perf_counter() >= next_pss
        if with_pss:
            next_pss = time.perf_counter() + PSS_SAMPLE_S
        procs = []
        if root_alive:
            try:
                procs = [root] + root.children(recursive=True)
            except psutil.Error:
                procs = [root]
        else:
            procs = [t.proc for t in tracked.values() if t.proc is not root]
        rss_root = rss_others = alive = pss_root = pss_others = 0
        for p in procs:
            t = tracked.get(p.pid)
            if t is None or t.proc is not p and not _same_process(t.proc, p):
                if t is not None:
                    retired.append(t)
                t = tracked[p.pid] = _Tracked(p)
            try:
                with t.proc.oneshot():
                    times = t.proc.cpu_times()
                    rss = t.proc.memory_info().rss
                pss = t.proc.memory_full_info().pss if with_pss else 0
            except psutil.Error:
                continue
            t.cpu_s = max(t.cpu_s, times.user + times.system)
            if rss:
                alive += 1
            if t.proc is root:
                rss_root, pss_root = rss, pss
            else:
                rss_others += rss
                pss_others += pss
        peak_root = max(peak_root, rss_root)
        peak_others = max(peak_others, rss_others)
        peak_tree = max(peak_tree, rss_root + rss_others)
        peak_pss = max(peak_pss, pss_root + pss_others)
        peak_others_pss = max(peak_others_pss, pss_others)
        max_processes = max(max_processes, alive)

    timed_out = interrupted = False
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        busy0 = _machine_busy_s()
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, stdin=subprocess.DEVNULL, env=env)
        root = psutil.Process(proc.pid)
        tracked[proc.pid] = _Tracked(root)
        term_sent_at: Optional[float] = None
        try:
            while os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None:
                sample(root_alive=True)
                elapsed = time.perf_counter() - t0
                if term_sent_at is None and elapsed > timeout_s:
                    timed_out, term_sent_at = True, elapsed
                    _signal(root, signal.SIGTERM)      # the run stops at the next tick and writes
                elif term_sent_at is not None and elapsed > term_sent_at + TERM_GRACE_S:
                    _kill_all(t.proc for t in tracked.values())
                time.sleep(sample_s)
        except KeyboardInterrupt:
            interrupted = True
            _signal(root, signal.SIGTERM)
            if not _wait_exit(proc.pid, TERM_GRACE_S / 3):
                _kill_all(t.proc for t in tracked.values())
        wall_s = time.perf_counter() - t0
        busy1 = _machine_busy_s()
        # The root is a zombie now: its own times are final, and so are those of the descendants
        # it reaped (children_*), which wait4's rusage covers too.
        root_own = root_children = 0.0
        try:
            ct = root.cpu_times()
            root_own, root_children = ct.user + ct.system, ct.children_user + ct.children_system
        except psutil.Error:
            pass
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = exit_code = os.waitstatus_to_exitcode(status)
        tracked[proc.pid].cpu_s = max(tracked[proc.pid].cpu_s, root_own)
        exact = max(usage.ru_utime + usage.ru_stime, root_own + root_children)

        # Descendants that outlived the root (orphans, which its times cannot hold): give them
        # time, then end them.
        leftovers = [t.proc for t in tracked.values() if t.proc is not root and _alive(t.proc)]
        orphan_pids = {p.pid for p in leftovers}
        deadline = time.perf_counter() + leftover_grace_s
        while leftovers and time.perf_counter() < deadline:
            sample(root_alive=False)
            time.sleep(sample_s)
            leftovers = [p for p in leftovers if _alive(p)]
        if leftovers:
            _kill_all(leftovers)
            _wait_gone(leftovers, 5.0)
        orphans_cpu = sum(t.cpu_s for pid, t in tracked.items() if pid in orphan_pids)
        sampled = sum(t.cpu_s for t in [*tracked.values(), *retired])
        out.seek(0)
        err.seek(0)
        stdout = out.read().decode(errors="replace")
        stderr = err.read().decode(errors="replace")
    peak_tree = max(peak_tree, usage.ru_maxrss * 1024)   # a run shorter than a sample period
    cpu_core_s = max(exact + orphans_cpu, sampled)
    other = None
    if busy0 is not None and busy1 is not None and wall_s > 0:
        other = max(busy1 - busy0 - cpu_core_s, 0.0) / wall_s
    return TreeMeasurement(
        exit_code=exit_code, wall_s=wall_s, cpu_core_s=cpu_core_s, other_cores=other,
        root_cpu_s=max(root_own, tracked[proc.pid].cpu_s),
        peak_tree_rss_kb=peak_tree // 1024, peak_root_rss_kb=peak_root // 1024,
        peak_others_rss_kb=peak_others // 1024, max_processes=max_processes,
        peak_tree_pss_kb=peak_pss // 1024, peak_others_pss_kb=peak_others_pss // 1024,
        stdout=stdout, stderr=stderr, timed_out=timed_out, interrupted=interrupted,
        leftovers_killed=len(leftovers))


def _wait_exit(pid: int, timeout_s: float) -> bool:
    """Wait until our child ``pid`` has exited, without reaping it (psutil's wait would)."""
    deadline = time.perf_counter() + timeout_s
    while os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None:
        if time.perf_counter() > deadline:
            return False
        time.sleep(0.05)
    return True


def _machine_busy_s() -> Optional[float]:
    """Core-seconds the whole machine has spent busy since boot (not idle, waiting or stolen)."""
    import psutil
    try:
        t = psutil.cpu_times()
    except Exception:
        return None
    return sum(getattr(t, k, 0.0) for k in ("user", "nice", "system", "irq", "softirq"))


def _same_process(a, b) -> bool:
    try:
        return a.create_time() == b.create_time()
    except Exception:
        return False


def _alive(p) -> bool:
    import psutil
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _signal(p, sig) -> None:
    import psutil
    try:
        if p.is_running():            # checks the pid still names the process we started
            p.send_signal(sig)
    except psutil.Error:
        pass


def _kill_all(procs) -> None:
    for p in list(procs):
        _signal(p, signal.SIGKILL)


def _wait_gone(procs, timeout_s: float) -> None:
    """Wait for processes that are not our children (psutil would reap a child)."""
    import psutil
    try:
        psutil.wait_procs([p for p in procs if _alive(p)], timeout=timeout_s)
    except psutil.Error:
        pass


def parse_summary(stdout: str) -> Optional[dict]:
    """The JSON object that ``run --json`` prints last on stdout, or None."""
    text = stdout.strip()
    starts = [i for i in range(len(text)) if text[i] == "{" and (i == 0 or text[i - 1] == "\n")]
    for i in reversed(starts):
        try:
            obj, end = json.JSONDecoder().raw_decode(text, i)
        except ValueError:
            continue
        if isinstance(obj, dict) and not text[end:].strip():
            return obj
    return None


def _tail(text: str, limit: int = STDERR_TAIL_CHARS, max_lines: int = 8) -> str:
    """The last lines of a run's stderr on one line (CSV-friendly)."""
    lines = [ln.strip() for ln in text.replace("\r", "\n").splitlines() if ln.strip()][-max_lines:]
    joined = " | ".join(lines)
    return ("…" + joined[-limit:]) if len(joined) > limit else joined


# ---------------------------------------------------------------------------------------------
# The sweep

@dataclass
class MemoryEstimate:
    """Per-controller-process cost for the multi-process skip rule."""
    per_process_mb: float = FALLBACK_PROCESS_MB
    base_mb: float = 0.0
    source: str = f"not measured yet: {FALLBACK_PROCESS_MB:.0f} MB per rclpy process (docs/architecture.md)"
    measured: bool = False

    def update(self, row: dict) -> None:
        """From a multi-process run: PSS per controller process (shared library pages counted once
        over all processes, as the memory they really take), RSS where PSS is not known."""
        n, root = int(row["Robots"]), _num(row.get("ArgosMem(kB)"))
        pss, rss = _num(row.get("Ros2Pss(kB)")), _num(row.get("Ros2Mem(kB)"))
        others, figure = (pss, "PSS") if pss else (rss, "RSS")
        if others is None or root is None or others <= 0:
            return
        self.per_process_mb = others / 1024 / n
        self.base_mb = root / 1024
        self.source = f"{figure} measured at N={n}, {row['executor']} executor"
        self.measured = True


@dataclass
class Sweep:
    world: Path
    ticks: int
    timeout_s: float
    robots_per_domain: Optional[int]         # given on the bench's command line, passed on
    memory_fraction: float
    domains: DomainAllocator
    estimate: MemoryEstimate = field(default_factory=MemoryEstimate)
    calibration: list = field(default_factory=list)
    interrupted: bool = False         # the last run was ended because the sweep was interrupted
    world_robots_per_domain: Optional[int] = None   # the world's multi_process.robots_per_domain

    def command(self, robots: int, mode: str, executor: str, domain: int, out: Path, ticks: int,
                workers: Optional[str] = None) -> list[str]:
        cmd = [sys.executable, "-m", "composed_sim.cli", "run", str(self.world), "--robots", str(robots),
               "--ticks", str(ticks), "--mode", mode, "--executor", executor, "--domain-id", str(domain),
               "--out", str(out), "--json", "--no-progress", "--no-picture"]
        if mode == "multi-process" and self.robots_per_domain:
            cmd += ["--robots-per-domain", str(self.robots_per_domain)]
        if mode == "composed" and workers is not None:
            cmd += ["--workers", workers]
        return cmd

    def one(self, robots: int, mode: str, executor: str, trial: int, ticks: Optional[int] = None,
            workers: Optional[str] = None) -> dict:
        ticks = ticks or self.ticks
        row = {c: None for c in COLUMNS}
        row.update({"Robots": robots, "Repetition": trial, "mode": mode, "executor": executor, "ticks": ticks,
                    "workers": workers if mode == "composed" else None})
        if mode == "multi-process":
            available = available_memory_mb()
            reason = skip_reason(self.estimate.per_process_mb, robots, available, base_mb=self.estimate.base_mb,
                                 fraction=self.memory_fraction, source=self.estimate.source)
            if reason:
                row.update(status="skipped", reason=reason)
                return row
        width = domains_needed(mode, robots, self.robots_per_domain or self.world_robots_per_domain)
        domain = self.domains.take(width)
        if domain is None:
            row.update(status="skipped", reason=f"needs {width} ROS domains from --domain-id {self.domains.base}, "
                                                f"beyond {self.domains.top}")
            return row
        row["domain_id"] = domain
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain), MPLBACKEND="Agg")
        if "ROS_LOCALHOST_ONLY" not in env:
            env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        with tempfile.TemporaryDirectory(prefix="composed-sim-bench-") as tmp:
            m = measure_tree(self.command(robots, mode, executor, domain, Path(tmp), ticks, workers), env=env,
                             timeout_s=self.timeout_s)
        summary = parse_summary(m.stdout)
        wall = m.wall_s
        row.update({
            "WallTime(s)": round(wall, 3), "CPU(%)": round(100 * m.cpu_core_s / wall, 1) if wall > 0 else None,
            "MaxMem(kB)": m.peak_tree_rss_kb, "MaxPss(kB)": m.peak_tree_pss_kb or None,
            "total_wall_s": round(wall, 3), "cpu_core_s": round(m.cpu_core_s, 3),
            "processes": m.max_processes, "exit_code": m.exit_code,
            "other_load_cores": None if m.other_cores is None else round(m.other_cores, 2),
        })
        if mode == "multi-process" and wall > 0:
            row.update({"ArgosCPU(%)": round(100 * m.root_cpu_s / wall, 1),
                        "Ros2CPU(%)": round(100 * max(m.cpu_core_s - m.root_cpu_s, 0.0) / wall, 1),
                        "ArgosMem(kB)": max(m.peak_root_rss_kb, int(1024 * (_num((summary or {}).get("peak_rss_mb")) or 0))),
                        "Ros2Mem(kB)": m.peak_others_rss_kb, "Ros2Pss(kB)": m.peak_others_pss_kb or None})
        if summary:
            phases = summary.get("phases_s") or {}
            row.update({k: _round(summary.get(k), 6) for k in ("setup_s", "ticks_wall_s")})
            row["real_time_factor"] = _round(summary.get("real_time_factor"), 4)
            row["workers_used"] = summary.get("workers") if mode == "composed" else None
            row.update({"per_robot_tick_us": _round(summary.get("per_robot_tick_us"), 2),
                        "violations": summary.get("violations"),
                        **{k: _round(phases.get(k), 6) for k in ("physics_s", "sensing_s", "ros_exchange_s")}})
        notes = []
        if m.interrupted:
            row["status"] = "interrupted"
            notes.append("the sweep was interrupted (Ctrl-C or SIGTERM) during this run")
        elif m.timed_out:
            row["status"] = "timeout"
            notes.append(f"stopped after the {self.timeout_s:g} s timeout")
        elif m.exit_code == 130:        # the run was stopped from outside the bench
            row["status"] = "interrupted"
            notes.append("the run was interrupted from outside the bench (exit code 130)")
        elif m.exit_code != 0:
            row["status"] = "failed"
            notes.append(f"exit code {m.exit_code}")
        elif summary is None:
            row["status"] = "failed"
            notes.append("no JSON summary on stdout")
        elif summary.get("ticks") != ticks:
            row["status"] = "failed"
            notes.append(f"ran {summary.get('ticks')} of {ticks} ticks")
        else:
            row["status"] = "ok"
        if m.leftovers_killed:
            notes.append(f"{m.leftovers_killed} processes outlived the run by {LEFTOVER_GRACE_S:g} s and were killed")
        if row["status"] != "ok" and m.stderr.strip():
            notes.append("stderr: " + _tail(m.stderr))
        row["reason"] = "; ".join(notes) or None
        if mode == "multi-process" and row["status"] == "ok":
            self.estimate.update(row)
        self.interrupted = m.interrupted
        return row

    def calibrate(self, executor: str) -> None:
        """A small multi-process run that measures the per-process cost before bigger ones."""
        row = self.one(CALIBRATION_ROBOTS, "multi-process", executor, 0, ticks=min(self.ticks, 20))
        self.calibration.append(row)


def available_memory_mb() -> float:
    """Available memory, bounded by this process's cgroup limit when there is one."""
    import psutil
    avail = psutil.virtual_memory().available
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            limit = Path(limit_file).read_text().strip()
            usage = int(Path(usage_file).read_text().strip())
        except (OSError, ValueError):
            continue
        if limit.isdigit() and int(limit) < 2**60:
            avail = min(avail, max(int(limit) - usage, 0))
        break
    return avail / 2**20


def _round(v, digits: int):
    x = _num(v)
    return None if x is None else round(x, digits)


def machine_info() -> dict:
    import psutil

    from composed_sim.results import versions
    model = None
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    vm = psutil.virtual_memory()
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    return {
        "cpu_model": model or platform.processor() or platform.machine(),
        "logical_cores": psutil.cpu_count(),
        "physical_cores": psutil.cpu_count(logical=False),
        "memory_total_mb": round(vm.total / 2**20),
        "memory_available_mb_at_start": round(available_memory_mb()),
        "load_average_at_start": load,
        "os": platform.platform(),
        "versions": versions(),
        "commit": _git_commit(),
        "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def _git_commit() -> Optional[str]:
    """HEAD of the checkout the package runs from, if it is one (read-only)."""
    root = Path(__file__).resolve().parent.parent
    if not (root / ".git").exists():
        return None
    try:
        res = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=10, env=dict(os.environ, GIT_OPTIONAL_LOCKS="0"))
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout.strip() or None if res.returncode == 0 else None


def resolve_world(given: Optional[Path]) -> Path:
    """The world to run: as given, else worlds/flocking.yaml of this package's checkout, else of
    the current folder."""
    from composed_sim.command_line import UserError
    if given is not None:
        if not given.is_file():
            raise UserError(f"--world {given}: no such file")
        return given.resolve()
    candidates = [Path(__file__).resolve().parent.parent / "worlds" / "flocking.yaml",
                  Path(__file__).resolve().parent / "data" / "worlds" / "flocking.yaml",
                  Path.cwd() / "worlds" / "flocking.yaml"]
    for c in candidates:
        if c.is_file():
            return c
    raise UserError("no default world found (looked for " + ", ".join(map(str, candidates)) +
                    "); pass --world WORLD.yaml")


def run(args) -> int:
    from composed_sim.command_line import UserError, check_writable
    if args.replot is not None:
        return _replot(args)

    from composed_sim.world.loader import WorldFileError, load_world
    world_path = resolve_world(args.world)
    try:
        world = load_world(world_path, ticks=args.ticks)
    except WorldFileError as e:
        raise UserError(str(e)) from None
    base = args.domain_id
    if base is None:
        text = os.environ.get("ROS_DOMAIN_ID", "0") or "0"
        try:
            base = int(text)
        except ValueError:
            raise UserError(f"ROS_DOMAIN_ID: expected a whole number, got {text!r}") from None
    try:
        domains = DomainAllocator(base)
    except ValueError as e:
        raise UserError(str(e)) from None
    check_writable(args.out)
    if args.report is not None:
        check_writable(args.report.parent / "figures")

    machine = machine_info()
    sweep = Sweep(world=world_path, ticks=args.ticks, timeout_s=args.timeout,
                  robots_per_domain=args.robots_per_domain, memory_fraction=args.memory_fraction,
                  domains=domains,
                  world_robots_per_domain=getattr(getattr(world, "multi_process", None), "robots_per_domain", None))
    plan = [(n, trial, mode, executor, workers) for n in args.sizes for trial in range(1, args.trials + 1)
            for mode in args.modes for executor in args.executors
            for workers in (args.workers if mode == "composed" else (None,))]
    settings = {"sizes": list(args.sizes), "modes": list(args.modes), "executors": list(args.executors),
                "workers": list(args.workers),
                "trials": args.trials, "ticks": args.ticks, "world": str(world_path), "world_name": world.name,
                "tick_s": world.tick_s, "timeout_s": args.timeout, "domain_base": base,
                "robots_per_domain": args.robots_per_domain, "memory_fraction": args.memory_fraction}
    command = command_line(args)
    print(f"bench: {len(plan)} runs of {world_path.name} ({args.ticks} ticks each) → {args.out}/", file=sys.stderr)

    rows: list[dict] = []
    interrupted = False
    t_start = time.perf_counter()
    old_term = _sigterm_interrupts()
    try:
        for i, (n, trial, mode, executor, workers) in enumerate(plan, 1):
            first_multi = mode == "multi-process" and not any(r["mode"] == mode for r in rows)
            if first_multi and n > CALIBRATION_ABOVE:
                print(f"bench: calibrating the multi-process memory cost with {CALIBRATION_ROBOTS} robots",
                      file=sys.stderr)
                sweep.calibrate(executor)
                cal = sweep.calibration[-1]
                print(f"bench: calibration {cal['status']}: {sweep.estimate.per_process_mb:.1f} MB per process "
                      f"({sweep.estimate.source})" + (f" — {cal['reason']}" if cal["reason"] else ""), file=sys.stderr)
                if sweep.interrupted:
                    interrupted = True
                    break
            row = sweep.one(n, mode, executor, trial, workers=workers)
            rows.append(row)
            print(_progress_line(i, len(plan), row, args.trials), file=sys.stderr)
            if sweep.interrupted:
                interrupted = True
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
    elapsed = time.perf_counter() - t_start

    doc = {"command": command, "machine": machine, "settings": settings, "elapsed_s": round(elapsed, 1),
           "interrupted": interrupted,
           "memory_estimate": {"per_process_mb": round(sweep.estimate.per_process_mb, 2),
                               "base_mb": round(sweep.estimate.base_mb, 1), "source": sweep.estimate.source},
           "calibration_runs": sweep.calibration, "columns": list(COLUMNS), "rows": rows}
    write_outputs(doc, args.out, args.report)
    bad = [r for r in rows if r["status"] not in ("ok", "skipped")]
    print(f"bench: {len(rows)} runs in {elapsed:.0f} s: "
          + ", ".join(f"{s} {sum(r['status'] == s for r in rows)}" for s in sorted({r['status'] for r in rows}))
          + f"; results in {args.out}/" + (f", report {args.report}" if args.report else ""), file=sys.stderr)
    if interrupted:
        return 130
    return 1 if bad else 0


def _sigterm_interrupts():
    """SIGTERM stops the sweep like Ctrl-C: the current run is ended, what ran so far is written.
    Returns the previous handler (None when not on the main thread, where it cannot be set)."""
    def handle(signum, frame):
        raise KeyboardInterrupt
    try:
        return signal.signal(signal.SIGTERM, handle)
    except ValueError:
        return None


def _progress_line(i: int, total: int, row: dict, trials: int) -> str:
    head = (f"bench [{i}/{total}] N={row['Robots']} {host_label(row)} {row['executor']} "
            f"trial {row['Repetition']}/{trials}: {row['status']}")
    if row["WallTime(s)"] is not None:
        head += f", wall {row['WallTime(s)']:.1f} s"
        if row["setup_s"] is not None:
            head += f" (setup {row['setup_s']:.1f} s, ticks {row['ticks_wall_s']:.1f} s)"
        head += f", CPU {row['CPU(%)']:.0f} %, peak {row['MaxMem(kB)'] / 1024:.0f} MB"
    if row["status"] != "ok" and row["reason"]:
        reason = row["reason"]
        head += f" — {reason if len(reason) <= 300 else '…' + reason[-300:]}"
    return head


def _replot(args) -> int:
    from composed_sim.command_line import UserError, check_writable
    try:
        doc = json.loads(args.replot.read_text())
        doc["rows"], doc["machine"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise UserError(f"--replot {args.replot}: not a runs.json of composed-sim bench ({e})") from None
    check_writable(args.out)
    if args.report is not None:
        check_writable(args.report.parent / "figures")
    write_outputs(doc, args.out, args.report)
    print(f"bench: redrew {len(doc['rows'])} runs from {args.replot} into {args.out}/"
          + (f" and {args.report}" if args.report else ""), file=sys.stderr)
    return 0


# ---------------------------------------------------------------------------------------------
# Outputs

def write_outputs(doc: dict, out: Path, report: Optional[Path]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_csv(doc["rows"], out / "runs.csv")
    (out / "runs.json").write_text(json.dumps(doc, indent=2) + "\n")
    figures = plot_figures(doc, out)
    if report is not None:
        import shutil
        fig_dir = report.parent / "figures"
        fig_dir.mkdir(parents=True, exist_ok=True)
        stem = report.stem
        copied = {}
        for key, path in figures.items():
            target = fig_dir / f"{stem}_{path.name}"
            shutil.copyfile(path, target)
            copied[key] = target
        shutil.copyfile(out / "runs.csv", fig_dir / f"{stem}_runs.csv")
        shutil.copyfile(out / "runs.json", fig_dir / f"{stem}_runs.json")
        report.write_text(render_report(doc, {k: p.relative_to(report.parent) for k, p in copied.items()},
                                        raw=(Path("figures") / f"{stem}_runs.csv", Path("figures") / f"{stem}_runs.json"),
                                        report=report))


def write_csv(rows: list[dict], path: Path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(COLUMNS), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in COLUMNS})


def _series_style(mode: str, workers: str, executor: str) -> dict:
    """Colour by executor; composed in one process solid, with workers dash-dotted, multi-process dashed."""
    colors = {"multi-threaded": "tab:blue", "single-threaded": "tab:orange", "events": "tab:green",
              "lockstep": "tab:red"}
    one_process = mode == "composed" and workers in ("", "1")
    linestyle = "-" if one_process else "-." if mode == "composed" else "--"
    return {"color": colors.get(executor, "tab:purple"), "linestyle": linestyle,
            "marker": "o" if one_process else "D" if mode == "composed" else "s"}


def plot_figures(doc: dict, out: Path) -> dict[str, Path]:
    """wall_time.png, cpu.png, memory.png: medians of our ok runs per mode/executor and the paper's
    means, against N on log-log axes."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agg = aggregate(doc["rows"])
    settings, machine = doc.get("settings", {}), doc["machine"]
    ticks = settings.get("ticks", 600)
    sim_s = ticks * settings.get("tick_s", 0.1)
    paper = {k: load_paper_results(f) for k, (f, _) in PAPER_VARIANTS.items()}
    cores = machine.get("logical_cores") or 0
    footer = (f"this machine: {machine.get('cpu_model')}, {machine.get('logical_cores')} logical cores, "
              f"{machine.get('memory_total_mb', 0) / 1024:.0f} GB, {machine.get('date', '')[:10]}; "
              f"{ticks} ticks per run; median of ok trials.  Paper: mean of 10 trials, 600 ticks, "
              f"12-core Ryzen 9 7900")
    specs = {
        "wall_time": ("WallTime(s)", 1.0, "wall time (s)", f"Wall time of {sim_s:g} s of simulated time"),
        "cpu": ("CPU(%)", 1.0, "CPU (% of one core)", "CPU use of the whole process tree"),
        "memory": ("MaxPss(kB)", 1 / 1024, "peak PSS (MB)", "Peak memory of the whole process tree (PSS)"),
    }
    written = {}
    for key, (col, scale, ylabel, title) in specs.items():
        fig, ax = plt.subplots(figsize=(7.5, 5.2), dpi=110)
        for pkey, (_, label) in PAPER_VARIANTS.items():
            ns = sorted(paper[pkey])
            paper_col = "MaxMem(kB)" if col == "MaxPss(kB)" else col     # the paper measured RSS
            ax.plot(ns, [paper[pkey][n][paper_col] * scale for n in ns], color="black" if pkey == "single" else "dimgrey",
                    linestyle=":", marker="^" if pkey == "single" else "v", label=label)
        series: dict[tuple, list] = {}
        for a in agg:
            value = a[col] if a[col] is not None or col != "MaxPss(kB)" else a["MaxMem(kB)"]   # older rows: RSS
            if value is not None:
                series.setdefault((a["mode"], a["workers"], a["executor"]), []).append(
                    (a["Robots"], value * scale, saturated(a, cores)))
        any_saturated = False
        for (mode, workers, executor), pts in series.items():
            xs, ys, sat = zip(*sorted(pts))
            style = _series_style(mode, workers, executor)
            label = host_label({"mode": mode, "workers": workers})
            ax.plot(xs, ys, label=f"{label}, {executor}", **style)
            hollow = [(x, y) for x, y, s in zip(xs, ys, sat) if s]
            if hollow:          # the machine was saturated: times are upper bounds
                any_saturated = True
                ax.plot(*zip(*hollow), linestyle="none", marker=style["marker"], markerfacecolor="white",
                        markeredgecolor=style["color"], markersize=7)
        if any_saturated:
            ax.plot([], [], linestyle="none", marker="o", markerfacecolor="white", markeredgecolor="grey",
                    label="hollow: machine saturated during the run")
        if key == "wall_time":
            ax.axhline(sim_s, color="black", linestyle="--", linewidth=1, label=f"real time ({sim_s:g} s)")
        if key == "memory" and machine.get("memory_total_mb"):
            ax.axhline(machine["memory_total_mb"], color="firebrick", linestyle="-.", linewidth=0.8,
                       label="this machine's memory")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("robots N")
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
        fig.text(0.01, 0.005, footer, fontsize=5.5, color="dimgrey")
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        path = out / FIGURES[key]
        fig.savefig(path)
        plt.close(fig)
        written[key] = path
    return written


def _f(v, digits: int = 1, scale: float = 1.0) -> str:
    x = _num(v)
    return "–" if x is None else f"{x * scale:,.{digits}f}"


def _ratio(a, b, digits: int = 2) -> str:
    x, y = _num(a), _num(b)
    return "–" if x is None or y is None or y == 0 else f"{x / y:.{digits}g}" if x / y < 0.01 else f"{x / y:.{digits}f}"


# The performance budget for composed mode (docs/speed.md), 600 ticks of the flocking world:
# N -> limits (None: no limit stated; the run must complete).
BUDGET = {1280: {"ticks_wall_s": 60.0, "MaxMem(kB)": 1.5 * 2**20, "setup_s": 15.0},
          10240: {"ticks_wall_s": None, "MaxMem(kB)": 12 * 2**20, "setup_s": 120.0}}
# … and linear scaling: the cost per robot-tick at the larger N within this factor of the smaller's.
SCALING = (80, 1280, 1.5)


SATURATED = 0.95   # share of the machine's cores busy (the run's + others') above which a run is flagged


def saturated(rec: dict, cores: int) -> bool:
    """Whether the machine's cores were all busy during a run (or the median of runs): its CPU % of
    one core / 100 + the other load >= SATURATED × cores."""
    cpu, other = _num(rec.get("CPU(%)")), _num(rec.get("other_load_cores"))
    if cpu is None or other is None or cores < 1:
        return False
    return cpu / 100 + other >= SATURATED * cores


def _budget_section(agg: list[dict], rows: list[dict]) -> list[str]:
    lines = ["", "## Against the design budget (composed mode, 600 ticks)", ""]
    checked = [a for a in agg if a["mode"] == "composed" and a["Robots"] in BUDGET]
    if not checked:
        return lines + ["The budget is stated at N = " + " and ".join(map(str, BUDGET)) +
                        "; this sweep ran neither."]
    lines += ["| N | host | executor | ticks wall s | limit | setup s | limit | peak PSS MB | limit | verdict |",
              "|---:|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for a in checked:
        limits = BUDGET[a["Robots"]]
        ticks_ok = {r.get("ticks") for r in rows if r["Robots"] == a["Robots"]} == {600}
        misses = []
        if not a["ok"]:
            misses.append("did not complete")
        # The ticks limit is for 600 ticks: a shorter sweep is judged on set-up and memory only.
        for key, label in ((("ticks_wall_s", "ticks wall"),) if ticks_ok else ()) + (
                ("setup_s", "setup"), ("MaxMem(kB)", "peak memory")):
            lim, val = limits[key], _num(a[key] if key != "MaxMem(kB)" else a["MaxPss(kB)"] or a[key])
            if lim is not None and val is not None and val > lim:
                misses.append(label)
        verdict = "over: " + ", ".join(misses) if misses else (
            "within budget" if ticks_ok else "set-up and memory within budget")
        if not ticks_ok:
            verdict += "; ticks not judged (not 600 ticks)"
        lim = lambda k, d, sc=1.0: "–" if limits[k] is None else f"≤ {limits[k] * sc:,.{d}f}"
        lines.append(f"| {a['Robots']} | {host_label(a)} | {a['executor']} | {_f(a['ticks_wall_s'], 1)} "
                     f"| {lim('ticks_wall_s', 0)} | {_f(a['setup_s'], 1)} | {lim('setup_s', 0)} "
                     f"| {_f(a['MaxPss(kB)'] or a['MaxMem(kB)'], 0, 1 / 1024)} "
                     f"| {lim('MaxMem(kB)', 0, 1 / 1024)} | {verdict} |")
    small, large, factor = SCALING
    for workers, executor in dict.fromkeys((a["workers"], a["executor"]) for a in agg if a["mode"] == "composed"):
        cost = {a["Robots"]: _num(a["per_robot_tick_us"]) for a in agg if a["mode"] == "composed"
                and a["executor"] == executor and a["workers"] == workers and a["ok"]}
        if cost.get(small) and cost.get(large):
            ratio = cost[large] / cost[small]
            label = host_label({"mode": "composed", "workers": workers})
            lines.append(f"\nScaling, {label}, {executor}: a robot-tick costs {cost[large]:.0f} µs at N = {large} and "
                         f"{cost[small]:.0f} µs at N = {small}: {ratio:.2f}× (limit ≤ {factor}×, "
                         f"{'within' if ratio <= factor else 'over'}).")
    return lines


def _workers_section(by: dict) -> list[str]:
    """Worker processes against one process: same N and executor, this run."""
    pairs = sorted((n, w, e) for (n, mode, w, e) in by
                   if mode == "composed" and w not in ("", "1") and (n, "composed", "1", e) in by
                   and by[(n, mode, w, e)]["ok"] and by[(n, "composed", "1", e)]["ok"])
    if not pairs:
        return []
    lines = ["", "## Worker processes / one process (same executor, this run)", "",
             "Below 1 means the workers need less. CPU: % of one core during the whole run.", "",
             "| N | workers | executor | ticks wall | total wall | setup s (1 → K) | CPU % (1 → K) | peak PSS MB (1 → K) |",
             "|---:|---|---|---:|---:|---:|---:|---:|"]
    for n, w, e in pairs:
        k, one = by[(n, "composed", w, e)], by[(n, "composed", "1", e)]
        lines.append(f"| {n} | {host_label(k).removeprefix('composed, ')} | {e} | {_ratio(k['ticks_wall_s'], one['ticks_wall_s'])} "
                     f"| {_ratio(k['total_wall_s'], one['total_wall_s'])} | {_f(one['setup_s'], 1)} → {_f(k['setup_s'], 1)} "
                     f"| {_f(one['CPU(%)'], 0)} → {_f(k['CPU(%)'], 0)} "
                     f"| {_f(one['MaxPss(kB)'], 0, 1 / 1024)} → {_f(k['MaxPss(kB)'], 0, 1 / 1024)} |")
    return lines


def render_report(doc: dict, figures: dict[str, Path], raw: tuple[Path, Path], report: Path) -> str:
    """The markdown report; ``figures`` and ``raw`` (csv, json) are paths relative to its folder."""
    m, s = doc["machine"], doc.get("settings", {})
    rows = doc["rows"]
    agg = aggregate(rows)
    ticks = s.get("ticks", 600)
    sim_s = ticks * s.get("tick_s", 0.1)
    v = m.get("versions", {})
    load = m.get("load_average_at_start")
    lines = [
        "# Benchmarks",
        "",
        f"Generated by `composed-sim bench` on {m.get('date')} from the runs below; do not edit by hand, "
        "re-run the command to regenerate it.",
        *(["", "Where a tick's time goes, profiled, and the speed work behind these figures: [speed.md](speed.md)."]
          if (report.parent / "speed.md").exists() else []),
        "",
        "## Machine",
        "",
        f"- CPU: {m.get('cpu_model')}, {m.get('logical_cores')} logical cores ({m.get('physical_cores')} physical)",
        f"- memory: {m.get('memory_total_mb', 0) / 1024:.1f} GB, {m.get('memory_available_mb_at_start', 0) / 1024:.1f} GB "
        "available at the start",
        f"- load average at the start: {', '.join(map(str, load)) if load else 'unknown'} (the machine is shared: "
        "compare ratios within this run, not absolute numbers across runs)",
        f"- {m.get('os')}; Python {v.get('python')}, rclpy {v.get('ros-jazzy-rclpy') or v.get('ros-rclpy')}, "
        f"rmw_fastrtps_cpp {v.get('ros-rmw-fastrtps-cpp')}, composed_sim {v.get('composed_sim')}"
        + (f", commit {m['commit']} (the tree may hold uncommitted changes)" if m.get("commit") else ""),
        "",
        "## Command",
        "",
        "```bash",
        doc.get("command", "composed-sim bench"),
        "```",
        "",
        f"{len(rows)} runs in {doc.get('elapsed_s', 0):.0f} s, each a `composed-sim run {Path(s.get('world', 'world')).name} "
        f"--ticks {ticks} --json` subprocess on its own ROS domain; raw rows: [{raw[0].name}]({raw[0].as_posix()}), "
        f"[{raw[1].name}]({raw[1].as_posix()}); `composed-sim bench --replot "
        f"{(report.parent / raw[1]).as_posix()} --report {report.as_posix()}` redraws the figures and this report from them.",
        "",
        f"## Results (median over the ok trials; {ticks} ticks = {sim_s:g} s simulated)",
        "",
        "| N | host | executor | ok/trials | setup s | ticks wall s | total wall s | real-time factor "
        "| µs / robot-tick | CPU % of one core | CPU core-s | peak tree PSS MB | peak tree RSS MB | violations "
        "| other load (cores) |",
        "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    cores = m.get("logical_cores") or 0
    any_saturated = False
    for a in agg:
        mark = " †" if saturated(a, cores) else ""
        any_saturated = any_saturated or bool(mark)
        lines.append(
            f"| {a['Robots']} | {host_label(a)} | {a['executor']} | {a['ok']}/{a['trials']} | {_f(a['setup_s'], 2)} "
            f"| {_f(a['ticks_wall_s'], 1)} | {_f(a['total_wall_s'], 1)}{mark} | {_f(a['real_time_factor'], 2)} "
            f"| {_f(a['per_robot_tick_us'], 0)} | {_f(a['CPU(%)'], 0)} | {_f(a['cpu_core_s'], 1)} "
            f"| {_f(a['MaxPss(kB)'], 0, 1 / 1024)} | {_f(a['MaxMem(kB)'], 0, 1 / 1024)} "
            f"| {'–' if a['violations'] is None else a['violations']} "
            f"| {_f(a['other_load_cores'], 2)} |")
    if any_saturated:
        lines += ["", f"† the machine was saturated during the run: its own CPU plus the other load reached "
                      f"{SATURATED:.0%} of the {cores} cores, so the run may have waited for a core and its times "
                      "are upper bounds."]
    odd = [r for r in rows if r["status"] != "ok"]
    if odd:
        lines += ["", "Runs skipped or not completed:", ""]
        for r in odd:
            lines.append(f"- N={r['Robots']} {host_label(r)} {r['executor']} trial {r['Repetition']}: "
                         f"**{r['status']}** — {str(r.get('reason') or '').replace('|', '/')[:400]}")
    est = doc.get("memory_estimate")
    if "multi-process" in s.get("modes", []) and est:
        lines += ["", f"Multi-process skip rule: predicted memory = simulator {est['base_mb']:.0f} MB + N × "
                      f"{est['per_process_mb']:.1f} MB per controller process ({est['source']}); a run is skipped "
                      f"when that exceeds {s.get('memory_fraction', DEFAULT_MEMORY_FRACTION):.0%} of the available memory."]

    # composed / multi-process, same executor, same sweep
    by = {(a["Robots"], a["mode"], a["workers"], a["executor"]): a for a in agg}
    pairs = [(n, w, e) for (n, mode, w, e) in by if mode == "composed" and (n, "multi-process", "", e) in by
             and by[(n, "multi-process", "", e)]["ok"] and by[(n, mode, w, e)]["ok"]]
    lines += _budget_section(agg, rows)
    lines += _workers_section(by)
    lines += ["", "## Composed / multi-process (same executor, this run)", ""]
    if pairs:
        lines += ["Below 1 means the composed host needs less. Memory: peak PSS of each whole process tree.", "",
                  "| N | composed host | executor | total wall | ticks wall | CPU core-s | peak memory |",
                  "|---:|---|---|---:|---:|---:|---:|"]
        for n, w, e in sorted(pairs):
            c, p = by[(n, "composed", w, e)], by[(n, "multi-process", "", e)]
            lines.append(f"| {n} | {host_label(c)} | {e} | {_ratio(c['total_wall_s'], p['total_wall_s'])} | "
                         f"{_ratio(c['ticks_wall_s'], p['ticks_wall_s'])} | {_ratio(c['cpu_core_s'], p['cpu_core_s'])} | "
                         f"{_ratio(c['MaxPss(kB)'] or c['MaxMem(kB)'], p['MaxPss(kB)'] or p['MaxMem(kB)'])} |")
    elif "multi-process" not in s.get("modes", []):
        lines.append("Multi-process mode was not part of this sweep.")
    else:
        lines.append("No swarm size where both modes completed in this sweep.")

    # composed / paper
    paper = {k: load_paper_results(f) for k, (f, _) in PAPER_VARIANTS.items()}
    lines += ["", "## Ours / the paper", "",
              "The paper's means over 10 trials (ARGoS with the ROS 2 bridge, one process per controller, "
              "Ryzen 9 7900 with 12 cores; columns WallTime(s), CPU(%), MaxMem(kB) of its CSVs) against our "
              "medians. ÷1t: ours / paper single-threaded; ÷12t: ours / paper multi-threaded. Below 1 means we need less."]
    if ticks != 600:
        lines.append(f"**These runs had {ticks} ticks, the paper's 600: the wall-time and CPU ratios are not comparable.**")
    lines += ["", "| N | host | executor | wall s | ÷1t | ÷12t | CPU % | ÷1t | ÷12t | peak RSS MB | ÷1t | ÷12t |",
              "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    any_paper = False
    for a in agg:
        p1, p12 = paper["single"].get(a["Robots"], {}), paper["multi"].get(a["Robots"], {})
        if not a["ok"] or not (p1 or p12):
            continue
        any_paper = True
        cells = []
        for col, digits, scale in (("WallTime(s)", 1, 1.0), ("CPU(%)", 0, 1.0), ("MaxMem(kB)", 0, 1 / 1024)):
            cells += [_f(a[col], digits, scale), _ratio(a[col], p1.get(col)), _ratio(a[col], p12.get(col))]
        lines.append(f"| {a['Robots']} | {host_label(a)} | {a['executor']} | " + " | ".join(cells) + " |")
    if not any_paper:
        lines.append("| – | no swarm size of this sweep is in the paper's results | | | | | | | | | | |")
    lines += ["", "The paper's own numbers, for reference:", "",
              "| N | wall s 1t | wall s 12t | CPU % 1t | CPU % 12t | peak MB 1t | peak MB 12t |",
              "|---:|---:|---:|---:|---:|---:|---:|"]
    for n in sorted(set(paper["single"]) | set(paper["multi"])):
        p1, p12 = paper["single"].get(n, {}), paper["multi"].get(n, {})
        lines.append(f"| {n} | {_f(p1.get('WallTime(s)'), 1)} | {_f(p12.get('WallTime(s)'), 1)} | "
                     f"{_f(p1.get('CPU(%)'), 0)} | {_f(p12.get('CPU(%)'), 0)} | {_f(p1.get('MaxMem(kB)'), 0, 1 / 1024)} | "
                     f"{_f(p12.get('MaxMem(kB)'), 0, 1 / 1024)} |")

    lines += ["", "## Figures", "",
              f"Medians of our ok runs per host and executor (composed in one process solid, with worker processes "
              f"dash-dotted, multi-process dashed; memory as PSS), the paper's "
              f"means (dotted), log-log against N; the wall-time plot has the real-time line at {sim_s:g} s.", ""]
    for key, label in (("wall_time", "wall time"), ("cpu", "CPU"), ("memory", "memory")):
        if key in figures:
            lines.append(f"![{label} against N]({figures[key].as_posix()})")
            lines.append("")
    lines += [
        "## What is measured",
        "",
        "- **total wall** (`WallTime(s)`): from spawning `composed-sim run` to its exit: interpreter start, imports, "
        "setup, the ticks, writing the results, as the paper timed a whole run. **setup** and **ticks wall** come from "
        "the run's own summary; **real-time factor** = simulated time / ticks wall.",
        "- **CPU** (`CPU(%)`): core-seconds of the whole process tree / total wall × 100, so 100 % is one core busy "
        "(the paper's convention); processes that exit between samples count up to their last sample, and the "
        "root's exact times and those of the children it reaped are read at its exit.",
        f"- **peak memory** (`MaxMem(kB)`): the largest sum of the resident sets of every process of the tree over "
        f"samples every {SAMPLE_S:g} s (pages shared between processes count once per process, so multi-process "
        "totals are upper bounds).",
        "- **peak PSS** (`MaxPss(kB)`): the same peak over the proportional set sizes (each shared page divided "
        f"among the processes mapping it, sampled every {PSS_SAMPLE_S:g} s): what the tree really occupies; the "
        "multi-process skip rule predicts with it.",
        "- **other load**: core-seconds the machine spent busy outside the run's process tree during it, / total "
        "wall: how much a neighbour (including the bench itself) competed for the cores.",
        "- The paper's `MaxMem` is `ArgosMem + Ros2Mem`, and its `Ros2Mem` stays between 37 MB (10 robots) and "
        "108 MB (1280 robots): it cannot hold every controller process's memory, so it likely counts one process "
        "of the ROS side, and the paper's memory curve leaves most of its controller processes out.",
    ]
    return "\n".join(lines) + "\n"
