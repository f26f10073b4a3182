"""A robot's ROS software as its authors wrote it (tests/user_pkg/swarm_vote): tutorial-style
``__init__(self)`` nodes, three per robot wired by remappings, a ROS 2 parameters file, a run-wide
node that starts the swarm on /swarm_command, and an opinion every robot broadcasts on /opinions
each tick. A robot drives only while it heard every robot's opinion of the tick before, so one
message cut or delayed anywhere stops a robot and shows in its trajectory."""
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed

from tests.conftest import importable
from composed_sim.command_line import EXIT_INTERRUPTED
from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
from composed_sim.hosts.workers.worker_host import WorkerHost
from composed_sim.world.loader import load_world

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "tests" / "user_pkg" / "swarm_vote"
WORLD = ROOT / "tests" / "user_pkg" / "swarm_vote_world.yaml"
START_TICK = 5              # the world's mission control sends "start" at 0.5 s
MAX_STEP_M = 0.08 * 0.1     # the parameters file's max_speed (the safety node's cap) over one tick


@pytest.fixture
def swarm_vote(monkeypatch):
    yield from importable(monkeypatch, PACKAGE)


def steps(result) -> np.ndarray:
    """[ticks, robots] distance each robot moved in each tick."""
    return np.linalg.norm(np.diff(result.trajectories.positions, axis=0), axis=2)


def test_the_package_runs_unchanged_and_every_robot_hears_every_message(swarm_vote, domain_id):
    world = load_world(WORLD)
    with ComposedHost(world, domain_id=domain_id) as host:
        reference = host.run()
        assert [type(n).__name__ for n in host.groups.robot_nodes[0]] == ["SensorLayer", "Behaviour", "Safety"]
        assert [n.get_fully_qualified_name() for n in host.groups.robot_nodes[3]] == \
            ["/bot3/sensor_layer", "/bot3/behaviour", "/bot3/safety"]
    assert reference.violations == []
    moved = steps(reference)
    assert (moved[:START_TICK] == 0).all()          # no robot moves before the start command …
    assert (moved[START_TICK:] > 1e-4).all()        # … all from its tick on, every tick (a stopped one: 0)
    assert moved.max() <= MAX_STEP_M + 1e-6         # behaviour's 0.1 m/s capped by the params file's 0.08


@pytest.mark.parametrize("executor", ["single-threaded", "events", "multi-threaded"])
def test_a_stock_executor_gives_the_same_run(swarm_vote, domain_id, executor):
    world = load_world(WORLD, ticks=12)
    runs = []
    for kind in ("lockstep", executor):
        with ComposedHost(world, executor=kind, domain_id=domain_id) as host:
            runs.append(host.run())
    assert runs[1].violations == []
    np.testing.assert_array_equal(runs[1].trajectories.positions, runs[0].trajectories.positions)


def test_every_worker_layout_gives_the_same_run(swarm_vote, domain_id):
    world = load_world(WORLD, ticks=15)
    with ComposedHost(world, domain_id=domain_id) as host:
        reference = host.run()
    for workers in (2, 3):
        with WorkerHost(world, workers=workers, domain_id=domain_id) as host:
            result = host.run()
        assert result.violations == [], (workers, result.violations[:3])
        np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions,
                                      err_msg=f"{workers} workers")
    assert (steps(reference)[START_TICK:] > 1e-4).all()


def test_multi_process_mode_gives_the_same_run_across_domains(swarm_vote, domain_id, mp_domain):
    # One process per robot, spread over three ROS domains: the run-wide topics still reach
    # every robot, at the same point of the tick.
    world = load_world(WORLD, ticks=12)
    with ComposedHost(world, domain_id=domain_id) as host:
        reference = host.run()
    with MultiProcessHost(world, domain_id=mp_domain, robots_per_domain=3) as host:
        assert len(set(host.domains.values())) == 3
        result = host.run()
    assert result.violations == [], result.violations[:3]
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)
    assert (steps(result)[START_TICK:] > 1e-4).all()


def test_run_wide_messages_are_recorded_with_their_own_type(swarm_vote, tmp_path):
    # The CLI, as a user runs it: the package on PYTHONPATH, its message package built on first
    # use; the run-wide topics are in the bag (with Opinion's definition), readable by rosbags.
    from rosbags.highlevel import AnyReader
    bag = tmp_path / "bag"
    run = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(WORLD), "--ticks", "8", "--out",
                          str(tmp_path / "out"), "--record", str(bag), "--record-topics", "/opinions",
                          "/swarm_command", "--no-progress", "--no-picture"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    with AnyReader([bag]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/opinions"] == "swarm_vote_interfaces/msg/Opinion"
        assert topics["/swarm_command"] == "std_msgs/msg/String"
        opinions = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
                    if c.topic == "/opinions"]
        commands = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages()
                    if c.topic == "/swarm_command"]
    # Every robot's opinion of ticks 0 … 6 (those of tick 7 open a tick the run no longer has).
    assert len(opinions) == 9 * 7
    assert {o.sender for o in opinions} == {f"bot{i}" for i in range(9)}
    assert commands == ["start"]


def test_a_chain_with_a_timer_in_the_middle_runs_alike_in_every_mode(swarm_vote, domain_id, mp_domain):
    # The pattern node reads no sensor of its robot and decides on a 0.1 s timer: its timer fires
    # at each tick's time, after the ranges of the tick reached it, in every host mode.
    world = load_world(ROOT / "tests" / "user_pkg" / "timed_pattern_world.yaml")
    with ComposedHost(world, domain_id=domain_id) as host:
        reference = host.run()
    assert reference.violations == []
    assert (steps(reference)[1:] > 1e-4).all()      # driving from tick 0's command on
    for host in (WorkerHost(world, workers=2, domain_id=domain_id),
                 MultiProcessHost(world, domain_id=mp_domain, robots_per_domain=3)):
        with host:
            result = host.run()
        assert result.violations == [], (type(host).__name__, result.violations[:3])
        np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions,
                                      err_msg=type(host).__name__)


def test_a_viewer_gets_run_wide_topics_with_their_own_types(swarm_vote, tmp_path):
    # --foxglove-topics '/opinions': the channel is advertised once a robot first publishes on it,
    # with the package's own message definition; the viewer then gets every robot's opinions. The
    # run is long (1000 ticks at twice real time) and is stopped with Ctrl-C once the viewer has
    # seen six ticks: a run of fixed length was over before a starved test process had subscribed.
    sys.path.insert(0, str(ROOT / "tests"))
    from foxglove_client import MESSAGE_DATA, channels, free_port, open_connection, subscribe
    port = free_port()
    run = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(WORLD), "--out", str(tmp_path / "out"),
                            "--no-progress", "--no-picture", "--rate", "2", "--ticks", "1000", "--foxglove",
                            f"127.0.0.1:{port}", "--foxglove-topics", "/opinions"], cwd=ROOT, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    by_tick: dict[int, int] = {}        # /opinions messages per log time
    clocks = 0                          # /clock messages: the run went on while /opinions did not come
    try:
        with open_connection(port) as ws:
            found = channels(ws, {"/opinions", "/clock"})
            assert found["/opinions"]["schemaName"] == "swarm_vote_interfaces/msg/Opinion"
            assert "string sender" in found["/opinions"]["schema"]
            opinions_sub, _clock_sub = list(subscribe(ws, [found["/opinions"]["id"], found["/clock"]["id"]]))
            deadline = time.monotonic() + 60
            while len(by_tick) < 6 and time.monotonic() < deadline:
                try:
                    frame = ws.recv(timeout=deadline - time.monotonic())
                except ConnectionClosed:        # the run ended: its exit and its lines say why
                    break
                if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
                    sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                    if sub_id == opinions_sub:
                        by_tick[log_time] = by_tick.get(log_time, 0) + 1
                    else:
                        clocks += 1
        if run.poll() is None:
            run.send_signal(signal.SIGINT)
        assert run.wait(timeout=120) == EXIT_INTERRUPTED, (run.returncode, run.stderr.read()[-2000:])
    finally:
        if run.poll() is None:
            run.kill()
    assert len(by_tick) >= 6, f"/opinions of {len(by_tick)} ticks reached the viewer in 60 s, /clock {clocks} " \
                              f"times; the run said:\n{run.stderr.read()[-2000:]}"
    assert set(list(by_tick.values())[1:-1]) == {9}     # all nine, every tick fully watched
