"""One robot's controller in its own OS process (multi-process mode).

    python -m composed_sim.hosts.controller_process --world W.yaml --robot bot3 --domain 5 \\
        --executor lockstep [--parent-pid PID] [--ready-fd FD]

It builds the very same plugin Node as the composed host (``create_controller``), in the robot's
namespace, on the given domain, with ``use_sim_time`` so it follows the simulator's /clock like
any ROS node. With ``--ready-fd`` it reports on that pipe once its contract endpoints are matched
with the simulator's, so the host can start tick 0 knowing no message will be lost. It exits
cleanly (nodes destroyed, context shut down, code 0) on SIGTERM or SIGINT, and with its parent:
``PR_SET_PDEATHSIG`` turns the parent's death, even by SIGKILL, into a SIGTERM here.
"""
from __future__ import annotations

import argparse
import ctypes
import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1
READY_TIMEOUT_S = 120.0
EXIT_PLUGIN = 3         # the plugin could not be built; the reason is on stderr


def die_with_parent(parent_pid: int | None) -> None:
    """SIGTERM when the parent dies (any way). Done first, before the slow imports; the getppid
    check covers a parent that died between our fork and the prctl."""
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0) != 0:
            print(f"prctl(PR_SET_PDEATHSIG) failed: errno {ctypes.get_errno()}", file=sys.stderr)
    if parent_pid is not None and os.getppid() != parent_pid:
        sys.exit(0)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m composed_sim.hosts.controller_process",
                                description="Run one robot's controller node in this process.")
    p.add_argument("--world", required=True, help="resolved world file (written by the host)")
    p.add_argument("--robot", required=True, help="robot name, e.g. bot3")
    p.add_argument("--domain", type=int, required=True, help="ROS domain id")
    p.add_argument("--executor", default="lockstep")
    p.add_argument("--parent-pid", type=int, default=None)
    p.add_argument("--ready-fd", type=int, default=None,
                   help="pipe to write 'ready <topics>' to once matched with the simulator")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    die_with_parent(args.parent_pid)
    stop = threading.Event()
    # SIGTERM (the host's cleanup, or PDEATHSIG) and SIGINT (someone signalling us directly; the
    # host starts us in our own process group, so a terminal's Ctrl-C does not reach us and the
    # host stops us itself at a tick boundary). Python runs the handler in the main thread.
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())

    import rclpy
    from rclpy.context import Context

    from composed_sim import plugins
    from composed_sim.hosts.composed import create_controller, make_executor
    from composed_sim.world.loader import load_world

    world = load_world(args.world)
    names = world.robot_names()
    if args.robot not in names:
        print(f"robot {args.robot!r} is not in {args.world}", file=sys.stderr)
        return EXIT_PLUGIN
    group_index = world.group_of_robot()[names.index(args.robot)]
    context = Context()
    rclpy.init(context=context, domain_id=args.domain)   # a non-default context: no rclpy handlers
    node = executor = spinner = None
    try:
        try:
            cls = plugins.load(world.robots[group_index].controller)
            node = create_controller(cls, args.robot, world, group_index, context, use_sim_time=True)
        except plugins.PluginError as e:
            print(e, file=sys.stderr)
            return EXIT_PLUGIN
        executor = make_executor(args.executor, context)
        executor.add_node(node)
        if args.ready_fd is not None:
            if not report_ready(node, args.robot, args.ready_fd, stop):
                return 0 if stop.is_set() else 1
        if args.executor in ("events", "lockstep"):
            # Driven from this thread, as the composed host does: the lockstep executor by design,
            # the EventsExecutor because its spin() in a thread hung in our probes (DESIGN.md).
            while not stop.is_set():
                executor.spin_once(timeout_sec=0.05)
        else:
            spinner = threading.Thread(target=spin, args=(executor,), daemon=True)
            spinner.start()
            while not stop.wait(1.0):   # a timed wait: signal handlers run between the waits
                pass
        return 0
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if spinner is not None:
            spinner.join(timeout=2.0)
        if node is not None:
            node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)


def spin(executor) -> None:
    import rclpy.executors
    try:
        executor.spin()
    except rclpy.executors.ExternalShutdownException:
        pass


def contract_endpoints(node, robot: str) -> list:
    """The node's publishers and subscriptions on contract topics (its own other topics and
    the parameter/rosout plumbing are not the simulator's business)."""
    from composed_sim.ros import contract as c
    topics = {c.topic_name(robot, t) for t in c.SENSOR_TOPICS + c.ACTUATOR_TOPICS} | {c.CLOCK_TOPIC}
    return [e for e in list(node.publishers) + list(node.subscriptions) if e.topic_name in topics]


def report_ready(node, robot: str, fd: int, stop: threading.Event) -> bool:
    """Wait until each contract endpoint of ours is matched with the simulator's (a publisher
    has a matched subscription, a subscription a matched publisher), then write
    ``ready <topic> …`` on the pipe: the host then checks its side of the same topics.
    Without this, a tick-0 sensor or the first LED message could go to a not-yet-matched
    endpoint and be lost (topics are volatile)."""
    from rclpy.publisher import Publisher
    endpoints = contract_endpoints(node, robot)
    deadline = time.monotonic() + READY_TIMEOUT_S
    while not all((e.get_subscription_count() if isinstance(e, Publisher) else e.get_publisher_count()) >= 1
                  for e in endpoints):
        if stop.is_set():
            return False
        if time.monotonic() > deadline:
            print(f"{robot}: no simulator matched within {READY_TIMEOUT_S:.0f} s", file=sys.stderr)
            return False
        time.sleep(0.002)
    with os.fdopen(fd, "w") as pipe:
        pipe.write("ready " + " ".join(sorted({e.topic_name for e in endpoints})) + "\n")
    return True


if __name__ == "__main__":
    sys.exit(main())
