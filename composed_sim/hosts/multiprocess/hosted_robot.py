"""One robot's nodes in a controller process of their own (controller_process.py): built as the
composed host builds them, on sim time from /clock; linked to the simulator for the run-wide
topics and the log lines; their start-up reported to the host; then served until a stop."""
from __future__ import annotations

import json
import os
import signal
import sys
import time
from typing import Callable, Optional

import rclpy
from rclpy.context import Context
from rclpy.time import Time as RosTime

from composed_sim import plugins
from composed_sim.hosting import (before_each_tick, CallRelay, clocks_to, Console, contract_endpoints,
                                  create_robot_nodes, driven_by_caller, FAILURE_MARK, HostedBlock, HostError,
                                  load_classes, LockstepExecutor, make_executor, matched, node_label, NodeLogs,
                                  poll_until, ProcessHosting, published_answer_type, raising_node, run_until_idle,
                                  RunWideLink, RunWideRelay, shut_down, Spinning)
from composed_sim.hosts.multiprocess.tick_readings import TickReadings
from composed_sim.ros import contract as c
from composed_sim.ros.answer_subscription import cmd_vel_gids
from composed_sim.ros.crazyflie.messages import SETPOINTS
from composed_sim.world.robot_models import get_model
from composed_sim.world.schema import World

READY_TIMEOUT_S = 120.0
# Words of the start-up reports:
TYPE_PREFIX = "type:"   # of "created": the type its cmd_vel publisher has (geometry_msgs/msg/Twist)
GID_PREFIX = "gid:"     # of "ready": one cmd_vel publisher's GID, in hex
RUN_WIDE_PREFIX = "run_wide:"   # of "created": a topic its run-wide link uses (hosting/run_wide/relay.py)
LATER = "later"                 # of "created": no cmd_vel publisher yet, one may come (wiring.answer_rule)
FIRST_TIMER_PREFIX = "timers_from:"   # of "created": the tick its first timer first fires (BuiltNodes)
SERVED_PREFIX = "served:"       # of "ready": a service its nodes serve, name=type (hosting/calls/between_places.py)
CLEANUP_LIMIT_S = 5         # s from the end of the work to a forced exit (SIGALRM)
# How often an idle controller process wakes (a message or a due timer ends the wait at once):
# only to see a stop request. Every wake-up walks the executor and builds a wait set; many a
# second, hundreds of processes waiting for the others to start took whole cores
# (docs/speed.md, "Multi-process start-up").
IDLE_WAKE_S = 0.5


# On stderr, one line: why its nodes could not be built, as JSON (message, field, user_traceback),
# which the host raises as the same PluginError a worker's would be (plugin_error_from_output).
PLUGIN_ERROR_MARK = "composed-sim-plugin-error"


def plugin_error_line(error: plugins.PluginError) -> str:
    return f"{PLUGIN_ERROR_MARK} " + json.dumps({"message": str(error), "field": list(error.field),
                                                  "user_traceback": error.user_traceback})


def plugin_error_from_output(output: str) -> Optional[plugins.PluginError]:
    """The PluginError a controller process wrote (``plugin_error_line``), or None."""
    at = output.rfind(PLUGIN_ERROR_MARK + " ")
    if at < 0:
        return None
    try:
        said = json.loads(output[at + len(PLUGIN_ERROR_MARK) + 1:].partition("\n")[0])
    except ValueError:
        return None
    return plugins.PluginError(said["message"], tuple(said["field"]), said["user_traceback"])


class HostedRobot:
    """The robot's context, nodes, run-wide link, executor and logs; ``close`` ends them in order."""

    def __init__(self, world: World, robot: str, hosting: ProcessHosting):
        self.world, self.robot, self.hosting = world, robot, hosting
        self.context = Context()
        rclpy.init(context=self.context, domain_id=hosting.domain_id)   # a non-default context: no rclpy handlers
        self.nodes: list = []
        self.answers_later = False          # no cmd_vel publisher yet (hosting/building/wiring.answer_rule)
        self.first_timer_tick = 0           # before it, its timers have not fired (BuiltNodes)
        self._reads_sensors = False         # do its nodes read its sensors (which then mark a tick's start)?
        self._tick_timers: list = []
        # Its part of a tick waits for the tick's readings, at most a third of the watchdog.
        self.readings = TickReadings(self.context, world.lockstep.watchdog_s / 3)
        self.link: Optional[RunWideLink] = None
        self.spinning: Optional[Spinning] = None
        self.block: Optional[HostedBlock] = None
        # The robot's log file is written here; this process's console is a file nobody reads, so
        # only a failure's traceback goes there (after FAILURE_MARK, for the host to show).
        # The console's part and the /rosout lines go to the simulator with the robot's part of each
        # tick (hosting/run_wide/link.py).
        self.logs = NodeLogs(hosting.logs, world.tick_ns, forward=True, console=Console(open(os.devnull, "w"))) \
            if hosting.logs is not None else None

    def build(self) -> bool:
        """Its nodes, its run-wide link and its executor; False (the reason on stderr) where the
        nodes cannot be built."""
        world, robot = self.world, self.robot
        names = world.robot_names()
        group_index = world.group_of_robot()[names.index(robot)]
        relay = RunWideRelay(names)
        try:
            built = create_robot_nodes(world, group_index, robot, self.context, classes=load_classes(world),
                                       relay=relay, origin=names.index(robot), use_sim_time=True, logs=self.logs)
        except plugins.PluginError as e:
            print(plugin_error_line(e), file=sys.stderr, flush=True)
            return False
        except HostError as e:
            print(e, file=sys.stderr)
            return False
        self.nodes, self.answers_later, self.first_timer_tick = built.nodes, built.answers_later, built.first_timer_tick
        self._clocks = [n.get_clock() for n in self.nodes]
        if self.logs is not None:
            # A line is stamped with the tick the robot's process is in: its nodes hear /clock one by
            # one, and a callback that the first of them to hear it wakes (a rate's sleep) logs then.
            clocks = self._clocks
            self.logs.clock = lambda: max(clock.now().nanoseconds for clock in clocks)
        place = names.index(robot)
        self.calls = CallRelay(names, relays_actions=self.hosting.lockstep)
        self._link(built, relay, place, world.robots[group_index])
        # Before the robot's first sensor callback of each tick: the tick's run-wide batch, and the
        # timers of its nodes that read no sensors moved to the tick's time.
        sensors = {c.topic_name(robot, t) for t in c.SENSOR_TOPICS}
        read = [s for n in self.nodes for s in n.subscriptions if s.topic_name in sensors]
        self._tick_timers = built.tick_timers
        before_each_tick(read, lambda stamp: self._starting_tick(stamp, built.tick_timers), self.readings.taken)
        self.readings.watch(read)
        self._reads_sensors = bool(read)
        if self.link is not None and (not read or built.answers_later):
            # While nothing it reads marks a tick's start (its sensor subscriptions may come
            # later), /clock does, on the link's node, which the executor walks first. Once it
            # reads its sensors they do: its part of the tick then waits for them.
            self.link.node.create_subscription(c.CLOCK_TYPE, c.CLOCK_TOPIC, lambda msg: self._reads_sensors or (
                self._starting_tick(RosTime.from_msg(msg.clock).nanoseconds, built.tick_timers)), 10)
        self.spinning = Spinning(make_executor(self.hosting.executor, self.context))
        if self.link is not None and isinstance(self.spinning.executor, LockstepExecutor):
            self.link.run_callback = self.spinning.executor.run_callback
        for node in ([self.link.node] if self.link is not None else []) + self.nodes:
            self.spinning.executor.add_node(node)
        # Its nodes hosted as in the composed host (hosting/hosted_block.py).
        self.block = HostedBlock(self.spinning.executor, [(node, robot, place, None) for node in self.nodes],
                                 robots=names, calls=self.calls, places=[place], relay=relay,
                                 on_new_endpoints=self._new_endpoints if self.link is not None else None)
        return True

    def _link(self, built, relay: RunWideRelay, place: int, group) -> None:
        """Its run-wide link, where it needs one: it carries the run-wide topics, the calls between
        the robot and the run-wide nodes (hosting/calls/between_places.py) and the log lines, and
        tells the simulator when a robot whose nodes cannot answer yet is idle."""
        world, robot = self.world, self.robot
        # A robot whose nodes cannot answer yet (no cmd_vel publisher, wiring.answer_rule; timers
        # not due) is quiet until they do: the link tells the simulator when its nodes are idle. So
        # is a drone (its firmware answers): what its nodes sent in the tick is in when the tick closes.
        quiet = group.answers == "when_published" or built.answers_later or built.first_timer_tick > 0 \
            or get_model(group.model).flies
        calls_between = bool(world.nodes) or any(self.calls.leaves(place, client.service_name)
                                                 for n in self.nodes for client in n.clients)
        if not (relay.in_use or quiet or self.logs is not None or calls_between):
            return
        self.link = RunWideLink(self.context, robot, relay,
                                receives=calls_between or any(relay.subscriptions_of(n) for n in self.nodes),
                                # the log lines' part too: each tick's lines reach the console and the bag
                                sends=quiet or self.logs is not None or calls_between
                                or any(relay.topics_published_by(n) for n in self.nodes),
                                timeout_s=world.lockstep.watchdog_s, logs=self.logs,
                                calls=self.calls, index=place)
        self.link.clocks = self._clocks
        self.link.holds_answers = driven_by_caller(self.hosting.executor, guarded=False)
        self.link.watch_answers([p for n in self.nodes for p in n.publishers
                                 if p.topic_name == c.topic_name(robot, c.CMD_VEL)])
        setpoints = {f"/{robot}/{name}" for name in SETPOINTS}      # a drone's (ros/crazyflie/messages.py)
        self.link.count([p for n in self.nodes for p in n.publishers if p.topic_name in setpoints])

    def _new_endpoints(self, robot: str, publishers: list, subscriptions: list) -> None:
        """Its nodes made publishers or subscriptions after start-up (a lifecycle node configured):
        the link notes a cmd_vel publisher's answers and, for the robot's first, tells the
        simulator its type to subscribe with; and tells it of new readers of the robot's sensors,
        which the simulator's publishers must match before they publish (or DDS would drop what
        they publish meanwhile)."""
        answers = [p for p in publishers if p.topic_name == c.topic_name(robot, c.CMD_VEL)]
        if answers:
            self.link.watch_answers(answers)
            if self.answers_later and self.link.answer_type is None:
                self.link.answer_type = c.type_name(answers[0].msg_type)
        sensors = {c.topic_name(robot, t) for t in c.SENSOR_TOPICS}
        reading = [s for s in subscriptions if s.topic_name in sensors]
        before_each_tick(reading, lambda stamp: self._starting_tick(stamp, self._tick_timers), self.readings.taken)
        self.readings.watch(reading)
        self._reads_sensors = self._reads_sensors or bool(reading)
        for topic in {s.topic_name for s in reading}:
            self.link.reads[topic] = sum(s.topic_name == topic for n in self.nodes for s in n.subscriptions)

    def _starting_tick(self, stamp: int, tick_timers) -> None:
        clocks_to(self._clocks, stamp)
        for timers in tick_timers:
            timers.advance_to(stamp)
        if self.link is not None:
            self.link.before_tick(stamp)
        if self.block is not None:
            self.block.start_tick()

    def report(self, fd: int, stopped: Callable[[], bool]) -> Optional[int]:
        """Tell the host on the pipe ``fd`` that the nodes exist, then that their contract endpoints
        are matched with the simulator's (its side checks the same topics). None: go on serving;
        else the exit code."""
        try:
            with os.fdopen(fd, "w", buffering=1) as report:
                link_endpoints = self.link.endpoints if self.link is not None else []
                answer_type = published_answer_type(self.nodes, self.robot)   # None: its publisher comes later
                words = ["created"] + ([f"{TYPE_PREFIX}{c.type_name(answer_type)}"] if answer_type else [])
                words += [LATER] if self.answers_later else []
                words += [f"{FIRST_TIMER_PREFIX}{self.first_timer_tick}"] if self.first_timer_tick else []
                words += [f"{RUN_WIDE_PREFIX}{e.topic_name}" for e in link_endpoints]
                report.write(" ".join(words) + "\n")
                endpoints = contract_endpoints(self.nodes, self.robot) + link_endpoints
                found = poll_until(lambda: all(matched(e) for e in endpoints), READY_TIMEOUT_S, stopped)
                if found is None:
                    print(f"{self.robot}: no simulator matched within {READY_TIMEOUT_S:.0f} s", file=sys.stderr)
                if not found:
                    return 0 if stopped() else 1
                topics = sorted({e.topic_name for e in endpoints})
                gids = [GID_PREFIX + gid.hex() for node in self.nodes for gid in cmd_vel_gids(node, self.robot)]
                served = [f"{SERVED_PREFIX}{name}={kind}" for name, kind in self.calls.services.items()]
                report.write(" ".join(["ready"] + topics + gids + served) + "\n")
        except BrokenPipeError:     # the host gave up on the start-up and is stopping us
            return 0
        return None

    def serve(self, stopped: Callable[[], bool]) -> None:
        """Run the nodes until a stop; send the robot's part of each tick over the link once its
        nodes are idle."""
        link, spinning = self.link, self.spinning
        sends = link is not None and link.sends
        if driven_by_caller(self.hosting.executor, guarded=False):
            if isinstance(spinning.executor, LockstepExecutor):
                spinning.executor.before_walk = self.readings.wait_for_the_rest
            while not stopped():
                spinning.executor.spin_once(timeout_sec=IDLE_WAKE_S)
                if sends:
                    link.send_held_answer()     # one cmd_vel per pass, the last (RunWideLink.watch_answers)
                if link is not None and link.reply_due:     # calls from the simulator: handled, answered
                    run_until_idle(spinning.executor)
                    link.reply()
                if sends and link.tick > link.sent and self.readings.all_in(link.tick):
                    run_until_idle(spinning.executor)
                    link.send()
            return
        spinning.start_thread()
        ticks_seen = -1
        while not stopped():
            # Signal handlers run during the sleep, which then goes on. A tick's run-wide messages
            # go out once the robot's nodes are past the tick's sensors for one look (a threaded
            # executor tells no one when it is idle).
            time.sleep(0.002 if sends else 0.1)
            if link is not None and link.reply_due:
                link.reply()
            if sends and link.tick > link.sent and self.readings.all_in(link.tick):
                if ticks_seen == link.tick:
                    link.send()
                ticks_seen = link.tick

    def failed(self, error: Exception) -> None:
        """A callback raised: its traceback to the robot's log, and marked, for the host, here."""
        node = raising_node(error, self.nodes)
        if self.logs is not None and node is not None:
            self.logs.exception(self.robot, type(node), node.get_logger().name, error, skip=host_frames())
            tick, _ = self.logs.now()
            print(f"{FAILURE_MARK} {node_label(type(node))} {type(error).__name__} {tick}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.logs is not None:
            self.logs.flush()
        if self.link is not None and self.link.tick >= 0:
            try:
                self.link.send_logs()    # a failing robot's last lines: the simulator's console counts them
            except Exception:            # noqa: BLE001 - its simulator may be gone: nothing to tell
                pass
        # A bound on the clean-up: a DDS call that waits on a peer that died with the simulator
        # (its shared-memory port, say) must not keep this process alive. SIGALRM has no handler
        # here, so the kernel ends the process even while a C call holds the interpreter.
        signal.alarm(CLEANUP_LIMIT_S)
        if self.block is not None:
            self.block.close()
        shut_down(self.spinning, [*self.nodes, *([self.link] if self.link is not None else [])], self.context,
                  shutdown_timeout_s=1.0, join_timeout_s=2.0)


def host_frames() -> str:
    """The files of a traceback's leading frames that are the host's or rclpy's executor, not the
    node's (``NodeLogs.exception``'s ``skip``): this package's hosts, hosting and ros folders."""
    import composed_sim.hosting
    import composed_sim.hosts
    import composed_sim.ros
    folders = [os.path.dirname(m.__file__) for m in (composed_sim.hosts, composed_sim.hosting, composed_sim.ros)]
    return ",".join([*(f + os.sep for f in folders), f"{os.sep}rclpy{os.sep}"])
