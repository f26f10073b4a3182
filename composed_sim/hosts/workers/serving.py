"""A worker's life after its launch (hosts/workers/launcher.py): its block of robots built in one
participant group, then one tick after another, as the main process sends them.

Everything a worker needs is imported here, at the top: the launcher imports this module once,
before it forks the workers, so that none of them pays for the imports (numpy, scipy, rclpy,
pydantic).
"""
from __future__ import annotations

import os
import resource
import sys
import time
from multiprocessing.connection import Connection
from typing import Callable, Optional

import numpy as np

from composed_sim import plugins
from composed_sim.core.senses import Senses
from composed_sim.hosting import HostError, NodeLogs, ParticipantGroups, use_worker_prefix
from composed_sim.hosts.tick_loop import acted_commands
from composed_sim.hosts.workers.shared_state import SharedState
from composed_sim.hosts.workers.messages import EXIT_SETUP, TickAnswers
from composed_sim.ros.taps import TapBuffer


def serve(fd: int, adopted: Callable[[], None]) -> int:
    """Build the block the main process asks for over the socket ``fd``, then answer its ticks
    until it says stop or is gone; the exit code (EXIT_SETUP: the block could not be built).
    ``adopted()`` runs when the block arrives: the main process sends it only once the launcher
    has exited, so this worker is the main process's child by then."""
    conn = Connection(fd)
    try:
        kind, setup = conn.recv()
    except EOFError:        # the main process is gone, or gave up before this worker's turn
        return 0
    assert kind == "setup", kind
    adopted()

    use_worker_prefix(setup.participant_prefix, setup.scratch_dir)
    world = setup.world
    # The robots' log files are written here; the main process gets the console's part.
    logs = NodeLogs(setup.hosting.logs, world.tick_ns, forward=True) if setup.hosting.logs is not None else None
    groups = ParticipantGroups(world, setup.start, setup.stop, setup.hosting,
                               robots_per_participant=setup.stop - setup.start, first_group=setup.index, logs=logs)
    try:
        groups.__enter__()
    except (plugins.PluginError, HostError) as e:
        if logs is not None:
            logs.flush()
        conn.send(("error", type(e).__name__, str(e), getattr(e, "field", ()), getattr(e, "user_traceback", "")))
        return EXIT_SETUP
    conn.send(("ready", groups.nodes, groups.calls_leave, groups.calls.take_outbox(), groups.answers_later,
               groups.run_wide_timers))
    # What every place of the run serves, before the run-wide nodes' part of tick 0 (which may ask),
    # and when the run-wide nodes' first timer fires (they are worker 0's).
    try:
        message = conn.recv()
    except EOFError:
        return 0
    if message[0] != "served":        # stopped during the start-up
        return 0
    _, served, run_wide_timers = message
    groups.calls.deliver(served)
    groups.note_run_wide_timers(run_wide_timers)
    conn.send(("run_wide", groups.close_run_wide(0), groups.calls.take_outbox()))
    wait, interrupting_hangs = groups.start_serving()
    block = Block(setup, groups, logs, wait, conn)
    with interrupting_hangs:
        while True:
            try:
                message = conn.recv()
            except EOFError:       # the main process is gone
                break
            if message[0] == "tick":
                conn.send(("answers", block.tick(*message[1:])))
            elif message[0] == "clock":
                groups.exchange.publish_clock(message[1])
            elif message[0] == "tap":
                block.tap = TapBuffer(message[1])
                block.node.set_message_tap(block.tap)
            elif message[0] == "stop":
                break
    # Destroying hundreds of nodes one by one takes long (each republishes its participant's
    # graph): nothing is left to write here but the logs, so the process just ends.
    if logs is not None:
        logs.flush()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


class Block:
    """The worker's robots in their participant group: a tick's sensors read from the shared
    state, published, answered, and the answers sent back, as in the single-process host."""

    def __init__(self, setup, groups: ParticipantGroups, logs: Optional[NodeLogs], wait: Callable[[float], bool],
                 conn: Connection):
        world = setup.world
        self.groups, self.logs, self.wait, self.conn = groups, logs, wait, conn
        (self.node,), self.exchange = groups.simulator_nodes, groups.exchange   # one group, one simulator node
        self.lockstep = world.lockstep
        self.m = setup.stop - setup.start
        self.previous = (np.zeros(self.m), np.zeros(self.m))
        self.seen = 0                       # violations already sent
        self.tap: Optional[TapBuffer] = None
        self.first_tick = None              # (CPU seconds, node code seconds) when the ticks began
        self.senses, self.rows = Senses(world), slice(setup.start, setup.stop)   # this block's sensors are read here
        self.shared = SharedState(self.senses, world.range_and_bearing.payload_bytes, setup.shared_state)
        self.kept: dict = {}                # the scene, floor and lights as last sent (core/senses.py)

    def round_trip(self, calls: list) -> Optional[list]:
        """This block is idle: its calls to the main process, which sends back the calls for it, or
        says the run is quiet (None) (hosting/calls/rounds.py)."""
        self.conn.send(("idle", calls))
        reply = self.conn.recv()
        return reply[1] if reply[0] == "calls" else None

    def tick(self, tick: int, route_messages: bool, changed: dict, batch: list, rounds: bool) -> TickAnswers:
        groups, exchange, node = self.groups, self.exchange, self.node
        groups.remote = self.round_trip if rounds else None
        if self.first_tick is None:
            self.first_tick = (time.process_time(), groups.node_time.seconds)
        self.kept.update(changed)
        frame = self.senses.frame(self.shared.inputs(tick, route_messages, **self.kept), self.shared.rows(self.rows),
                                  self.rows)
        groups.open_tick(frame.tick, batch)
        exchange.publish_tick(frame)
        self.wait(self.lockstep.watchdog_s)
        commands = (np.empty(self.m), np.empty(self.m))
        exchange.close_tick(self.lockstep.fallback, self.previous, commands)
        self.previous = acted_commands(frame.tick, commands)     # what the main process acts on
        self.shared.write_commands(self.rows, *commands)
        answers = TickAnswers(frame.tick, exchange.take_led_commands(), exchange.take_rab_payloads())
        answers.violations = [(v.tick, v.robot, v.reason) for v in node.violations[self.seen:]]
        self.seen = len(node.violations)
        if self.tap is not None:
            answers.tapped = self.tap.drain()
        answers.drones = groups.take_drone_commands()    # before the run-wide nodes' part of the next tick
        answers.run_wide = groups.close_run_wide(frame.tick + 1)
        answers.calls = groups.calls.take_outbox()       # the run-wide nodes' part's calls, for the next tick
        answers.calls_leave = groups.calls_leave          # (a client made since may call another place)
        answers.peak_rss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        answers.another_simulator = exchange.another_simulator()
        if self.logs is not None:
            answers.logs = self.logs.drain()
        answers.cpu_s = time.process_time() - self.first_tick[0]
        answers.node_code_s = groups.node_time.seconds - self.first_tick[1]
        return answers
