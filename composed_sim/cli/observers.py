"""The tick observers a run asks for on the command line: the recording, the live views."""
from __future__ import annotations

import contextlib
import sys

from composed_sim.cli.settings import RunSettings
from composed_sim.command_line import UserError


def run_observers(settings: RunSettings, world, host, outputs: contextlib.ExitStack, interrupts, logs) -> list:
    """The recording, live markers, the Foxglove server and pacing asked for on the command
    line, as tick observers (in that order: a tick is shown before the pause after it)."""
    from composed_sim.live.observers import MarkerObserver, RecordingObserver, Scene
    from composed_sim.ros.taps import Taps

    record, live = settings.outputs, settings.live
    observers, taps = [], []
    scene = Scene(host.sim, world.tick_ns)
    recorder = None
    if record.record is not None:
        from composed_sim.outputs.recording import BagRecorder
        recorder = outputs.enter_context(BagRecorder(record.record, robot_names=host.sim.names, tick_s=world.tick_s,
                                                     topics_globs=record.record_topics, world=world))
        interrupts.on_second = recorder.close_if_idle   # even a hard quit leaves a readable bag
        recorder.set_custom("executor", settings.hosting.executor)  # what `replay --check` re-simulates with
        observers.append(RecordingObserver(recorder, scene))
        from composed_sim.live.observers import RosoutObserver
        observers.append(RosoutObserver(recorder, logs))
        if record.record_topics:
            _warn_unmatched_globs(record.record_topics, world, "--record-topics")
            taps.append(recorder)
    if live.markers:
        observers.append(MarkerObserver(host.observer_node(), scene))
    if live.foxglove is not None:
        from composed_sim.live.foxglove_server import FoxgloveError, FoxgloveServer
        try:
            server = FoxgloveServer(scene, live.foxglove, dict(_run_topics(world)), live.foxglove_topics,
                                    wait_for_viewer_s=live.wait_for_viewer_s)
        except FoxgloveError as e:
            raise UserError(str(e)) from None
        outputs.callback(server.close)
        print(f"composed-sim: serving Foxglove on ws://{live.foxglove[0]}:{server.port}", file=sys.stderr)
        observers.append(server)
        if live.foxglove_topics:
            _warn_unmatched_globs(live.foxglove_topics, world, "--foxglove-topics")
            taps.append(server)
    if taps:
        host.set_message_tap(Taps(taps))
    if live.rate is not None:
        from composed_sim.live.pacing import Pacer
        observers.append(Pacer(live.rate, world.tick_s))
    return observers


def _run_topics(world) -> list[tuple[str, str]]:
    """(topic, message type) of every robot's contract topic in this run."""
    from composed_sim.ros import contract as c
    from composed_sim.ros.robot_settings import robot_devices
    return [(c.topic_name(name, t), t.type_name)
            for name, devices in zip(world.robot_names(), robot_devices(world)) for t in c.robot_topics(devices)]


def _warn_unmatched_globs(globs, world, flag: str) -> None:
    """A topic glob that matches no topic of this run is a warning naming two that exist."""
    from composed_sim.ros import contract as c
    from composed_sim.ros.taps import TopicGlobs
    from composed_sim.hosting import is_run_wide
    topics = [topic for topic, _ in _run_topics(world)] + [c.SWARM_MARKERS_TOPIC]
    robots = frozenset(world.robot_names())
    for glob in globs:
        matcher = TopicGlobs([glob])
        # A run-wide topic (/swarm_command) exists once a node publishes it: not known before.
        if not any(matcher.wants(t) for t in topics) and not (glob.startswith("/") and is_run_wide(glob, robots)):
            print(f"composed-sim: warning: {flag} {glob!r} matches no topic of this run "
                  f"(its topics are like {topics[0]} and {topics[-2] if len(topics) > 1 else topics[0]})",
                  file=sys.stderr)


class WorkerMemory:
    """Samples each worker process's resident memory at the ticks where the tick loop samples
    the main process's (``hosts/tick_loop.MEMORY_SAMPLES`` a run): summary.json's
    ``workers_rss_mb_by_tick``, [tick, [MB per worker]] (null for a worker on another machine)."""

    def __init__(self, host, ticks: int):
        from composed_sim.hosts.tick_loop import MEMORY_SAMPLES
        self.host = host
        self.every = max(1, ticks // MEMORY_SAMPLES)
        self.samples: list = []

    def on_tick(self, sim) -> None:
        if sim.tick % self.every == 0:
            self.sample(sim.tick)

    def sample(self, tick: int) -> None:
        found = self.host.workers_rss_mb()
        if found is not None and (not self.samples or self.samples[-1][0] != tick):
            self.samples.append([tick, [None if mb is None else round(mb, 1) for mb in found]])
