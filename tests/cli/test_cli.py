"""The composed-sim command as a user runs it: outputs, recordings, rendering, errors."""
import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from composed_sim.outputs.results import load_trajectories

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"


def cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "composed_sim.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_run_records_a_bag_that_replays_and_renders(tmp_path):
    out, bag = tmp_path / "out", tmp_path / "bag"
    run = cli("run", FLOCKING, "--robots", 8, "--ticks", 15, "--out", out, "--record", bag,
              "--record-topics", "/bot1*/cmd_vel", "/bot0/light", "--markers", "--no-progress", "--json")
    assert run.returncode == 0, run.stderr[-2000:]
    summary = json.loads(run.stdout)
    assert summary["ticks"] == 15 and summary["robots"] == 8 and summary["violations"] == 0
    with np.load(out / "trajectories.npz") as t:
        assert t["positions"].shape == (16, 8, 2) and t["led_colors"].shape == (16, 8, 3)
        assert (t["led_colors"][-1] == (255, 0, 0)).all()        # every beacon lit red by the flocking plugin
    replay = cli("replay", bag, "--check")
    assert replay.returncode == 0, replay.stderr
    assert "15 ticks recorded" in replay.stdout and "/bot1/cmd_vel" in replay.stdout
    assert "/bot0/light" in replay.stdout and "/bot2/cmd_vel" not in replay.stdout
    for target in ("final.png", "run.gif"):
        r = cli("render", out, "--out", tmp_path / target)
        assert r.returncode == 0, r.stderr
        assert (tmp_path / target).stat().st_size > 1000


def test_a_recorded_run_is_reproduced_from_its_saved_configuration(tmp_path):
    """The results hold what reproduces the run: the resolved world (seed, overrides applied)
    and the versions. Re-running that world gives the same trajectories, bit for bit."""
    first, again = tmp_path / "first", tmp_path / "again"
    run = cli("run", FLOCKING, "--robots", 7, "--ticks", 25, "--seed", 11, "--watchdog", 5, "--out", first,
              "--record", tmp_path / "bag", "--no-progress", "--no-picture", "--json")
    assert run.returncode == 0, run.stderr[-2000:]
    summary = json.loads(run.stdout)
    assert summary["seed"] == 11 and {"composed_sim", "ros-rclpy", "ros-fastrtps", "numpy", "pymunk"} <= set(summary["versions"])
    rerun = cli("run", first / "world.yaml", "--executor", "events", "--out", again, "--no-progress", "--no-picture")
    assert rerun.returncode == 0, rerun.stderr[-2000:]
    with np.load(first / "trajectories.npz") as a, np.load(again / "trajectories.npz") as b:
        assert a["positions"].shape == (26, 7, 2)
        for key in ("positions", "headings", "led_colors"):
            assert np.array_equal(a[key], b[key]), key


def test_argos_experiment_runs_with_a_controller_mapping(tmp_path):
    r = cli("run", ROOT / "worlds" / "flocking.argos", "--controller", "flocking", "--ticks", 10,
            "--out", tmp_path, "--no-progress", "--no-picture", "--json")
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(r.stdout)["ticks"] == 10


def test_worlds_lists_the_shipped_worlds():
    r = cli("worlds")
    assert r.returncode == 0
    assert "flocking.yaml" in r.stdout and "flocking.argos" in r.stdout


@pytest.mark.parametrize("args, message", [
    (("run", "nope.yaml"), "nope.yaml: no such world file"),
    (("run", FLOCKING, "--robots", "0"), "--robots: must be >= 1 (got 0)"),
    (("run", FLOCKING, "--controller", "flocking"), "--controller: only for ARGoS .argos files"),
    (("render", ROOT, "--out", "x.avi"), "must end in .png, .gif or .mp4"),
    (("replay", ROOT / "worlds"), "not a readable recording"),
])
def test_user_mistakes_are_one_line_and_exit_2(args, message):
    r = cli(*args)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert message in r.stderr and "Traceback" not in r.stderr


def test_recording_into_an_existing_directory_is_refused(tmp_path):
    r = cli("run", FLOCKING, "--robots", 2, "--ticks", 2, "--out", tmp_path / "o", "--record", tmp_path)
    assert r.returncode == 2 and "already exists" in r.stderr


@pytest.mark.parametrize("workers", [1, 2])
def test_live_markers_reach_a_subscriber_in_another_process(tmp_path, domain_id, workers):
    """What an RViz or Foxglove user does: subscribe to /swarm/markers while a run goes on (with
    workers, the main process publishes them from a node of its own)."""
    import time

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from visualization_msgs.msg import MarkerArray

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    node = Node("watcher", context=ctx, start_parameter_services=False, enable_rosout=False)
    received = []
    node.create_subscription(MarkerArray, "/swarm/markers", received.append, 10)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    # A run far longer than needed; once markers arrive the test stops it as a user would (Ctrl-C).
    run = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "6",
                            "--ticks", "100000", "--markers", "--workers", str(workers), "--out", str(tmp_path), "--no-progress",
                            "--no-picture", "--domain-id", str(domain_id)], cwd=ROOT,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not received and run.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        run.send_signal(signal.SIGINT)
        assert run.wait(timeout=120) == 130, run.stderr.read()[-2000:]
        assert json.loads((tmp_path / "summary.json").read_text())["interrupted"] is True
    finally:
        if run.poll() is None:
            run.kill()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    assert received, "no MarkerArray arrived while the run was going"
    bodies, headings, *world = received[0].markers     # then the static world: walls, light
    assert world and all(m.ns == "world" for m in world)
    assert len(bodies.points) == 6 and len(bodies.colors) == 6 and len(headings.points) == 12
    assert bodies.header.frame_id == "world"


@pytest.mark.parametrize("workers, participants", [(1, 4), (3, 3)])
def test_another_process_hears_every_tick_of_robots_in_every_participant(tmp_path, domain_id, workers,
                                                                          participants):
    """The composed host splits the robots over DDS participants that ignore one another (in one
    process, or one per worker process); a process outside (ros2 topic echo, a recorder) still
    discovers all of them and receives every tick's sensors and answers, without a gap, from
    robots of two participants (bot6 is in the last). The run is paced (``--rate 10``: a hundred
    ticks a second): the topics are reliable keep-last 10, and a message the transport drops is
    resent only while it is among the writer's last ten; unpaced, a thousand ticks a second, a
    listener starved by CI's load for a moment lost one (DDS's rule, not the simulator's)."""
    import time

    import rclpy
    from geometry_msgs.msg import TwistStamped
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import LaserScan

    from composed_sim.ros import contract as c

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    node = Node("echo", context=ctx, start_parameter_services=False, enable_rosout=False)
    stamps = {topic: [] for topic in ("/bot6/light", "/bot5/light", "/bot5/cmd_vel")}
    # A reader history deep enough that this test's Python, not the publisher, is never what drops
    # a message.
    deep = QoSProfile(depth=10_000, reliability=ReliabilityPolicy.RELIABLE)
    for topic, received in stamps.items():
        node.create_subscription(TwistStamped if topic.endswith("cmd_vel") else LaserScan, topic,
                                 lambda msg, received=received: received.append(c.stamp_key(msg.header.stamp)), deep)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    run = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "7",
                            "--robots-per-participant", "2", "--workers", str(workers), "--ticks", "100000", "--rate", "10",
                            "--out", str(tmp_path),
                            "--no-progress", "--no-picture", "--domain-id", str(domain_id)], cwd=ROOT,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while (min(map(len, stamps.values())) < 30 and run.poll() is None and time.monotonic() < deadline):
            executor.spin_once(timeout_sec=0.1)
        run.send_signal(signal.SIGINT)
        assert run.wait(timeout=120) == 130, run.stderr.read()[-2000:]
    finally:
        if run.poll() is None:
            run.kill()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["participants"] == participants and summary["workers"] == workers
    assert summary["violations"] == 0
    tick_ns = 100_000_000
    for topic, received in stamps.items():
        assert len(received) >= 30, (topic, len(received))
        ticks = np.array(received) // tick_ns
        assert np.array_equal(ticks, np.arange(ticks[0], ticks[0] + len(ticks))), (topic, ticks)


def _wait_for_ticks(domain_id: int, proc: subprocess.Popen, ticks: int) -> None:
    """Until the run in ``proc`` has published /clock ``ticks`` times (it is past its start-up)."""
    import time

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    try:
        node = Node("clock_watcher", context=ctx, start_parameter_services=False, enable_rosout=False)
        seen = []
        node.create_subscription(Clock, "/clock", seen.append, 10)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        deadline = time.monotonic() + 120
        while len(seen) < ticks and proc.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert len(seen) >= ticks, "the run published no /clock"
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_sigterm_stops_at_a_tick_boundary_and_keeps_results_and_recording(tmp_path, domain_id):
    from composed_sim.outputs.recording import read_recording

    out, bag = tmp_path / "out", tmp_path / "bag"
    run = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "5",
                            "--ticks", "100000", "--record", str(bag), "--out", str(out), "--no-progress",
                            "--domain-id", str(domain_id)], cwd=ROOT,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_ticks(domain_id, run, 5)
        run.send_signal(signal.SIGTERM)
        assert run.wait(timeout=120) == 130, run.stderr.read()[-2000:]
    finally:
        if run.poll() is None:
            run.kill()
    summary = json.loads((out / "summary.json").read_text())
    ticks = summary["ticks"]
    assert summary["interrupted"] is True and 5 <= ticks < 100000
    with np.load(out / "trajectories.npz") as t:
        assert t["positions"].shape == (ticks + 1, 5, 2)
        final = t["positions"][-1]
    recording = read_recording(bag)          # closed properly: readable, every tick in it
    assert recording.ticks_done == ticks and np.array_equal(recording.positions[-1], final)
    assert (out / "arena.png").stat().st_size > 1000


def test_a_second_ctrl_c_quits_at_once_even_with_a_hung_controller(tmp_path, faulty_plugin, domain_id):
    """The first Ctrl-C waits for a tick boundary that a controller hung for 60 s keeps away."""
    import time

    import yaml
    data = yaml.safe_load(FLOCKING.read_text())
    data["lockstep"] = {"watchdog_s": 20.0}
    data["robots"][0].update(controller=faulty_plugin, count=3,
                             params={"fault": "hang", "faulty_robot": "bot1", "from_tick": 3,
                                     "announce": str(tmp_path / "hung")})
    world = tmp_path / "hang.yaml"
    world.write_text(yaml.safe_dump(data))
    run = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(world), "--out", str(tmp_path / "o"),
                            "--no-progress", "--domain-id", str(domain_id)], cwd=ROOT,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not (tmp_path / "hung").exists() and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert (tmp_path / "hung").exists(), "bot1 never reached its hang"
        run.send_signal(signal.SIGINT)
        time.sleep(0.5)    # not a hope: either way the run must not end on its own within the 20 s watchdog
        assert run.poll() is None
        t0 = time.monotonic()
        run.send_signal(signal.SIGINT)
        assert run.wait(timeout=10) == 130
        assert time.monotonic() - t0 < 5
        assert "again to quit at once" in run.stderr.read()
        # Quit at once, but not empty-handed: the last checkpoint (tick 0 here) is in --out.
        summary = json.loads((tmp_path / "o" / "summary.json").read_text())
        assert summary["checkpoint"] is True and summary["ticks"] == 0
        # The trajectories as streamed to --out (outputs/stream.py), up to that checkpoint.
        assert load_trajectories(tmp_path / "o").positions.shape == (1, 3, 2)
    finally:
        if run.poll() is None:
            run.kill()


@pytest.mark.parametrize("ros2_installed", [False, True])
def test_the_watch_hint_names_what_this_machine_has(tmp_path, ros2_installed):
    """The pip-only install has no ros2 command: the hint names it only where one is on PATH."""
    import os
    import shutil
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    if ros2_installed:
        (bin_dir / "ros2").write_text("#!/bin/sh\n")
        (bin_dir / "ros2").chmod(0o755)
    path = os.pathsep.join([str(bin_dir)] + [d for d in os.environ["PATH"].split(os.pathsep)
                                             if not (Path(d) / "ros2").exists()])
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"} | {"PATH": path}
    assert (shutil.which("ros2", path=path) is not None) == ros2_installed
    r = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", FLOCKING, "--robots", "2", "--ticks", "2",
                        "--markers", "--no-progress", "--no-picture", "--json", "--out", tmp_path / "o"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    domain = json.loads(r.stdout)["domain_id"]
    hint = next(line for line in r.stderr.splitlines() if line.startswith("composed-sim: ROS domain"))
    assert hint == (f"composed-sim: ROS domain {domain} (free, picked); to watch it: an rclpy process with "
                    f"ROS_DOMAIN_ID={domain} (docs/contract.md, \"Watching a run from another process\")"
                    + (f" or ROS_DOMAIN_ID={domain} ros2 topic list" if ros2_installed else "")
                    + "; or run with --foxglove (the Foxglove app, no ROS install needed)")


def test_the_documented_watcher_lists_a_runs_topics_and_hears_its_clock(tmp_path, domain_id):
    """docs/contract.md's pip-only stand-in for `ros2 topic list` and `ros2 topic echo` works."""
    import os
    import re
    doc = (ROOT / "docs" / "contract.md").read_text()
    section = doc[doc.index("## Watching a run from another process"):]
    (tmp_path / "watch.py").write_text(re.search(r"```python\n(.*?)```", section, flags=re.S).group(1))
    run = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "2",
                            "--ticks", "100000", "--out", str(tmp_path / "out"), "--no-progress", "--no-picture",
                            "--domain-id", str(domain_id)], cwd=ROOT,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_for_ticks(domain_id, run, 2)
        watch = subprocess.run([sys.executable, str(tmp_path / "watch.py")], capture_output=True, text=True,
                               timeout=60, env=os.environ | {"ROS_DOMAIN_ID": str(domain_id)})
    finally:
        run.send_signal(signal.SIGTERM)
        run.wait(timeout=120)
    assert watch.returncode == 0, watch.stderr[-2000:]
    lines = watch.stdout.splitlines()
    assert "/bot1/cmd_vel geometry_msgs/msg/TwistStamped" in lines and "/clock rosgraph_msgs/msg/Clock" in lines
    assert re.fullmatch(r"\d+ \d+", lines[-1]), lines[-1]      # a /clock sample


def test_run_help_says_how_the_domain_is_chosen(capsys):
    """A run without --domain-id or $ROS_DOMAIN_ID picks a free domain: the help says so."""
    from composed_sim.cli import main
    with pytest.raises(SystemExit) as exit_:
        main(["run", "--help"])
    assert exit_.value.code == 0
    help_text = " ".join(capsys.readouterr().out.split())
    assert ("--domain-id DOMAIN_ID ROS domain of the run, refused if another simulator uses it (default: "
            "$ROS_DOMAIN_ID where set, else the first free domain from 0 up, printed first and recorded in "
            "summary.json; multi-process mode: the first of a block of free domains)") in help_text
    assert "$ROS_DOMAIN_ID or 0" not in help_text


@pytest.mark.parametrize("no_picture", [True, False])
def test_the_run_names_the_files_it_wrote_and_no_other(tmp_path, no_picture):
    """Under --no-picture there is no arena.png, and the closing line does not claim one."""
    out = tmp_path / "out"
    r = cli("run", FLOCKING, "--robots", 3, "--ticks", 3, "--no-progress", "--out", out,
            *(["--no-picture"] if no_picture else []))
    assert r.returncode == 0, r.stderr[-2000:]
    line = r.stdout.strip().splitlines()[-1].strip()
    assert line.startswith(f"results in {out}/ (") and line.endswith(")"), line
    named = [name.rstrip("/") for name in line[len(f"results in {out}/ ("):-1].split(", ")]
    assert sorted(named) == sorted(p.name for p in out.iterdir())
    assert ("arena.png" in named) is (not no_picture)


@pytest.mark.parametrize("workers", [1, 2])
def test_the_summary_says_where_the_main_process_spends_a_tick_and_what_the_host_costs(tmp_path, workers):
    """summary.json's phase table adds up to the tick's wall time; the nodes' own code and the
    host's cost per robot-tick add up to the CPU the run spent."""
    out = tmp_path / "out"
    r = cli("run", FLOCKING, "--robots", 8, "--ticks", 20, "--workers", workers, "--no-progress", "--no-picture",
            "--out", out)
    assert r.returncode == 0, r.stderr[-2000:]
    s = json.loads((out / "summary.json").read_text())
    table = s["phases_per_tick_ms"]
    phases = {"physics", "sensing", "sending_frames", "waiting", "gathering_answers", "loop_functions",
              "recording", "other"}
    assert set(table) == phases | {"serial"}
    per_tick_ms = 1e3 * s["ticks_wall_s"] / s["ticks"]
    assert sum(table[p] for p in phases) == pytest.approx(per_tick_ms, rel=0.01)
    assert table["serial"] == pytest.approx(per_tick_ms - table["waiting"], rel=0.01, abs=0.01)
    assert all(table[p] >= 0 for p in phases - {"other"}) and table["physics"] > 0
    # One process reads the sensors itself; worker processes read their own robots' (core/senses.py).
    assert (table["sensing"] > 0) is (workers == 1)
    # The flocking controller's own arithmetic runs every robot-tick; the host costs something too.
    assert s["node_code_per_robot_tick_us"] > 0 and s["host_cost_per_robot_tick_us"] > 0
    assert "per tick (ms): " in r.stdout and "per robot-tick: host " in r.stdout
