"""A worker process of the worker host: a block of robots in one participant group, one executor.

``python -m composed_sim.hosts.worker_process --fd N --parent-pid P`` is started by
``hosts/workers.py``; it talks to the main process over the socket ``N`` (pickled messages,
``multiprocessing.connection``), once per tick each way:

    main → worker   ("setup", WorkerSetup)         once, first
                    ("tap", [glob, …])             record these topics' messages (--record-topics)
                    ("tick", tick, routed, changed, batch)  a tick: the world's state is in the
                                                   shared state (shared_state.py); what changed of
                                                   the scene, floor and lights; the run-wide
                                                   messages that open it (ros/run_wide.py)
                    ("clock", tick)                /clock alone, for the state after the last tick
                    ("stop",)                      end now
    worker → main   ("ready", nodes, messages)     discovery done: tick 0 can start; what its nodes
                                                   published on run-wide topics while being built
                    ("error", kind, message, field) the block could not be built
                    ("answers", TickAnswers)       the tick's LEDs, payloads, violations (its
                                                   commands: in the shared state),
                                                   and its nodes' console lines (hosts/node_logs.py)

Inside, a tick is exactly the single-process host's: the worker reads its block's sensors
(core/senses.py), its simulator node publishes them, the executor runs the controllers' callbacks until every robot answered or the watchdog
expired, and the simulator node's ``close_tick`` computes the commands with the fallbacks.

The worker dies with the main process (PR_SET_PDEATHSIG, SIGKILL included) and ignores SIGINT: a
terminal's Ctrl-C is for the main process, which stops at a tick boundary and then stops us.
"""
from __future__ import annotations

import argparse
import os
import resource
import signal
import sys
import time
from dataclasses import dataclass, field
from typing import Optional

from composed_sim.hosts.processes import die_with_parent

EXIT_SETUP = 3          # the block could not be built; the reason went to the main process


@dataclass
class WorkerSetup:
    world: object             # schema World
    start: int                # the block: robots start … stop-1
    stop: int
    index: int                # the worker's number; its participant group has the same
    executor: str
    domain_id: int
    participant_prefix: bytes  # the GUID prefix of the worker's one participant (ros/participants.py)
    scratch_dir: str           # where the worker may write its Fast DDS profile
    shared_state: int          # the descriptor of the world's state in shared memory (shared_state.py)
    logs: Optional[object] = None   # node_logs.LogSettings: its robots' log files are written here


@dataclass
class TickAnswers:
    """A block's answers to a tick; its commands are in the shared state (shared_state.py)."""
    tick: int
    leds: dict = field(default_factory=dict)           # row in the block → [L, 3] uint8
    rab: dict = field(default_factory=dict)            # row in the block → [B] uint8
    violations: list = field(default_factory=list)     # new ones since the last tick: (tick, robot, reason)
    tapped: list = field(default_factory=list)         # (topic, type, bytes, stamp ns)
    run_wide: list = field(default_factory=list)       # (topic, type, bytes) for the next tick's batch
    peak_rss_kb: int = 0                               # the worker's own peak resident memory so far
    another_simulator: Optional[str] = None            # NodesExchange.another_simulator, this tick
    logs: tuple = ()                                   # NodeLogs.drain(): console lines, failures, /rosout
    cpu_s: float = 0.0                                 # the worker's CPU seconds since its first tick
    node_code_s: float = 0.0                           # of which inside its nodes' own code (ros/node_time.py)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m composed_sim.hosts.worker_process")
    p.add_argument("--fd", type=int, required=True)
    p.add_argument("--parent-pid", type=int, required=True)
    args = p.parse_args(argv)
    # SIGKILL, not SIGTERM: a worker has nothing to write, and must not linger in a callback.
    die_with_parent(args.parent_pid, signal.SIGKILL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})

    from multiprocessing.connection import Connection
    conn = Connection(args.fd)
    kind, setup = conn.recv()
    assert kind == "setup", kind

    from composed_sim.ros.participants import use_worker_prefix
    use_worker_prefix(setup.participant_prefix, setup.scratch_dir)

    import numpy as np

    from composed_sim import plugins
    from composed_sim.hosts.controllers import HostError
    from composed_sim.hosts.lockstep import acted_commands
    from composed_sim.hosts.node_logs import NodeLogs
    from composed_sim.hosts.participant_groups import ParticipantGroups
    from composed_sim.core.senses import Senses
    from composed_sim.hosts.shared_state import SharedState
    from composed_sim.ros import node_time
    from composed_sim.ros.taps import TapBuffer

    world = setup.world
    # The robots' log files are written here; the main process gets the console's part.
    logs = NodeLogs(setup.logs, world.tick_ns, forward=True) if setup.logs is not None else None
    groups = ParticipantGroups(world, setup.start, setup.stop, executor=setup.executor, domain_id=setup.domain_id,
                               robots_per_participant=setup.stop - setup.start, first_group=setup.index, logs=logs)
    try:
        groups.__enter__()
    except (plugins.PluginError, HostError) as e:
        if logs is not None:
            logs.flush()
        conn.send(("error", type(e).__name__, str(e), getattr(e, "field", ())))
        return EXIT_SETUP
    conn.send(("ready", groups.nodes, groups.close_run_wide(0)))

    m = setup.stop - setup.start
    (node,), exchange = groups.simulator_nodes, groups.exchange    # one participant group, one simulator node
    lockstep = world.lockstep
    previous = (np.zeros(m), np.zeros(m))
    seen = 0                       # violations already sent
    tap = None
    wait, interrupting_hangs = groups.start_serving()
    first_tick = None              # (CPU seconds, node code seconds) when the ticks began
    senses, block = Senses(world), slice(setup.start, setup.stop)     # this block's sensors are read here
    shared = SharedState(senses, world.range_and_bearing.payload_bytes, setup.shared_state)
    kept: dict = {}                # the scene, floor and lights as last sent (core/senses.py)
    with interrupting_hangs:
        while True:
            try:
                message = conn.recv()
            except EOFError:       # the main process is gone
                break
            if message[0] == "tick":
                _, tick, route_messages, changed, batch = message
                if first_tick is None:
                    first_tick = (time.process_time(), node_time.seconds())
                kept.update(changed)
                frame = senses.frame(shared.inputs(tick, route_messages, **kept), shared.rows(block), block)
                groups.open_tick(frame.tick, batch)
                exchange.publish_tick(frame)
                wait(lockstep.watchdog_s)
                commands = (np.empty(m), np.empty(m))
                exchange.close_tick(lockstep.fallback, previous, commands)
                previous = acted_commands(frame.tick, commands)     # what the main process acts on
                shared.write_commands(block, *commands)
                answers = TickAnswers(frame.tick, exchange.take_led_commands(), exchange.take_rab_payloads())
                answers.violations = [(v.tick, v.robot, v.reason) for v in node.violations[seen:]]
                seen = len(node.violations)
                if tap is not None:
                    answers.tapped = tap.drain()
                answers.run_wide = groups.close_run_wide(frame.tick + 1)
                answers.peak_rss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                answers.another_simulator = exchange.another_simulator()
                if logs is not None:
                    answers.logs = logs.drain()
                answers.cpu_s = time.process_time() - first_tick[0]
                answers.node_code_s = node_time.seconds() - first_tick[1]
                conn.send(("answers", answers))
            elif message[0] == "clock":
                exchange.publish_clock(message[1])
            elif message[0] == "tap":
                tap = TapBuffer(message[1])
                node.set_message_tap(tap)
            elif message[0] == "stop":
                break
    # Destroying hundreds of nodes one by one takes long (each republishes its participant's
    # graph): nothing is left to write here but the logs, so the process just ends.
    if logs is not None:
        logs.flush()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


if __name__ == "__main__":
    # Run as the module's own name, so that what it pickles (TickAnswers) unpickles in the main process.
    from composed_sim.hosts.worker_process import main as module_main
    sys.exit(module_main())
