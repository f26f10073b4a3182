"""The sweep: every (size, mode, workers, executor, trial) run as its own ``composed-sim run``
subprocess, in domains no earlier run used, skipped when it would not fit in memory."""
from __future__ import annotations

import os
import signal
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from composed_sim.bench.arguments import BenchSettings, command_line
from composed_sim.bench.machine import available_memory_mb, machine_info
from composed_sim.bench.experiments import DEFAULT_EXPERIMENT, EXPERIMENTS, experiment_of_world, shipped_world
from composed_sim.bench.replot import replot
from composed_sim.bench.report import write_outputs
from composed_sim.bench.rules import (CALIBRATION_ABOVE, CALIBRATION_ROBOTS, COLUMNS, FALLBACK_PROCESS_MB, PHASE_COLUMNS,
                                      PHASES, DomainAllocator, as_number, domains_needed, host_label, skip_reason)
from composed_sim.bench.tree import LEFTOVER_GRACE_S, TreeMeasurement, measure_tree, parse_summary, tail
from composed_sim.hosts.settings import AUTO_WORKERS, HostSettings, environment_domain



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
        n, root = int(row["Robots"]), as_number(row.get("ArgosMem(kB)"))
        pss, rss = as_number(row.get("Ros2Pss(kB)")), as_number(row.get("Ros2Mem(kB)"))
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
    experiment: str                          # its rows' experiment (bench/experiments.py)
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
        hosting = HostSettings(mode=mode, executor=executor, domain_id=domain, domain_given=True,
                               workers=workers or AUTO_WORKERS, robots_per_domain=self.robots_per_domain or None)
        return [sys.executable, "-m", "composed_sim.cli", "run", str(self.world), "--robots", str(robots),
                "--ticks", str(ticks), *hosting.argv(), "--out", str(out), "--json", "--no-progress", "--no-picture"]

    def one(self, robots: int, mode: str, executor: str, trial: int, ticks: Optional[int] = None,
            workers: Optional[str] = None) -> dict:
        ticks = ticks or self.ticks
        row = {c: None for c in COLUMNS}
        row.update({"experiment": self.experiment, "Robots": robots, "Repetition": trial, "mode": mode,
                    "executor": executor, "ticks": ticks,
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
        m = self.measure(robots, mode, executor, domain, ticks, workers)
        summary = parse_summary(m.stdout)
        row.update(measured_columns(m, mode, summary))
        if summary:
            row.update(summary_columns(summary, mode))
        row["status"], notes = self.outcome(m, summary, ticks)
        row["reason"] = "; ".join(notes) or None
        if mode == "multi-process" and row["status"] == "ok":
            self.estimate.update(row)
        self.interrupted = m.interrupted
        return row

    def measure(self, robots: int, mode: str, executor: str, domain: int, ticks: int,
                workers: Optional[str]) -> TreeMeasurement:
        """One run, its process tree measured, on ROS domain ``domain``, writing into a folder
        removed after it."""
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain), MPLBACKEND="Agg")
        if "ROS_LOCALHOST_ONLY" not in env:
            env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        with tempfile.TemporaryDirectory(prefix="composed-sim-bench-") as tmp:
            return measure_tree(self.command(robots, mode, executor, domain, Path(tmp), ticks, workers), env=env,
                                timeout_s=self.timeout_s)

    def outcome(self, m: TreeMeasurement, summary: Optional[dict], ticks: int) -> tuple[str, list[str]]:
        """A measured run's status (ok, failed, timeout, interrupted) and the notes that explain it."""
        notes = []
        if m.interrupted:
            status = "interrupted"
            notes.append("the sweep was interrupted (Ctrl-C or SIGTERM) during this run")
        elif m.timed_out:
            status = "timeout"
            notes.append(f"stopped after the {self.timeout_s:g} s timeout")
        elif m.exit_code == 130:        # the run was stopped from outside the bench
            status = "interrupted"
            notes.append("the run was interrupted from outside the bench (exit code 130)")
        elif m.exit_code != 0:
            status = "failed"
            notes.append(f"exit code {m.exit_code}")
        elif summary is None:
            status = "failed"
            notes.append("no JSON summary on stdout")
        elif summary.get("ticks") != ticks:
            status = "failed"
            notes.append(f"ran {summary.get('ticks')} of {ticks} ticks")
        else:
            status = "ok"
        if m.leftovers_killed:
            notes.append(f"{m.leftovers_killed} processes outlived the run by {LEFTOVER_GRACE_S:g} s and were killed")
        if status != "ok" and m.stderr.strip():
            notes.append("stderr: " + tail(m.stderr))
        return status, notes

    def calibrate(self, executor: str) -> None:
        """A small multi-process run that measures the per-process cost before bigger ones."""
        row = self.one(CALIBRATION_ROBOTS, "multi-process", executor, 0, ticks=min(self.ticks, 20))
        self.calibration.append(row)


def measured_columns(m: TreeMeasurement, mode: str, summary: Optional[dict]) -> dict:
    """A row's columns from its measured process tree: wall time, CPU, memory; in multi-process
    mode the simulator's (the root) and the controller processes' apart."""
    wall = m.wall_s
    columns = {
        "WallTime(s)": round(wall, 3), "CPU(%)": round(100 * m.cpu_core_s / wall, 1) if wall > 0 else None,
        "MaxMem(kB)": m.peak_tree_rss_kb, "MaxPss(kB)": m.peak_tree_pss_kb or None,
        "total_wall_s": round(wall, 3), "cpu_core_s": round(m.cpu_core_s, 3),
        "processes": m.max_processes, "exit_code": m.exit_code,
        "other_load_cores": None if m.other_cores is None else round(m.other_cores, 2),
    }
    if mode == "multi-process" and wall > 0:
        columns.update({"ArgosCPU(%)": round(100 * m.root_cpu_s / wall, 1),
                        "Ros2CPU(%)": round(100 * max(m.cpu_core_s - m.root_cpu_s, 0.0) / wall, 1),
                        "ArgosMem(kB)": max(m.peak_root_rss_kb,
                                            int(1024 * (as_number((summary or {}).get("peak_rss_mb")) or 0))),
                        "Ros2Mem(kB)": m.peak_others_rss_kb, "Ros2Pss(kB)": m.peak_others_pss_kb or None})
    return columns


def summary_columns(summary: dict, mode: str) -> dict:
    """A row's columns from the run's JSON summary; what an older composed-sim did not write is
    None (an empty cell, "–" in the report)."""
    phases = summary.get("phases_s") or {}
    per_tick = summary.get("phases_per_tick_ms") or {}
    return {**{k: _round(summary.get(k), 6) for k in ("setup_s", "ticks_wall_s")},
            "real_time_factor": _round(summary.get("real_time_factor"), 4),
            "workers_used": summary.get("workers") if mode == "composed" else None,
            "per_robot_tick_us": _round(summary.get("per_robot_tick_us"), 2),
            "violations": summary.get("violations"),
            **{k: _round(phases.get(k), 6) for k in ("physics_s", "sensing_s", "ros_exchange_s")},
            **{k: _round(summary.get(k), 3) for k in ("host_cost_per_robot_tick_us", "node_code_per_robot_tick_us")},
            **{col: _round(per_tick.get(p), 4) for p, col in zip(PHASES, PHASE_COLUMNS)}}


def _round(v, digits: int):
    x = as_number(v)
    return None if x is None else round(x, digits)


def resolve_worlds(args) -> dict[str, Path]:
    """Experiment name → world file to sweep: --experiments' shipped worlds, else --world (named
    after its experiment when it is a shipped one, else after its file), else flocking."""
    from composed_sim.command_line import UserError
    if args.world is not None and args.experiments:
        raise UserError("--world and --experiments: give one of them (--world sweeps one world file of yours)")
    if args.world is not None:
        if not args.world.is_file():
            raise UserError(f"--world {args.world}: no such file")
        known = experiment_of_world(args.world)
        return {known.name if known else args.world.stem: args.world.resolve()}
    worlds = {}
    for name in args.experiments or (DEFAULT_EXPERIMENT,):
        path = shipped_world(EXPERIMENTS[name])
        if not path.is_file():
            raise UserError(f"--experiments {name}: its world file {path} is missing (a checkout's worlds/ folder "
                            "holds the shipped worlds); pass --world WORLD.yaml")
        worlds[name] = path
    return worlds


def run(args: BenchSettings) -> int:
    from composed_sim.command_line import check_writable
    if args.replot is not None:
        return replot(args)
    if args.physics is not None:
        return _physics_step(args)
    worlds = _load_worlds(args)
    if args.machines:
        from composed_sim.bench.distributed import run_distributed
        check_writable(args.out)
        for path, _ in worlds.values():
            run_distributed(path, args.sizes, args.ticks, args.machines, args.workers[0], args.trials, args.out,
                            machine_info())
        return 0
    base, domains = _domains(args)
    check_writable(args.out)
    if args.report is not None:
        check_writable(args.report.parent / "figures")

    machine = machine_info()
    # One sweep per experiment; the domains, the memory estimate and its calibration runs are the
    # whole bench's.
    estimate, calibration = MemoryEstimate(), []
    sweeps = {name: Sweep(world=path, experiment=name, ticks=args.ticks, timeout_s=args.timeout,
                          robots_per_domain=args.robots_per_domain, memory_fraction=args.memory_fraction,
                          domains=domains, estimate=estimate, calibration=calibration,
                          world_robots_per_domain=getattr(getattr(world, "multi_process", None), "robots_per_domain", None))
              for name, (path, world) in worlds.items()}
    plan = [(name, n, trial, mode, executor, workers) for name in worlds for n in args.sizes
            for trial in range(1, args.trials + 1) for mode in args.modes for executor in args.executors
            for workers in (args.workers if mode == "composed" else (None,))]
    settings = _settings(args, worlds, base)
    command = command_line(args)
    print(f"bench: {len(plan)} runs of {', '.join(p.name for p, _ in worlds.values())} ({args.ticks} ticks each) "
          f"→ {args.out}/", file=sys.stderr)

    rows: list[dict] = []
    t_start = time.perf_counter()
    interrupted = _run_plan(plan, sweeps, rows, args.trials)
    elapsed = time.perf_counter() - t_start

    doc = {"command": command, "machine": machine, "settings": settings, "elapsed_s": round(elapsed, 1),
           "interrupted": interrupted,
           "memory_estimate": {"per_process_mb": round(estimate.per_process_mb, 2),
                               "base_mb": round(estimate.base_mb, 1), "source": estimate.source},
           "calibration_runs": calibration, "columns": list(COLUMNS), "rows": rows}
    write_outputs(doc, args.out, args.report)
    bad = [r for r in rows if r["status"] not in ("ok", "skipped")]
    print(f"bench: {len(rows)} runs in {elapsed:.0f} s: "
          + ", ".join(f"{s} {sum(r['status'] == s for r in rows)}" for s in sorted({r['status'] for r in rows}))
          + f"; results in {args.out}/" + (f", report {args.report}" if args.report else ""), file=sys.stderr)
    if interrupted:
        return 130
    return 1 if bad else 0


def _physics_step(args: BenchSettings) -> int:
    """``--physics``: the physics step alone, over the sizes and region counts, into physics.json."""
    from composed_sim.bench.physics_step import main as measure_physics_step
    args.out.mkdir(parents=True, exist_ok=True)
    return measure_physics_step(["--robots", ",".join(map(str, args.sizes)),
                                 "--regions", ",".join(map(str, args.physics)), "--out", str(args.out / "physics.json")])


def _load_worlds(args: BenchSettings) -> dict[str, tuple[Path, object]]:
    """Experiment name → (world file, its World), each loaded; a bad file is the user's error."""
    from composed_sim.command_line import UserError
    from composed_sim.world.loader import WorldFileError, load_world
    worlds = {}
    for name, path in resolve_worlds(args).items():
        try:
            worlds[name] = (path, load_world(path, ticks=args.ticks))
        except WorldFileError as e:
            raise UserError(str(e)) from None
    return worlds


def _domains(args: BenchSettings) -> tuple[int, DomainAllocator]:
    """The first ROS domain (--domain-id, else $ROS_DOMAIN_ID, else 0) and the allocator of the
    runs' domains from it."""
    from composed_sim.command_line import UserError
    base = args.domain_id
    if base is None:
        try:
            base = environment_domain() or 0
        except ValueError as e:
            raise UserError(str(e)) from None
    try:
        return base, DomainAllocator(base)
    except ValueError as e:
        raise UserError(str(e)) from None


def _settings(args: BenchSettings, worlds: dict[str, tuple[Path, object]], base: int) -> dict:
    """The sweep's settings as runs.json records them."""
    first_path, first_world = next(iter(worlds.values()))
    return {"sizes": list(args.sizes), "modes": list(args.modes), "executors": list(args.executors),
            "workers": list(args.workers),
            "trials": args.trials, "ticks": args.ticks, "world": str(first_path), "world_name": first_world.name,
            "experiments": {name: {"world": str(path), "world_name": world.name, "tick_s": world.tick_s}
                            for name, (path, world) in worlds.items()},
            "tick_s": first_world.tick_s, "timeout_s": args.timeout, "domain_base": base,
            "robots_per_domain": args.robots_per_domain, "memory_fraction": args.memory_fraction}


def _run_plan(plan: list[tuple], sweeps: dict, rows: list[dict], trials: int) -> bool:
    """Run the plan's runs one after the other, appending their rows; True when interrupted
    (Ctrl-C or SIGTERM: the run going on is ended, what ran so far stays)."""
    old_term = _sigterm_interrupts()
    try:
        for i, (name, n, trial, mode, executor, workers) in enumerate(plan, 1):
            sweep = sweeps[name]
            first_multi = mode == "multi-process" and not any(r["mode"] == mode for r in rows)
            if first_multi and n > CALIBRATION_ABOVE:
                print(f"bench: calibrating the multi-process memory cost with {CALIBRATION_ROBOTS} robots",
                      file=sys.stderr)
                sweep.calibrate(executor)
                cal = sweep.calibration[-1]
                print(f"bench: calibration {cal['status']}: {sweep.estimate.per_process_mb:.1f} MB per process "
                      f"({sweep.estimate.source})" + (f" — {cal['reason']}" if cal["reason"] else ""), file=sys.stderr)
                if sweep.interrupted:
                    return True
            row = sweep.one(n, mode, executor, trial, workers=workers)
            rows.append(row)
            print(_progress_line(i, len(plan), row, trials), file=sys.stderr)
            if sweep.interrupted:
                return True
    except KeyboardInterrupt:
        return True
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
    return False


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
    head = (f"bench [{i}/{total}] {row['experiment']} N={row['Robots']} {host_label(row)} {row['executor']} "
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
