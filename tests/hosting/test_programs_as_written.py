"""Small robots' ROS 2 programs as other people write them (tests/user_pkg/programs_as_written, no
composed_sim import), each hosted in every mode: ``--workers 1``, ``--workers 2``, ``--workers 1
--executor multi-threaded`` and ``--mode multi-process``. Each test asserts what the program's own
process would do: the same nodes, a robot's nodes in a process of their own under rclpy's
``MultiThreadedExecutor`` with ``use_sim_time``, driven by a /clock that moves at real-time pace.
Where a test's docstring says why that is so, it reasons from rclpy's own code (rclpy 7.1.6, the
Jazzy wheels); the programs were also run that way outside the repository.

What a program does is read from the nodes' log lines (``<out>/logs/<robot>.log``: tick and text,
the same in every mode) and from the run's result (violations, paths).

Each program failed in some mode before this change (docs/contract.md lists the programs and what
they showed). The cells that still differ are rclpy's own multi-threaded executor's, kept for
comparison: marked ``xfail`` with what they show (not strict: their threads' timing decides). The default run covers ``--workers
1`` (and ``--workers 2`` where the failure was of worker processes), ``-m slow`` the whole matrix."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Optional

import numpy as np
import pytest

from tests.conftest import importable
from composed_sim.world.loader import dump_world, load_world
from composed_sim.world.schema import NodeSpec

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
PACKAGE = ROOT / "tests" / "user_pkg" / "programs_as_written"
INTERFACES = ROOT / "tests" / "user_pkg" / "robot_programs_interfaces"
MODES = ("workers 1", "workers 2", "multi-threaded", "multi-process")
PER_PARTICIPANT = "workers 1, a participant per robot"      # what --workers 1 does past 80 robots
THREADED_WORKERS = "workers 2, multi-threaded"              # rclpy's executor in each worker
THREADS_TIMING = ("under rclpy's own multi-threaded executor (kept for comparison) the ticks in which calls and "
                  "feedback come depend on its threads' timing")


@pytest.fixture
def programs(monkeypatch):
    yield from importable(monkeypatch, PACKAGE)


def cells(failing: dict[str, str], default: tuple[str, ...] = ("workers 1",)) -> list:
    """The modes as parameters: ``failing`` maps a mode to what it shows on today's hosting
    (strict xfail); the modes not in ``default`` run with ``-m slow``."""
    params = []
    for mode in MODES:
        # Under rclpy's multi-threaded executor the outcome also depends on its threads' timing.
        marks = [pytest.mark.xfail(strict=mode != "multi-threaded", reason=failing[mode])] if mode in failing else []
        if mode not in default:
            marks.append(pytest.mark.slow)
        params.append(pytest.param(mode, marks=marks, id=mode.replace(" ", "-")))
    return params


def world_of(*nodes: str, robots: int = 2, ticks: int = 10, run_wide: tuple = (), watchdog_s: float = 1.0,
             **group):
    """``robots`` foot-bots of the flocking arena, each running ``nodes`` (``module:Class`` of
    programs_as_written, or ``(module:Class, parameters)``), and the ``run_wide`` nodes."""
    def spec(node) -> NodeSpec:
        name, parameters = (node, {}) if isinstance(node, str) else node
        return NodeSpec(node=f"programs_as_written.{name}", parameters=parameters)
    world = load_world(FLOCKING, robots=robots, ticks=ticks, seed=3)
    base = world.robots[0]
    robots_group = base.model_copy(update={"count": robots, "controller": None, "params": {},
                                           "nodes": [spec(n) for n in nodes], **group})
    return world.model_copy(update={
        "robots": [robots_group], "interfaces": [str(INTERFACES)], "nodes": [spec(n) for n in run_wide],
        "lockstep": world.lockstep.model_copy(update={"watchdog_s": watchdog_s})})


LINE = re.compile(r"^\[(\w+)\] \[(?:sim [\d.]+ s, tick (\d+)|set-up)\] \[([\w.]+)\]: (.*)$")


@dataclass
class Line:
    tick: int           # -1: while the nodes were built
    node: str           # the logger's name: ``bot0.planner``, ``dispatcher``
    text: str


@dataclass
class Run:
    result: object
    lines: dict[str, list[Line]]          # per log file (robot, or run-wide node): its lines in order

    def of(self, owner: str, node: Optional[str] = None) -> list[Line]:
        return [line for line in self.lines.get(owner, []) if node is None or line.node.endswith(f".{node}")
                or line.node == node]

    def texts(self, owner: str, node: Optional[str] = None) -> list[str]:
        return [line.text for line in self.of(owner, node)]

    def ticks_of(self, owner: str, text: str) -> list[int]:
        return [line.tick for line in self.of(owner) if line.text.startswith(text)]

    @property
    def violations(self) -> list:
        return self.result.violations

    def moved(self) -> np.ndarray:
        positions = self.result.trajectories.positions
        return np.linalg.norm(positions[-1] - positions[0], axis=1)


def read_logs(folder: Path) -> dict[str, list[Line]]:
    lines: dict[str, list[Line]] = {}
    for file in sorted(folder.glob("*.log")):
        for text in file.read_text().splitlines():
            match = LINE.match(text)
            if match:
                tick = int(match[2]) if match[2] is not None else -1
                lines.setdefault(file.stem, []).append(Line(tick, match[3], match[4]))
    return lines


@pytest.fixture
def run_in(programs, tmp_path, domain_id, mp_domain):
    """``run_in(world, mode)``: the world run by the host that ``composed-sim run`` starts for the
    mode, its nodes' log lines in files as the command line writes them."""
    from composed_sim.hosting import WARN, Console, LogSettings, NodeLogs
    from composed_sim.hosts.make import make_host
    from composed_sim.hosts.settings import HostSettings
    settings = {"workers 1": HostSettings(workers=1), "workers 2": HostSettings(workers=2),
                "multi-threaded": HostSettings(workers=1, executor="multi-threaded"),
                "multi-process": HostSettings(mode="multi-process", robots_per_domain=2),
                PER_PARTICIPANT: HostSettings(workers=1, robots_per_participant=1),
                THREADED_WORKERS: HostSettings(workers=2, executor="multi-threaded")}

    def run(world, mode: str) -> Run:
        folder = tmp_path / re.sub(r"\W+", "-", mode) / "logs"
        logs = NodeLogs(LogSettings(str(folder), WARN), world.tick_ns, console=Console(logs_hint=str(folder)))
        domain = mp_domain if mode == "multi-process" else domain_id
        with make_host(replace(settings[mode], domain_id=domain), world, logs) as host:
            result = host.run()
        logs.flush()
        return Run(result, read_logs(folder))
    return run


# --- services ------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", cells({"multi-threaded": (
    "rclpy's own MultiThreadedExecutor stalls when two robots' blocking calls share it, as they do hosted: "
    "with rclpy alone, 2 robots' nodes in one executor of 4 threads and each tick published once both "
    "answered, 124 of 166 calls timed out at 2 s; one robot per executor, as in its own process, 0 of 100")}))
def test_a_blocking_call_with_a_timeout_is_answered_within_the_tick(run_in, mode):
    """``call(req, timeout_sec=2.0)`` from a scan callback, client and subscription in one
    reentrant group, the planner listed first. In its own process another thread of the
    MultiThreadedExecutor serves ``plan`` and takes the response while the callback waits: the
    answer comes long before 2 s, and the robot answers every tick."""
    run = run_in(world_of("services:Planner", "services:TimeoutCaller", ticks=6), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        assert run.ticks_of(robot, "Incoming request") == list(range(6))
        assert run.ticks_of(robot, "planner did not answer") == []
    assert (run.moved() > 0.01).all()


@pytest.mark.parametrize("mode", cells({}))
def test_an_awaited_call_async_in_a_reentrant_group_answers_from_tick_0(run_in, mode):
    """``await cli.call_async(req)`` in an ``async def`` scan callback, client and subscription in
    one reentrant group (as rclpy's examples put them): the response is taken while the coroutine
    waits, so each scan is answered in its tick."""
    run = run_in(world_of("services:Planner", "services:AwaitingCaller", ticks=6), mode)
    assert run.violations == []
    assert run.ticks_of("bot0", "Incoming request") == list(range(6))


@pytest.mark.parametrize("mode", cells({"multi-threaded": (
    "under a stock executor a call between hosted nodes completes the client's future at once, whatever the "
    "client's group (services.hand_over): the response is taken while rclpy would hold the group, and the robot "
    "answers every tick")}))
def test_an_awaited_call_whose_response_needs_the_callbacks_own_group_waits_forever(run_in, mode):
    """The same with client and subscription left in the node's default (mutually exclusive)
    group. rclpy's executor holds the group from the callback's start until its coroutine is done
    (``Executor._make_handler``: ``beginning_execution`` … ``ending_execution`` around the awaited
    callback), and takes the client's response only when the group may run: in its own process
    the first scan's call is served and its response never taken, no later scan is handled, and
    the robot never answers (measured so: 0 answers of 5 scans). So the robot is late from tick 0
    on and is failed as unresponsive, as a hung process is; the planner is asked once."""
    world = world_of("services:Planner", "services:AwaitingInItsGroup", ticks=5, watchdog_s=0.3)
    run = run_in(world, mode)
    for robot in ("bot0", "bot1"):
        late = [v for v in run.violations if v.robot == robot]
        assert late and late[0].tick == 0 and "no answer" in late[0].reason
        assert "unresponsive" in late[-1].reason
        asked = run.ticks_of(robot, "Incoming request")
        # A controller process stopped as unresponsive loses the log lines it had not written yet.
        assert asked == [0] or (mode == "multi-process" and asked == [])
    assert (run.moved() == 0).all()


@pytest.mark.parametrize("mode", cells({}))
def test_a_request_sent_from_a_constructor_is_delivered(run_in, mode):
    """``call_async`` from the constructor, after ``wait_for_service`` said the service is there
    (what ``main()`` does right after building the node in the ROS 2 examples). In its own process
    the request reaches the matched service, which answers once its executor spins: the result is
    there by the first tick."""
    run = run_in(world_of("services:Planner", "services:ConstructorCaller", "driving:Drive", ticks=3), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        # Served and answered before the first tick's end (while the nodes are built, or in tick 0).
        assert run.ticks_of(robot, "Incoming request") in ([-1], [0])
        assert run.ticks_of(robot, "Result of plan: linear 0.0375") in ([-1], [0])



@pytest.mark.parametrize("mode", cells({}, default=("workers 1", "workers 2")) + [PER_PARTICIPANT, THREADED_WORKERS])
def test_robots_ask_a_run_wide_service_once_it_is_ready_and_are_answered_within_the_tick(run_in, mode):
    """Each robot asks the run-wide ``/fleet/orders`` on every scan with ``call_async`` and a done
    callback, once ``service_is_ready()``. In its own process the fleet's service is on the ROS
    graph long before the first /clock (discovery takes well under a second on one host), and a
    response crosses DDS in milliseconds, far inside the tick's watchdog: every tick answered."""
    run = run_in(world_of("services:AsksForOrders", ticks=6, run_wide=["services:FleetOrders"]), mode)
    assert run.violations == []
    assert [line for robot in ("bot0", "bot1") for line in run.texts(robot) if "not ready" in line] == []


# --- parameters ----------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", cells({"multi-threaded": THREADS_TIMING}, default=("workers 1", "workers 2"))
                         + [PER_PARTICIPANT])
def test_a_run_wide_node_finds_each_robots_parameter_services_ready(run_in, mode):
    """A run-wide node checks ``service_is_ready()`` on each robot's ``/botN/tunable/set_parameters``
    client before it sets ``speed``. A node's parameter services exist from its construction; in
    its own process they are on the ROS graph before the first /clock: ready at the first check,
    and each robot drives at its new speed from then on. The set comes from the dispatcher's 1 s
    timer, which fires once its process heard /clock at 1 s, as every process did: the robot's
    node serves it with its clock at 1 s too (hosted, its clock moved with the tick's sensors,
    after the run-wide nodes' calls were served: it read 0.9 s)."""
    run = run_in(world_of("parameters:Tunable", ticks=16, run_wide=["parameters:SpeedDispatcher"]), mode)
    assert run.violations == []
    dispatched = run.of("dispatcher")
    assert [line.text for line in dispatched if "not ready" in line.text] == []
    assert sorted(line.text for line in dispatched) == ["bot0: set True", "bot1: set True"]
    for robot in ("bot0", "bot1"):
        assert run.texts(robot, "tunable") == ["speed set to 0.05 at 1 s"]
    assert (run.moved() > 0.01).all()


@pytest.mark.parametrize("mode", cells({}))
def test_a_parameter_client_waits_for_a_hosted_nodes_parameter_services(run_in, mode):
    """``AsyncParameterClient(self, "tunable").wait_for_services(timeout_sec=2.0)`` in a
    constructor (rclpy's demo's pattern), for the robot's own ``tunable`` node, built before it.
    In its own process the services are discovered within the timeout; the set is then served."""
    run = run_in(world_of("parameters:Tunable", "parameters:WaitingTuner", ticks=4), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        assert run.texts(robot, "tunable") == ["speed set to 0.05 at 0 s"]     # before tick 0
        assert run.texts(robot, "tuner") == ["set: True"]
    assert (run.moved() > 0.005).all()


@pytest.mark.parametrize("mode", cells({"multi-threaded": (
    "under rclpy's own multi-threaded executor (kept for comparison) its own sleep holds the tick until the "
    "watchdog: the robot fails as hung")}, default=("workers 1", "multi-process")))
def test_a_nodes_timer_steers_on_time_while_its_scan_callback_pauses(run_in, mode):
    """A scan callback in a group of its own calls ``time.sleep(0.3)`` on the scan of 0.1 s; the
    node's 0.1 s timer, in its default group, steers. In its own process the executor's other
    threads fire the timer on time meanwhile (0.2, 0.3 and 0.4 s), and the callback resumes 0.3 s
    on: the robot answers every tick. (Hosted, the timer fired only once the tick's sensor
    callbacks had returned: it missed 0.2 and 0.3 s, and fired three times at 0.4 s.)"""
    run = run_in(world_of("sleeping:PausingScanner", ticks=8, answers="when_published"), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        texts = run.texts(robot, "scanner")
        assert [t for t in texts if t.startswith("steer")] == [f"steer at {k / 10:g} s" for k in range(1, 8)]
        assert [t for t in texts if not t.startswith("steer")] == ["pausing at 0.1 s", "resumed at 0.4 s"]
    assert (run.moved() > 0.005).all()


# --- lifecycle -----------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", cells({}, default=("workers 1", "workers 2")))
def test_a_lifecycle_node_that_activates_itself_later_is_waited_for(run_in, mode):
    """A ``LifecycleNode`` makes its ``cmd_vel`` lifecycle publisher in ``on_configure`` and
    configures and activates itself from a 0.3 s timer; its group says ``answers: when_published``.
    In its own process nothing refuses it: until it is active it publishes nothing, and the
    robot's base keeps its last command (none yet: it stands); from then on it steers."""
    run = run_in(world_of("lifecycle:LateActivating", ticks=8, answers="when_published"), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        assert run.texts(robot) == ["configured", "activated"]
        assert run.ticks_of(robot, "configured") == run.ticks_of(robot, "activated") == [3]
    positions = run.result.trajectories.positions
    assert np.array_equal(positions[3], positions[0])            # standing until active
    assert (run.moved() > 0.005).all()


@pytest.mark.parametrize("mode", cells({}, default=("workers 1", "multi-process")))
def test_what_an_inactive_lifecycle_publisher_drops_is_no_answer(run_in, mode):
    """A lifecycle node configured at 0.2 s and activated at 0.5 s publishes on its lifecycle
    ``cmd_vel`` publisher every 0.1 s from the configure on. Until the activation rclpy's lifecycle
    publisher drops those messages: nothing reaches the robot's base, which keeps its last command
    (none: it stands), as it does before the configure. (In multi-process mode the dropped
    messages counted as answers: every robot failed "no answer before the watchdog" from 0.3 s.)"""
    run = run_in(world_of("lifecycle:EagerSteerer", ticks=10, answers="when_published"), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        assert run.ticks_of(robot, "configured") == [2] and run.ticks_of(robot, "activated") == [5]
    positions = run.result.trajectories.positions
    assert np.array_equal(positions[5], positions[0])            # standing until active
    assert (run.moved() > 0.005).all()


@pytest.mark.parametrize("mode", cells({}))
def test_a_lifecycle_talker_destroys_its_timer_in_on_cleanup(run_in, mode):
    """lifecycle_py's talker pattern, stepped through configure, activate, deactivate and clean-up
    by a timer of its own, beside the robot's drive node. Destroying an entity in a transition
    is ordinary rclpy: the executor stops seeing it. The robot drives on to the end."""
    run = run_in(world_of("driving:Drive", "lifecycle:CleanedUpTalker", ticks=12), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        texts = [t for t in run.texts(robot, "talker") if not t.startswith("Lifecycle publisher is active")]
        assert texts == ["on_configure() is called.", "on_activate() is called.", "on_deactivate() is called.",
                         "on_cleanup() is called."]
        lines = run.of(robot, "talker")
        published = [i for i, line in enumerate(lines) if line.text.startswith("Lifecycle publisher is active")]
        order = [line.text for line in lines]
        assert published and order.index("on_activate() is called.") < published[0]
        assert published[-1] < order.index("on_deactivate() is called.")
    assert (run.moved() > 0.02).all()


# --- actions -------------------------------------------------------------------------------------

def pacer(sleep_on: str = "clock", server: str = "Pacer") -> tuple:
    return f"actions:{server}", {"sleep_on": sleep_on}



@pytest.mark.parametrize("mode", cells({}))
def test_an_action_between_a_robots_nodes_runs_to_its_result(run_in, mode):
    """A server and a client among a robot's nodes: a 3-step goal, its 3 feedbacks, its result."""
    run = run_in(world_of("driving:Drive", pacer(), "actions:PaceClient", ticks=16), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        client = run.texts(robot, "pace_client")
        assert sorted(client) == sorted(["Sending goal request...", "Goal accepted", "Received feedback: 2",
                                         "Received feedback: 1", "Received feedback: 0", "Goal succeeded: 3"])



@pytest.mark.parametrize("mode", cells({"multi-threaded": THREADS_TIMING}))
def test_an_action_client_hears_its_goal_accepted_before_its_first_feedback(run_in, mode):
    """In its own process rclpy's server sends the goal response before it starts executing
    (``ActionServer._execute_goal_request``: ``send_goal_response``, then ``execute``), so the
    client's "Goal accepted" (the send-goal future's done callback) comes before the first
    feedback, every time."""
    run = run_in(world_of("driving:Drive", pacer(), "actions:PaceClient", ticks=8), mode)
    for robot in ("bot0", "bot1"):
        client = run.texts(robot, "pace_client")
        assert client[:3] == ["Sending goal request...", "Goal accepted", "Received feedback: 2"]


ACTION_BETWEEN_PLACES = ("an action between places is rclpy's under its own multi-threaded executor (kept for "
                         "comparison): through DDS, a tick late")


@pytest.mark.parametrize("mode", cells({"multi-threaded": ACTION_BETWEEN_PLACES}))
def test_a_fleet_nodes_goals_to_its_robots_are_done_within_the_tick(run_in, mode):
    """A run-wide fleet manager sends each robot's action server a goal at 0.1 s; the server
    executes at once, without pausing. In processes of their own every step of it (acceptance,
    three feedbacks, the result) happens before the next /clock tick: the same tick. (Through DDS
    outside the rounds of calls between places it took a tick for each message: the goal's result
    arrived at tick 3 instead of 1.)"""
    run = run_in(world_of("driving:Drive", pacer("none"), run_wide=("actions:FleetDispatcher",), ticks=8), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        lines = [line for line in run.of("dispatcher") if line.text.startswith(f"{robot}:")]
        assert [line.text for line in lines] == [f"{robot}: {t}" for t in (
            "sending goal", "goal accepted", "feedback 2", "feedback 1", "feedback 0", "result 3, status 4")]
        assert {line.tick for line in lines} == {1}
        assert run.ticks_of(robot, "Returning result") == [1]


@pytest.mark.parametrize("mode", cells({"multi-threaded": ACTION_BETWEEN_PLACES}))
def test_robots_goals_to_a_run_wide_action_server_are_done_within_the_tick(run_in, mode):
    """The other way: each robot's client sends its goal at 0.1 s to one run-wide server, which
    executes at once: the client hears it accepted, its feedback and its result in that tick."""
    run = run_in(world_of("driving:Drive", ("actions:PaceClient", {"action": "/pace"}),
                          run_wide=(pacer("none"),), ticks=8), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        client = run.of(robot, "pace_client")
        assert [line.text for line in client] == ["Sending goal request...", "Goal accepted", "Received feedback: 2",
                                                  "Received feedback: 1", "Received feedback: 0", "Goal succeeded: 3"]
        assert {line.tick for line in client} == {1}
    assert run.texts("pacer").count("Returning result") == 2


ACTION_PROGRAMS = {"feedback": ("Pacer", "PaceClient"), "cancel": ("Pacer", "CancellingClient"),
                   "queue": ("QueueingPacer", "TwoGoalsClient")}
WALL_SLEEP_OFF_PACE = ("under rclpy's executor the sleep holds one of its threads in wall time, but the run does not "
                       "keep real-time pace: the feedbacks come 0 or 1 tick apart, a cancel after the goal is done")


def action_cells() -> list:
    params = []
    for sleep_on in ("wall", "clock"):
        for program in ACTION_PROGRAMS:
            failing = {"multi-threaded": WALL_SLEEP_OFF_PACE if sleep_on == "wall" else THREADS_TIMING}
            for cell in cells(failing):
                params.append(pytest.param(sleep_on, program, *cell.values, marks=cell.marks,
                                           id=f"{sleep_on}-{program}-{cell.id}"))
    return params


def assert_as_in_its_own_process(run: Run, program: str) -> None:
    for robot in ("bot0", "bot1"):
        client, server = run.texts(robot, "pace_client"), run.texts(robot, "pacer")
        if program == "feedback":
            assert client[:3] == ["Sending goal request...", "Goal accepted", "Received feedback: 2"]
            assert client[-1] == "Goal succeeded: 3"
            ticks = run.ticks_of(robot, "Publishing feedback")
            assert len(ticks) == 3 and all(2 <= b - a <= 4 for a, b in zip(ticks, ticks[1:])), ticks
        elif program == "cancel":
            assert "Goal successfully canceled" in client and "Goal failed to cancel" not in client
            assert "Goal canceled" in server and "Returning result" not in server
        else:
            assert "Goal put in the queue" in server and "Next goal pulled from the queue" in server
            assert client.count("Goal succeeded: 2") == 2


@pytest.mark.parametrize("sleep_on, program, mode", action_cells())
def test_an_action_server_that_pauses_between_feedbacks_behaves_as_in_its_own_process(run_in, sleep_on, program,
                                                                                      mode):
    """The ROS 2 examples' servers pace their feedback with ``time.sleep`` in the execute callback
    (here 0.3 s between feedbacks), in a reentrant group under a MultiThreadedExecutor: while one
    thread sleeps, others serve the client's cancel and further goals, and on sim time at
    real-time pace the world moves 0.3 s (3 ticks) meanwhile. So the client hears "Goal
    accepted", then one feedback about every 3 ticks; a cancel sent 0.5 s after acceptance
    cancels the goal; a second goal sent at once waits in the queueing server's queue. The same
    with the pause on the node's clock (``sleep_for``)."""
    server, client = ACTION_PROGRAMS[program]
    world = world_of("driving:Drive", pacer(sleep_on, server), f"actions:{client}", ticks=20, watchdog_s=2.0)
    run = run_in(world, mode)
    assert run.violations == []
    assert_as_in_its_own_process(run, program)


@pytest.mark.parametrize("mode", cells({"multi-threaded": (
    "under rclpy's own multi-threaded executor (kept for comparison) a done callback runs as rclpy's task, outside "
    "the callback guard: the nodes run on")}))
def test_rclpy_shutdown_in_a_done_callback_ends_the_robots_nodes_visibly(run_in, mode):
    """The examples' action clients call ``rclpy.shutdown()`` once the result is in. In its own
    process that shuts down the process's context: spinning stops, ``main()`` returns, the
    process ends, and with it every node of the robot: from then on nothing answers for it."""
    run = run_in(world_of("driving:Drive", pacer("none"), "actions:ShuttingDownClient", ticks=6), mode)
    for robot in ("bot0", "bot1"):
        done = run.ticks_of(robot, "Goal succeeded")
        assert len(done) == 1
        later = [v for v in run.violations if v.robot == robot]
        assert later and later[0].tick >= done[0] and "shutdown" in later[0].reason, later


def heading_changes(run: Run) -> np.ndarray:
    """Per robot, how far it turned over the run (rad, unwrapped, counter-clockwise positive)."""
    theta = np.unwrap(run.result.trajectories.headings, axis=0)
    return theta[-1] - theta[0]


@pytest.mark.parametrize("mode", cells({"multi-threaded": (
    "under rclpy's own multi-threaded executor (kept for comparison) a callback's rclpy.spin_once(node) builds rclpy's "
    "global executor, which has no context in a host: the execute callback raises and the goal is aborted")},
    default=("workers 1", "multi-process")))
def test_a_server_that_spins_its_node_to_turn_drives_its_square(run_in, mode):
    """A vendor's patrol pattern (programs_as_written/turning.py): the execute callback drives a
    side paced by ``time.sleep``, then turns with ``rclpy.spin_once(self, timeout_sec=0.1)``
    between commands, reading the odometry that the spin lets in. In its own process that spin
    runs the node's odometry callback from inside the execute callback (rclpy's global executor
    is the one spinning the node), so the heading it reads moves on and every turn ends at 90°:
    four sides, four feedbacks, the result, about one full turn. Then the client's
    ``threading.Timer(0.1, rclpy.shutdown)`` ends its process, and with it the robot's nodes."""
    devices = load_world(FLOCKING).robots[0].devices
    with_odometry = devices.model_validate({**devices.model_dump(exclude_unset=True), "odometry": {}})
    world = world_of("turning:SquareServer", "turning:SquareClient", ticks=300, watchdog_s=2.0,
                     answers="when_published", devices=with_odometry)
    run = run_in(world, mode)
    turned = heading_changes(run)
    for i, robot in enumerate(("bot0", "bot1")):
        client = run.texts(robot, "square_client")
        assert client == ["sides left: 3", "sides left: 2", "sides left: 1", "sides left: 0", "Result: 4"], client
        assert abs(turned[i] - 2 * np.pi) < 0.15, turned
        ended = [v for v in run.violations if v.robot == robot]
        assert len(ended) == 1 and "rclpy.shutdown()" in ended[0].reason, ended
        assert ended[0].tick >= run.ticks_of(robot, "Result")[0]
    assert (run.moved() < 0.1).all()          # back near its start: a closed square of 0.1 m sides


# --- callback groups -----------------------------------------------------------------------------

@pytest.mark.parametrize("mode", cells({}))
def test_a_callback_group_of_the_users_own_throttles_its_callbacks(run_in, mode):
    """A ``CallbackGroup`` subclass whose ``can_execute``/``beginning_execution`` let one callback
    begin per 0.5 s of the node's clock, with a 0.1 s timer in it. rclpy's executors take a ready
    entity only when its group's ``can_execute`` says so (``Executor._wait_for_ready_callbacks``)
    and run it only if ``beginning_execution`` agrees: over 2 s, 4 callbacks."""
    run = run_in(world_of("driving:Drive", "groups:ThrottledChatter", ticks=20, watchdog_s=3.0), mode)
    assert run.violations == []
    for robot in ("bot0", "bot1"):
        assert len(run.ticks_of(robot, "Publishing:")) == 4


# --- interface packages --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def dotted_cache(tmp_path_factory) -> str:
    """An XDG_CACHE_HOME spelled with ``..``, one per module (the interface package is built once)."""
    base = tmp_path_factory.mktemp("xdg")
    (base / "a").mkdir()
    return f"{base}/a/../cache"


@pytest.mark.parametrize("mode", [
    pytest.param(["--workers", "1"], id="workers-1"),
    pytest.param(["--mode", "multi-process"], marks=pytest.mark.slow, id="multi-process")])
def test_a_world_with_interfaces_runs_with_a_cache_path_spelled_with_dot_dot(programs, tmp_path, dotted_cache, mode):
    """``XDG_CACHE_HOME=/a/b/../c``: the interface package is built under it and imported from
    there; the run goes on as with any other spelling of the same folder."""
    world = world_of("driving:Drive", "services:Planner", robots=2, ticks=2)
    path = tmp_path / "world.yaml"
    path.write_text(dump_world(world))
    done = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(path), *mode, "--out",
                           str(tmp_path / "out")], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "XDG_CACHE_HOME": dotted_cache})
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "out" / "summary.json").exists()
