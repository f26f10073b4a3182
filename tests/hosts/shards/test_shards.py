"""Controllers sharded over hosts through DDS: `composed-sim host` shards serving a simulator run
with `--external-controllers`, on one machine and across network namespaces joined by a bridge
(separate network stacks, as separate machines would be)."""
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import network_namespaces, start
from composed_sim import cli
from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosting import HostError
from composed_sim.hosts.discovery import DiscoveryError, configure
from composed_sim.hosts.shards.external_controllers import GONE_REASON, ExternalControllersHost
from composed_sim.hosts.shards.robot_ranges import RangeError, format_ranges, parse_ranges
from composed_sim.world.loader import load_world

ROOT = Path(__file__).resolve().parents[3]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
ROBOTS, TICKS, SEED = 12, 60, 3


# --- pure parts -------------------------------------------------------------------------------

def test_robot_ranges_parse_and_format_back():
    assert parse_ranges("0-9,20-29", 640) == list(range(10)) + list(range(20, 30))
    assert parse_ranges(" 5 ", 6) == [5]
    assert parse_ranges("0-639", 640) == list(range(640))
    assert format_ranges([7, 0, 1, 2, 5, 8]) == "0-2,5,7-8"
    assert format_ranges(parse_ranges("3,0-1,9", 10)) == "0-1,3,9"


@pytest.mark.parametrize("text, message", [
    ("0-12", r"outside the world's 12 robots \(indices 0-11\)"),
    ("3-1", "0 <= FIRST <= LAST"),
    ("a-b", "not an index"),
    ("0-3,2", "listed twice"),
    ("1,,2", "expected indices"),
    ("", "expected indices"),
])
def test_bad_robot_ranges_are_named(text, message):
    with pytest.raises(RangeError, match=message):
        parse_ranges(text, 12)


def test_discovery_defaults_to_subnet_and_keeps_what_the_user_set():
    env = {}
    assert configure(environ=env) == ("SUBNET", None) and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    description, warning = configure(environ=env)
    assert description == "LOCALHOST" and "only shards on this machine" in warning
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOCALHOST_ONLY": "1"}
    description, warning = configure(discovery_range="subnet", static_peers="10.0.0.2;10.0.0.3", environ=env)
    assert description == "SUBNET + static peers 10.0.0.2;10.0.0.3" and warning is None
    assert env == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "10.0.0.2;10.0.0.3"}
    with pytest.raises(DiscoveryError, match="--static-peers"):
        configure(static_peers=" ; ", environ={})


def test_host_with_a_range_outside_the_world_is_one_line_and_exit_2(capsys):
    assert cli.main(["host", str(FLOCKING), "--world-robots", "12", "--robots", "0-5,10-12"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == ("composed-sim: error: --robots: robot range '0-5,10-12': '10-12' is outside the "
                           "world's 12 robots (indices 0-11)")


# --- through real DDS, one machine --------------------------------------------------------------

def world(robots=ROBOTS, ticks=TICKS, seed=SEED, watchdog_s=None):
    w = load_world(FLOCKING, robots=robots, ticks=ticks, seed=seed)
    if watchdog_s is not None:
        w = w.model_copy(update={"lockstep": w.lockstep.model_copy(update={"watchdog_s": watchdog_s})})
    return w


def shard_cmd(robots: str, *, n=ROBOTS, seed=SEED, extra=()) -> list[str]:
    return [sys.executable, "-m", "composed_sim.cli", "host", str(FLOCKING), "--world-robots", str(n),
            "--seed", str(seed), "--robots", robots, "--discovery-timeout", "60", *extra]


def test_a_missing_shard_is_a_clear_error_naming_the_robots(tmp_path, processes):
    processes.append(start(shard_cmd("0-1", n=4), tmp_path / "shard.log"))
    # The simulator's discovery window starts once the shard announces itself (its line says so):
    # on a loaded machine the shard's own start-up took longer than the 4 s window.
    deadline = time.monotonic() + 120
    while "waiting for the simulator" not in (tmp_path / "shard.log").read_text():
        assert processes[0].poll() is None and time.monotonic() < deadline, (tmp_path / "shard.log").read_text()
        time.sleep(0.1)
    with pytest.raises(HostError, match=r"no controller shard hosts robots 2-3 \(bot2, bot3\) after 4 s "
                                        r"\(shards found: [^ ]+:\d+ hosts 0-1\)"):
        with ExternalControllersHost(world(robots=4), domain_id=int(os.environ["ROS_DOMAIN_ID"]),
                                     discovery_timeout_s=4.0):
            pass
    # Its simulator is gone: the shard ends by itself.
    assert processes[0].wait(timeout=30) == 0, (tmp_path / "shard.log").read_text()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_shard_that_disappears_turns_into_violations_for_its_robots(tmp_path, processes, sig, domain_id):
    # A watchdog that the first cross-process tick (one-off transport set-up) meets on a loaded machine.
    w = world(robots=4, ticks=30, watchdog_s=1.0)
    processes.append(start(shard_cmd("0-1", n=4), tmp_path / "a.log"))
    processes.append(start(shard_cmd("2-3", n=4), tmp_path / "b.log"))
    victim = processes[1]
    kill_at = 10
    done = []

    def progress(n):
        done.append(n)
        if len(done) == kill_at:
            victim.send_signal(sig)
            victim.wait(timeout=10)

    t0 = time.perf_counter()
    with ExternalControllersHost(w, domain_id=domain_id, discovery_timeout_s=60) as host:
        result = host.run(progress=progress)
    wall = time.perf_counter() - t0
    assert result.trajectories.ticks_done == 30 and not result.interrupted
    assert result.violations and {v.robot for v in result.violations} == {"bot2", "bot3"}
    assert min(v.tick for v in result.violations) >= kill_at
    if sig == signal.SIGTERM:
        # A clean exit removes its endpoints at once: one violation per robot, no waiting after.
        assert sorted((v.robot, v.reason) for v in result.violations) == [
            ("bot2", f"controller failed: {GONE_REASON}"), ("bot3", f"controller failed: {GONE_REASON}")]
    else:
        # Killed outright: DDS learns it only when the participant's lease runs out (Fast DDS: 20 s);
        # the watchdog closes each tick without them until they are unresponsive for 3 watchdogs.
        reasons = [v.reason for v in result.violations]
        assert set(reasons) - {"no answer before the watchdog"} <= {
            f"controller failed: {GONE_REASON}", *(r for r in reasons if r.startswith("controller failed: unresponsive"))}
        assert sum(r.startswith("controller failed") for r in reasons) == 2
        assert wall < 30 * 1.0 + 30
    # Fallback zero: the lost robots stand still from the tick after; the others fly on.
    pos = result.trajectories.positions
    first = min(v.tick for v in result.violations)
    lost = pos[first + 1:, 2:4]
    assert np.abs(lost - lost[0]).max() < 1e-3
    assert np.linalg.norm(pos[-1, :2] - pos[first + 1, :2], axis=1).min() > 0.005
    assert processes[0].wait(timeout=30) == 0      # the surviving shard ends with the simulator


# --- across network namespaces -------------------------------------------------------------------

@pytest.fixture
def netns():
    yield from network_namespaces(["sim", "s0", "s1"])


def test_two_shards_in_other_network_namespaces_match_the_composed_run_bit_for_bit(tmp_path, netns, domain_id,
                                                                                 processes):
    with ComposedHost(world(), domain_id=domain_id) as host:
        reference = host.run()
    # Real UDP between the namespaces: SUBNET discovery (multicast), and no shared-memory transport,
    # which Fast DDS would otherwise pick between processes of one machine.
    env = {**os.environ, "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4", "ROS_DOMAIN_ID": str(domain_id)}
    distributed = ["--discovery-range", "subnet"]
    out = tmp_path / "out"
    processes.append(start(netns.exec("s0", shard_cmd("0-5", extra=distributed)), tmp_path / "s0.log", env))
    processes.append(start(netns.exec("s1", shard_cmd("6-11", extra=distributed)), tmp_path / "s1.log", env))
    sim = start(netns.exec("sim", [sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING),
                                   "--robots", str(ROBOTS), "--ticks", str(TICKS), "--seed", str(SEED),
                                   "--external-controllers", "--discovery-timeout", "60", *distributed,
                                   "--out", str(out), "--no-picture", "--no-progress"]),
                tmp_path / "sim.log", env)
    processes.append(sim)
    assert sim.wait(timeout=120) == 0, (tmp_path / "sim.log").read_text()
    for role, shard in zip(("s0", "s1"), processes[:2]):    # they end by themselves with the simulator
        assert shard.wait(timeout=30) == 0, (tmp_path / f"{role}.log").read_text()
    # The traffic went through the veth links, not around them.
    assert all(netns.counters(role)["rx_bytes"] > 10_000 for role in ("sim", "s0", "s1"))
    with np.load(out / "trajectories.npz") as got:
        assert np.array_equal(got["positions"], reference.trajectories.positions)
        assert np.array_equal(got["headings"], reference.trajectories.headings)
        assert np.array_equal(got["led_colors"], reference.trajectories.led_colors)
    assert (out / "violations.csv").read_text().strip() == "tick,robot,reason"
    assert np.ptp(reference.trajectories.positions[:, :, 0], axis=0).max() > 0.01    # they moved
