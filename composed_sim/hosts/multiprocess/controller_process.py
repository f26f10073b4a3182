"""One robot's controller in its own OS process (multi-process mode).

    python -m composed_sim.hosts.multiprocess.controller_process --world W.yaml --robot bot3 --domain 5 \\
        --executor lockstep [--parent-pid PID] [--report-fd FD]

It builds the very same nodes as the composed host (``create_robot_nodes``), in the robot's
namespace, on the given domain, with ``use_sim_time`` so it follows the simulator's /clock like
any ROS node. With ``--report-fd`` it reports its start-up on that pipe: ``created type:<type>`` once
its node exists (the type of its cmd_vel publisher, which the simulator subscribes with: not read
from the ROS graph, where a stray publisher could pass for it), ``ready <topics> gid:<hex>…`` once
its contract endpoints are matched with the simulator's (so the host can start tick 0 knowing no
message will be lost; the GIDs are its cmd_vel publishers', the only ones the simulator takes this
robot's answers from), then closes it. It exits cleanly (node destroyed, context shut down, code
0) on SIGTERM (and on SIGINT when run by hand), and with its parent: ``PR_SET_PDEATHSIG`` turns the
parent's death, even by SIGKILL, into a SIGTERM here.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time

from composed_sim.hosts.processes import die_with_parent

READY_TIMEOUT_S = 120.0
# Words of the start-up reports:
TYPE_PREFIX = "type:"   # of "created": the type its cmd_vel publisher has (geometry_msgs/msg/Twist)
GID_PREFIX = "gid:"     # of "ready": one cmd_vel publisher's GID, in hex
RUN_WIDE_PREFIX = "run_wide:"   # of "created": a topic its run-wide link uses (hosting/run_wide/relay.py)
EXIT_SETUP = 3          # the controller could not be built; the reason is on stderr
CLEANUP_LIMIT_S = 5         # s from the end of the work to a forced exit (SIGALRM)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m composed_sim.hosts.multiprocess.controller_process",
                                description="Run one robot's controller node in this process.")
    p.add_argument("--world", required=True, help="resolved world file (written by the host)")
    p.add_argument("--robot", required=True, help="robot name, e.g. bot3")
    p.add_argument("--domain", type=int, required=True, help="ROS domain id")
    p.add_argument("--executor", default="lockstep")
    p.add_argument("--parent-pid", type=int, default=None)
    p.add_argument("--log-dir", default=None, help="write the nodes' log lines to LOG_DIR/<robot>.log")
    p.add_argument("--log-level", type=int, default=30, help="the nodes' console level (a LoggingSeverity)")
    p.add_argument("--rosout", action="store_true", help="send the nodes' log lines for /rosout to the simulator")
    p.add_argument("--report-fd", type=int, default=None,
                   help="pipe for start-up reports: 'created type:<type>', then 'ready <topics> gid:<hex>…'")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    die_with_parent(args.parent_pid)
    stop = StopRequest()
    # SIGTERM (the host's cleanup, or PDEATHSIG) stops us cleanly; Python runs the handler in the
    # main thread. SIGINT too when run by hand. Under a host (--parent-pid) SIGINT is ignored: a
    # Ctrl-C is for the simulator, which stops at a tick boundary and then stops us. We are in a
    # process group of our own, but a terminal's SIGINT can still hit us between fork and
    # setpgid; the host spawns us with SIGINT blocked, so such a signal waits, pending, until
    # here, where ignoring it discards it.
    signal.signal(signal.SIGTERM, stop.request)
    signal.signal(signal.SIGINT, signal.SIG_IGN if args.parent_pid is not None else stop.request)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})

    import rclpy
    from rclpy.context import Context

    from composed_sim import plugins
    from composed_sim.hosting import HostError
    from composed_sim.hosting.building import (contract_endpoints, create_robot_nodes, load_classes, published_answer_type)
    from composed_sim.hosting.executors.running import make_executor
    from composed_sim.hosting.node_logs import FAILURE_MARK, Console, LogSettings, NodeLogs, node_label, raising_node
    from composed_sim.ros import contract as c
    from composed_sim.ros.answer_subscription import cmd_vel_gids
    from composed_sim.hosting.run_wide.relay import RunWideRelay
    from composed_sim.hosting.run_wide.link import RunWideLink
    from composed_sim.hosting.sim_timers import before_each_tick
    from composed_sim.world.loader import load_world

    world = load_world(args.world)
    names = world.robot_names()
    if args.robot not in names:
        print(f"robot {args.robot!r} is not in {args.world}", file=sys.stderr)
        return EXIT_SETUP
    group_index = world.group_of_robot()[names.index(args.robot)]
    context = Context()
    rclpy.init(context=context, domain_id=args.domain)   # a non-default context: no rclpy handlers
    nodes, executor, spinner, link = [], None, None, None
    # The robot's log file is written here; this process's console is a file nobody reads, so
    # only a failure's traceback goes there (after FAILURE_MARK, for the host to show).
    # The console's part and the /rosout lines go to the simulator with the robot's part of each
    # tick (hosting/run_wide/link.py).
    logs = NodeLogs(LogSettings(args.log_dir, args.log_level, rosout=args.rosout), world.tick_ns, forward=True,
                    console=Console(open(os.devnull, "w"))) if args.log_dir else None
    try:
        relay = RunWideRelay(names)
        try:
            built = create_robot_nodes(world, group_index, args.robot, context, classes=load_classes(world),
                                       relay=relay, origin=names.index(args.robot), use_sim_time=True,
                                       logs=logs)
            nodes = built.nodes
        except (plugins.PluginError, HostError) as e:
            print(e, file=sys.stderr)
            return EXIT_SETUP
        if logs is not None:
            clock = nodes[0].get_clock()
            logs.clock = lambda: clock.now().nanoseconds
        # The link also tells the simulator when a robot that answers when published is idle.
        quiet = world.robots[group_index].answers == "when_published"
        if relay.in_use or quiet or logs is not None:
            link = RunWideLink(context, args.robot, relay, receives=any(relay.subscriptions_of(n) for n in nodes),
                               # the log lines' part too: each tick's lines reach the console and the bag
                               sends=quiet or logs is not None or any(relay.topics_published_by(n) for n in nodes),
                               timeout_s=world.lockstep.watchdog_s, logs=logs)
            link.watch_answers([p for n in nodes for p in n.publishers
                                if p.topic_name == c.topic_name(args.robot, c.CMD_VEL)])
        # Before the robot's first sensor callback of each tick: the tick's run-wide batch, and the
        # timers of its nodes that read no sensors moved to the tick's time.
        sensors = {c.topic_name(args.robot, t) for t in c.SENSOR_TOPICS}
        before_each_tick([s for n in nodes for s in n.subscriptions if s.topic_name in sensors],
                         lambda stamp: starting_tick(stamp, built.tick_timers, link))
        executor = make_executor(args.executor, context)
        for node in nodes:
            executor.add_node(node)
        if args.report_fd is not None:
            try:
                with os.fdopen(args.report_fd, "w", buffering=1) as report:
                    answer_type = published_answer_type(nodes, args.robot)   # None: its publisher comes later
                    words = ["created"] + ([f"{TYPE_PREFIX}{c.type_name(answer_type)}"] if answer_type else [])
                    words += [f"{RUN_WIDE_PREFIX}{e.topic_name}" for e in (link.endpoints if link else ())]
                    report.write(" ".join(words) + "\n")
                    endpoints = contract_endpoints(nodes, args.robot) + (link.endpoints if link else [])
                    if not wait_until_matched(endpoints, args.robot, stop):
                        return 0 if stop.is_set() else 1
                    topics = sorted({e.topic_name for e in endpoints})
                    gids = [GID_PREFIX + gid.hex() for node in nodes for gid in cmd_vel_gids(node, args.robot)]
                    report.write(" ".join(["ready"] + topics + gids) + "\n")
            except BrokenPipeError:     # the host gave up on the start-up and is stopping us
                return 0
        if args.executor in ("events", "lockstep"):
            # Driven from this thread, as the composed host does: the lockstep executor by design,
            # the EventsExecutor because its spin() in a thread hung in our probes (docs/architecture.md).
            while not stop.is_set():
                executor.spin_once(timeout_sec=IDLE_WAKE_S)
                if link is not None and link.sends and link.tick > link.sent:
                    run_until_idle(executor)
                    link.send()
        else:
            spinner = threading.Thread(target=spin, args=(executor,), daemon=True)
            spinner.start()
            ticks_seen = -1
            while not stop.is_set():
                # Signal handlers run during the sleep, which then goes on. A tick's run-wide messages
                # go out once the robot's nodes are past the tick's sensors for one look (a
                # threaded executor tells no one when it is idle).
                time.sleep(0.002 if link is not None and link.sends else 0.1)
                if link is not None and link.sends and link.tick > link.sent:
                    if ticks_seen == link.tick:
                        link.send()
                    ticks_seen = link.tick
        return 0
    except Exception as e:
        # A callback raised (the executor passes it on): this process ends with it, as a plain
        # ROS node's would; the traceback goes to the robot's log and, marked, to the host.
        node = raising_node(e, nodes)
        if logs is not None and node is not None:
            logs.exception(args.robot, type(node), node.get_logger().name, e, skip=host_frames())
            tick, _ = logs.now()
            print(f"{FAILURE_MARK} {node_label(type(node))} {type(e).__name__} {tick}",
                  file=sys.stderr, flush=True)
        raise
    finally:
        if logs is not None:
            logs.flush()
        if link is not None and link.tick >= 0:
            try:
                link.send_logs()    # a failing robot's last lines: the simulator's console counts them
            except Exception:       # noqa: BLE001 - its simulator may be gone: nothing to tell
                pass
        # A bound on the clean-up: a DDS call that waits on a peer that died with the simulator
        # (its shared-memory port, say) must not keep this process alive. SIGALRM has no handler
        # here, so the kernel ends the process even while a C call holds the interpreter.
        signal.alarm(CLEANUP_LIMIT_S)
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if spinner is not None:
            spinner.join(timeout=2.0)
        for node in nodes:
            node.destroy_node()
        if link is not None:
            link.destroy()
        if context.ok():
            rclpy.shutdown(context=context)


def host_frames() -> str:
    """The files of a traceback's leading frames that are the host's or rclpy's executor, not the
    node's (``NodeLogs.exception``'s ``skip``): this package's hosts, hosting and ros folders."""
    import composed_sim.hosting
    import composed_sim.hosts
    import composed_sim.ros
    folders = [os.path.dirname(m.__file__) for m in (composed_sim.hosts, composed_sim.hosting, composed_sim.ros)]
    return ",".join([*(f + os.sep for f in folders), f"{os.sep}rclpy{os.sep}"])


class StopRequest:
    """Set by a signal handler, read by the main loop. A plain attribute, not a
    ``threading.Event``: ``Event.set`` takes a lock, and a handler can run again while an earlier
    run of it holds that lock, which deadlocks the process. That happens when the parent is
    killed: each of its exiting threads re-parents us and sends PDEATHSIG again, so several
    SIGTERMs arrive at once. A controller once hung for good that way."""

    def __init__(self) -> None:
        self._requested = False

    def request(self, signum=None, frame=None) -> None:
        self._requested = True

    def is_set(self) -> bool:
        return self._requested


def spin(executor) -> None:
    import rclpy.executors
    try:
        executor.spin()
    except rclpy.executors.ExternalShutdownException:
        pass


def starting_tick(stamp: int, tick_timers, link) -> None:
    for timers in tick_timers:
        timers.advance_to(stamp)
    if link is not None:
        link.before_tick(stamp)


def run_until_idle(executor, rounds: int = 1000) -> None:
    """Run what is ready until nothing is: a robot's chain may go on after its answer, and what it
    publishes on run-wide topics belongs to the tick."""
    from composed_sim.hosting.executors.lockstep import LockstepExecutor
    for _ in range(rounds):
        if isinstance(executor, LockstepExecutor):
            if executor.dispatch_ready() == 0:
                return
        else:
            executor.spin_once(timeout_sec=0)
            return


# How often an idle controller process wakes (a message or a due timer ends the wait at once):
# only to see a stop request. Every wake-up walks the executor and builds a wait set (~0.35 ms);
# at 20 a second, hundreds of processes waiting for the others to start took whole cores
# (docs/speed.md, "Multi-process start-up").
IDLE_WAKE_S = 0.5


def wait_until_matched(endpoints, robot: str, stop: StopRequest) -> bool:
    """Wait until each contract endpoint of ours is matched with the simulator's (a publisher
    has a matched subscription, a subscription a matched publisher); the host then checks its
    side of the same topics. Without this a tick-0 sensor, an answer or the first LED message
    could go to a not-yet-matched endpoint and be lost (topics are volatile)."""
    from rclpy.publisher import Publisher
    deadline = time.monotonic() + READY_TIMEOUT_S
    pause = 0.002
    while not all((e.get_subscription_count() if isinstance(e, Publisher) else e.get_publisher_count()) >= 1
                  for e in endpoints):
        if stop.is_set():
            return False
        if time.monotonic() > deadline:
            print(f"{robot}: no simulator matched within {READY_TIMEOUT_S:.0f} s", file=sys.stderr)
            return False
        time.sleep(pause)
        pause = min(2 * pause, 0.05)     # hundreds of children may be waiting at once
    return True


if __name__ == "__main__":
    sys.exit(main())
