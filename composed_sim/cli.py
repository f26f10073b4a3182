"""The ``composed-sim`` command."""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
from pathlib import Path

from composed_sim.command_line import UserError, check_writable, number_arg

EXIT_USAGE = 2       # bad input: world file, plugin, CLI value
EXIT_INTERRUPTED = 130


_positive_int = number_arg(int, minimum=1)
_non_negative_int = number_arg(int, minimum=0)
_positive_float = number_arg(float, minimum=0, inclusive=False)


def _workers(text: str):
    """--workers: a whole number >= 1, or auto."""
    return "auto" if text == "auto" else _positive_int(text)


def build_parser() -> argparse.ArgumentParser:
    from composed_sim.hosts.choices import EXECUTORS, MODES, ROBOTS_PER_PARTICIPANT

    parser = argparse.ArgumentParser(prog="composed-sim", description=(
        "Swarm simulator whose robot controllers are ROS 2 nodes, hosted with the simulator in a few processes."))
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="run a world file headless and write its results",
                         description="Run a world: the controller nodes hosted with simulator nodes in "
                                     "worker processes, in lockstep; writes summary.json, trajectories.npz, "
                                     "violations.csv, world.yaml and arena.png into --out.")
    run.add_argument("world", type=Path, help="world file (YAML, e.g. worlds/flocking.yaml) or an ARGoS .argos file")
    run.add_argument("--robots", type=_positive_int, help="total number of robots (overrides the world)")
    run.add_argument("--ticks", type=_positive_int, help="ticks to simulate (overrides length_ticks)")
    run.add_argument("--seed", type=_non_negative_int, help="random seed (overrides the world)")
    run.add_argument("--mode", choices=MODES, default="composed",
                     help="composed: the controllers hosted together (see --workers); multi-process: one process per "
                          "controller over balanced ROS domains, as in the paper (default: %(default)s)")
    run.add_argument("--executor", choices=EXECUTORS, default="lockstep",
                     help="rclpy executor running the nodes (default: %(default)s)")
    run.add_argument("--robots-per-domain", type=_positive_int, default=None,
                     help="multi-process mode: robots per ROS domain (default: the world's, else 50)")
    run.add_argument("--robots-per-participant", type=_positive_int, default=ROBOTS_PER_PARTICIPANT,
                     help="composed mode with --workers 1: robots per DDS participant, all in one domain; fewer "
                          "make set-up faster, each costs a participant (default: %(default)s; each worker "
                          "process holds one participant)")
    run.add_argument("--workers", type=_workers, default="auto", metavar="K|auto",
                     help="composed mode: worker processes hosting the controller nodes, each with its own "
                          "executor on its own core; 1: everything in this process; auto: from the swarm "
                          "size and the usable cores (default: %(default)s)")
    run.add_argument("--watchdog", type=_positive_float, metavar="SECONDS",
                     help="wall seconds to wait for a controller's answer before its fallback")
    run.add_argument("--fallback", choices=("zero", "previous"), help="command given to a late robot")
    run.add_argument("--domain-id", type=int, default=None,
                     help="ROS domain (default: $ROS_DOMAIN_ID or 0)")
    run.add_argument("--controller", metavar="NAME",
                     help="for an ARGoS .argos file: the controller plugin its robots run")
    run.add_argument("--out", type=Path, default=Path("out"), help="output directory (default: %(default)s)")
    run.add_argument("--record", type=Path, metavar="DIR",
                     help="record a rosbag2 (MCAP) directory: /clock, /swarm/state and --record-topics")
    run.add_argument("--record-topics", nargs="+", default=[], metavar="GLOB",
                     help="per-robot topics to record too, e.g. '/bot1*/cmd_vel' '/*/light'")
    run.add_argument("--markers", action="store_true",
                     help="publish the swarm as one visualization_msgs/MarkerArray on /swarm/markers")
    run.add_argument("--foxglove", nargs="?", const="127.0.0.1:8765", metavar="[HOST:]PORT",
                     help="serve the run live to the Foxglove app (WebSocket; default 127.0.0.1:8765)")
    run.add_argument("--foxglove-topics", nargs="+", default=[], metavar="GLOB",
                     help="per-robot topics to serve too, e.g. '/bot0/*'")
    run.add_argument("--rate", type=_positive_float, metavar="R", help="run at most R x real time (1: real time)")
    run.add_argument("--wait-for-viewer", type=_positive_float, metavar="SECONDS", default=0.0,
                     help="with --foxglove: wait at tick 0 until a viewer subscribes, at most SECONDS")
    run.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    run.add_argument("--no-picture", action="store_true", help="skip arena.png")
    run.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    run.add_argument("--external-controllers", action="store_true",
                     help="run the simulator only; the controllers are hosted by `composed-sim host` shards "
                          "(on this or other machines), waited for before tick 0 (docs/distributed.md)")
    _add_distributed_options(run, "with --external-controllers: ")

    host = sub.add_parser("host", help="host a range of robots' controllers for a simulator elsewhere",
                          description="Host some robots' controller nodes in this process (one context, one "
                                      "executor) for a simulator started with `run --external-controllers`, on "
                                      "this or another machine; ends when that simulator is gone, or on "
                                      "Ctrl-C/SIGTERM (docs/distributed.md).")
    host.add_argument("world", type=Path, help="the simulator's world file (YAML or ARGoS)")
    host.add_argument("--robots", required=True, metavar="RANGES",
                      help="robot indices to host: 0-639, 5 or 0-9,20-29")
    host.add_argument("--world-robots", type=_positive_int, metavar="N",
                      help="total number of robots, when the simulator was given --robots N")
    host.add_argument("--seed", type=_non_negative_int, help="random seed, when the simulator was given --seed")
    host.add_argument("--controller", metavar="NAME", help="for an ARGoS .argos file: the controller plugin")
    host.add_argument("--executor", choices=EXECUTORS, default="lockstep",
                      help="rclpy executor running the hosted nodes (default: %(default)s)")
    host.add_argument("--domain-id", type=int, default=None, help="ROS domain (default: $ROS_DOMAIN_ID or 0)")
    _add_distributed_options(host, "")

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

    sub.add_parser("worlds", help="list the shipped world files")

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
    return parser


def _add_distributed_options(parser: argparse.ArgumentParser, prefix: str) -> None:
    from composed_sim.hosts.discovery import DEFAULT_DISCOVERY_TIMEOUT_S, RANGES
    parser.add_argument("--discovery-timeout", type=_positive_float, metavar="SECONDS",
                        default=DEFAULT_DISCOVERY_TIMEOUT_S,
                        help=f"{prefix}how long to wait for the other side before giving up (default: %(default)s)")
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


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    args.exit_when_done = argv is None    # a program of its own (not called from Python): see cmd_run
    try:
        if args.command == "plugins":
            return cmd_plugins()
        if args.command == "bench":
            from composed_sim import bench
            return bench.run(args)
        if args.command == "sweep":
            from composed_sim.sweep import command as sweep_command
            return sweep_command.run(args)
        if args.command == "render":
            return cmd_render(args)
        if args.command == "replay":
            return cmd_replay(args)
        if args.command == "export":
            return cmd_export(args)
        if args.command == "worlds":
            return cmd_worlds()
        if args.command == "host":
            return cmd_host(args)
        if args.json and args.exit_when_done:
            _keep_stdout_for_json()
        return cmd_run(args)
    except UserError as e:
        print(f"composed-sim: error: {e}", file=sys.stderr)
        return EXIT_USAGE


def cmd_plugins() -> int:
    from composed_sim import plugins
    try:
        found = plugins.installed()
    except plugins.PluginError as e:
        raise UserError(str(e)) from None
    for name, ep in found.items():
        dist = getattr(ep, "dist", None)
        print(f"{name:20s} {ep.value}  ({dist.name} {dist.version})" if dist else f"{name:20s} {ep.value}")
    return 0


def _domain_id(arg: int | None) -> int:
    text = str(arg) if arg is not None else os.environ.get("ROS_DOMAIN_ID", "0") or "0"
    try:
        value = int(text)
    except ValueError:
        raise UserError(f"ROS_DOMAIN_ID: expected a whole number, got {text!r}") from None
    from composed_sim.world.schema import MAX_DOMAIN
    if not 0 <= value <= MAX_DOMAIN:
        raise UserError(f"--domain-id: must be within 0..{MAX_DOMAIN} (got {value})")
    return value


class _Interrupts:
    """First Ctrl-C/SIGTERM: stop at the next tick boundary and write results. Second: exit now."""

    def __init__(self, message: str = "stopping at the next tick"):
        self.requested = False
        self.on_second = None    # called before a hard quit, e.g. to close a recording
        self.message = message

    def __enter__(self):
        self._old = {s: signal.signal(s, self._handle) for s in (signal.SIGINT, signal.SIGTERM)}
        return self

    def _handle(self, signum, frame):
        if self.requested:
            if self.on_second is not None:
                self.on_second()
            os._exit(EXIT_INTERRUPTED)
        self.requested = True
        print(f"\ncomposed-sim: {self.message} (again to quit at once)", file=sys.stderr)

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)


def cmd_run(args) -> int:
    from composed_sim import plugins
    from composed_sim.core.placement import PlacementError
    from composed_sim.hosts.composed import ComposedHost
    from composed_sim.hosts.controllers import HostError
    from composed_sim.hosts.domain_claim import DomainTaken, claim_domains, claim_free_domain, run_identity
    from composed_sim.hosts.workers import WorkerHost, auto_workers, usable_cores
    from composed_sim.results import summarize, write_results

    world = _load_any_world(args)
    lockstep = {k: v for k, v in (("watchdog_s", args.watchdog), ("fallback", args.fallback)) if v is not None}
    if lockstep:
        world = world.model_copy(update={"lockstep": world.lockstep.model_copy(update=lockstep)})
    from composed_sim.ros.participants import remove_stale_shared_memory
    remove_stale_shared_memory()        # what dead runs left in /dev/shm (ros/participants.py)
    domain_given = args.domain_id is not None or bool(os.environ.get("ROS_DOMAIN_ID"))
    domain_id = _domain_id(args.domain_id)
    check_writable(args.out)
    if args.record is not None and args.record.exists():
        raise UserError(f"--record {args.record}: already exists; a recording goes into a new directory")
    if args.record_topics and args.record is None:
        raise UserError("--record-topics: needs --record DIR")
    if (args.foxglove_topics or args.wait_for_viewer) and args.foxglove is None:
        raise UserError("--foxglove-topics and --wait-for-viewer: need --foxglove")
    if args.foxglove is not None:
        from composed_sim.foxglove_server import parse_address
        try:
            args.foxglove = parse_address(args.foxglove)
        except ValueError as e:
            raise UserError(f"--foxglove: {e}") from None
    if not args.external_controllers:
        _check_no_distributed_flags(args)

    distributed = _distributed_settings(args) if args.external_controllers else None
    _check_plugins(args.world, world)

    def make_host(domain_id: int):
        if args.external_controllers:
            from composed_sim.hosts.external import ExternalControllersHost
            return ExternalControllersHost(world, domain_id=domain_id, discovery_timeout_s=args.discovery_timeout,
                                           discovery=distributed)
        if args.mode == "multi-process":
            from composed_sim.hosts.multiprocess import MultiProcessHost
            return MultiProcessHost(world, executor=args.executor, domain_id=domain_id,
                                    robots_per_domain=args.robots_per_domain)
        workers = auto_workers(len(world.robot_names())) if args.workers == "auto" else args.workers
        if workers == 1:
            return ComposedHost(world, executor=args.executor, domain_id=domain_id,
                                robots_per_participant=args.robots_per_participant)
        return WorkerHost(world, workers=workers, executor=args.executor, domain_id=domain_id)

    try:
        host = make_host(domain_id)
        # The run owns its domains (hosts/domain_claim.py): a given one must be free, else the
        # first free block is taken and the host rebuilt there.
        used = sorted(set(host.domains.values())) if args.mode == "multi-process" and not args.external_controllers \
            else [domain_id]
        given = domain_given or (args.mode == "multi-process" and used[0] != domain_id)
        about = run_identity(world.name)
        if given:
            claim = claim_domains(used, about, given=True)
        else:
            claim, domain_id = claim_free_domain(len(used), about)
            host = make_host(domain_id)
            used = [domain_id + i for i in range(len(used))]
            print(f"composed-sim: ROS domain {domain_id}{f'..{used[-1]}' if len(used) > 1 else ''} (free, "
                  f"picked; to watch it: ROS_DOMAIN_ID={domain_id} ros2 topic list)", file=sys.stderr)
    except (HostError, DomainTaken) as e:
        raise UserError(str(e)) from None

    def finish(result, checkpoint: bool = False) -> dict:
        mode = "external-controllers" if args.external_controllers else args.mode
        summary = summarize(world, result, setup_s=host.setup.setup_s, mode=mode,
                            executor=args.executor,
                            phases={"physics_s": host.sim.times.physics_s, "sensing_s": host.sim.times.sensing_s})
        summary["participants"] = host.setup.participants
        summary["workers"] = host.setup.workers
        summary["workers_requested"] = args.workers if args.mode == "composed" else None
        if isinstance(host, WorkerHost):        # every process's peak (pages shared between them count in each)
            summary["workers_peak_rss_mb"] = [round(mb, 1) for mb in host.workers_peak_rss_mb()]
            summary["peak_rss_mb"] += sum(summary["workers_peak_rss_mb"])
        summary["domain_id"], summary["domains"] = used[0], used
        summary["checkpoint"] = checkpoint     # true: written while running; the run did not end
        summary["out"] = str(args.out)
        write_results(args.out, world, result, summary, picture=not (args.no_picture or checkpoint),
                      checkpoint=checkpoint)
        return summary

    with _Interrupts() as interrupts, contextlib.ExitStack() as outputs:
        try:
            with host:
                if host.setup.workers > 1 and not args.json:     # said once set-up went well
                    print(f"composed-sim: {len(host.sim.names)} robots in {host.setup.workers} worker processes"
                          + (f" (--workers auto, {usable_cores()} usable cores)" if args.workers == "auto" else ""),
                          file=sys.stderr)
                observers = _run_observers(args, world, host, outputs, interrupts)
                progress = _progress_bar(world.length_ticks, disabled=args.no_progress)
                try:
                    result = host.run(progress=progress.update, should_stop=lambda: interrupts.requested,
                                      observers=observers, checkpoint=lambda partial: finish(partial, True))
                except Exception as e:
                    partial = getattr(e, "partial_result", None)
                    if partial is not None:   # write what was simulated before the failure
                        finish(partial)
                        print(f"composed-sim: the run failed at tick {partial.trajectories.ticks_done}; "
                              f"results so far are in {args.out}/", file=sys.stderr)
                    raise
                finally:
                    progress.close()
                summary = finish(result)
                code = EXIT_INTERRUPTED if result.interrupted else 0
                if args.exit_when_done and isinstance(host, (ComposedHost, WorkerHost)):
                    # Destroying thousands of nodes one by one takes minutes (each destruction
                    # republishes the participant's graph, docs/speed.md): with every result and
                    # the recording written, the process ends and the system reclaims the rest.
                    outputs.close()
                    _print_summary(args, world, summary)
                    sys.stdout.flush()
                    sys.stderr.flush()
                    os._exit(code)
        except (plugins.PluginError, PlacementError) as e:
            raise UserError(_located(args.world, e)) from None
        except HostError as e:
            raise UserError(str(e)) from None
    claim.release()
    _print_summary(args, world, summary)
    return code


def _print_summary(args, world, summary: dict) -> None:
    if args.json:
        with _json_stdout():
            print(json.dumps(summary, indent=2), flush=True)
    else:
        from composed_sim.loop_functions import describe
        metrics = summary.get("metrics") or {}
        print(_human_summary(summary, describe(world, metrics.get("initial", {}), metrics.get("final", {}))))


_json_fd: int | None = None     # the real stdout while a --json run sends everything else to stderr


def _keep_stdout_for_json() -> None:
    """Fast DDS's C++ logging writes to file descriptor 1 (e.g. about stale shared-memory ports
    of a killed run): with --json, stdout must hold the summary only, so until then fd 1 is stderr."""
    global _json_fd
    if _json_fd is None:
        sys.stdout.flush()
        _json_fd = os.dup(1)
        os.dup2(2, 1)


@contextlib.contextmanager
def _json_stdout():
    if _json_fd is None:
        yield
        return
    sys.stdout.flush()
    os.dup2(_json_fd, 1)
    try:
        yield
    finally:
        sys.stdout.flush()


def _check_plugins(world_path, world) -> None:
    """Every group's controller plugin loads: one error naming the world file's line and field,
    before any node or process is started."""
    from composed_sim import plugins
    for i, group in enumerate(world.robots):
        try:
            plugins.load(group.controller)
        except plugins.PluginError as e:
            e.field = ("robots", i, "controller")
            raise UserError(_located(world_path, e)) from None
    from composed_sim.loop_functions import LoopFunctionsError, make
    try:
        make(world)        # loads the class and checks its params; init() comes with the run
    except LoopFunctionsError as e:
        raise UserError(_located(world_path, e)) from None


def _located(world_path, error: Exception) -> str:
    """The error's message, prefixed with the world file's line of the field it concerns."""
    from composed_sim.world.loader import field_line, format_path
    field = getattr(error, "field", ())
    if not field and getattr(error, "group_index", None) is not None:    # a PlacementError
        field = ("robots", error.group_index, "placement")
    if not field:
        return str(error)
    message = str(error)
    path = format_path(field)
    if not message.startswith(path.split(".")[0]):
        message = f"{path}: {message}"
    return f"{field_line(world_path, field)}: {message}"


def _distributed_settings(args) -> str:
    """Check the flags of a distributed run and put its discovery settings into the environment."""
    from composed_sim.hosts.discovery import DiscoveryError, configure
    if args.command == "run" and args.mode != "composed":
        raise UserError("--external-controllers: the controllers are in `composed-sim host` shards, "
                        "so --mode multi-process does not apply")
    try:
        description, warning = configure(discovery_range=args.discovery_range, static_peers=args.static_peers,
                                         discovery_server=args.discovery_server)
    except DiscoveryError as e:
        raise UserError(str(e)) from None
    if warning:
        print(f"composed-sim: note: {warning}", file=sys.stderr)
    return description


def _check_no_distributed_flags(args) -> None:
    given = [flag for flag, value in (("--discovery-range", args.discovery_range), ("--static-peers", args.static_peers),
                                      ("--discovery-server", args.discovery_server)) if value is not None]
    if given:
        raise UserError(f"{given[0]}: only for a distributed run (with --external-controllers)")


def cmd_host(args) -> int:
    """A controller shard: serves until the simulator is gone (0) or Ctrl-C/SIGTERM (130)."""
    from composed_sim import plugins
    from composed_sim.hosts.controllers import HostError
    from composed_sim.hosts.robot_ranges import RangeError, parse_ranges
    from composed_sim.hosts.shard import ShardHost

    world = _load_any_world(argparse.Namespace(world=args.world, robots=args.world_robots, ticks=None,
                                               seed=args.seed, controller=args.controller))
    try:
        robots = parse_ranges(args.robots, len(world.robot_names()))
    except RangeError as e:
        raise UserError(f"--robots: {e}") from None
    domain_id = _domain_id(args.domain_id)
    discovery = _distributed_settings(args)
    with _Interrupts("stopping the shard") as interrupts:
        try:
            with ShardHost(world, robots, executor=args.executor, domain_id=domain_id,
                           should_stop=lambda: interrupts.requested) as shard:
                print(f"composed-sim host: {len(robots)} controllers ({args.robots}) in ROS domain {domain_id}, "
                      f"discovery {discovery}; waiting for the simulator", file=sys.stderr)
                if shard.wait_for_simulator(args.discovery_timeout):
                    print("composed-sim host: matched with the simulator; serving", file=sys.stderr)
                    ended = shard.serve()
                else:
                    ended = "stopped"
        except (plugins.PluginError, HostError) as e:
            raise UserError(str(e)) from None
    print(f"composed-sim host: {'the simulator is gone' if ended == 'simulator gone' else 'stopped'}; done",
          file=sys.stderr)
    return EXIT_INTERRUPTED if ended == "stopped" else 0


def _load_any_world(args):
    """A YAML world file or an ARGoS experiment file, with the command line's overrides."""
    from composed_sim.argos_import import ArgosFileError, is_argos_file, load_argos, warning_text
    from composed_sim.world.loader import WorldFileError, load_world, with_overrides

    try:
        if is_argos_file(args.world):
            try:
                world, warnings = load_argos(args.world, controller=args.controller, ticks=args.ticks)
            except ArgosFileError as e:      # the reason first, then what else the import noticed
                text = warning_text(str(args.world), list(e.warnings))
                raise UserError(str(e) + (f"\ncomposed-sim: warning: {text}" if text else "")) from None
            text = warning_text(str(args.world), warnings)
            if text:
                print(f"composed-sim: warning: {text}", file=sys.stderr)
            return with_overrides(world, robots=args.robots, ticks=args.ticks, seed=args.seed,
                                  source=str(args.world))
        if args.controller is not None:
            raise UserError("--controller: only for ARGoS .argos files (a YAML world names its controllers)")
        return load_world(args.world, robots=args.robots, ticks=args.ticks, seed=args.seed)
    except WorldFileError as e:
        raise UserError(str(e)) from None


def _run_observers(args, world, host, outputs: contextlib.ExitStack, interrupts) -> list:
    """The recording, live markers, the Foxglove server and pacing asked for on the command
    line, as tick observers (in that order: a tick is shown before the pause after it)."""
    from composed_sim.observers import MarkerObserver, RecordingObserver, Scene
    from composed_sim.ros.taps import Taps

    observers, taps = [], []
    scene = Scene(host.sim, world.tick_ns)
    recorder = None
    if args.record is not None:
        from composed_sim.recording import BagRecorder
        recorder = outputs.enter_context(BagRecorder(args.record, robot_names=host.sim.names, tick_s=world.tick_s,
                                                     topics_globs=args.record_topics, world=world))
        interrupts.on_second = recorder.close_if_idle   # even a hard quit leaves a readable bag
        recorder.set_custom("executor", args.executor)  # what `replay --check` re-simulates with
        observers.append(RecordingObserver(recorder, scene))
        if args.record_topics:
            _warn_unmatched_globs(args.record_topics, world, "--record-topics")
            taps.append(recorder)
    if args.markers:
        observers.append(MarkerObserver(host.observer_node(), scene))
    if args.foxglove is not None:
        from composed_sim.foxglove_server import FoxgloveError, FoxgloveServer
        try:
            server = FoxgloveServer(scene, args.foxglove, dict(_run_topics(world)), args.foxglove_topics,
                                    wait_for_viewer_s=args.wait_for_viewer)
        except FoxgloveError as e:
            raise UserError(str(e)) from None
        outputs.callback(server.close)
        print(f"composed-sim: serving Foxglove on ws://{args.foxglove[0]}:{server.port}", file=sys.stderr)
        observers.append(server)
        if args.foxglove_topics:
            _warn_unmatched_globs(args.foxglove_topics, world, "--foxglove-topics")
            taps.append(server)
    if taps:
        host.set_message_tap(Taps(taps))
    if args.rate is not None:
        from composed_sim.pacing import Pacer
        observers.append(Pacer(args.rate, world.tick_s))
    return observers


def _run_topics(world) -> list[tuple[str, str]]:
    """(topic, message type) of every robot's contract topic in this run."""
    from composed_sim.ros import contract as c
    from composed_sim.ros.robot_settings import robot_devices
    return [(c.topic_name(name, t), c.type_name(t.msg_type))
            for name, devices in zip(world.robot_names(), robot_devices(world)) for t in c.robot_topics(devices)]


def _warn_unmatched_globs(globs: list[str], world, flag: str) -> None:
    """A topic glob that matches no topic of this run is a warning naming two that exist."""
    from composed_sim.ros import contract as c
    from composed_sim.ros.taps import TopicGlobs
    topics = [topic for topic, _ in _run_topics(world)] + [c.SWARM_MARKERS_TOPIC]
    for glob in globs:
        matcher = TopicGlobs([glob])
        if not any(matcher.wants(t) for t in topics):
            print(f"composed-sim: warning: {flag} {glob!r} matches no topic of this run "
                  f"(its topics are like {topics[0]} and {topics[-2] if len(topics) > 1 else topics[0]})",
                  file=sys.stderr)


def cmd_export(args) -> int:
    from composed_sim.export import ExportError, export_table
    out = args.out or args.results / f"trajectories.{args.format}"
    try:
        rows = export_table(args.results, out, args.format)
    except ExportError as e:
        raise UserError(str(e)) from None
    print(f"{out}: {rows} rows")
    return 0


def cmd_render(args) -> int:
    from composed_sim.render import render
    out = _render_target(args.out)
    traj, world, leds, tick_s = _load_results_or_recording(args.source)
    frames = render(traj, world, out, led_colors=leds, fps=args.fps, size_px=args.size,
                    trail_ticks=args.trail, every=args.every, tick_s=tick_s)
    print(f"{out}: {frames} frame{'s' if frames != 1 else ''}")
    return 0


def cmd_replay(args) -> int:
    from composed_sim.render import render
    out = _render_target(args.out) if args.out else None
    rec = _read_recording(args.recording)
    n = len(rec.names)
    print(f"{args.recording}: {rec.world.name if rec.world else 'unknown world'}, {n} robots, "
          f"{rec.ticks_done} ticks recorded ({rec.ticks_done * rec.tick_s:.1f} s sim time); "
          f"topics: {', '.join(sorted(rec.topics))}")
    if rec.world is not None and n and rec.world.lights:
        import numpy as np
        centroid = np.asarray(rec.positions[-1]).mean(axis=0)
        print(f"  final centroid to light: {np.linalg.norm(centroid - rec.world.lights[0].position):.2f} m")
    if out is not None:
        frames = render(rec, rec.world, out, led_colors=rec.led_colors, fps=args.fps, size_px=args.size,
                        trail_ticks=args.trail, every=args.every, tick_s=rec.tick_s)
        print(f"{out}: {frames} frames")
    if args.check:
        problem = _check_recording(rec)
        if problem:
            print(f"composed-sim: check failed: {problem}", file=sys.stderr)
            return 1
    return 0


def _check_recording(rec) -> str | None:
    """Re-simulate the recorded world (its seed, its executor) and compare every recorded tick's
    /swarm/state with the simulation, bit for bit. None when they agree; else the first gap or
    difference."""
    import numpy as np
    if rec.world is None:
        return "the recording holds no world to re-simulate"
    ticks = rec.ticks
    if len(ticks) == 0 or ticks[0] != 0:
        return f"the recording does not start at tick 0 (first: {ticks[0] if len(ticks) else 'none'})"
    gaps = np.flatnonzero(np.diff(ticks) != 1)
    if len(gaps):
        t = int(ticks[gaps[0]])
        return f"tick {t + 1} is missing (after tick {t}, the next recorded is {int(ticks[gaps[0] + 1])})"
    from composed_sim.hosts.composed import ComposedHost
    from composed_sim.hosts.domain_claim import claim_free_domain, run_identity
    executor = rec.executor or "lockstep"
    claim, domain = claim_free_domain(1, run_identity(rec.world.name))
    try:
        with ComposedHost(rec.world, executor=executor, domain_id=domain) as host:
            if host.sim.names != rec.names:
                return "the recorded robots are not the recorded world's"
            t = host.run(len(ticks) - 1).trajectories
    finally:
        claim.release()
    for name, recorded, simulated in (("position", rec.positions, t.positions), ("heading", rec.headings, t.headings),
                                      ("LED colour", rec.led_colors, t.led_colors)):
        differs = np.flatnonzero((recorded != simulated).reshape(len(ticks), len(rec.names), -1).any(axis=2).ravel())
        if len(differs):
            tick, robot = divmod(int(differs[0]), len(rec.names))
            return (f"tick {tick}, {rec.names[robot]}: the recorded {name} {recorded[tick, robot].tolist()} is not the "
                    f"re-simulated {simulated[tick, robot].tolist()} (world {rec.world.name!r}, seed {rec.world.seed}, "
                    f"{executor} executor)")
    print(f"  check: ticks 0…{len(ticks) - 1} re-simulated (seed {rec.world.seed}, {executor} executor): every "
          f"recorded pose and LED colour identical, bit for bit")
    return None


def _render_target(out: Path) -> Path:
    if out.suffix.lower() not in (".png", ".gif", ".mp4"):
        raise UserError(f"--out {out}: the file must end in .png, .gif or .mp4")
    parent = out.parent if str(out.parent) else Path(".")
    check_writable(parent)
    parent.mkdir(parents=True, exist_ok=True)      # the picture is drawn next, right away
    return out


def _read_recording(path: Path):
    from composed_sim.recording import RecordingError, read_recording
    try:
        return read_recording(path)
    except (RecordingError, FileNotFoundError, NotADirectoryError) as e:
        raise UserError(f"{path}: not a readable recording ({e})") from None


def _load_results_or_recording(source: Path):
    """(trajectories, world, led colours [T+1, n, 3] or None, tick_s) from either kind of directory."""
    from composed_sim.results import TRAJECTORIES, WORLD, load_trajectories
    from composed_sim.world.loader import WorldFileError, load_world
    if (source / "metadata.yaml").exists():
        rec = _read_recording(source)
        return rec, rec.world, rec.led_colors, rec.tick_s
    if not (source / TRAJECTORIES).exists():
        raise UserError(f"{source}: neither a results directory ({TRAJECTORIES}) nor a recording (metadata.yaml)")
    try:
        world = load_world(source / WORLD)
    except WorldFileError as e:
        raise UserError(str(e)) from None
    traj = load_trajectories(source / TRAJECTORIES)
    return traj, world, traj.led_colors, world.tick_s


def shipped_worlds() -> list[Path]:
    """worlds/*.yaml and *.argos next to the package (a source checkout or an editable install)."""
    here = Path(__file__).resolve().parent.parent / "worlds"
    return sorted(p for p in here.glob("*") if p.suffix in (".yaml", ".argos")) if here.is_dir() else []


def cmd_worlds() -> int:
    from composed_sim.argos_import import is_argos_file
    worlds = shipped_worlds()
    if not worlds:
        raise UserError("no shipped worlds found next to the package (install from a source checkout)")
    for path in worlds:
        first = next((line.lstrip("# ").strip() for line in path.read_text().splitlines()
                      if line.startswith("#") or line.startswith("<!--")), "")
        kind = "ARGoS" if is_argos_file(path) else "YAML"
        print(f"{path}  [{kind}]  {first.strip('<!- >')}")
    return 0


PROGRESS_LOG_S = 5.0    # without a terminal: a progress line this often at most


def _progress_bar(total: int, disabled: bool):
    """tqdm's bar on a terminal; on a log (CI, a file, a pipe) a plain line now and then instead
    of thousands of carriage returns."""
    from tqdm import tqdm
    if disabled or sys.stderr.isatty():
        return tqdm(total=total, unit="tick", file=sys.stderr, disable=disabled, dynamic_ncols=True,
                    desc="simulating")
    return _ProgressLines(total)


class _ProgressLines:
    def __init__(self, total: int):
        import time
        self._clock = time.monotonic
        self.total, self.done = total, 0
        self._start = self._last = self._clock()
        self._said = False

    def update(self, n: int = 1) -> None:
        self.done += n
        now = self._clock()
        if not self._said or now - self._last >= PROGRESS_LOG_S:
            self._said, self._last = True, now
            self._line(now)

    def _line(self, now: float) -> None:
        rate = self.done / max(now - self._start, 1e-9)
        print(f"simulating: {self.done}/{self.total} ticks ({100 * self.done / max(self.total, 1):.0f} %), "
              f"{rate:.1f} tick/s", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.done and self._last != self._clock():
            self._line(self._clock())


def _workers_text(s: dict) -> str:
    if not s.get("workers") or s["workers"] == 1:
        return ""
    return f" in {s['workers']} worker processes" + (" (auto)" if s.get("workers_requested") == "auto" else "")


def _human_summary(s: dict, metric_lines: list[str] = ()) -> str:
    ph = s["phases_s"]
    lines = [
        f"{s['world']}: {s['robots']} robots, {s['ticks']} ticks ({s['sim_time_s']:.1f} s sim time), "
        f"{s['mode']} mode{_workers_text(s)}, {s['executor']} executor"
        + ("  [interrupted]" if s["interrupted"] else ""),
        f"  setup {s['setup_s']:.2f} s, ticks {s['ticks_wall_s']:.2f} s wall, "
        f"real-time factor {s['real_time_factor'] or 0:.2f}, peak RSS {s['peak_rss_mb']:.0f} MB",
        f"  per tick: physics {1e3 * ph['physics_s'] / max(s['ticks'], 1):.1f} ms, "
        f"sensing {1e3 * ph['sensing_s'] / max(s['ticks'], 1):.1f} ms, "
        f"ROS exchange {1e3 * ph['ros_exchange_s'] / max(s['ticks'], 1):.1f} ms",
        f"  violations: {s['violations']}",
    ]
    lines += metric_lines
    if s.get("finished"):
        lines.append(f"  ended by the loop functions at tick {s['ticks']}")
    lines.append(f"  results in {s['out']}/ (summary.json, trajectories.npz, arena.png)")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
