"""``composed-sim sweep``: one command runs a grid of runs (seeds × swarm sizes × world fields by
dotted path) in parallel, each a child ``composed-sim run`` with its own output folder, and
gathers their results into one table, one metrics file and plots (docs/experiments.md).

grid.py     the grid: parsing, dotted-path overrides checked against the world schema before any run
runner.py   one run in a child process, resumable by its spec hash; the local pool and Dask runners
report.py   runs.csv, metrics.csv and the plots
command.py  the command's arguments and its main
"""
