"""The ``composed-sim sweep`` command: arguments, the grid from the command line or a sweep file,
the runs (local pool or Dask cluster) with progress, the tables and plots."""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from composed_sim.command_line import UserError, check_writable, number_arg
from composed_sim.sweep import report
from composed_sim.sweep.grid import Grid, GridError, parse_list, parse_set, whole_numbers
from composed_sim.sweep.runner import dask_cluster, local_pool
from composed_sim.world.loader import WorldFileError, read_yaml


@dataclass(frozen=True)
class SweepSettings:
    """``composed-sim sweep``'s options, as ``add_arguments`` declares and parses them."""
    spec: Path
    seeds: Optional[str]
    robots: Optional[str]
    set: list[str]
    ticks: Optional[int]
    jobs: Optional[int]
    cluster: Optional[str]
    cluster_security: Optional[str]
    out: Path
    no_plots: bool


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("spec", type=Path, help="a world file (YAML) or a sweep file (YAML with `world:`)")
    parser.add_argument("--seeds", help="seeds: 1-5 or 1,2,7")
    parser.add_argument("--robots", help="swarm sizes: 20,80")
    parser.add_argument("--set", action="append", default=[], metavar="PATH=V1,V2",
                        help="a world field by dotted path and its values, e.g. robots.0.params.gain=500,1000 "
                             "(repeatable)")
    parser.add_argument("--ticks", type=number_arg(int, minimum=1), help="ticks per run (overrides length_ticks)")
    parser.add_argument("--jobs", type=number_arg(int, minimum=1), default=None,
                        help="runs at once on this machine (default: the usable cores)")
    parser.add_argument("--cluster", metavar="ADDRESS",
                        help="run on a Dask distributed cluster, e.g. tls://scheduler:8786 (--out on a shared file system)")
    parser.add_argument("--cluster-security", metavar="CA,CERT,KEY|FILE",
                        help="with --cluster: the cluster's TLS files (its CA, this client's certificate and key), "
                             "or a `composed-sim credentials make` file (default: Dask's own configuration)")
    parser.add_argument("--out", type=Path, default=Path("out/sweep"), help="output directory (default: %(default)s)")
    parser.add_argument("--no-plots", action="store_true", help="skip the plots")


def cluster_security(given: Optional[str]):
    """Dask's ``Security`` for --cluster-security (CA,CERT,KEY files, or a credentials file); None
    where not given, for Dask's own configuration."""
    if not given:
        return None
    from composed_sim.hosting import HostError
    from composed_sim.hosts.machines.credentials import load, tls_files_security
    paths = [Path(p) for p in given.split(",")]
    try:
        if len(paths) == 1:
            return load(paths[0]).security()
        if len(paths) == 3:
            return tls_files_security(*paths)
    except HostError as e:
        raise UserError(f"--cluster-security {e}") from None
    raise UserError(f"--cluster-security {given}: expected CA,CERT,KEY (three files) or one credentials file")


def grid_from(args) -> Grid:
    """The grid of the command line, over a sweep file's when one is given (the command line wins)."""
    spec_path = args.spec
    data = _sweep_file(spec_path)
    if data:
        spec_path = (spec_path.parent / str(data["world"])).resolve()

    def values(cli: str | None, key: str, minimum: int, example: str) -> list:
        if cli is not None:
            return whole_numbers(parse_list(cli, f"--{key}"), f"--{key}", minimum=minimum, example=example)
        given = data.get(key, [])
        parsed = parse_list(str(given), key) if isinstance(given, (str, int)) else list(given)
        return whole_numbers(parsed, f"{args.spec}: {key}", minimum=minimum, example=example)

    file_sets = data.get("set") or {}
    if not isinstance(file_sets, dict):
        raise GridError(f"{args.spec}: set: must map dotted paths to values, e.g. "
                        f"{{robots.0.params.gain: [500, 1000]}} (got {file_sets!r})")
    sets = {path: (list(v) if isinstance(v, list) else parse_list(str(v), f"set.{path}"))
            for path, v in file_sets.items()}
    sets.update(parse_set(text) for text in args.set)
    return Grid(spec_path, seeds=values(args.seeds, "seeds", 0, "1-5 or 1,2,7"),
                robots=values(args.robots, "robots", 1, "20,80"),
                sets=sets, ticks=args.ticks if args.ticks is not None else data.get("ticks"))


def _sweep_file(path: Path) -> dict:
    """A sweep file's fields, or {} where ``path`` is a world file (a world has no ``world:`` field)."""
    if path.suffix not in (".yaml", ".yml") or not path.is_file():
        return {}
    try:
        loaded = read_yaml(path)
    except WorldFileError as e:
        raise GridError(str(e)) from None
    if not (isinstance(loaded, dict) and "world" in loaded):
        return {}
    unknown = set(loaded) - {"world", "seeds", "robots", "set", "ticks"}
    if unknown:
        raise GridError(f"{path}: unknown sweep file field {sorted(unknown)[0]!r} "
                        f"(fields: world, seeds, robots, set, ticks)")
    return loaded


def run(args: SweepSettings) -> int:
    try:
        grid = grid_from(args)
        specs = grid.specs()       # every world checked before any run starts
    except GridError as e:
        raise UserError(str(e)) from None
    check_writable(args.out)
    swept = list(specs[0].values) if specs else []
    if args.cluster_security and not args.cluster:
        raise UserError("--cluster-security: only with --cluster")
    if args.cluster:
        security = cluster_security(args.cluster_security)
        if security is None and args.cluster.startswith("tls://"):
            from distributed.security import Security
            if Security().tls_ca_file is None:          # Dask's own configuration has none either
                raise UserError(f"--cluster {args.cluster}: a TLS cluster needs its files: --cluster-security "
                                f"CA,CERT,KEY, or Dask's configuration (distributed.comm.tls, docs/experiments.md)")
        if args.cluster.startswith("tcp://"):
            print(f"composed-sim sweep: {args.cluster}: plain tcp://, neither authenticated nor encrypted: the runs "
                  f"go to whoever answers there (a TLS cluster is tls://, docs/experiments.md)", file=sys.stderr)
        try:
            rows_as_done = dask_cluster(specs, str(args.out), args.cluster, security)
        except (ValueError, OSError) as e:      # a malformed or unreachable address
            raise UserError(f"--cluster {args.cluster}: {e}") from None
        where = f"Dask cluster {args.cluster}"
    else:
        from composed_sim.hosts.workers.worker_host import usable_cores
        jobs = args.jobs or usable_cores()
        where, rows_as_done = f"{jobs} at a time", local_pool(specs, str(args.out), jobs)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"composed-sim sweep: {len(specs)} runs ({' × '.join(f'{k} {len(set(s.values[k] for s in specs))}' for k in swept)}), "
          f"{where}, into {args.out}/", file=sys.stderr)
    rows: list[dict] = []
    t0 = time.perf_counter()
    progress = _progress(len(specs))
    try:
        for row in rows_as_done:
            rows.append(row)
            failed = sum(r["status"] != "ok" for r in rows)
            progress.set_postfix_str(f"{failed} failed", refresh=False)
            progress.update(1)
            if row["status"] != "ok":
                last = row["error"].strip().splitlines()[-1:] or ["?"]
                progress.write(f"composed-sim sweep: run {row['run']} {row['status']} (exit {row['exit_code']}): {last[0]}")
    except KeyboardInterrupt:
        print("\ncomposed-sim sweep: interrupted; writing the runs done so far", file=sys.stderr)
    finally:
        progress.close()
        report.write_tables(args.out, rows, swept)
    wall = time.perf_counter() - t0
    plots = [] if args.no_plots else report.plot(args.out, rows, swept)
    failed = sum(r["status"] != "ok" for r in rows)
    reused = sum(bool(r.get("reused")) for r in rows)
    print(f"{len(rows)} runs ({failed} failed, {reused} reused) in {wall:.1f} s wall; {args.out / report.RUNS}"
          + (f", {args.out / report.METRICS}" if (args.out / report.METRICS).exists() else "")
          + (f", {len(plots)} plots" if plots else ""))
    return 1 if failed or len(rows) < len(specs) else 0


def _progress(total: int):
    from tqdm import tqdm
    return tqdm(total=total, unit="run", desc="sweep", file=sys.stderr, dynamic_ncols=True,
                mininterval=0 if not sys.stderr.isatty() else 0.1)
