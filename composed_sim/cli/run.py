"""``composed-sim run``: load the world, start the host its settings ask for, run the ticks with the
observers, write the results, whatever ends the run."""
from __future__ import annotations

import contextlib
import errno
import json
import os
import sys

from composed_sim.cli.common import Interrupts, check_plugins, configure_discovery, load_any_world, located
from composed_sim.cli.observers import run_observers
from composed_sim.cli.report import JsonStdout, print_summary, progress_bar, watch_hint
from composed_sim.cli.settings import RunSettings
from composed_sim.command_line import EXIT_INTERRUPTED, RunStopped, UserError, check_writable

EXIT_CONTROLLER_FAILED = 1      # --fail-fast: a controller failed
# A write refused for lack of room: the disk or quota is full, or the file size limit reached.
DISK_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def cmd_run(settings: RunSettings, json_stdout: JsonStdout) -> int:
    from composed_sim.hosting import LEVELS, Console, LogSettings, NodeLogs, remove_stale_shared_memory

    world = settings.lockstep.applied_to(load_any_world(settings.world))
    removed = remove_stale_shared_memory()    # what dead processes left in /dev/shm (hosting/dds/shared_memory.py)
    out = settings.outputs.out
    check_writable(out)
    if settings.hosting.discovery is not None:      # --external-controllers: the world's are not started
        configure_discovery(settings.hosting.discovery)
    else:
        check_plugins(settings.world.path, world)
    # The nodes' log lines and tracebacks: OUT/logs/<robot>.log, the console's share once (hosting/guard/node_logs.py).
    logs_dir = out / "logs"
    for old in logs_dir.glob("*.log"):          # a run before into the same --out
        old.unlink()
    logs = NodeLogs(LogSettings(str(logs_dir), LEVELS[settings.outputs.log_level],
                                rosout=settings.outputs.record is not None),
                    world.tick_ns, console=Console(logs_hint=str(logs_dir)))
    run = Run(settings, world, logs, json_stdout)
    run.removed_shared_memory = removed
    try:
        summary, files, code = run.run_and_write()
    except OSError as e:
        if e.errno not in DISK_FULL:
            raise
        run.claim.release()
        raise RunStopped(_disk_full_line(settings, e)) from None
    run.claim.release()
    print_summary(json_stdout if settings.outputs.json else None, world, summary,
                  files + (["logs/"] if _kept(logs_dir) else []))
    return code


class Run:
    """One run: its host in domains of its own, the ticks, the results written."""

    def __init__(self, settings: RunSettings, world, logs, json_stdout: JsonStdout):
        from composed_sim.hosting import HostError
        from composed_sim.hosts.domain_claim import DomainTaken
        from composed_sim.hosts.make import host_in_own_domains
        self.settings, self.world, self.logs, self.json_stdout = settings, world, logs, json_stdout
        self.fail_fast = FailFast(settings.control.fail_fast)
        self.worker_memory = None       # with worker processes: their memory, sampled (cli/observers.py)
        self.removed_shared_memory = 0  # files of dead processes removed from /dev/shm before the run
        try:
            self.host, self.claim, picked = host_in_own_domains(settings.hosting, world, logs)
        except (HostError, DomainTaken) as e:
            raise UserError(str(e)) from None
        self.domains = self.host.ros_domains()
        if picked:
            live = settings.live
            hint = watch_hint(self.domains[0], foxglove=live.foxglove is not None, markers=live.markers)
            print(f"composed-sim: ROS domain {self.domains[0]}"
                  f"{f'..{self.domains[-1]}' if len(self.domains) > 1 else ''} (free, picked); {hint}", file=sys.stderr)

    def finish(self, result, checkpoint: bool = False) -> tuple[dict, list[str]]:
        """Write the results; the summary and the names of the files written."""
        from composed_sim.outputs.results import summarize, write_results
        host, hosting, out = self.host, self.settings.hosting, self.settings.outputs.out
        summary = summarize(self.world, result, setup_s=host.setup.setup_s, mode=self.settings.mode,
                            executor=hosting.executor,
                            phases={"physics_s": host.sim.times.physics_s, "sensing_s": host.sim.times.sensing_s})
        summary["participants"] = host.setup.participants
        summary["workers"] = host.setup.workers
        summary["workers_requested"] = hosting.workers if hosting.mode == "composed" else None
        summary["physics_processes"] = host.sim.physics_processes     # core/engine.py: cells or regions
        workers_peak_rss_mb = host.workers_peak_rss_mb()
        if workers_peak_rss_mb is not None:     # every process's peak (pages shared between them count in each)
            summary["workers_peak_rss_mb"] = [round(mb, 1) for mb in workers_peak_rss_mb]
            summary["peak_rss_mb"] += sum(summary["workers_peak_rss_mb"])
        if self.worker_memory is not None and result.trajectories.ticks_done:
            self.worker_memory.sample(result.trajectories.ticks_done)
            summary["workers_rss_mb_by_tick"] = self.worker_memory.samples
        summary["domain_id"], summary["domains"] = self.domains[0], self.domains
        if hosting.machines is not None:       # the state sent per tick to all machines, payload bytes
            summary["state_bytes_per_tick"] = round(host.bytes_sent_per_tick(result.trajectories.ticks_done))
        summary["checkpoint"] = checkpoint     # true: written while running; the run did not end
        summary["out"] = str(out)
        summary["logs"] = str(out / "logs")
        summary["failed_by"] = self.logs.console.failures    # "ZeroDivisionError in pkg.mod:Class": robots
        summary["stopped_by_fail_fast"] = self.fail_fast.reason
        drones = host.sim.drones
        if drones is not None:
            summary["near_misses"] = drones.near_misses.summary(result.trajectories.names)
        files = write_results(out, self.world, result, summary,
                              picture=self.settings.outputs.picture and not checkpoint, checkpoint=checkpoint,
                              near_misses=None if drones is None else drones.near_misses.events)
        return summary, files

    def run_and_write(self) -> tuple[dict, list, int]:
        """Run the ticks with the observers, write the results; (summary, files written, exit code)."""
        from composed_sim import plugins
        from composed_sim.core.placement import PlacementError
        from composed_sim.hosting import HostError
        from composed_sim.hosts.tick_loop import AnotherSimulator

        with Interrupts() as interrupts, contextlib.ExitStack() as outputs:
            try:
                with self.host:
                    return self._ticks(interrupts, outputs)
            except (plugins.PluginError, PlacementError) as e:
                if getattr(e, "user_traceback", ""):       # once, above the error's line
                    print(f"composed-sim: where it raised:\n{e.user_traceback}", file=sys.stderr)
                raise UserError(located(self.settings.world.path, e)) from None
            except (HostError, AnotherSimulator) as e:
                raise UserError(str(e)) from None

    def _ticks(self, interrupts, outputs: contextlib.ExitStack) -> tuple[dict, list, int]:
        host, settings, out = self.host, self.settings, self.settings.outputs.out
        if self.removed_shared_memory:      # said once the run is set up: an error stays the only line
            n = self.removed_shared_memory
            print(f"composed-sim: removed {n} shared-memory file{'s' if n != 1 else ''} of dead processes "
                  f"from /dev/shm", file=sys.stderr)
        self._say_workers()
        observers = run_observers(settings, self.world, host, outputs, interrupts, self.logs)
        if host.workers_rss_mb() is not None:
            from composed_sim.cli.observers import WorkerMemory
            self.worker_memory = WorkerMemory(host, self.world.length_ticks)
            observers.append(self.worker_memory)
        progress = progress_bar(self.world.length_ticks, disabled=not settings.control.progress)
        from composed_sim.outputs.stream import TrajectoryStream
        try:
            # The poses, metrics and violations go to --out as the run goes (outputs/stream.py).
            result = host.run(progress=progress.update,
                              should_stop=lambda: interrupts.requested or self.fail_fast.stops(host),
                              observers=observers, checkpoint=lambda partial: self.finish(partial, True),
                              trajectories=TrajectoryStream.factory(out, self.world.tick_s))
        except Exception as e:
            partial = getattr(e, "partial_result", None)
            if isinstance(e, OSError) and e.errno in DISK_FULL:
                _write_if_room(self.finish, partial)
                raise
            if partial is not None:   # write what was simulated before the failure
                self.finish(partial)
                print(f"composed-sim: the run failed at tick {partial.trajectories.ticks_done}; "
                      f"results so far are in {out}/", file=sys.stderr)
            raise
        finally:
            progress.close()
            self.logs.flush()
        summary, files = self.finish(result)
        code = EXIT_INTERRUPTED if result.interrupted else 0
        if self.fail_fast.reason:
            code = EXIT_CONTROLLER_FAILED
            print(f"composed-sim: --fail-fast: {self.fail_fast.reason}; stopped at tick "
                  f"{result.trajectories.ticks_done}, results so far in {out}/", file=sys.stderr)
        for line in self.logs.console.closing_lines():
            print(line, file=sys.stderr)
        if settings.control.exit_when_done and host.end_before_exit():
            # With every result and the recording written, the process ends and the system
            # reclaims the nodes (Host.end_before_exit).
            outputs.close()
            host.sim.close()         # the physics regions' workers end in order, not by the death signal
            _leave_no_shared_memory()
            print_summary(self.json_stdout if settings.outputs.json else None, self.world, summary,
                          files + (["logs/"] if _kept(out / "logs") else []))
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
        return summary, files, code

    def _say_workers(self) -> None:
        """Once set-up went well: how many worker processes host the robots."""
        from composed_sim.hosts.settings import AUTO_WORKERS
        from composed_sim.hosts.workers.worker_host import usable_cores
        host = self.host
        if self.settings.hosting.machines is not None:      # also with --json: a script watches for it
            print(f"composed-sim: {len(host.sim.names)} robots on {host.placement()}", file=sys.stderr, flush=True)
        elif (host.setup.workers > 1 or host.sim.physics_processes > 1) and not self.settings.outputs.json:
            auto = self.settings.hosting.workers == AUTO_WORKERS
            physics = host.sim.physics_processes
            print(f"composed-sim: {len(host.sim.names)} robots in {host.setup.workers} worker "
                  f"process{'es' if host.setup.workers > 1 else ''}"
                  + (f" (--workers auto, {usable_cores()} usable cores)" if auto else "")
                  + (f"; physics in {physics} processes" if physics > 1 else ""), file=sys.stderr)


def _leave_no_shared_memory() -> None:
    """This process ends without destroying its participants: the shared-memory files of its own
    and of its ended workers go now, not at the next run (hosting/dds/shared_memory.py)."""
    from composed_sim.hosting import remove_own_shared_memory, remove_stale_shared_memory
    remove_stale_shared_memory()
    remove_own_shared_memory()


def _kept(folder) -> bool:
    """Did the run write anything into ``folder``? An empty one is removed."""
    if folder.is_dir() and not any(folder.iterdir()):
        folder.rmdir()
    return folder.is_dir()


def _disk_full_line(settings: RunSettings, error: OSError) -> str:
    """One line: the file that could not be written, the tick reached, what is kept."""
    from composed_sim.outputs.recording.repair import is_unfinished
    from composed_sim.outputs.results import SUMMARY
    out, record = settings.outputs.out, settings.outputs.record
    partial = getattr(error, "partial_result", None)
    stopped = f" at tick {partial.trajectories.ticks_done}" if partial is not None else ""
    try:
        results = f"results of ticks 0…{json.loads((out / SUMMARY).read_text())['ticks']} in {out}/"
    except (OSError, ValueError, KeyError):
        results = f"no results in {out}/"
    kept = [results]
    if record is not None and is_unfinished(record):
        kept.append(f"the recording up to its last flush in {record}/ (with room again: "
                    f"composed-sim bag repair {record})")
    elif record is not None:
        kept.append(f"the recording in {record}/")
    why = "file size limit reached" if error.errno == errno.EFBIG else "disk full"
    return (f"{why}: cannot write {error.filename or out} ({error.strerror}); the run stopped{stopped}; "
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
