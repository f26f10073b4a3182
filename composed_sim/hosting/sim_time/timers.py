"""A hosted controller's timers on sim time, fired at a defined point of the tick.

The order within tick k, for each robot, in every executor and both host modes:

1. the node's clock reads tick k's time from the tick's open (the host sets it);
2. the simulator publishes tick k's sensors; the robot's sensor callbacks of tick k run;
3. then its timers due at or before tick k's time fire. A ``cmd_vel`` published from a timer
   callback answers tick k, exactly as one published from a sensor callback. A sensor callback
   that sleeps on the node's clock counts as done, and the timers follow the node's clock until
   it wakes (in its own process, other threads fire them meanwhile).

A timer fires first one period after the time it was created at, as rclpy's does on sim time: one
created while the controller is constructed (before tick 0, the clock at 0) first at its period, a
0.1 s timer on a 10 Hz world at tick 1, then every tick. Until then its robot has had no chance to
answer from it, and is not late (``first_due_ns``, ``first_timer_tick``: ros/answer_ledger.py
keeps its last command until then); nor is any robot before the run-wide nodes' first timer
fired, since what they publish or call from it (a start command) may be what its nodes wait
for. A timer slower than the tick fires every k-th tick (the world file says so with
``answers_every_ticks``); one faster than the tick fires once per tick, at the tick's time (rcl
skips the periods a time jump passed over).

How: each timer runs on a clock of its own (a ``ROSClock`` in ROS-time mode, which only we set),
advanced to tick k's time when the node's last sensor callback of tick k has returned. So no
executor can fire a timer before the readings of its tick were handled, whichever ready entity it
picks first. A node that subscribes to none of its robot's sensors (a later node of a robot's
chain, a run-wide node) has its timers moved to tick k's time by the host when the tick opens
(``advance_to``). Callback-driven controllers (no timers) are not touched and pay nothing.
"""
from __future__ import annotations

import inspect
import math
import threading
from typing import Callable, Collection, Optional

from greenlet import getcurrent
from rclpy.clock import JumpThreshold, ROSClock
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.subscription import Subscription

from composed_sim.devices.common import cdr
from composed_sim.hosting.sim_time.sleeps import SLEEP_HOOK
from composed_sim.ros.driven_clocks import follow_sim_time, set_sim_time


class SimTimers:
    """The timers of one controller node (one robot)."""

    def __init__(self, tick_ns: int, *, follow_stamps: bool = False):
        """``follow_stamps``: set the node's clock to a sensor message's stamp when it is behind,
        before the callback runs (multi-process mode, where the node's clock follows /clock, which
        may arrive after the sensors; in composed mode the host sets it at publish)."""
        self._tick_ns = tick_ns
        self._follow_stamps = follow_stamps
        self._node: Optional[Node] = None
        self._clocks: list[ROSClock] = []             # each timer's clock
        self.periods_s: list[float] = []
        self.first_due_ns = math.inf    # when the first of the timers made before tick 0 first fires
        self._constructed = False
        self._sensor_topics: frozenset[str] = frozenset()
        self._watching = False
        self._expected = 0              # sensor callbacks per tick: the node's sensor subscriptions
        self._stamp = -1                # the tick (stamp ns) whose callbacks are being counted
        self._seen = 0
        self._lock = threading.Lock()   # sensor callbacks of one node may run on several threads
        self._advanced_ns = -1          # the time the timers' clocks were last moved to
        self._sleepers = 0              # sensor callbacks set aside, asleep on the node's clock
        self._follow = None             # meanwhile: the timers follow the node's clock (a jump callback)

    # --- set-up ------------------------------------------------------------------------------

    def prepare(self, node: Node) -> None:
        """Before ``node``'s constructor: its ``create_timer`` puts timers on sim time
        (controllers create their timers there)."""
        self._node = node
        node.create_timer = self._create_timer

    def started(self, sensor_topics: Collection[str]) -> None:
        """The node is constructed; ``sensor_topics``: its robot's sensor topics (resolved names),
        the subscriptions whose callbacks a tick's timers wait for."""
        self._constructed = True
        self._sensor_topics = frozenset(sensor_topics)
        if self._clocks:
            self._watch()

    def _create_timer(self, timer_period_sec: float, callback: Callable, callback_group=None,
                      clock=None, autostart: bool = True):
        create = Node.create_timer.__get__(self._node)
        if clock is not None:       # the controller chose its clock (a steady one, say): its own
            return create(timer_period_sec, callback, callback_group, clock, autostart)
        timer_clock = ROSClock()
        follow_sim_time(timer_clock)
        # First due one period after now, as in rclpy: before tick 0 the node's clock reads 0.
        start = self._node.get_clock().now().nanoseconds if self._constructed else 0
        set_sim_time((timer_clock,), start)
        timer = create(timer_period_sec, callback, callback_group, timer_clock, autostart)
        with self._lock:
            self._clocks.append(timer_clock)
        self.periods_s.append(timer_period_sec)
        if not self._constructed and autostart:
            self.first_due_ns = min(self.first_due_ns, start + round(timer_period_sec * 1e9))
        if self._constructed and not self._watching:
            self._watch()
        return timer

    @property
    def follows_sensors(self) -> bool:
        """Does the node subscribe to its robot's sensors? Its timers then fire once its sensor
        callbacks of the tick have run; the timers of a node without (a later node of a robot's
        chain, a run-wide node) are moved to each tick's time by the host (``advance_to``)."""
        return any(s.topic_name in self._sensor_topics for s in self._node.subscriptions)

    def advance_to(self, now_ns: int) -> None:
        """The tick at ``now_ns`` has begun: timers due by then may fire."""
        self._advance(now_ns)

    def _watch(self) -> None:
        """Count the node's sensor callbacks per tick."""
        self._watching = True
        subs = [s for s in self._node.subscriptions if s.topic_name in self._sensor_topics]
        self._expected = len(subs)
        for sub in subs:
            sub.callback = self._counting(sub)

    def _counting(self, sub: Subscription) -> Callable:
        callback = sub.callback
        raw = sub.raw
        node_clock = self._node.get_clock()

        def run(msg, *info):
            stamp = sensor_stamp(msg, raw)
            if self._follow_stamps:
                clocks_to((node_clock,), stamp)
            me = getcurrent()
            told, asleep = getattr(me, SLEEP_HOOK, None), []
            setattr(me, SLEEP_HOOK, lambda: asleep or self._fell_asleep(stamp, asleep))
            try:
                return callback(msg, *info)
            finally:
                setattr(me, SLEEP_HOOK, told)
                if asleep:
                    self._woke()
                else:
                    self._handled(stamp)
        if not inspect.iscoroutinefunction(callback):
            return with_signature_of(sub, run)

        async def run_async(msg, *info):
            # An ``async def`` callback stays one, so that every executor runs its coroutine (rclpy's
            # awaits only what a coroutine function returns): its tick counts as handled once
            # the coroutine is made, as a plain callback's once it returned.
            return await run(msg, *info)
        return with_signature_of(sub, run_async)

    # --- per tick ------------------------------------------------------------------------------

    def _fell_asleep(self, stamp: int, asleep: list) -> None:
        """A sensor callback of tick ``stamp`` sleeps until a later time on the node's clock (it is
        set aside: sim_time/sleeps.py). Its tick counts as handled, and until it wakes the timers
        follow the node's clock, which the host moves as each tick opens: in its own process the
        node's timers fire on time meanwhile, in the executor's other threads."""
        asleep.append(True)
        with self._lock:
            self._sleepers += 1
            if self._sleepers == 1:
                clock = self._node.get_clock()
                self._follow = clock.create_jump_callback(
                    JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=None, on_clock_change=False),
                    post_callback=lambda _: self._advance(clock.now().nanoseconds))
        self._handled(stamp)

    def _woke(self) -> None:
        with self._lock:
            self._sleepers -= 1
            if self._sleepers == 0 and self._follow is not None:
                self._follow.unregister()
                self._follow = None

    def _handled(self, stamp: int) -> None:
        with self._lock:
            if stamp != self._stamp:
                if stamp < self._stamp:
                    return          # a reading of an earlier tick, handled late: its tick is over
                self._stamp, self._seen = stamp, 0
            self._seen += 1
            if self._seen != self._expected:
                return
        self._advance(stamp)

    def _advance(self, now_ns: int) -> None:
        with self._lock:
            if now_ns <= self._advanced_ns:     # a reading handled late (it waited for its group)
                return
            self._advanced_ns = now_ns
            clocks = list(self._clocks)
        set_sim_time(clocks, now_ns)

    def period_warnings(self, controller: str, answers_every_ticks: Optional[int]) -> list[str]:
        """Timers that will not answer the ticks as the world file expects. The messages name the
        node's class, not the robot, so that they are the same for every robot of a group.
        ``answers_every_ticks``: None for a robot that answers when published (no tick to miss)."""
        out = []
        tick_s = self._tick_ns * 1e-9
        for period in self.periods_s:
            ratio = period / tick_s
            if period <= 0:
                continue
            if not (_whole(ratio) or _whole(1 / ratio)):
                out.append(f"controller {controller!r} has a timer of {period:g} s, neither a multiple nor a "
                           f"divisor of the world's tick ({tick_s:g} s): it fires at irregular ticks")
            elif ratio > 1.5 and answers_every_ticks == 1:
                out.append(f"controller {controller!r} has a timer of {period:g} s, {round(ratio)} ticks: if it "
                           f"answers from that timer, set answers_every_ticks: {round(ratio)} in its robot group, "
                           f"or each tick in between is a violation")
        return out


def first_timer_tick(timers: Collection[SimTimers], tick_ns: int) -> int:
    """The tick at which the first of the timers that ``timers``' nodes made before tick 0 first
    fires (0: none has one)."""
    due = min((t.first_due_ns for t in timers), default=math.inf)
    return 0 if due == math.inf else math.ceil(due / tick_ns - 1e-9)


def _whole(x: float) -> bool:
    return math.isclose(x, round(x), rel_tol=1e-9, abs_tol=1e-9)


def clocks_to(clocks, stamp: int) -> None:
    """Move each of a robot's nodes' ``clocks`` that is behind to ``stamp`` (ns), in a process whose
    node clocks follow /clock (multi-process mode): each node hears /clock on its own, maybe after
    the tick's sensors or its run-wide batch reached another of them; in their own process every
    node's clock has moved before what the tick brings is handled."""
    set_sim_time(clocks, stamp, forward_only=True)


def before_each_tick(subscriptions, on_tick: Callable[[int], None],
                     on_each: Optional[Callable[[int, object], None]] = None) -> None:
    """Call ``on_tick(stamp ns)`` before the first of these sensor subscriptions' callbacks of each
    tick (a process whose node clocks follow /clock: a controller process of multi-process mode), e.g. to move the
    timers of a robot's nodes that read no sensors to the tick's time; ``on_each(stamp ns,
    subscription)`` before every one."""
    last = [-1]
    for sub in subscriptions:
        callback, raw = sub.callback, sub.raw

        def run(msg, *info, callback=callback, raw=raw, sub=sub):
            stamp = sensor_stamp(msg, raw)
            if stamp > last[0]:
                last[0] = stamp
                on_tick(stamp)
            if on_each is not None:
                on_each(stamp, sub)
            return callback(msg, *info)
        sub.callback = with_signature_of(sub, run)


def sensor_stamp(msg, raw: bool) -> int:
    """A sensor message's stamp in ns, from its bytes (``raw``) or its header."""
    return cdr.stamp_ns(msg) if raw else msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def with_signature_of(sub: Subscription, run: Callable) -> Callable:
    """``run(msg, *info)`` as a callback of ``sub``: rclpy picks a subscription's call signature
    from its callback's, so it keeps the original's."""
    with_info = sub._callback_type is Subscription.CallbackType.WithMessageInfo
    if inspect.iscoroutinefunction(run):
        async def with_message_info(msg, info):
            return await run(msg, info)

        async def message_only(msg):
            return await run(msg)
        return with_message_info if with_info else message_only
    return (lambda msg, info: run(msg, info)) if with_info else (lambda msg: run(msg))
