"""One robot's controller in its own OS process (multi-process mode).

    python -m composed_sim.hosts.multiprocess.controller_process --world W.yaml --robot bot3 --domain 5 \\
        --executor lockstep [--parent-pid PID] [--report-fd FD]

It builds the very same nodes as the composed host (hosted_robot.py), in the robot's namespace, on
the given domain, with ``use_sim_time`` so it follows the simulator's /clock like any ROS node.
With ``--report-fd`` it reports its start-up on that pipe: ``created type:<type>`` once its node
exists (the type of its cmd_vel publisher, which the simulator subscribes with: not read from the
ROS graph, where a stray publisher could pass for it), ``ready <topics> gid:<hex>…`` once its
contract endpoints are matched with the simulator's (so the host can start tick 0 knowing no
message will be lost; the GIDs are its cmd_vel publishers', the only ones the simulator takes this
robot's answers from), then closes it. It exits cleanly (node destroyed, context shut down, code
0) on SIGTERM (and on SIGINT when run by hand), and with its parent: ``PR_SET_PDEATHSIG`` turns the
parent's death, even by SIGKILL, into a SIGTERM here.

This module is light: what it imports before ``die_with_parent`` delays that for hundreds of
children starting at once.
"""
from __future__ import annotations

import argparse
import signal
import sys
from typing import Optional

from composed_sim.hosting import ProcessHosting
from composed_sim.hosts.processes import die_with_parent

EXIT_SETUP = 3          # the controller could not be built; the reason is on stderr


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m composed_sim.hosts.multiprocess.controller_process",
                                description="Run one robot's controller node in this process.")
    p.add_argument("--world", required=True, help="resolved world file (written by the host)")
    p.add_argument("--robot", required=True, help="robot name, e.g. bot3")
    ProcessHosting.add_arguments(p)
    p.add_argument("--parent-pid", type=int, default=None)
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

    from composed_sim.hosts.multiprocess.hosted_robot import HostedRobot
    from composed_sim.world.loader import load_world

    world = load_world(args.world)
    if args.robot not in world.robot_names():
        print(f"robot {args.robot!r} is not in {args.world}", file=sys.stderr)
        return EXIT_SETUP
    from composed_sim.hosting import end_process_on_thread_shutdown
    end_process_on_thread_shutdown(stop.end_with)     # rclpy.shutdown() from a thread of the nodes'
    robot = HostedRobot(world, args.robot, ProcessHosting.from_args(args))
    try:
        if not robot.build():
            return EXIT_SETUP
        if args.report_fd is not None and (code := robot.report(args.report_fd, stop.is_set)) is not None:
            return code
        robot.serve(stop.is_set)
        if stop.ending is not None:
            raise stop.ending       # as when a callback calls it: this process ends with its reason
        return 0
    except Exception as e:
        # A callback raised (the executor passes it on): this process ends with it, as a plain
        # ROS node's would; the traceback goes to the robot's log and, marked, to the host.
        robot.failed(e)
        raise
    finally:
        robot.close()


class StopRequest:
    """Set by a signal handler, read by the main loop. A plain attribute, not a
    ``threading.Event``: ``Event.set`` takes a lock, and a handler can run again while an earlier
    run of it holds that lock, which deadlocks the process. That happens when the parent is
    killed: each of its exiting threads re-parents us and sends PDEATHSIG again, so several
    SIGTERMs arrive at once. A controller once hung for good that way."""

    def __init__(self) -> None:
        self._requested = False
        self.ending: Optional[BaseException] = None     # what ended the nodes from a thread of theirs

    def request(self, signum=None, frame=None) -> None:
        self._requested = True

    def end_with(self, ending: BaseException) -> None:
        self.ending = ending
        self._requested = True

    def is_set(self) -> bool:
        return self._requested


if __name__ == "__main__":
    sys.exit(main())
