"""The ``composed-sim`` command: its arguments, and the dispatch to each subcommand's module
(``run.py``: a run and its outputs, from its typed ``settings.py``, with the observers its settings
ask for, ``observers.py``; ``report.py``: what a run prints; ``distributed.py``: ``join`` and
``credentials``; ``files.py``: worlds, plugins, results and recordings; ``interfaces.py``: interface
packages; ``common.py``: what they share). ``bench`` and ``sweep`` are packages of their own."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from composed_sim.cli.distributed import cmd_credentials, cmd_join
from composed_sim.cli.files import cmd_bag_repair, cmd_export, cmd_plugins, cmd_render, cmd_replay, cmd_worlds
from composed_sim.cli.interfaces import cmd_interfaces
from composed_sim.cli.report import JsonStdout
from composed_sim.cli.run import cmd_run
from composed_sim.cli.settings import LiveSettings, OutputSettings, run_settings, typed
from composed_sim.command_line import EXIT_FAILED, EXIT_USAGE, RunStopped, UserError, number_arg

_positive_int = number_arg(int, minimum=1)
_non_negative_int = number_arg(int, minimum=0)
_positive_float = number_arg(float, minimum=0, inclusive=False)


def _workers(text: str):
    """--workers: a whole number >= 1, or auto."""
    from composed_sim.hosts.settings import AUTO_WORKERS
    return AUTO_WORKERS if text == AUTO_WORKERS else _positive_int(text)


class _OneLineParser(argparse.ArgumentParser):
    """argparse's errors as one line naming the command, plus where the usage is, instead of the
    whole usage first: the mistake is the line a user must see (subcommands' parsers are of this
    class too, add_subparsers makes them so)."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(prog="composed-sim", description=(
        "Swarm simulator whose robot controllers are ROS 2 nodes, hosted with the simulator in a few processes."))
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_run(sub)
    _add_join(sub)
    _add_credentials(sub)
    _add_file_commands(sub)
    interfaces = sub.add_parser("interfaces", help="build ROS 2 interface packages (.msg, .srv) into Python messages",
                                description="Build a user's interface packages with the pip-installed rosidl "
                                            "toolchain, cached by content (docs/interfaces.md).")
    interfaces_sub = interfaces.add_subparsers(dest="interfaces_command", required=True, metavar="ACTION")
    interfaces_build = interfaces_sub.add_parser("build", help="build (or find built) interface packages",
                                                 description="Build each package folder (package.xml, msg/, srv/) "
                                                             "in order, a package may use those before it; print "
                                                             "where each is, how long it took, whether it was cached.")
    interfaces_build.add_argument("packages", type=Path, nargs="+", metavar="DIR", help="an interface package folder")

    bench = sub.add_parser("bench", help="benchmark swarm sizes, modes and executors against the paper",
                           description="Sweep swarm sizes, host modes and executors; measure setup, "
                                       "wall time, CPU and peak memory of each run's process tree; write "
                                       "CSV, JSON and figures side by side with the paper's results.")
    from composed_sim import bench as bench_module
    bench_module.add_arguments(bench)

    sweep = sub.add_parser("sweep", help="run a grid of runs over seeds, swarm sizes and world fields",
                           description="Run a world over seeds, swarm sizes and world fields by dotted path, "
                                       "in parallel, each run its own process, domain and folder; write runs.csv, "
                                       "metrics.csv and plots (docs/experiments.md). Resumable.")
    from composed_sim.sweep import command as sweep_command
    sweep_command.add_arguments(sweep)
    parser.commands = sub.choices        # name → subcommand parser, for the errors found after parsing
    return parser


def _add_hosting_flags(parser: argparse.ArgumentParser, *, seed_help: str, domain_help: str) -> None:
    """The seed, an ARGoS file's controller, the executor, the ROS domain."""
    from composed_sim.hosting import DEFAULT_EXECUTOR, EXECUTORS
    parser.add_argument("--seed", type=_non_negative_int, help=seed_help)
    parser.add_argument("--controller", metavar="NAME",
                        help="for an ARGoS .argos file: the controller plugin its robots run")
    parser.add_argument("--executor", choices=EXECUTORS, default=DEFAULT_EXECUTOR,
                        help="rclpy executor running the nodes (default: %(default)s)")
    parser.add_argument("--domain-id", type=int, default=None, help=domain_help)


def _add_run(sub) -> None:
    run = sub.add_parser("run", help="run a world file headless and write its results",
                         description="Run a world: the controller nodes hosted with simulator nodes in "
                                     "worker processes, in lockstep; writes summary.json, trajectories.npz, "
                                     "violations.csv, world.yaml and arena.png into --out.")
    run.add_argument("world", type=Path, help="world file (YAML, e.g. worlds/flocking.yaml) or an ARGoS .argos file")
    run.add_argument("--robots", type=_positive_int, help="total number of robots (overrides the world)")
    run.add_argument("--ticks", type=_positive_int, help="ticks to simulate (overrides length_ticks)")
    _add_hosting_flags(run, seed_help="random seed (overrides the world)", domain_help=(
        "ROS domain of the run, refused if another simulator uses it (default: $ROS_DOMAIN_ID where set, else the "
        "first free domain from 0 up, printed first and recorded in summary.json; multi-process mode: the first of "
        "a block of free domains)"))
    _add_run_hosting_options(run)
    _add_run_output_options(run)
    _add_run_machine_options(run)


def _add_run_hosting_options(run: argparse.ArgumentParser) -> None:
    """How a run hosts its controllers (mode, domains, participants, workers) and what it does
    with a late one."""
    from composed_sim.hosts.settings import AUTO_WORKERS, DEFAULT_MODE, MODES, HostSettings
    from composed_sim.world.schema import ROBOTS_PER_DOMAIN
    run.add_argument("--mode", choices=MODES, default=DEFAULT_MODE,
                     help="composed: the controllers hosted together (see --workers); multi-process: one process per "
                          "controller over balanced ROS domains, as in the paper (default: %(default)s)")
    run.add_argument("--robots-per-domain", type=_positive_int, default=None,
                     help=f"multi-process mode: robots per ROS domain (default: the world's, else {ROBOTS_PER_DOMAIN})")
    run.add_argument("--robots-per-participant", type=_positive_int, default=HostSettings.robots_per_participant,
                     help="composed mode with --workers 1: robots per DDS participant, all in one domain; fewer "
                          "make set-up faster, each costs a participant (default: %(default)s; each worker "
                          "process holds one participant)")
    run.add_argument("--workers", type=_workers, default=AUTO_WORKERS, metavar="K|auto",
                     help="composed mode: worker processes hosting the controller nodes, each with its own "
                          "executor on its own core; 1: everything in this process; auto: from the swarm "
                          "size and the usable cores (default: %(default)s)")
    run.add_argument("--watchdog", type=_positive_float, metavar="SECONDS",
                     help="wall seconds to wait for a controller's answer before its fallback")
    run.add_argument("--fallback", choices=("zero", "previous"), help="command given to a late robot")


def _add_run_output_options(run: argparse.ArgumentParser) -> None:
    """What a run writes, records, shows live, and prints."""
    from composed_sim.live import DEFAULT_FOXGLOVE_HOST, DEFAULT_FOXGLOVE_PORT
    outputs, live = OutputSettings(), LiveSettings()
    run.add_argument("--out", type=Path, default=outputs.out, help="output directory (default: %(default)s)")
    run.add_argument("--record", type=Path, metavar="DIR",
                     help="record a rosbag2 (MCAP) directory: /clock, /swarm/state and --record-topics")
    run.add_argument("--record-topics", nargs="+", default=[], metavar="GLOB",
                     help="per-robot topics to record too, e.g. '/bot1*/cmd_vel' '/*/light'")
    run.add_argument("--markers", action="store_true",
                     help="publish the swarm as one visualization_msgs/MarkerArray on /swarm/markers")
    foxglove = f"{DEFAULT_FOXGLOVE_HOST}:{DEFAULT_FOXGLOVE_PORT}"
    run.add_argument("--foxglove", nargs="?", const=foxglove, metavar="[HOST:]PORT",
                     help=f"serve the run live to the Foxglove app (WebSocket; default {foxglove})")
    run.add_argument("--foxglove-topics", nargs="+", default=[], metavar="GLOB",
                     help="per-robot topics to serve too, e.g. '/bot0/*'")
    run.add_argument("--rate", type=_positive_float, metavar="R", help="run at most R x real time (1: real time)")
    run.add_argument("--wait-for-viewer", type=_positive_float, metavar="SECONDS", default=live.wait_for_viewer_s,
                     help="with --foxglove: wait at tick 0 until a viewer subscribes, at most SECONDS")
    run.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    run.add_argument("--no-picture", action="store_true", help="skip arena.png")
    run.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    run.add_argument("--log-level", choices=("debug", "info", "warn", "error"), default=outputs.log_level,
                     help="the nodes' log lines shown on the console, each call site once per node class "
                          "(all go to OUT/logs/<robot>.log; default: %(default)s)")
    run.add_argument("--fail-fast", action="store_true",
                     help="stop the run at the first controller failure, exit code 1 (for CI)")


def _add_run_machine_options(run: argparse.ArgumentParser) -> None:
    """A run over several machines: the robots hosted elsewhere (--machines) or the controllers
    driven by processes outside the run (--external-controllers)."""
    run.add_argument("--machines", metavar="N|ADDR,ADDR",
                     help="host the robots on other machines, each with worker processes of its own: how many "
                          "machines, or their addresses or host names in robot order; the run prints the command "
                          "to start on each (`composed-sim join`), and waits --discovery-timeout for them "
                          "(docs/distributed.md)")
    run.add_argument("--listen", metavar="HOST:PORT",
                     help="with --machines: the address the machines reach this simulator at (default: every "
                          "interface, a free port)")
    run.add_argument("--credentials", type=Path, metavar="FILE",
                     help="with --machines: the run's TLS credentials, made beforehand with `composed-sim credentials "
                          "make` (default: new ones for this run, in OUT/credentials.pem)")
    run.add_argument("--insecure", action="store_true",
                     help="with --machines: plain tcp://, no TLS: whoever reaches the port can run code in the "
                          "simulator (only on a network of your own)")
    run.add_argument("--external-controllers", action="store_true",
                     help="run the simulator only: each robot is driven by whatever process of the run's ROS "
                          "domain publishes its cmd_vel (your own programs, on this or other machines), waited for "
                          "before tick 0; the world's controllers and nodes are not started (docs/distributed.md)")
    _add_distributed_options(run, "with --external-controllers: ")


def _add_join(sub) -> None:
    join = sub.add_parser("join", help="host a block of robots of a run on this machine (run --machines)",
                          description="Join the run of a simulator started with `run --machines`: this machine "
                                      "hosts the block of robots the simulator gives it, in worker processes of "
                                      "its own; ends when the run ends, or on Ctrl-C/SIGTERM (docs/distributed.md).")
    join.add_argument("address", help="the simulator's address, as it printed it (tls://HOST:PORT)")
    join.add_argument("--credentials", type=Path, metavar="FILE",
                      help="the run's credentials file, as the simulator printed it (needed for tls://)")
    join.add_argument("--insecure", action="store_true",
                      help="join a simulator started with --insecure over plain tcp://")
    join.add_argument("--run", metavar="ID", help="the run's id, as the simulator printed it: a machine started "
                                                  "with another run's command is refused")
    join.add_argument("--workers", type=_workers, default="auto", metavar="K|auto",
                      help="worker processes on this machine (default: %(default)s, from its robots and cores)")
    join.add_argument("--timeout", type=_positive_float, default=120.0, metavar="SECONDS",
                      help="how long to look for the simulator (default: %(default)s)")


def _add_credentials(sub) -> None:
    credentials = sub.add_parser("credentials", help="make TLS credentials for runs over machines",
                                 description="Make the credentials of a run over machines beforehand (a batch job: "
                                             "the simulator and every machine read one file over the cluster's "
                                             "file system): a CA of their own and a certificate it signed, in "
                                             "DIR/credentials.pem, readable by you only (docs/distributed.md).")
    action = credentials.add_subparsers(dest="credentials_command", required=True, metavar="ACTION")
    make = action.add_parser("make", help="write DIR/credentials.pem")
    make.add_argument("dir", type=Path, metavar="DIR", help="the folder to write it into (made if missing)")


def _add_file_commands(sub) -> None:
    sub.add_parser("plugins", help="list the installed controller plugins")
    export = sub.add_parser("export", help="write a run's trajectories as a tidy table (CSV or Parquet)",
                            description="One row per (tick, robot): tick, time_s, robot, group, model, x, y, yaw, "
                                        "LED colour; for pandas or polars.")
    export.add_argument("results", type=Path, help="a results directory (--out of run)")
    export.add_argument("--format", choices=("csv", "parquet"), default="csv")
    export.add_argument("--out", type=Path, help="the table file (default: RESULTS/trajectories.csv|parquet)")

    render = sub.add_parser("render", help="draw a run's results or recording as PNG, GIF or MP4",
                            description="Draw the arena, robots with heading and LED colour, trails and a "
                                        "tick caption from a results directory (of `run`) or a recording.")
    render.add_argument("source", type=Path, help="a results directory (--out of run) or a --record directory")
    render.add_argument("--out", type=Path, required=True, help="run.mp4, run.gif or final.png")
    _add_render_options(render)

    replay = sub.add_parser("replay", help="re-render or re-check a recorded run without simulating it",
                            description="Read a --record directory back: print what it holds, check it is "
                                        "complete, and optionally render it.")
    replay.add_argument("recording", type=Path, help="a --record directory (rosbag2 with MCAP)")
    replay.add_argument("--out", type=Path, help="also render it: run.mp4, run.gif or final.png")
    replay.add_argument("--check", action="store_true", help="exit 1 unless every tick of the world was recorded")
    _add_render_options(replay)

    bag = sub.add_parser("bag", help="mend a recording", description="Tools for --record directories.")
    bag_sub = bag.add_subparsers(dest="bag_command", required=True, metavar="COMMAND")
    bag_repair = bag_sub.add_parser(
        "repair", help="make the bag of a killed run complete and readable",
        description="Write the MCAP index and metadata.yaml of a recording whose run was killed (SIGKILL, power "
                    "loss, full disk), from its chunks on disk: every tick up to the last one complete on disk.")
    bag_repair.add_argument("recording", type=Path, help="a --record directory")
    sub.add_parser("worlds", help="list the shipped world files")


def _add_distributed_options(parser: argparse.ArgumentParser, prefix: str) -> None:
    from composed_sim.hosts.discovery import RANGES
    from composed_sim.hosts.settings import DiscoverySettings
    parser.add_argument("--discovery-timeout", type=_positive_float, metavar="SECONDS",
                        default=DiscoverySettings.timeout_s,
                        help=f"{prefix.replace(':', ' or --machines:') if prefix else ''}how long to wait for the "
                             f"other side before giving up (default: %(default)s)")
    parser.add_argument("--discovery-range", choices=RANGES, type=str.lower, default=None,
                        help=f"{prefix}ROS_AUTOMATIC_DISCOVERY_RANGE (default: the environment's, else subnet)")
    parser.add_argument("--static-peers", metavar="ADDR;ADDR",
                        help=f"{prefix}ROS_STATIC_PEERS: addresses of the other machines, for networks without multicast")
    parser.add_argument("--discovery-server", metavar="ADDR:PORT",
                        help=f"{prefix}ROS_DISCOVERY_SERVER: a Fast DDS discovery server")


def _add_render_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fps", type=_positive_float, default=10.0, help="frames per second (default: %(default)s)")
    parser.add_argument("--size", type=_positive_int, default=800, help="frame side in pixels (default: %(default)s)")
    parser.add_argument("--trail", type=_non_negative_int, default=50, help="trail length in ticks (default: %(default)s)")
    parser.add_argument("--every", type=_positive_int, default=1, help="draw every k-th tick (default: %(default)s)")


def _parse(argv: list[str] | None) -> argparse.Namespace:
    """The arguments; an unknown flag is reported by its subcommand's parser, so that the line
    names the command whose --help lists the flags (the top parser would say just composed-sim)."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        parser.commands[args.command].error(f"unrecognized arguments: {' '.join(unknown)}")
    return args


def _error_prefix(command: str) -> str:
    """A sweep's own mistakes name the sweep, like its argparse errors and its progress lines:
    its runs' errors, in their logs and rows, are the ones that start "composed-sim: error"."""
    return "composed-sim sweep" if command == "sweep" else "composed-sim"


COMMANDS = {"plugins": lambda args: cmd_plugins(), "render": cmd_render, "replay": cmd_replay,
            "bag": cmd_bag_repair, "export": cmd_export, "worlds": lambda args: cmd_worlds(), "join": cmd_join,
            "credentials": cmd_credentials,
            "interfaces": cmd_interfaces}


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    exit_when_done = argv is None    # a program of its own (not called from Python): see cmd_run
    try:
        if args.command == "bench":
            from composed_sim import bench
            return bench.run(typed(bench.BenchSettings, args))
        if args.command == "sweep":
            from composed_sim.sweep import command as sweep_command
            return sweep_command.run(typed(sweep_command.SweepSettings, args))
        if args.command in COMMANDS:
            return COMMANDS[args.command](args)
        settings = run_settings(args, exit_when_done=exit_when_done)
        json_stdout = JsonStdout()
        if settings.outputs.json and exit_when_done:
            json_stdout.keep()
        return cmd_run(settings, json_stdout)
    except UserError as e:
        print(f"{_error_prefix(args.command)}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except RunStopped as e:
        print(f"composed-sim: error: {e}", file=sys.stderr)
        return EXIT_FAILED
