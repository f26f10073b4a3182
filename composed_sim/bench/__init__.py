"""``composed-sim bench``: sweep swarm sizes, host modes and executors; measure each run's whole
process tree; write CSV, JSON, figures and a markdown report side by side with the paper's results.

``--experiments flocking,synchronization,plain-nodes`` sweeps several shipped worlds one after the
other (rows and report grouped by experiment); ``--world`` sweeps a world file of yours.

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
raw rows in ``FILE's folder/figures/``. ``--replot runs.json …`` redraws all that from the stored
rows of one or several sweeps.

The package: ``arguments`` (the options), ``experiments`` (the experiments --experiments names,
each a shipped world), ``rules`` (the paper's figures, the skip rule, domains, aggregation), ``tree``
(measuring one process tree), ``sweep`` (running the grid), ``report`` (CSV, JSON and the markdown
report), ``figures``, ``sections`` (the report's per-tick phases, host cost and paper comparison) and
``cells`` (its table cells).
"""
from composed_sim.bench.arguments import add_arguments, command_line
from composed_sim.bench.experiments import EXPERIMENTS
from composed_sim.bench.rules import (COLUMNS, PHASE_COLUMNS, PHASES, SAFE_DOMAIN_MAX, DomainAllocator, domains_needed,
                                      load_paper_results, paper_results_dir, skip_reason)
from composed_sim.bench.sweep import run
from composed_sim.bench.tree import measure_tree, parse_summary

__all__ = ["COLUMNS", "EXPERIMENTS", "PHASES", "PHASE_COLUMNS", "SAFE_DOMAIN_MAX", "DomainAllocator", "add_arguments", "command_line", "domains_needed",
           "load_paper_results", "measure_tree", "paper_results_dir", "parse_summary", "run", "skip_reason"]
