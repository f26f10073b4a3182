"""``composed-sim run``: load the world, pick and start the host, run the ticks with the observers,
write the results, whatever ends the run."""
from __future__ import annotations

import contextlib
import errno
import json
import os
import sys

from composed_sim.command_line import EXIT_INTERRUPTED, RunStopped, UserError, check_writable
from composed_sim.cli.common import (Interrupts, check_no_distributed_flags, check_plugins, distributed_settings,
                                     load_any_world, located, pick_domain)
from composed_sim.cli.report import print_summary, progress_bar, watch_hint

EXIT_CONTROLLER_FAILED = 1      # --fail-fast: a controller failed


def cmd_run(args) -> int:
    from composed_sim.hosts.composed import ComposedHost
    from composed_sim.hosting import HostError
    from composed_sim.hosts.domain_claim import DomainTaken, claim_domains, claim_free_domain, run_identity
    from composed_sim.hosting.node_logs import LEVELS, Console, LogSettings, NodeLogs
    from composed_sim.hosts.workers.host import WorkerHost, auto_workers
    from composed_sim.outputs.results import summarize, write_results

    world = load_any_world(args)
    lockstep = {k: v for k, v in (("watchdog_s", args.watchdog), ("fallback", args.fallback)) if v is not None}
    if lockstep:
        world = world.model_copy(update={"lockstep": world.lockstep.model_copy(update=lockstep)})
    from composed_sim.hosting.participants import remove_stale_shared_memory
    remove_stale_shared_memory()        # what dead runs left in /dev/shm (hosting/participants.py)
    domain_given = args.domain_id is not None or bool(os.environ.get("ROS_DOMAIN_ID"))
    domain_id = pick_domain(args.domain_id)
    check_writable(args.out)
    if args.record is not None and args.record.exists():
        raise UserError(f"--record {args.record}: already exists; a recording goes into a new directory")
    if args.record_topics and args.record is None:
        raise UserError("--record-topics: needs --record DIR")
    if (args.foxglove_topics or args.wait_for_viewer) and args.foxglove is None:
        raise UserError("--foxglove-topics and --wait-for-viewer: need --foxglove")
    if args.foxglove is not None:
        from composed_sim.live.foxglove_server import parse_address
        try:
            args.foxglove = parse_address(args.foxglove)
        except ValueError as e:
            raise UserError(f"--foxglove: {e}") from None
    if not args.external_controllers:
        check_no_distributed_flags(args)

    distributed = distributed_settings(args) if args.external_controllers else None
    check_plugins(args.world, world)
    # The nodes' log lines and tracebacks: OUT/logs/<robot>.log, the console's share once (hosting/node_logs.py).
    logs_dir = args.out / "logs"
    for old in logs_dir.glob("*.log"):          # a run before into the same --out
        old.unlink()
    logs = NodeLogs(LogSettings(str(logs_dir), LEVELS[args.log_level], rosout=args.record is not None),
                    world.tick_ns, console=Console(logs_hint=str(logs_dir)))
    fail_fast = FailFast(args.fail_fast)

    def make_host(domain_id: int):
        if args.external_controllers:
            from composed_sim.hosts.distributed.external import ExternalControllersHost
            return ExternalControllersHost(world, domain_id=domain_id, discovery_timeout_s=args.discovery_timeout,
                                           discovery=distributed)
        if args.mode == "multi-process":
            from composed_sim.hosts.multiprocess.host import MultiProcessHost
            return MultiProcessHost(world, executor=args.executor, domain_id=domain_id,
                                    robots_per_domain=args.robots_per_domain, logs=logs)
        workers = auto_workers(len(world.robot_names())) if args.workers == "auto" else args.workers
        if workers == 1:
            return ComposedHost(world, executor=args.executor, domain_id=domain_id,
                                robots_per_participant=args.robots_per_participant, logs=logs)
        return WorkerHost(world, workers=workers, executor=args.executor, domain_id=domain_id, logs=logs)

    try:
        host = make_host(domain_id)
        # The run owns its domains (hosts/domain_claim.py): a given one must be free, else the
        # first free block is taken and the host rebuilt there.
        used = host.ros_domains()
        given = domain_given or (args.mode == "multi-process" and used[0] != domain_id)
        about = run_identity(world.name)
        shards_first = args.external_controllers    # distributed: its shards may be up already
        if given:
            claim = claim_domains(used, about, given=True, controllers_expected=shards_first)
        else:
            claim, domain_id = claim_free_domain(len(used), about, controllers_expected=shards_first)
            host = make_host(domain_id)
            used = [domain_id + i for i in range(len(used))]
            hint = watch_hint(domain_id, foxglove=args.foxglove is not None, markers=args.markers)
            print(f"composed-sim: ROS domain {domain_id}{f'..{used[-1]}' if len(used) > 1 else ''} (free, "
                  f"picked); {hint}", file=sys.stderr)
    except (HostError, DomainTaken) as e:
        raise UserError(str(e)) from None

    def finish(result, checkpoint: bool = False) -> tuple[dict, list[str]]:
        """Write the results; the summary and the names of the files written."""
        mode = "external-controllers" if args.external_controllers else args.mode
        summary = summarize(world, result, setup_s=host.setup.setup_s, mode=mode,
                            executor=args.executor,
                            phases={"physics_s": host.sim.times.physics_s, "sensing_s": host.sim.times.sensing_s})
        summary["participants"] = host.setup.participants
        summary["workers"] = host.setup.workers
        summary["workers_requested"] = args.workers if args.mode == "composed" else None
        workers_peak_rss_mb = host.workers_peak_rss_mb()
        if workers_peak_rss_mb is not None:     # every process's peak (pages shared between them count in each)
            summary["workers_peak_rss_mb"] = [round(mb, 1) for mb in workers_peak_rss_mb]
            summary["peak_rss_mb"] += sum(summary["workers_peak_rss_mb"])
        summary["domain_id"], summary["domains"] = used[0], used
        summary["checkpoint"] = checkpoint     # true: written while running; the run did not end
        summary["out"] = str(args.out)
        summary["logs"] = str(logs_dir)
        summary["failed_by"] = logs.console.failures    # "ZeroDivisionError in pkg.mod:Class": robots
        summary["stopped_by_fail_fast"] = fail_fast.reason
        files = write_results(args.out, world, result, summary, picture=not (args.no_picture or checkpoint),
                              checkpoint=checkpoint)
        return summary, files

    try:
        summary, files, code = _run_and_write(args, world, host, finish, logs, fail_fast)
    except OSError as e:
        if e.errno not in DISK_FULL:
            raise
        claim.release()
        raise RunStopped(_disk_full_line(args, e)) from None
    claim.release()
    print_summary(args, world, summary, files + (["logs/"] if _kept(logs_dir) else []))
    return code


def _kept(folder) -> bool:
    """Did the run write anything into ``folder``? An empty one is removed."""
    if folder.is_dir() and not any(folder.iterdir()):
        folder.rmdir()
    return folder.is_dir()


# A write refused for lack of room: the disk or quota is full, or the file size limit reached.
DISK_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def _disk_full_line(args, error: OSError) -> str:
    """One line: the file that could not be written, the tick reached, what is kept."""
    from composed_sim.outputs.bag_repair import is_unfinished
    from composed_sim.outputs.results import SUMMARY
    partial = getattr(error, "partial_result", None)
    stopped = f" at tick {partial.trajectories.ticks_done}" if partial is not None else ""
    try:
        results = f"results of ticks 0…{json.loads((args.out / SUMMARY).read_text())['ticks']} in {args.out}/"
    except (OSError, ValueError, KeyError):
        results = f"no results in {args.out}/"
    kept = [results]
    if args.record is not None and is_unfinished(args.record):
        kept.append(f"the recording up to its last flush in {args.record}/ (with room again: "
                    f"composed-sim bag repair {args.record})")
    elif args.record is not None:
        kept.append(f"the recording in {args.record}/")
    why = "file size limit reached" if error.errno == errno.EFBIG else "disk full"
    return (f"{why}: cannot write {error.filename or args.out} ({error.strerror}); the run stopped{stopped}; "
            f"kept: {' and '.join(kept)}")


class FailFast:
    """--fail-fast: the first controller failure seen stops the run."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.reason = ""          # the first failure's violation, "bot1: controller failed: …"

    def stops(self, host) -> bool:
        if self.enabled and not self.reason:
            self.reason = _first_failure(host)
        return bool(self.reason)


def _first_failure(host) -> str:
    """The first violation that failed a robot so far, as "bot1: controller failed: …", or ""."""
    from composed_sim.core.violations import FAILED
    exchange = host.exchange
    first = next((v for v in (exchange.violations if exchange is not None else ()) if v.reason.startswith(FAILED)),
                 None)
    return f"{first.robot}: {first.reason}" if first is not None else ""


def _run_and_write(args, world, host, finish, logs, fail_fast: FailFast) -> tuple[dict, list, int]:
    """Run the ticks with the observers, write the results; (summary, files written, exit code)."""
    from composed_sim import plugins
    from composed_sim.core.placement import PlacementError
    from composed_sim.hosting import HostError
    from composed_sim.hosts.lockstep import AnotherSimulator
    from composed_sim.hosts.workers.host import usable_cores

    with Interrupts() as interrupts, contextlib.ExitStack() as outputs:
        try:
            with host:
                if host.setup.workers > 1 and not args.json:     # said once set-up went well
                    print(f"composed-sim: {len(host.sim.names)} robots in {host.setup.workers} worker processes"
                          + (f" (--workers auto, {usable_cores()} usable cores)" if args.workers == "auto" else ""),
                          file=sys.stderr)
                observers = _run_observers(args, world, host, outputs, interrupts, logs)
                progress = progress_bar(world.length_ticks, disabled=args.no_progress)
                try:
                    result = host.run(progress=progress.update,
                                      should_stop=lambda: interrupts.requested or fail_fast.stops(host),
                                      observers=observers, checkpoint=lambda partial: finish(partial, True))
                except Exception as e:
                    partial = getattr(e, "partial_result", None)
                    if isinstance(e, OSError) and e.errno in DISK_FULL:
                        _write_if_room(finish, partial)
                        raise
                    if partial is not None:   # write what was simulated before the failure
                        finish(partial)
                        print(f"composed-sim: the run failed at tick {partial.trajectories.ticks_done}; "
                              f"results so far are in {args.out}/", file=sys.stderr)
                    raise
                finally:
                    progress.close()
                    logs.flush()
                summary, files = finish(result)
                code = EXIT_INTERRUPTED if result.interrupted else 0
                if fail_fast.reason:
                    code = EXIT_CONTROLLER_FAILED
                    print(f"composed-sim: --fail-fast: {fail_fast.reason}; stopped at tick "
                          f"{result.trajectories.ticks_done}, results so far in {args.out}/", file=sys.stderr)
                for line in logs.console.closing_lines():
                    print(line, file=sys.stderr)
                if args.exit_when_done and host.end_before_exit():
                    # With every result and the recording written, the process ends and the system
                    # reclaims the nodes (Host.end_before_exit).
                    outputs.close()
                    print_summary(args, world, summary, files + (["logs/"] if _kept(args.out / "logs") else []))
                    sys.stdout.flush()
                    sys.stderr.flush()
                    os._exit(code)
        except (plugins.PluginError, PlacementError) as e:
            raise UserError(located(args.world, e)) from None
        except (HostError, AnotherSimulator) as e:
            raise UserError(str(e)) from None
    return summary, files, code


def _write_if_room(finish, partial) -> None:
    """The results so far, after a write failed for lack of room: the part written of a file
    is given back, so the smaller files may fit; if not, the last checkpoint stays."""
    if partial is None:
        return
    try:
        finish(partial, True)
    except OSError as e:
        if e.errno not in DISK_FULL:
            raise


def _run_observers(args, world, host, outputs: contextlib.ExitStack, interrupts, logs) -> list:
    """The recording, live markers, the Foxglove server and pacing asked for on the command
    line, as tick observers (in that order: a tick is shown before the pause after it)."""
    from composed_sim.live.observers import MarkerObserver, RecordingObserver, Scene
    from composed_sim.ros.taps import Taps

    observers, taps = [], []
    scene = Scene(host.sim, world.tick_ns)
    recorder = None
    if args.record is not None:
        from composed_sim.outputs.recording import BagRecorder
        recorder = outputs.enter_context(BagRecorder(args.record, robot_names=host.sim.names, tick_s=world.tick_s,
                                                     topics_globs=args.record_topics, world=world))
        interrupts.on_second = recorder.close_if_idle   # even a hard quit leaves a readable bag
        recorder.set_custom("executor", args.executor)  # what `replay --check` re-simulates with
        observers.append(RecordingObserver(recorder, scene))
        from composed_sim.live.observers import RosoutObserver
        observers.append(RosoutObserver(recorder, logs))
        if args.record_topics:
            _warn_unmatched_globs(args.record_topics, world, "--record-topics")
            taps.append(recorder)
    if args.markers:
        observers.append(MarkerObserver(host.observer_node(), scene))
    if args.foxglove is not None:
        from composed_sim.live.foxglove_server import FoxgloveError, FoxgloveServer
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
        from composed_sim.live.pacing import Pacer
        observers.append(Pacer(args.rate, world.tick_s))
    return observers


def _run_topics(world) -> list[tuple[str, str]]:
    """(topic, message type) of every robot's contract topic in this run."""
    from composed_sim.ros import contract as c
    from composed_sim.ros.robot_settings import robot_devices
    return [(c.topic_name(name, t), t.type_name)
            for name, devices in zip(world.robot_names(), robot_devices(world)) for t in c.robot_topics(devices)]


def _warn_unmatched_globs(globs: list[str], world, flag: str) -> None:
    """A topic glob that matches no topic of this run is a warning naming two that exist."""
    from composed_sim.ros import contract as c
    from composed_sim.ros.taps import TopicGlobs
    from composed_sim.hosting.run_wide.relay import is_run_wide
    topics = [topic for topic, _ in _run_topics(world)] + [c.SWARM_MARKERS_TOPIC]
    robots = frozenset(world.robot_names())
    for glob in globs:
        matcher = TopicGlobs([glob])
        # A run-wide topic (/swarm_command) exists once a node publishes it: not known before.
        if not any(matcher.wants(t) for t in topics) and not (glob.startswith("/") and is_run_wide(glob, robots)):
            print(f"composed-sim: warning: {flag} {glob!r} matches no topic of this run "
                  f"(its topics are like {topics[0]} and {topics[-2] if len(topics) > 1 else topics[0]})",
                  file=sys.stderr)
