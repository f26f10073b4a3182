"""Watching a run live over the Foxglove WebSocket protocol (--foxglove), paced runs (--rate), the
scene's markers (one per robot size), and tidy tables (export)."""
import json
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.csv
import pyarrow.parquet
import pytest
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import MarkerArray

from composed_sim.live.observers import Scene
from composed_sim.live.markers import world_shapes
from composed_sim.world.loader import load_world
from composed_sim.world.robot_models import get_model
from foxglove_client import channels, free_port, open_connection, receive_until_closed, subscribe

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
HETEROGENEOUS = ROOT / "worlds" / "heterogeneous.yaml"
TICKS = 20


def start_run(*args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", *map(str, args)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def cli(*args):
    return subprocess.run([sys.executable, "-m", "composed_sim.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def summary_of(run_args, tmp_path, name):
    out = tmp_path / name
    r = cli("run", *run_args, "--out", out, "--no-progress", "--no-picture", "--json")
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout), out


def test_a_viewer_gets_every_tick_and_misbehaving_clients_change_nothing(tmp_path):
    """The test client subscribes as the app does; a second client connects, sends garbage and
    leaves mid-run; the run's trajectories are those of a run nobody watched."""
    port = free_port()
    out = tmp_path / "watched"
    world_args = (FLOCKING, "--robots", 3, "--ticks", TICKS, "--workers", 1)
    run = start_run(*world_args, "--out", out, "--no-progress", "--no-picture", "--foxglove", f"127.0.0.1:{port}",
                    "--foxglove-topics", "/bot0/*", "--wait-for-viewer", 60)
    try:
        with open_connection(port) as ws:
            found = channels(ws, {"/swarm/markers", "/clock", "/bot0/light", "/bot0/cmd_vel"})
            assert found["/swarm/markers"]["schemaName"] == "visualization_msgs/msg/MarkerArray"
            assert found["/bot0/light"]["schemaName"] == "sensor_msgs/msg/LaserScan"
            for c in found.values():
                assert c["encoding"] == "cdr" and c["schemaEncoding"] == "ros2msg"
            assert not any(t.startswith("/bot1/") for t in found)     # only the selected robot topics
            assert "MSG: std_msgs/Header" in found["/swarm/markers"]["schema"]
            # The scene last: it releases --wait-for-viewer, so the others see tick 0 too.
            subs = subscribe(ws, [found[t]["id"] for t in ("/bot0/light", "/clock", "/swarm/markers")])
            with open_connection(port) as intruder:

                def misbehave(count):
                    if count == 10:
                        intruder.send(b"\x07garbage")
                        intruder.send("{not json")
                        intruder.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 999}]}))
                    elif count == 30:
                        intruder.close()                  # a viewer that leaves mid-run
                got = receive_until_closed(ws, on_message=misbehave)
        assert run.wait(timeout=120) == 0, run.stderr.read()[-2000:]
    finally:
        run.kill()
    light, clock, scene = (got.get(s, []) for s in subs)
    tick_ns = 100_000_000
    assert [t for t, _ in scene] == [k * tick_ns for k in range(TICKS + 1)]     # tick 0 … 20, one each
    assert [t for t, _ in clock] == [k * tick_ns for k in range(TICKS + 1)]
    assert [t for t, _ in light] == [k * tick_ns for k in range(TICKS)]         # readings of ticks 0 … 19
    assert len(deserialize_message(light[0][1], LaserScan).intensities) == 24
    with np.load(out / "trajectories.npz") as t:
        positions = t["positions"]
    for k, (_, data) in enumerate(scene):
        bodies = deserialize_message(data, MarkerArray).markers[0]
        assert bodies.ns == "swarm_bodies"
        served = np.array([(p.x, p.y) for p in bodies.points])
        np.testing.assert_array_equal(served, positions[k])
    unwatched, _ = summary_of(world_args, tmp_path, "unwatched")
    with np.load(tmp_path / "unwatched" / "trajectories.npz") as t:
        np.testing.assert_array_equal(t["positions"], positions)


def test_rate_one_runs_in_real_time(tmp_path):
    """20 ticks of 0.1 s at --rate 1 take 2 s; unpaced, far less (a ratio, not a deadline)."""
    world_args = (FLOCKING, "--robots", 3, "--ticks", TICKS, "--workers", 1)
    paced, _ = summary_of((*world_args, "--rate", 1), tmp_path, "paced")
    unpaced, _ = summary_of(world_args, tmp_path, "unpaced")
    paced_s, unpaced_s = paced["ticks_wall_s"], unpaced["ticks_wall_s"]
    sim_s = TICKS * 0.1
    assert paced_s >= 0.99 * sim_s                   # never faster than asked
    # Pacing adds only the wait: at most the unpaced time's own share on top of 2 s.
    assert paced_s / sim_s <= 1 + unpaced_s / sim_s + 0.25, (paced_s, unpaced_s)


def test_a_port_in_use_is_one_line_naming_it(tmp_path):
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        r = cli("run", FLOCKING, "--robots", 2, "--ticks", 2, "--workers", 1, "--out", tmp_path / "o",
                "--no-progress", "--foxglove", str(port))
    assert r.returncode == 2
    errors = [line for line in r.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and f"port {port}" in errors[0] and "pid " in errors[0], r.stderr


def test_markers_size_each_robot_by_its_own_model():
    """worlds/heterogeneous.yaml: foot-bots and e-pucks in one scene, each at its own size."""
    from composed_sim.core.simulation import Simulation
    world = load_world(HETEROGENEOUS)
    sim = Simulation(world)
    msg = deserialize_message(Scene(sim, world.tick_ns).cdr(sim), MarkerArray)
    bodies = [m for m in msg.markers if m.ns == "swarm_bodies"]
    sizes = sorted((m.scale.x, m.scale.z, len(m.points)) for m in bodies)
    epuck, footbot = get_model("e-puck"), get_model("foot-bot")
    assert sizes == [(2 * epuck.body_radius_m, epuck.body_height_m, 8),        # 8 e-pucks, 6 foot-bots
                     (2 * footbot.body_radius_m, footbot.body_height_m, 6)]
    for m in bodies:
        for p in m.points:
            robot = int(np.argmin(np.hypot(*(sim.positions - (p.x, p.y)).T)))
            assert m.scale.x == pytest.approx(2 * sim.radii[robot])
    walls = [m for m in msg.markers if m.ns == "world"]
    assert len(walls) == len(world_shapes(world)) == 5           # 4 walls + the dark floor circle


def test_export_writes_one_row_per_tick_and_robot(tmp_path):
    _, out = summary_of((HETEROGENEOUS, "--ticks", 3, "--workers", 1), tmp_path, "het")
    with np.load(out / "trajectories.npz") as t:
        positions, headings, names = t["positions"], t["headings"], list(t["names"])
    for fmt, read in (("csv", pyarrow.csv.read_csv), ("parquet", pyarrow.parquet.read_table)):
        r = cli("export", out, "--format", fmt)
        assert r.returncode == 0, r.stderr
        table = read(out / f"trajectories.{fmt}").to_pydict()
        assert len(table["tick"]) == 4 * 14 and table["tick"][14] == 1
        xy = np.stack([table["x"], table["y"]], axis=1).reshape(4, 14, 2)
        np.testing.assert_array_equal(xy, positions)
        np.testing.assert_array_equal(np.reshape(table["yaw"], (4, 14)), headings)
        assert table["robot"][:14] == names
        assert table["model"][:14] == ["foot-bot"] * 6 + ["e-puck"] * 8
        assert table["group"][:14] == [0] * 6 + [1] * 8
    missing = cli("export", tmp_path / "nothing")
    assert missing.returncode == 2 and "not a results directory" in missing.stderr
