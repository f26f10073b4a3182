"""One robot's faulty callback stays that robot's fault (composed host).

Every controller runs in the host's process, so a callback that raises, overruns or never returns
would otherwise stop the executor and with it the whole swarm. The guard wraps each controller's
subscription and timer callbacks:

- a callback that raises marks its robot failed (in multi-process mode its process would die),
  ``SystemExit`` included; one that tried to spin the nodes itself, or to shut down the host's
  context, is told so in its violation;
- a callback that returns after more than the watchdog gets its robot's answer to this tick
  rejected: the fallback and a violation, as a late answer gets across processes. The other
  robots' callbacks run after it, so they are not affected;
- a callback still running after ``unresponsive_s`` is interrupted and its robot marked failed.
  The interruption is a ``ControllerHung`` exception raised inside the callback by a SIGALRM
  handler, which only works where callbacks run in the main thread (the lockstep, events and
  single-threaded executors, which the composed host drives from it). Signals interrupt sleeps
  and lock waits too; only a callback stuck inside C code that ignores signals cannot be
  stopped. The multi-threaded executor runs callbacks on worker threads: a hung one there is
  failed by the simulator's unresponsive rule, and then interrupted by an asynchronous
  exception in its thread, which takes effect as soon as it runs Python code again (a callback
  blocked forever inside C keeps its worker thread).
- a failed robot's callbacks are not run any more;
- the same holds for what a node creates after its constructor (``guard_new``: a lifecycle
  node's transition, a callback), its services' callbacks, ``async def`` callbacks (wrapped as
  coroutines, so that every executor still awaits them) and the tasks the lockstep executor runs
  for a robot (a future's done callback, an action's execution: ``CallbackWatcher``);
- ``on_exception(robot, node, error)``, when set, gets the exception that failed a robot (its
  traceback goes to the robot's log, hosting/guard/node_logs.py).
"""
from __future__ import annotations

import contextlib
import ctypes
import inspect
import signal
import threading
import time
import weakref
from typing import Callable, Optional, Protocol, Sequence, runtime_checkable

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.subscription import Subscription

from composed_sim.hosting.executors.lockstep import CallbackWatcher
from composed_sim.hosting.guard.node_time import NodeTime


class ServedRobots(Protocol):
    """What the guard asks of the simulator node that serves a robot (ros/simulator_node.py)."""
    failed: np.ndarray                  # [n] bool, per row

    def row_of(self, robot: str) -> int: ...
    def mark_failed(self, robot: str, reason: str) -> None: ...
    def reject_answer(self, robot: str, reason: str) -> None: ...


@runtime_checkable
class BatchingNode(Protocol):
    """A node that takes a tick's sensor messages in one call and times its own code itself
    (ros/controller.py's ``SwarmController``): the guard wraps that call too."""
    lockstep_batch: Optional[tuple]
    node_time: Optional[NodeTime]

    def sensor_batch(self) -> tuple[tuple, Callable[[list], None]]: ...


class ControllerHung(BaseException):
    """Raised inside a callback that ran too long. A BaseException, so that a plugin's own
    ``except Exception`` does not swallow it."""


class CallbackGuard(CallbackWatcher):
    def __init__(self, watchdog_s: float, unresponsive_s: float, node_time: NodeTime):
        """``node_time``: where the CPU time of the nodes' own code goes (node_time.py)."""
        self.node_time = node_time
        self._watchdog_s = watchdog_s
        self._unresponsive_s = unresponsive_s
        self._running: Optional[str] = None            # robot whose callback runs in the main thread
        self._started = 0.0
        self._cpu_started = None                       # … and its thread's CPU clock then (NodeTime.start)
        self._main = threading.main_thread()
        # Worker thread → the robots whose callbacks it runs, innermost last: two callbacks of one
        # robot may run at once on two threads (a reentrant callback group).
        self._workers: dict[int, list[str]] = {}
        self._workers_lock = threading.Lock()
        self.calls = 0                                 # callbacks run: lets a waiter see progress
        self.running = 0                               # callbacks running now on worker threads
        self.calls_of: dict[str, int] = {}             # per robot: its callbacks run so far
        self.on_exception: Optional[Callable[[str, Node, BaseException], None]] = None
        self._robots: dict[str, tuple[ServedRobots, Node]] = {}   # robot → who serves it, its first node
        self._robot_of: dict[int, str] = {}            # id(node) → its robot
        self._wrapped: set[int] = set()                # ids of the entities whose callbacks are wrapped
        _GUARDS.add(self)

    def guard(self, node: Node, robot: str, sim_node: ServedRobots, relayed: Sequence = ()) -> None:
        """Wrap the callbacks of every subscription, timer and service ``node`` has (a controller
        creates them in its constructor), and of its subscriptions on run-wide topics (``relayed``,
        hosting/run_wide/relay.py); ``sim_node`` serves ``robot``."""
        self._robots.setdefault(robot, (sim_node, node))
        self._robot_of[id(node)] = robot
        self.guard_new(node, relayed)
        if isinstance(node, BatchingNode):   # its sensors' messages in one call (ros/controller.py)
            subscriptions, on_sensors = node.sensor_batch()
            node.lockstep_batch = (subscriptions, self._wrap(on_sensors, node, robot, sim_node, False))
            node.node_time = self.node_time

    def guard_new(self, node: Node, relayed: Sequence = ()) -> None:
        """Wrap the callbacks of what ``node`` (guarded) created since it was last looked at."""
        robot = self._robot_of[id(node)]
        sim_node = self._robots[robot][0]
        wrapped = self._wrapped
        for sub in (*node.subscriptions, *relayed):
            if id(sub) not in wrapped and sub.callback is not None:
                wrapped.add(id(sub))
                with_info = sub._callback_type is Subscription.CallbackType.WithMessageInfo
                sub.callback = self._wrap(sub.callback, node, robot, sim_node, with_info)
        for entity in (*node.timers, *node.services):
            if id(entity) not in wrapped and entity.callback is not None:
                wrapped.add(id(entity))
                entity.callback = self._wrap(entity.callback, node, robot, sim_node, False)

    def _wrap(self, callback: Callable, node: Node, robot: str, sim_node: ServedRobots, with_info: bool) -> Callable:
        """``callback`` guarded; an ``async def`` one stays a coroutine function (``_wrap_async``)."""
        if inspect.iscoroutinefunction(callback):
            return self._wrap_async(callback, node, robot, sim_node, with_info)
        failed = sim_node.failed         # shared, read-only here
        # The base class times its subclass's own code itself (hosting/guard/node_time.py).
        own_time = not isinstance(node, BatchingNode)
        node_time = self.node_time
        row = sim_node.row_of(robot)
        calls_of = self.calls_of

        main = self._main.ident
        get_ident, monotonic = threading.get_ident, time.monotonic

        def run(*args):
            if failed[row]:
                return None
            in_main = get_ident() == main
            started = monotonic()
            if in_main:        # callbacks in this thread run one at a time: no lock needed
                self._running, self._started = robot, started
                self.calls += 1
                calls_of[robot] = calls_of.get(robot, 0) + 1
                self._cpu_started = node_time.start() if own_time else None
            else:
                cpu = self._enter_thread(robot, own_time)
            try:
                try:
                    result = callback(*args)
                finally:
                    if in_main:
                        self._running = None
                    else:
                        self._leave_thread()
            except (ControllerHung, Exception, SystemExit) as e:    # sys.exit() fails its robot, not the host    # noqa: BLE001 - a user's callback may raise anything: it fails its robot
                self._callback_failed(robot, node, sim_node, e, started)
                return None
            # A callback set aside while it waited (hosting/executors/scheduler.py) is timed without
            # the wait: ``take_back`` moved its start on.
            took = monotonic() - (self._started if in_main else started)
            if own_time:
                # (in the main thread ``take_back`` moved its start on past a wait, as ``_started``)
                node_time.stop(self._cpu_started if in_main else cpu)
            # Worker threads (multi-threaded executor) meet the tick's wall-clock deadline instead.
            if in_main and took > self._watchdog_s:
                sim_node.reject_answer(robot, f"late: a callback took {took:.2f} s, more than "
                                              f"the watchdog's {self._watchdog_s} s")
            return result
        # rclpy picks a subscription's call signature from the callback's: keep the original's
        # (``run`` itself binds one argument, or none for a timer).
        return (lambda msg, info: run(msg, info)) if with_info else run

    def _enter_thread(self, robot: str, own_time: bool) -> Optional[tuple[float, int]]:
        """A callback starts on one of a multi-threaded executor's threads: its CPU clock."""
        with self._workers_lock:
            self._workers.setdefault(threading.get_ident(), []).append(robot)
            self.calls += 1
            self.running += 1
            self.calls_of[robot] = self.calls_of.get(robot, 0) + 1
        return self.node_time.start() if own_time else None

    def _leave_thread(self) -> None:
        ident = threading.get_ident()
        with self._workers_lock:   # after this, stop_worker cannot reach this callback
            robots = self._workers[ident]
            robots.pop()
            if not robots:
                del self._workers[ident]
            self.running -= 1

    def _callback_failed(self, robot: str, node: Node, sim_node: ServedRobots, error: BaseException,
                         started: float) -> None:
        if isinstance(error, ControllerHung):
            self._running = None
            sim_node.mark_failed(robot, f"hung: callback still running after "
                                        f"{time.monotonic() - started:.1f} s, interrupted")
        else:
            sim_node.mark_failed(robot, _failure(error))
        if self.on_exception is not None:     # where it failed or hung
            self.on_exception(robot, node, error)

    def _wrap_async(self, callback: Callable, node: Node, robot: str, sim_node: ServedRobots,
                    with_info: bool) -> Callable:
        """An ``async def`` callback: its failure is its robot's. Its steps are timed by whoever
        runs them (the lockstep executor's ``task_started``), not across its awaits."""
        failed, row, calls_of = sim_node.failed, sim_node.row_of(robot), self.calls_of

        async def run(*args):
            if failed[row]:
                return None
            self.calls += 1
            calls_of[robot] = calls_of.get(robot, 0) + 1
            try:
                return await callback(*args)
            except ControllerHung as e:
                self._fail(robot, node, e, f"hung: callback still running after {self._unresponsive_s:.1f} s, "
                                           f"interrupted")
            except (Exception, SystemExit) as e:    # noqa: BLE001 - a user's callback may raise anything: it fails its robot
                self._fail(robot, node, e, _failure(e))
            return None
        if with_info:
            async def run_with_info(msg, info):
                return await run(msg, info)
            return run_with_info
        return run

    def _fail(self, robot: str, node: Node, error: BaseException, reason: str) -> None:
        self._robots[robot][0].mark_failed(robot, reason)
        if self.on_exception is not None:
            self.on_exception(robot, node, error)

    # --- what the lockstep executor tells it (hosting/executors/lockstep.py) -------------------

    def owner(self) -> Optional[str]:
        return self._running

    def robot_of(self, node: Node) -> Optional[str]:
        return self._robot_of.get(id(node))

    def owner_alive(self, node: Node) -> bool:
        robot = self._robot_of.get(id(node))
        if robot is None:
            return True
        served = self._robots[robot][0]
        return not served.failed[served.row_of(robot)]

    def node_failed(self, node: Node, error: BaseException) -> None:
        robot = self._robot_of.get(id(node))
        if robot is None:
            raise error
        self._fail(robot, node, error, _failure(error))

    def task_started(self, robot: Optional[str]) -> bool:
        if robot is None:
            return True
        served = self._robots.get(robot)
        if served is not None and served[0].failed[served[0].row_of(robot)]:
            return False
        self._running, self._started = robot, time.monotonic()
        self.calls += 1
        self.calls_of[robot] = self.calls_of.get(robot, 0) + 1
        return True

    def task_ended(self) -> None:
        self._running = None

    def task_failed(self, robot: Optional[str], error: BaseException) -> bool:
        served = self._robots.get(robot) if robot is not None else None
        if served is None:
            return False
        hung = isinstance(error, ControllerHung)
        self._fail(robot, served[1], error, "hung: a task of it still running after "
                   f"{self._unresponsive_s:.1f} s, interrupted" if hung else _failure(error))
        return True

    def set_aside(self) -> object:
        cpu_at = time.thread_time() if self._cpu_started is not None else None
        state = (self._running, self._started, self._cpu_started, time.monotonic(), cpu_at)
        self._running = None
        return state

    def take_back(self, state: object) -> None:
        """The callback's wall and CPU clocks move on by the time it was set aside: neither its
        lateness nor its node's own time counts what ran meanwhile."""
        running, started, cpu_started, set_aside_at, cpu_at = state
        self._running, self._started = running, started + (time.monotonic() - set_aside_at)
        self._cpu_started = cpu_started if cpu_started is None else \
            (cpu_started[0] + (time.thread_time() - cpu_at), cpu_started[1])

    def caller_robot(self) -> Optional[str]:
        """The robot whose guarded callback (or task) runs in this thread now, if any."""
        if threading.get_ident() == self._main.ident:
            return self._running
        with self._workers_lock:
            robots = self._workers.get(threading.get_ident())
            return robots[-1] if robots else None

    def end_robot(self, robot: str, ending: BaseException) -> None:
        """A thread of ``robot``'s ended its process (``rclpy.shutdown()``): the robot is stopped,
        with the call as the reason, as a callback's would."""
        served = self._robots.get(robot)
        if served is not None:
            self._fail(robot, served[1], ending, str(ending))

    def in_callback(self) -> bool:
        """Is this thread running a guarded callback now?"""
        if threading.get_ident() == self._main.ident:
            return self._running is not None
        return threading.get_ident() in self._workers

    def stop_worker(self, robot: str) -> None:
        """Interrupt ``robot``'s callback if it runs on a worker thread (a SimulatorNode.on_failed
        hook: the robot has just been failed, e.g. as unresponsive)."""
        with self._workers_lock:
            for ident, robots in self._workers.items():
                if robot in robots:
                    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(ident), ctypes.py_object(ControllerHung))

    # --- interrupting a hung callback in the main thread ---------------------------------------

    @contextlib.contextmanager
    def interrupting_hangs(self, callbacks_in_this_thread: bool):
        """While running ticks: a periodic SIGALRM checks on the callback running in the main
        thread, if that is where callbacks run (and this is the main thread)."""
        if not (callbacks_in_this_thread and threading.current_thread() is self._main):
            yield
            return
        old_handler = signal.signal(signal.SIGALRM, self._on_alarm)
        period = max(0.05, self._unresponsive_s / 4)
        signal.setitimer(signal.ITIMER_REAL, period, period)
        try:
            yield
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0, 0)
            signal.signal(signal.SIGALRM, old_handler)

    def _on_alarm(self, signum, frame) -> None:
        if self._running is not None and time.monotonic() - self._started >= self._unresponsive_s:
            raise ControllerHung(self._running)


class HostContextShutdown(RuntimeError):
    """Raised by ``rclpy.shutdown(context=…)`` on a host's context from inside a callback."""


class RobotShutdown(SystemExit):
    """A hosted node called ``rclpy.shutdown()``: in its own process that ends the process, so here
    it ends its robot's nodes (the robot is stopped, with this as the reason), not the host."""
    an_end = True       # not a fault: its log says so in a line, with no traceback


_GUARDS: "weakref.WeakSet[CallbackGuard]" = weakref.WeakSet()     # this process's, for the threads' robots
# A process that hosts one robot's nodes unguarded (multi-process mode's controller process): how it
# ends when a thread of theirs calls rclpy.shutdown(), as their own process would.
process_shutdown: Optional[Callable[[BaseException], None]] = None
_THREADS_ROBOT = "composed_sim_robot"      # a thread's (guard, robot), where a robot's callback made it


def stop_robots_that_shut_down() -> None:
    """``rclpy.shutdown()`` and ``rclpy.try_shutdown()`` of the default context, which a host never
    initialises (each hosted node has its process's context), stop the calling robot: raised from
    the call, the robot's guard (or its controller process) takes it as the end its own process
    would have had. Called from a thread that one of a robot's callbacks made (a
    ``threading.Timer(0.1, rclpy.shutdown)``), it stops that robot in the same way, from that
    thread, as its own process would end. The host's own calls name their context and are
    untouched."""
    if getattr(rclpy.shutdown, "stops_robot", False):
        return
    for name in ("shutdown", "try_shutdown"):
        original = getattr(rclpy, name)

        def call(*, context=None, uninstall_handlers=None, original=original, name=name):
            if context is None:
                ending = RobotShutdown(f"stopped: a node called rclpy.{name}(), which ends its own process: "
                                       f"its robot's nodes end here")
                thread = threading.current_thread()
                made_by = getattr(thread, _THREADS_ROBOT, None)
                if made_by is not None and not any(guard.in_callback() for guard in _GUARDS):
                    guard, robot = made_by
                    guard.end_robot(robot, ending)
                    return None
                if process_shutdown is not None and thread is not threading.main_thread():
                    process_shutdown(ending)        # a process of one robot's nodes ends with it
                    return None
                raise ending
            kwargs = {} if uninstall_handlers is None else {"uninstall_handlers": uninstall_handlers}
            return original(context=context, **kwargs)
        call.stops_robot = True
        setattr(rclpy, name, call)
    _note_threads_robot()


def end_process_on_thread_shutdown(end: Callable[[BaseException], None]) -> None:
    """In a process of one robot's nodes, unguarded: ``end(reason)`` when a thread of theirs calls
    ``rclpy.shutdown()`` (the process then ends as it would for a callback's call)."""
    global process_shutdown
    process_shutdown = end


def _note_threads_robot() -> None:
    """Each thread made inside a guarded callback remembers the robot whose callback made it."""
    init = threading.Thread.__init__

    def noting_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        for guard in _GUARDS:
            robot = guard.caller_robot()
            if robot is not None:
                setattr(self, _THREADS_ROBOT, (guard, robot))
                return
        made_by = getattr(threading.current_thread(), _THREADS_ROBOT, None)    # a thread of a robot's thread
        if made_by is not None:
            setattr(self, _THREADS_ROBOT, made_by)
    threading.Thread.__init__ = noting_init


def refuse_shutdown_from_callbacks(context, guard: CallbackGuard) -> None:
    """Make ``rclpy.shutdown`` of a hosted context, called from a controller's callback, raise
    instead: the context is its participant group's, and shutting it down would silently stop
    every other robot of the group. The host itself shuts it down with ``Context.shutdown``."""
    shutdown, try_shutdown = context.shutdown, context.try_shutdown

    def refuse(original):
        def call(*args, **kwargs):
            if guard.in_callback():
                raise HostContextShutdown("called rclpy.shutdown on the host's context: hosted controllers "
                                          "must not shut down ROS, the host owns the context")
            return original(*args, **kwargs)
        return call
    context.shutdown, context.try_shutdown = refuse(shutdown), refuse(try_shutdown)


_SPIN_CALLS = frozenset({"spin", "spin_once", "spin_until_future_complete", "spin_once_until_future_complete"})


def _failure(error: BaseException) -> str:
    """The failed robot's reason; a controller that spun inside its callback is told why that fails."""
    if isinstance(error, RobotShutdown):
        return str(error)
    tb = error.__traceback__
    while tb is not None:
        code = tb.tb_frame.f_code
        if code.co_name in _SPIN_CALLS and "rclpy" in code.co_filename.replace("\\", "/").split("/"):
            return (f"controllers must not spin: the host spins them ({code.co_name} called inside a callback "
                    f"raised {type(error).__name__}: {error})")
        tb = tb.tb_next
    return f"callback raised {type(error).__name__}: {error}"
