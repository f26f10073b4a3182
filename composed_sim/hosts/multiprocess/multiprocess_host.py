"""The multi-process host: every robot's controller in its own OS process, as in the paper.

Each controller process (``composed_sim.hosts.multiprocess.controller_process``) runs the very same plugin
class on the very same topics as in composed mode, in the ROS domain ``domains.assign_domains``
gives its robot. The simulator process joins each used domain with its own rclpy Context and one
SimulatorNode serving that domain's robots, spun by its own executor thread; ``NodesExchange``
makes those nodes look like one to ``run_lockstep``, so lockstep, the watchdog and the fallbacks
are exactly the composed host's.

Children never outlive the simulator: they run in their own process groups (a terminal's Ctrl-C
reaches only the simulator, which stops at a tick boundary), get SIGTERM then SIGKILL in
``__exit__`` (normal end, exceptions, KeyboardInterrupt), and PR_SET_PDEATHSIG covers the
simulator being killed outright.
"""
from __future__ import annotations

import os
import selectors
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Iterable, Optional

import numpy as np
import rclpy
from rclpy.context import Context

from composed_sim.core.simulation import Simulation
from composed_sim.hosts.base import ControllersElsewhere, SetupInfo, say_answers_later
from composed_sim.hosting import (check_executor, create_run_wide_nodes, DEFAULT_EXECUTOR, failure_from_output,
                                  first_timer_tick_of, flying_robots, has_run_wide_nodes, HostError, load_classes,
                                  LockstepExecutor, matched, NodesExchange, ProcessDrones, ProcessHosting, Spinning,
                                  wait_for_run_wide_timers)
from composed_sim.hosts.multiprocess.domains import DomainError, assign_domains
from composed_sim.hosts.multiprocess.children import ControllerProcess, died_reason
from composed_sim.hosts.multiprocess.hosted_robot import plugin_error_from_output
from composed_sim.hosts.processes import InterruptWatch, exit_reason, reap, signal_group
from composed_sim.ros import contract as c
from composed_sim.ros.robot_settings import robot_settings
from composed_sim.hosts.multiprocess.exchange import LinkedExchange, RunWideLinks
from composed_sim.ros.simulator_node import AnswerTypeError, SimulatorNode
from composed_sim.world.loader import dump_world
from composed_sim.world.schema import World

# Children in start-up at once: start-up is CPU-bound (interpreter, imports, DDS participant),
# so a few per core keeps every core busy without thrashing a small machine.
SPAWN_AT_ONCE = max(2, 2 * (os.cpu_count() or 1))
STALL_TIMEOUT_S = 60.0     # start-up fails when no child became ready for this long
DETECT_PERIOD_S = 0.1      # how often start-up looks up the cmd_vel types not known yet
POLL_S = NodesExchange.POLL_S   # look for dead children this often
TERM_GRACE_S = 5.0         # SIGTERM → SIGKILL
FAILED_GRACE_S = 2.0       # a failed robot's process: SIGTERM → SIGKILL


class MultiProcessHost(ControllersElsewhere):
    """Context manager: the per-domain contexts and simulator nodes, and one child process per
    robot; everything stopped and reaped in ``__exit__`` (the ``Host`` interface, hosts/base.py).

    ``executor`` is the controllers' executor (in each child). Each of the simulator's
    per-domain nodes is spun by a LockstepExecutor in a thread of its own: it takes the answers
    that are ready without rebuilding a wait set per message, and its callbacks only store them.
    """

    def __init__(self, world: World, *, executor: str = DEFAULT_EXECUTOR, domain_id: int = 0,
                 robots_per_domain: Optional[int] = None, logs=None):
        """``logs``: a ``NodeLogs`` (hosting/guard/node_logs.py): each child writes its robot's log file
        with its settings; a child's failure shows its traceback here."""
        check_executor(executor)
        self.logs = logs
        self.world = world
        # What each controller process is told (its domain is its robot's).
        self.hosting = ProcessHosting(executor, domain_id, logs.settings if logs is not None else None)
        mp = world.multi_process
        self.robots_per_domain = robots_per_domain or mp.robots_per_domain
        first = mp.first_domain if mp.first_domain is not None else domain_id
        try:
            self.domains = assign_domains(world.robot_names(), self.robots_per_domain, first, mp.domains)
        except DomainError as e:
            raise HostError(f"multi-process mode: {e}") from None
        self.sim: Optional[Simulation] = None
        self.exchange: Optional[NodesExchange] = None
        self.processes: list[ControllerProcess] = []
        self.setup: Optional[SetupInfo] = None
        self._contexts: list[Context] = []
        self._nodes: dict[int, SimulatorNode] = {}
        self._spinning: list[Spinning] = []          # per domain: its simulator node's executor thread
        self._tmp: Optional[Path] = None
        self._last_check = 0.0
        self._startup_interrupted = False
        self.run_wide = RunWideLinks(world, logs, relays_actions=self.hosting.lockstep)
        self.drones = ProcessDrones(world)

    # --- start-up ---------------------------------------------------------------------------

    def __enter__(self) -> "MultiProcessHost":
        t0 = time.perf_counter()
        try:
            classes = load_classes(self.world)       # fail here, not in N children
            self.sim = Simulation(self.world)
            self._tmp = Path(tempfile.mkdtemp(prefix="composed_sim_mp_"))
            world_file = self._tmp / "world.yaml"
            world_file.write_text(dump_world(self.world), encoding="utf-8")
            tick_ns, lockstep = self.world.tick_ns, self.world.lockstep
            for d in sorted(set(self.domains.values())):
                rows = [i for i, name in enumerate(self.sim.names) if self.domains[name] == d]
                context = Context()
                rclpy.init(context=context, domain_id=d)
                self._contexts.append(context)
                self._nodes[d] = SimulatorNode([self.sim.names[i] for i in rows],
                                               [self.sim.models[i] for i in rows], context=context,
                                               tick_ns=tick_ns, rows=np.array(rows, dtype=int),
                                               node_name=f"composed_sim_d{d}", lockstep=lockstep,
                                               rab_payload_bytes=self.world.range_and_bearing.payload_bytes,
                                               **robot_settings(self.world, rows))
                self._nodes[d].on_failed.append(self._stop_failed)
                self._nodes[d].drones = self.drones.make_endpoints(context, rows, f"composed_sim_d{d}")
            self.drones.serve_alone(self.run_wide.calls, self.sim.names)
            if has_run_wide_nodes(self.world):
                self.run_wide.nodes = create_run_wide_nodes(self.world, self._contexts[0], classes=classes,
                                                            relay=self.run_wide.relay, logs=self.logs)
                self.run_wide.nodes.host(self.run_wide.relay, self.run_wide.calls, self.sim.names,
                                         self.drones.graph_changed(self._contexts[0]))
                self.drones.attach_server(self.run_wide.nodes)
            self.exchange = LinkedExchange(self._nodes, self.domains, self.sim.names, self.world.tick_ns, self.run_wide,
                                           self._check_children, lockstep.watchdog_s + lockstep.unresponsive_s,
                                           drones=self.drones)
            with InterruptWatch() as interrupts:
                self._start_controllers(world_file, interrupts)
            self._startup_interrupted = interrupts.requested
            for d, node in self._nodes.items():
                spinning = Spinning(LockstepExecutor(context=node.context))
                spinning.executor.add_node(node)
                spinning.start_thread(f"executor-d{d}")
                self._spinning.append(spinning)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.setup = SetupInfo(time.perf_counter() - t0, len(self.processes) + len(self._nodes))
        return self

    def _start_controllers(self, world_file: Path, interrupts: InterruptWatch) -> None:
        """Spawn the children and wait until each is matched on both sides.

        At most SPAWN_AT_ONCE children are in the CPU-heavy part of start-up (interpreter,
        imports, node) at a time; waiting for DDS discovery (0.1–3 s, Fast DDS's resend periods)
        costs no CPU, so children in that phase do not count. Popen is called from this (the
        host's) thread on purpose: PR_SET_PDEATHSIG fires when the thread that forked the child
        ends, not only when the process does. A Ctrl-C ends the start-up early (see run()).
        """
        waiting = [name for name, g in zip(self.sim.names, self.world.group_of_robot())   # a drone with no
                   if self.world.robots[g].node_specs]                                   # nodes has no process
        flying = flying_robots(self.world)          # a drone's firmware answers: no cmd_vel to wait for
        unmatched: dict[str, ControllerProcess] = {}
        endpoints = {d: node.endpoints_by_topic() for d, node in self._nodes.items()}
        last_progress = next_detection = time.monotonic()
        with selectors.DefaultSelector() as pipes:
            while (waiting or unmatched) and not interrupts.requested:
                while waiting and sum(not p.created for p in unmatched.values()) < SPAWN_AT_ONCE:
                    p = self._spawn(waiting.pop(0), world_file)
                    unmatched[p.robot] = p
                    pipes.register(p.pipe, selectors.EVENT_READ, p)
                for key, _ in pipes.select(timeout=0.01):
                    p = key.data
                    if not p.read_pipe():       # EOF: it wrote "ready" and closed, or it died
                        pipes.unregister(p.pipe)
                        p.close_pipe()
                        if p.topics is None:
                            self._failed_start(p)
                detect = time.monotonic() >= next_detection     # a graph query per robot not known yet
                if detect:
                    next_detection = time.monotonic() + DETECT_PERIOD_S
                self._subscribe_answers(unmatched.values(), endpoints, detect)
                for d, node in self._nodes.items():   # a drone's controller: its setpoints subscribed, matched
                    if detect and node.drones is not None and node.drones.refresh():
                        endpoints[d].update(node.drones.endpoints_by_topic())
                for p in unmatched.values():
                    if p.created and p.run_wide_topics and not p.linked:
                        link = self.run_wide.link(p.domain, self._nodes[p.domain].context)
                        endpoints[p.domain].update(link.add_robot(self.sim.names.index(p.robot), p.robot,
                                                                  p.run_wide_topics))
                        p.linked = True
                for robot, p in list(unmatched.items()):
                    answers = p.answers_later or flying[self.sim.names.index(robot)] \
                        or self._nodes[p.domain].answer_subscription(robot) is not None
                    if p.topics is not None and answers and all(matched(endpoints[p.domain].get(t)) for t in p.topics):
                        del unmatched[robot]
                        last_progress = time.monotonic()
                if time.monotonic() - last_progress > STALL_TIMEOUT_S:
                    missing = sorted(unmatched, key=self.sim.names.index)
                    seen = "; ".join(self._nodes[self.domains[r]].connection_of(r) for r in missing[:3])
                    raise HostError(f"controllers of {', '.join(missing)} were not matched with the simulator "
                                    f"within {STALL_TIMEOUT_S:.0f} s (each must publish {c.CMD_VEL.name} and "
                                    f"subscribe to a sensor; seen: {seen}); {len(waiting)} more not started")
        self._started()

    def _started(self) -> None:
        """Every controller matched: what the simulator nodes and the run-wide nodes learn of them."""
        for node in self._nodes.values():
            node.note_controllers({p.robot: p.gids for p in self.processes})
        later = [p.robot for p in self.processes if p.answers_later]
        for p in self.processes:
            if p.answers_later or p.first_timer_tick:
                self._nodes[p.domain].answer_later([p.robot], None if p.answers_later else p.first_timer_tick)
        # Until the run-wide nodes' first timer fires, the robots may wait for it (a start command):
        # each process's run-wide link says when its nodes are idle (hosting/run_wide/link.py).
        wait_for_run_wide_timers(self._nodes.values(), first_timer_tick_of(self.run_wide.nodes))
        say_answers_later(sorted(later, key=self.sim.names.index))
        # What each robot's process serves: to the run-wide nodes here, and with tick 0's first
        # handover to every robot (their clients find it ready, hosting/calls/between_places.py).
        places = {name: i for i, name in enumerate(self.sim.names)}
        self.run_wide.calls.announce([(places[p.robot], name, kind) for p in self.processes for name, kind in p.served])

    def _subscribe_answers(self, children: Iterable[ControllerProcess], endpoints: dict, detect: bool) -> None:
        """Subscribe to each created child's robot's cmd_vel with the type the child reported; with
        ``detect``, with the type the ROS graph lists for the children that reported none (their
        publisher came later). Never before the child is created: until then, what the graph lists
        on the topic is not this run's controller."""
        for p in children:
            node = self._nodes[p.domain]
            if not p.created or node.answer_subscription(p.robot) is not None:
                continue
            try:
                if p.answer_type is not None:
                    node.take_answers_as(p.robot, p.answer_type)
                elif detect:
                    node.detect_answer_types([p.robot])
            except AnswerTypeError as e:
                raise HostError(str(e)) from None
            endpoints[p.domain][c.topic_name(p.robot, c.CMD_VEL)] = node.answer_subscription(p.robot)

    def _failed_start(self, p: ControllerProcess) -> None:
        try:
            code = p.popen.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            raise HostError(f"the controller process of {p.robot} closed its start-up pipe without "
                            f"reporting:\n{p.tail() or '(no output)'}") from None
        error = plugin_error_from_output(p.tail(20000))
        if error is not None:       # its nodes could not be built: as a worker's would say it
            raise error
        raise HostError(f"the controller process of {p.robot} (domain {p.domain}) ended during "
                        f"start-up ({exit_reason(code)}):\n{p.tail() or '(no output)'}")

    def _spawn(self, robot: str, world_file: Path) -> ControllerProcess:
        read_fd, write_fd = os.pipe()    # its start-up reports; EOF when it is done or dead
        log = self._tmp / f"{robot}.log"
        cmd = [sys.executable, "-m", "composed_sim.hosts.multiprocess.controller_process", "--world", str(world_file),
               "--robot", robot, *replace(self.hosting, domain_id=self.domains[robot]).argv(),
               "--parent-pid", str(os.getpid()), "--report-fd", str(write_fd)]
        # Own process group: a terminal's Ctrl-C goes to the simulator only (which stops the run
        # at a tick boundary), and killpg reaches anything the child started. SIGINT blocked while
        # forking: one arriving before the child's setpgid stays pending until the child ignores it.
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            with open(log, "wb") as out:
                popen = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                         pass_fds=(write_fd,), process_group=0)
        except BaseException:
            os.close(read_fd)
            raise
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
            os.close(write_fd)
        p = ControllerProcess(robot, self.domains[robot], popen, log, read_fd)
        self.processes.append(p)
        return p

    # --- the run ----------------------------------------------------------------------------

    @property
    def simulator_nodes(self) -> list[SimulatorNode]:
        return list(self.exchange.nodes)

    def _check_children(self) -> None:
        """A child that ended mid-run: its robot is marked failed (violation recorded once) and
        gets the fallback every tick after. poll() also reaps it."""
        now = time.monotonic()
        if now - self._last_check < POLL_S:
            return
        self._last_check = now
        for p in self.processes:
            if p.stopping_since is not None and p.popen.returncode is None \
                    and now - p.stopping_since > FAILED_GRACE_S and p.popen.poll() is None:
                signal_group(p.popen, signal.SIGKILL)      # hung in a callback: SIGTERM waits for it
            if p.popen.returncode is None and p.popen.poll() is not None:
                self._nodes[p.domain].mark_failed(p.robot, died_reason(p))
                failure = failure_from_output(p.tail(100_000)) if self.logs is not None else None
                if failure is not None:
                    label, kind, tick, text = failure
                    self.logs.failure(p.robot, label, kind, tick, text)

    def _stop_failed(self, robot: str) -> None:
        """A robot failed by the simulator (hung, silent, too many violations): its process goes,
        as its callbacks would stop being run in composed mode. SIGTERM first, so that it ends
        its DDS participant itself; SIGKILL FAILED_GRACE_S later if it has not (a callback that
        never returns; ``_check_children``). Killed at once, a controller can die holding its
        shared-memory port's lock, and what goes toward that port then waits (the likely cause
        of a healthy robot of the same domain once missing the watchdog the tick after)."""
        p = next(p for p in self.processes if p.robot == robot)
        if p.stopping_since is None and p.popen.returncode is None:
            p.stopping_since = time.monotonic()
            signal_group(p.popen, signal.SIGTERM)

    # --- shutdown ---------------------------------------------------------------------------

    def stop_processes(self) -> None:
        """End every controller process and remove their files: all a run that ends its own
        process next needs. Destroying the simulator's nodes as well can hang there: a controller
        killed while it held its shared-memory port's lock leaves the lock held, and the graph
        update each destruction sends to that port waits for it forever."""
        self._stop_children()
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def ros_domains(self) -> list[int]:
        return sorted(set(self.domains.values()))

    def end_before_exit(self) -> bool:
        self.stop_processes()
        return True

    def __exit__(self, *exc) -> None:
        self.stop_processes()
        for spinning in self._spinning:
            spinning.stop()
        self._spinning = []
        self.run_wide.destroy()
        self.drones.destroy()
        for node in self._nodes.values():
            node.destroy_node()
        self._nodes = {}
        for context in self._contexts:
            if context.ok():
                rclpy.shutdown(context=context)
        self._contexts = []
        if self.sim is not None:
            self.sim.close()

    def _stop_children(self) -> None:
        """SIGTERM to every child's group (SIGKILL to a failed robot's, which had its SIGTERM),
        SIGKILL to whatever is left after TERM_GRACE_S, reap all. Only unreaped children are
        signalled: a reaped child's pid may belong to another process by now."""
        for p in self.processes:
            p.close_pipe()
        for p in self.processes:      # a failed robot's still there did not heed its SIGTERM
            signal_group(p.popen, signal.SIGTERM if p.stopping_since is None else signal.SIGKILL)
        reap([p.popen for p in self.processes], TERM_GRACE_S)
