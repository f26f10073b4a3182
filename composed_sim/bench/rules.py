"""The bench's fixed facts and pure rules: the paper's sizes and columns, the memory skip rule,
ROS domains per run, aggregation of trials."""
from __future__ import annotations

import csv
import math
import statistics
from pathlib import Path
from typing import Iterable, Optional

from composed_sim.hosting import EXECUTORS  # also the report's order of them
from composed_sim.hosts.settings import MODES
from composed_sim.world.schema import MAX_DOMAIN, ROBOTS_PER_DOMAIN


PAPER_SIZES = (3, 5, 10, 20, 40, 80, 160, 320, 640, 1280)

# The paper's CSV columns, in its order, filled with our measurements (see the module docstring).
# ArgosCPU/ArgosMem: the run's root process (the simulator); Ros2CPU/Ros2Mem: every other process
# of its tree (the controllers). Only filled in multi-process mode: in composed mode one process
# is both sides and cannot be split.
PAPER_COLUMNS = ("Robots", "Repetition", "WallTime(s)", "CPU(%)", "MaxMem(kB)",
                 "ArgosCPU(%)", "Ros2CPU(%)", "ArgosMem(kB)", "Ros2Mem(kB)")
OUR_COLUMNS = ("mode", "workers", "workers_used", "executor", "status", "ticks", "setup_s", "ticks_wall_s", "total_wall_s",
               "cpu_core_s", "real_time_factor", "per_robot_tick_us", "violations",
               "physics_s", "sensing_s", "ros_exchange_s", "processes", "other_load_cores", "domain_id",
               "exit_code", "reason", "MaxPss(kB)", "Ros2Pss(kB)", "experiment",
               "host_cost_per_robot_tick_us", "node_code_per_robot_tick_us")
# The main process's time per tick, by phase, as a run's summary.json gives it (phases_per_tick_ms);
# serial = everything but waiting (for the nodes' answers). One column each: phase_<name>_ms.
PHASES = ("physics", "sensing", "sending_frames", "waiting", "gathering_answers", "loop_functions", "recording",
          "other", "serial")
PHASE_COLUMNS = tuple(f"phase_{p}_ms" for p in PHASES)
COLUMNS = PAPER_COLUMNS + OUR_COLUMNS + PHASE_COLUMNS
# workers: composed mode's --workers as asked ("1", "auto", "4"), empty in multi-process mode;
# workers_used: what the run used (auto's choice). Ros2Pss(kB): the PSS of every process but the root.
# status: ok | skipped | failed (non-zero exit or no summary) | timeout | interrupted
# experiment: the bench experiment (bench/experiments.py) or the --world file's stem; older sweeps'
# rows have none (bench/experiments.experiment_name names them).
# host_cost_per_robot_tick_us, node_code_per_robot_tick_us: from the run's summary, when it has them.
# other_load_cores: cores kept busy by everything outside the run's tree during it, on average (the
# machine is shared: a run next to a busy neighbour is slower, and this says so).

DEFAULT_TIMEOUT_S = 3600.0
DEFAULT_MEMORY_FRACTION = 0.8
FALLBACK_PROCESS_MB = 70.0       # docs/architecture.md: one rclpy process with a node, until measured
CALIBRATION_ROBOTS = 3           # dedicated multi-process run measuring the per-process cost …
CALIBRATION_ABOVE = 10           # … when the sweep's first multi-process size is larger than this
SAFE_DOMAIN_MAX = 101            # ROS 2 on Linux: domains 0..101 never reach the ephemeral ports

SATURATED = 0.95   # share of the machine's cores busy (the run's + others') above which a run is flagged

FIGURES = {"wall_time": "wall_time.png", "cpu": "cpu.png", "memory": "memory.png"}


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


def saturated(rec: dict, cores: int) -> bool:
    """Whether the machine's cores were all busy during a run (or the median of runs): its CPU % of
    one core / 100 + the other load >= SATURATED × cores."""
    cpu, other = as_number(rec.get("CPU(%)")), as_number(rec.get("other_load_cores"))
    if cpu is None or other is None or cores < 1:
        return False
    return cpu / 100 + other >= SATURATED * cores


def as_number(v) -> Optional[float]:
    if v is None or v == "":
        return None
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


MEDIAN_FIELDS = ("WallTime(s)", "CPU(%)", "MaxMem(kB)", "MaxPss(kB)", "workers_used", "setup_s", "ticks_wall_s", "total_wall_s",
                 "cpu_core_s", "real_time_factor", "per_robot_tick_us", "processes", "other_load_cores",
                 "host_cost_per_robot_tick_us", "node_code_per_robot_tick_us") + PHASE_COLUMNS


def aggregate(rows: Iterable[dict], settings: Optional[dict] = None) -> list[dict]:
    """One record per (experiment, Robots, mode, workers, executor): medians over the ok trials,
    counts of all trials; experiments in the order of their first row. ``settings``: the sweep's,
    which names the experiment of rows from before experiments (see experiment_name)."""
    from composed_sim.bench.experiments import experiment_name
    groups: dict[tuple, list[dict]] = {}
    first_seen: dict[str, int] = {}
    for r in rows:
        workers = "" if r.get("workers") is None else str(r["workers"])
        experiment = experiment_name(r, settings or {})
        first_seen.setdefault(experiment, len(first_seen))
        groups.setdefault((experiment, int(r["Robots"]), r["mode"], workers, r["executor"]), []).append(r)
    out = []
    def order(key: tuple) -> tuple:
        experiment, n, mode, workers, executor = key
        return (first_seen[experiment], n, MODES.index(mode) if mode in MODES else len(MODES),
                (0, int(workers)) if workers.isdigit() else (1, 0),
                EXECUTORS.index(executor) if executor in EXECUTORS else len(EXECUTORS), executor)

    for (experiment, n, mode, workers, executor), recs in sorted(groups.items(), key=lambda kv: order(kv[0])):
        ok = [r for r in recs if r["status"] == "ok"]
        agg = {"experiment": experiment, "Robots": n, "mode": mode, "workers": workers, "executor": executor,
               "trials": len(recs), "ok": len(ok), "statuses": sorted({r["status"] for r in recs})}
        for k in MEDIAN_FIELDS:
            vals = [x for x in (as_number(r.get(k)) for r in ok) if x is not None]
            agg[k] = statistics.median(vals) if vals else None
        viol = [as_number(r.get("violations")) for r in ok]
        agg["violations"] = int(max(v for v in viol if v is not None)) if any(v is not None for v in viol) else None
        out.append(agg)
    return out


def host_label(rec: dict) -> str:
    """How a row's or record's controllers were hosted: "composed, 1 process", "composed, workers
    auto (8)", "multi-process"."""
    if rec["mode"] != "composed":
        return rec["mode"]
    workers, used = str(rec.get("workers") or "1"), as_number(rec.get("workers_used"))
    if workers == "1":
        return "composed, 1 process"
    return f"composed, workers {workers}" + (f" ({used:.0f})" if workers == "auto" and used else "")
