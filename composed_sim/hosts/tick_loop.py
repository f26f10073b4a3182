"""The lockstep tick loop shared by every host.

Per tick, one way: sensors of tick k → messages → controllers → answers (or the watchdog's
fallback) → actuator arrays → physics → sensors of tick k+1. A host supplies only how the
controllers' callbacks get run while the loop waits (``wait_for_answers``).
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Callable, Optional, Protocol, Sequence

import numpy as np
import psutil

from composed_sim.world.robot_models import display_colors
from composed_sim.core.simulation import SensorFrame, Simulation
from composed_sim.core.violations import Violation
from composed_sim.loop_functions import LoopHooks


@dataclass
class Trajectories:
    """Poses at ticks 0 … T (row t is the state after t physics steps)."""
    names: list[str]
    positions: np.ndarray     # [T+1, n, 2] m
    headings: np.ndarray      # [T+1, n] rad
    ticks_done: int = 0       # rows filled beyond the initial pose
    led_colors: Optional[np.ndarray] = None   # [T+1, n, 3] uint8: each robot's display colour
    altitudes: Optional[np.ndarray] = None    # [T+1, n] m above the floor; None: no robot flies
    # Where the loop functions' metric rows go as they are taken; None: they stay in memory
    # (LoopResult.metrics). A subclass that streams the rows to disk (outputs/stream.py) sets it.
    metrics_sink = None

    @classmethod
    def allocate(cls, sim: Simulation, ticks: int) -> "Trajectories":
        t = cls(sim.names, np.zeros((ticks + 1, sim.n, 2)), np.zeros((ticks + 1, sim.n)),
                led_colors=np.zeros((ticks + 1, sim.n, 3), dtype=np.uint8),
                altitudes=None if sim.drones is None else np.zeros((ticks + 1, sim.n)))
        t.positions[0], t.headings[0] = sim.positions, sim.headings
        t.led_colors[0] = display_colors(sim.led_colors)
        if t.altitudes is not None:
            t.altitudes[0] = sim.altitudes
        return t

    def record(self, sim: Simulation) -> None:
        self.ticks_done += 1
        self.positions[self.ticks_done] = sim.positions
        self.headings[self.ticks_done] = sim.headings
        self.led_colors[self.ticks_done] = display_colors(sim.led_colors)
        if self.altitudes is not None:
            self.altitudes[self.ticks_done] = sim.altitudes

    def filled(self) -> "Trajectories":
        """Only the rows written so far (a run stopped early keeps what it has)."""
        k = self.ticks_done + 1
        leds = None if self.led_colors is None else self.led_colors[:k]
        altitudes = None if self.altitudes is None else self.altitudes[:k]
        return Trajectories(self.names, self.positions[:k], self.headings[:k], self.ticks_done, leds, altitudes)


# Where the main process's time goes in a tick (summary.json's ``phases_per_tick_ms``; every
# phase but ``waiting`` is the serial part that more cores cannot share).
PHASES = ("physics", "sensing", "sending_frames", "waiting", "gathering_answers", "loop_functions",
          "recording", "other")


@dataclass
class LoopTimes:
    ros_exchange_s: float = 0.0    # publishing sensors, controllers' callbacks, collecting answers
    ticks_wall_s: float = 0.0
    phases_s: dict = field(default_factory=lambda: dict.fromkeys(PHASES, 0.0))
    cpu_s: float = 0.0             # CPU seconds of this process and the controllers' during the ticks
    main_cpu_s: float = 0.0        # of which this process's (all its threads)
    node_code_s: float = 0.0       # seconds inside the nodes' own code (hosting/guard/node_time.py), all processes


class PhaseClock:
    """Charges the wall time since the previous lap to a phase."""

    def __init__(self, phases: dict):
        self.phases = phases
        self.started = self._last = time.perf_counter()

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.phases[phase] += now - self._last
        self._last = now

    def recharge(self, charged: str, phase: str, seconds: float) -> None:
        """Move ``seconds`` of a lap charged to ``charged`` to ``phase`` (e.g. sensing done on demand)."""
        self.phases[charged] -= seconds
        self.phases[phase] += seconds


@dataclass
class LoopResult:
    trajectories: Trajectories
    violations: list[Violation]
    times: LoopTimes
    interrupted: bool = False
    # (tick, resident MB of this process) about 50 times per run: flat memory, or where it grows
    memory: list[tuple[int, float]] = field(default_factory=list)
    metrics: list[dict] = field(default_factory=list)   # the loop functions' rows, {"tick": t, ...}
    finished: bool = False     # the loop functions ended the run (is_finished)


MEMORY_SAMPLES = 50


def resident_mb() -> float:
    return psutil.Process().memory_info().rss / 2**20


class TickObserver(Protocol):
    """Watches the world after each tick (tick 0 included): recording, live markers."""
    def on_tick(self, sim: Simulation) -> None: ...


class Exchange(Protocol):
    """The simulator's side of the ROS exchange: simulator nodes in this process
    (hosting/nodes_exchange.py), or worker processes that hold them (hosts/workers/worker_host.py)."""
    violations: list[Violation]

    #: True: ``publish_state(sim)``, the exchange's processes read the sensors themselves
    #: (core/senses.py); False: ``publish_tick(sim.frame)``.
    senses_itself: bool

    def publish_tick(self, frame: SensorFrame) -> None: ...
    def publish_state(self, sim: Simulation) -> None: ...
    def publish_clock(self, tick: int) -> None: ...
    def close_tick(self, fallback: str, previous: tuple[np.ndarray, np.ndarray],
                   commands: tuple[np.ndarray, np.ndarray]) -> None: ...
    def take_led_commands(self) -> dict[int, np.ndarray]: ...
    def take_rab_payloads(self) -> dict[int, np.ndarray]: ...
    def take_drone_commands(self) -> list:
        """The drones' commands of the tick, wherever they were taken (core/drone_commands.py)."""
    def another_simulator(self) -> Optional[str]:
        """Another simulator in one of the run's ROS domains (``SimulatorNode.another_simulator``)."""
    def gathering_s(self) -> float:
        """Seconds spent so far inside ``wait_for_answers`` receiving and unpacking answers, not
        waiting for them."""
    def controllers_time_s(self) -> tuple[float, float]:
        """(CPU seconds of the controllers' processes other than this one, seconds inside the
        nodes' own code in every process), both since the first tick."""


class AnotherSimulator(Exception):
    """Another simulator publishes /clock in one of the run's ROS domains: the run stops."""


def acted_commands(tick: int, commands: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The wheel commands that act in the step after ``tick``: ARGoS's tick order.

    ARGoS's step is act, physics, media, then sense and control, so its first step applies the
    actuators' initial zero command and its controllers first decide on the state after one step.
    Here the controllers also answer tick 0 (the state before any step: their LEDs and payloads
    act, as an ARGoS controller's ``Init`` settings do), but the first step drives no wheel; from
    then on the answer to tick t acts in step t + 1, as in ARGoS. So a run's tick t is ARGoS's tick
    t for the same file (docs/fidelity.md, "Tick order"), not its tick t + 1.
    """
    if tick == 0:
        return np.zeros_like(commands[0]), np.zeros_like(commands[1])
    return commands


CHECKPOINT_EVERY = 100   # ticks between two checkpoints (docs/faults.md gives what one costs)


class LoopBook:
    """What a run of the tick loop keeps besides the tick order: the time spent (wall, CPU, per
    phase), memory samples, checkpoints, and the result, whole or so far."""

    def __init__(self, traj: Trajectories, exchange: Exchange, hooks: LoopHooks, ticks: int,
                 checkpoint: Optional[Callable[[LoopResult], None]]):
        self.traj, self._exchange, self._hooks, self._checkpoint = traj, exchange, hooks, checkpoint
        self.times = LoopTimes()
        self.memory = [(0, resident_mb())]
        self._sample_every = max(1, ticks // MEMORY_SAMPLES)
        self._t_start = time.perf_counter()
        self._cpu_start, self._controllers_start = time.process_time(), exchange.controllers_time_s()
        if checkpoint is not None:
            checkpoint(self.so_far())

    def so_far(self) -> LoopResult:
        """What was simulated until now, as an interrupted run's result."""
        self._count_time()
        return LoopResult(self.traj.filled(), list(self._exchange.violations), self.times, True, self.memory,
                          list(self._hooks.rows))

    def tick_done(self, sim: Simulation) -> None:
        if sim.tick % self._sample_every == 0:
            self.memory.append((sim.tick, resident_mb()))
        if self._checkpoint is not None and sim.tick % CHECKPOINT_EVERY == 0:
            self._checkpoint(self.so_far())

    def result(self, sim: Simulation, interrupted: bool) -> LoopResult:
        self._count_time()
        if self.memory[-1][0] != sim.tick:
            self.memory.append((sim.tick, resident_mb()))
        return LoopResult(self.traj.filled(), list(self._exchange.violations), self.times, interrupted, self.memory,
                          self._hooks.rows, self._hooks.finished)

    def _count_time(self) -> None:
        times = self.times
        times.ticks_wall_s = time.perf_counter() - self._t_start
        cpu_elsewhere, node_code = self._exchange.controllers_time_s()
        times.main_cpu_s = time.process_time() - self._cpu_start
        times.cpu_s = times.main_cpu_s + cpu_elsewhere - self._controllers_start[0]
        times.node_code_s = node_code - self._controllers_start[1]
        phases = times.phases_s
        phases["other"] = times.ticks_wall_s - sum(v for k, v in phases.items() if k != "other")


def run_lockstep(sim: Simulation, exchange: Exchange, wait_for_answers: Callable[[float], bool],
                 ticks: int, *, progress: Optional[Callable[[int], None]] = None,
                 should_stop: Callable[[], bool] = lambda: False,
                 observers: Sequence[TickObserver] = (),
                 checkpoint: Optional[Callable[[LoopResult], None]] = None,
                 trajectories: Optional[Callable[[Simulation, int], Trajectories]] = None, logs=None) -> LoopResult:
    """Run ``ticks`` lockstep ticks; ``wait_for_answers(timeout_s)`` runs or awaits the controllers
    until every robot answered the published tick or the watchdog time is over. ``checkpoint``
    gets the result so far at tick 0 and every CHECKPOINT_EVERY ticks (marked interrupted): what a
    run killed outright, or quit by a second Ctrl-C, leaves behind. ``trajectories(sim, ticks)``
    makes what records each tick's poses, at tick 0 (default: ``Trajectories.allocate``, in memory).
    ``logs``: the run's NodeLogs, where the drones' refused commands are told (else the console)."""
    lockstep = sim.world.lockstep
    traj = (trajectories or Trajectories.allocate)(sim, ticks)
    previous = (np.zeros(sim.n), np.zeros(sim.n))
    hooks = _tick_0(sim, traj, observers)
    book = LoopBook(traj, exchange, hooks, ticks, checkpoint)
    refused = refusal_report(sim.names, logs)
    interrupted = False
    try:
        for _ in range(ticks):
            if should_stop():
                interrupted = True
                break
            clock = PhaseClock(book.times.phases_s)
            answers = exchange_tick(sim, exchange, wait_for_answers, lockstep, previous, clock, refused)
            commands = acted_commands(sim.tick, answers)
            book.times.ros_exchange_s += time.perf_counter() - clock.started
            sim.set_velocity_commands(*commands)
            previous = commands
            clock.lap("gathering_answers")
            hooks.pre_step(sim)
            clock.lap("loop_functions")
            sim.advance()
            clock.lap("physics")
            traj.record(sim)
            clock.lap("recording")
            sensed = sim.times.sensing_s
            finished = hooks.post_step(sim)
            clock.lap("loop_functions")
            clock.recharge("loop_functions", "sensing", sim.times.sensing_s - sensed)   # sim.frame read
            for observer in observers:
                observer.on_tick(sim)
            if progress is not None:
                progress(1)
            book.tick_done(sim)
            clock.lap("recording")
            if finished:
                break
        hooks.end(sim)
        exchange.publish_clock(sim.tick)      # the last state simulated is on the wire too
    except BaseException as e:
        # Nothing is lost: whoever handles the error can still write what was simulated so far.
        e.partial_result = book.so_far()
        raise
    return book.result(sim, interrupted)



def _tick_0(sim: Simulation, traj: Trajectories, observers: Sequence[TickObserver]) -> LoopHooks:
    """The world's loop functions (composed_sim/loop_functions.py) started, and tick 0 sensed and
    shown to the observers: the world as the loop functions' start left it."""
    hooks = LoopHooks(sim)
    hooks.rows_to = traj.metrics_sink
    hooks.start(sim)
    sim.sense()
    hooks.at_tick_0(sim)
    for observer in observers:
        observer.on_tick(sim)
    return hooks


def exchange_tick(sim: Simulation, exchange: Exchange, wait_for_answers: Callable[[float], bool], lockstep,
                  previous: tuple[np.ndarray, np.ndarray], clock: PhaseClock,
                  refused: Callable[[list], None] = lambda refusals: None) -> tuple[np.ndarray, np.ndarray]:
    """The tick's ROS part: the sensors out, the controllers' answers in (or the watchdog's
    fallback under ``lockstep``), their LEDs and payloads set, the drones' commands given to their
    firmware (``refused``: told what it refused); the commands the answers give."""
    sensed = sim.times.sensing_s
    if exchange.senses_itself:
        exchange.publish_state(sim)
    else:
        exchange.publish_tick(sim.frame)      # the frame is read here, on first use
    clock.lap("sending_frames")
    clock.recharge("sending_frames", "sensing", sim.times.sensing_s - sensed)
    gathered = exchange.gathering_s()
    wait_for_answers(lockstep.watchdog_s)
    if (other := exchange.another_simulator()) is not None:
        raise AnotherSimulator(
            f"another simulator joined the run's ROS domain at tick {sim.tick}: {other} publishes "
            f"/clock there too, so this run's robots hear its topics and the run stopped; give each "
            f"run its own domain (leave --domain-id and ROS_DOMAIN_ID unset to pick a free one)")
    clock.lap("waiting")
    # What was received and unpacked while waiting was not waiting.
    clock.recharge("waiting", "gathering_answers", exchange.gathering_s() - gathered)
    commands = (np.empty(sim.n), np.empty(sim.n))
    exchange.close_tick(lockstep.fallback, previous, commands)
    for robot, colors in exchange.take_led_commands().items():
        sim.set_led_colors(robot, colors)
    for robot, payload in exchange.take_rab_payloads().items():
        sim.set_rab_payload(robot, payload)
    drone_commands = exchange.take_drone_commands()
    if drone_commands and sim.drones is not None:
        refused(sim.drones.apply(drone_commands))
    return commands


def refusal_report(names: Sequence[str], logs=None) -> Callable[[list], None]:
    """The drones' refused commands (core/drone_commands.Refusal) told as Crazyswarm2's server tells
    what it cannot do, a warning: in the drone's log and, once per kind, on the console (``logs``,
    the run's NodeLogs); without logs, once per kind on stderr."""
    from composed_sim.hosting import WARN
    told: set[str] = set()

    def report(refusals: list) -> None:
        for refusal in refusals:
            owner = names[refusal.robot] if refusal.robot >= 0 else "crazyflie_server"
            kind = refusal.text.split(":")[0]
            if logs is not None:
                logs.emit(owner, "crazyflie_server", "crazyflie_server", WARN, f"[{owner}] {refusal.text}",
                          ("drone commands", "", kind))
            elif kind not in told:
                told.add(kind)
                print(f"composed-sim: warning: [{owner}] {refusal.text}", file=sys.stderr)
    return report
