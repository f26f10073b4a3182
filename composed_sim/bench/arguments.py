"""``composed-sim bench``'s command-line options, and the exact command line a sweep records."""
from __future__ import annotations

import argparse
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from composed_sim.bench.experiments import DEFAULT_EXPERIMENT, EXPERIMENTS
from composed_sim.bench.rules import DEFAULT_MEMORY_FRACTION, DEFAULT_TIMEOUT_S, PAPER_SIZES
from composed_sim.world.schema import ROBOTS_PER_DOMAIN


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


@dataclass(frozen=True)
class BenchSettings:
    """``composed-sim bench``'s options, as ``add_arguments`` declares and parses them."""
    sizes: tuple[int, ...]
    modes: tuple[str, ...]
    executors: tuple[str, ...]
    workers: tuple[str, ...]
    trials: int
    ticks: int
    experiments: Optional[tuple[str, ...]]
    world: Optional[Path]
    out: Path
    timeout: float
    report: Optional[Path]
    domain_id: Optional[int]
    robots_per_domain: Optional[int]
    memory_fraction: float
    replot: Optional[list[Path]]
    physics: Optional[tuple[int, ...]] = None
    machines: int = 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from composed_sim.hosting import EXECUTORS as executors
    from composed_sim.hosts.settings import MODES as modes
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
    parser.add_argument("--experiments", type=_choice_list(tuple(EXPERIMENTS)), default=None, metavar="NAME,…",
                        help="experiments to sweep one after the other, each a shipped world file: "
                             + ", ".join(f"{e.name} ({e.world})" for e in EXPERIMENTS.values())
                             + f" (default: {DEFAULT_EXPERIMENT}, or --world)")
    parser.add_argument("--world", type=Path, default=None,
                        help="a world file to sweep instead of --experiments (default: the shipped "
                             "worlds/flocking.yaml, the paper's experiment)")
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
    parser.add_argument("--physics", type=_size_list, default=None, metavar="K,K,…",
                        help="instead of runs: the physics step alone (bench/physics_step.py) at --sizes robots "
                             "(e.g. 1280,10240,102400), one engine and these region counts (1: cells in one "
                             "process), into OUT/physics.json")
    parser.add_argument("--machines", type=_positive(int), default=0, metavar="M",
                        help="the distributed row instead of the sweep (as root): per size, the simulator and M "
                             "machines in network namespaces of this machine, each with the first --workers "
                             "value's worker processes, against one machine with as many and with --workers auto "
                             "(distributed.json in --out)")
    parser.add_argument("--replot", type=Path, nargs="+", default=None, metavar="RUNS.json",
                        help="run nothing: redraw the figures (into --out) and the --report from the "
                             "runs.json of an earlier sweep, or of several sweeps of the same tick "
                             "count run apart (their rows together, each command listed)")


def command_line(args: BenchSettings) -> str:
    """The ``composed-sim bench`` command that reproduces this sweep (what was given, spelled out)."""
    parts = ["composed-sim", "bench",
             "--sizes", ",".join(map(str, args.sizes)), "--modes", ",".join(args.modes),
             "--executors", ",".join(args.executors), "--workers", ",".join(args.workers),
             "--trials", str(args.trials), "--ticks", str(args.ticks)]
    if getattr(args, "experiments", None):
        parts += ["--experiments", ",".join(args.experiments)]
    if args.world is not None:
        parts += ["--world", str(args.world)]
    if args.timeout != DEFAULT_TIMEOUT_S:
        parts += ["--timeout", f"{args.timeout:g}"]
    if args.domain_id is not None:
        parts += ["--domain-id", str(args.domain_id)]
    if args.robots_per_domain is not None:
        parts += ["--robots-per-domain", str(args.robots_per_domain)]
    if getattr(args, "machines", 0):
        parts += ["--machines", str(args.machines)]
    if args.memory_fraction != DEFAULT_MEMORY_FRACTION:
        parts += ["--memory-fraction", f"{args.memory_fraction:g}"]
    parts += ["--out", str(args.out)]
    if args.report is not None:
        parts += ["--report", str(args.report)]
    return shlex.join(parts)
