"""``composed-sim bench``: sweep swarm sizes, host modes and executors; measure each run's whole
process tree; write CSV, JSON, figures and a markdown report side by side with the paper's results.

``--experiments flocking,synchronization,plain-nodes`` sweeps several shipped worlds one after the
other (rows and report grouped by experiment); ``--world`` sweeps a world file of yours.

Each run is its own ``composed-sim run ... --json`` subprocess on a ROS domain (a block of domains
in multi-process mode) that the previous run did not use, its whole process tree watched with
psutil. What each column measures is written in the report itself ("What is measured",
docs/benchmarks.md); the rows go to runs.csv and runs.json in --out, with the figures, and
``--report FILE.md`` writes the report. ``--replot runs.json …`` redraws all that from the stored
rows of one or several sweeps.

The package: ``arguments.py`` (the options), ``experiments.py`` (the experiments --experiments
names, each a shipped world), ``rules.py`` (the paper's figures, the skip rule, domains,
aggregation), ``tree.py`` (measuring one process tree), ``machine.py`` (the machine a sweep ran on),
``sweep.py`` (running the grid), ``replot.py`` (``--replot``), ``report.py`` (CSV, JSON and the
markdown report), ``figures.py``, ``sections.py`` (the report's per-tick phases, host cost and paper
comparison) and ``cells.py`` (its table cells); beside the sweep, ``physics_step.py`` (the physics step alone, ``--physics``),
``distributed.py`` and ``netns.py`` (the row over machines, ``--machines``, in network namespaces)
and ``rclpy_floor.py`` (the rclpy calls alone).
"""
from composed_sim.bench.arguments import BenchSettings, add_arguments, command_line
from composed_sim.bench.experiments import EXPERIMENTS
from composed_sim.bench.rules import (COLUMNS, PHASE_COLUMNS, PHASES, SAFE_DOMAIN_MAX, DomainAllocator, domains_needed,
                                      load_paper_results, paper_results_dir, skip_reason)
from composed_sim.bench.sweep import run
from composed_sim.bench.tree import measure_tree, parse_summary

__all__ = ["BenchSettings", "COLUMNS", "EXPERIMENTS", "PHASES", "PHASE_COLUMNS", "SAFE_DOMAIN_MAX", "DomainAllocator", "add_arguments", "command_line", "domains_needed",
           "load_paper_results", "measure_tree", "paper_results_dir", "parse_summary", "run", "skip_reason"]
