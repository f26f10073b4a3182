"""End to end through real rclpy: the composed host flies the flocking swarm."""
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from composed_sim import plugins
from composed_sim.world.robot_models import FOOTBOT
from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosting.process_hosting import EXECUTORS
from composed_sim.world.loader import load_world

FLOCKING = Path(__file__).resolve().parents[2] / "worlds" / "flocking.yaml"


def run(world, executor="single-threaded", domain_id=0, ticks=None):
    with ComposedHost(world, executor=executor, domain_id=domain_id) as host:
        return host.run(ticks)


@pytest.fixture(scope="module")
def flock_run():
    import os
    world = load_world(FLOCKING, robots=30, ticks=300, seed=7)
    return world, run(world, "multi-threaded", int(os.environ["ROS_DOMAIN_ID"]))


def test_swarm_flocks_towards_the_light(flock_run):
    world, result = flock_run
    pos = result.trajectories.positions
    assert result.trajectories.ticks_done == 300 and pos.shape == (301, 30, 2)
    light = np.asarray(world.lights[0].position)
    before = np.linalg.norm(pos[0].mean(axis=0) - light)
    after = np.linalg.norm(pos[-1].mean(axis=0) - light)
    # 300 ticks = 30 s; the light vector alone drives at 2.5 cm/s, so ≥ 0.3 m closer is a real approach.
    assert after < before - 0.3, (before, after)


def test_swarm_spreads_to_the_target_distance_without_collisions(flock_run):
    world, result = flock_run
    pos = result.trajectories.positions
    target = world.robots[0].params["target_distance_m"]
    nearest = lambda p: np.sort(np.linalg.norm(p[:, None] - p[None], axis=2), axis=1)[:, 1]
    start, end = nearest(pos[0]).mean(), nearest(pos[-1]).mean()
    # Placed at 5 robots/m² (≈ 0.25 m apart), Lennard-Jones spreads them towards δ = 0.75 m.
    assert start < 0.5 * target
    assert 0.6 * target < end < 1.4 * target, end
    min_gap = min(pdist(p).min() for p in pos[::5])
    assert min_gap > 2 * FOOTBOT.body_radius_m - 0.005     # bodies never overlap beyond solver slop
    assert result.violations == []


def test_same_seed_same_trajectories_and_other_seed_differs(domain_id):
    world = load_world(FLOCKING, robots=12, ticks=60, seed=3)
    a, b = run(world, domain_id=domain_id), run(world, domain_id=domain_id)
    np.testing.assert_array_equal(a.trajectories.positions, b.trajectories.positions)
    np.testing.assert_array_equal(a.trajectories.headings, b.trajectories.headings)
    c = run(load_world(FLOCKING, robots=12, ticks=60, seed=4), domain_id=domain_id)
    assert not np.array_equal(a.trajectories.positions, c.trajectories.positions)


def test_every_executor_gives_identical_trajectories(domain_id):
    world = load_world(FLOCKING, robots=15, ticks=80, seed=11)
    results = {ex: run(world, ex, domain_id) for ex in EXECUTORS}
    ref = results["single-threaded"].trajectories
    assert np.ptp(ref.positions[:, :, 0], axis=0).max() > 0.01   # the robots did move
    for ex, r in results.items():
        assert r.violations == [], ex
        np.testing.assert_array_equal(r.trajectories.positions, ref.positions, err_msg=ex)


def test_plain_node_plugin_from_another_package_drives_robots(third_party_plugin, domain_id):
    assert third_party_plugin in plugins.installed()
    world = load_world(FLOCKING, robots=5, ticks=40, seed=1)
    world = world.model_copy(update={"robots": [world.robots[0].model_copy(
        update={"controller": third_party_plugin, "params": {"speed": 0.08}})]})
    result = run(world, domain_id=domain_id)
    assert result.violations == []
    pos = result.trajectories.positions
    moved = np.linalg.norm(pos[-1] - pos[0], axis=1)
    # 40 ticks at up to 8 cm/s, one tick of latency: about 0.31 m each unless something was close.
    assert np.median(moved) > 0.2, moved


def test_unknown_parameter_and_unknown_plugin_are_clear_errors(domain_id):
    world = load_world(FLOCKING, robots=2, ticks=5)
    bad = world.model_copy(update={"robots": [world.robots[0].model_copy(
        update={"params": {**world.robots[0].params, "gian": 3.0}})]})
    with pytest.raises(plugins.PluginError, match=r"robots\[0\]\.params: controller 'flocking' has no parameter 'gian'"):
        run(bad, domain_id=domain_id)
    nope = world.model_copy(update={"robots": [world.robots[0].model_copy(update={"controller": "nope"})]})
    with pytest.raises(plugins.PluginError, match="unknown controller plugin 'nope'.*flocking"):
        run(nope, domain_id=domain_id)


@pytest.fixture(scope="module")
def one_participant_run():
    import os
    world = load_world(FLOCKING, robots=7, ticks=40, seed=5)
    with ComposedHost(world, executor="lockstep", domain_id=int(os.environ["ROS_DOMAIN_ID"]),
                      robots_per_participant=7) as host:
        assert host.setup.participants == 1
        return world, host.run()


@pytest.mark.parametrize("executor", EXECUTORS)
def test_robots_split_over_participants_fly_as_in_one(one_participant_run, executor, domain_id):
    """3 robots per participant: 3 shards of 3, 3 and 1 robots, each its own DDS participant with
    its simulator node; every executor runs them all, bit for bit as in one participant."""
    world, whole = one_participant_run
    with ComposedHost(world, executor=executor, domain_id=domain_id, robots_per_participant=3) as host:
        assert host.setup.participants == 3 and [len(n.rows) for n in host.simulator_nodes] == [3, 3, 1]
        sharded = host.run()
    assert sharded.violations == whole.violations == []
    np.testing.assert_array_equal(sharded.trajectories.positions, whole.trajectories.positions)
    np.testing.assert_array_equal(sharded.trajectories.headings, whole.trajectories.headings)
    np.testing.assert_array_equal(sharded.trajectories.led_colors, whole.trajectories.led_colors)


def test_the_participant_profile_is_set_unless_the_user_gave_one(monkeypatch, tmp_path):
    from composed_sim.hosting.dds import participants
    for variable in participants.PROFILE_VARIABLES:
        monkeypatch.delenv(variable, raising=False)
    assert participants.ignore_participants_of_this_process()
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(participants.PROFILE)
    assert "FILTER_SAME_PROCESS" in participants.PROFILE.read_text()
    assert participants.ignore_participants_of_this_process()          # ours already: still in force
    own = tmp_path / "mine.xml"
    monkeypatch.setenv("FASTDDS_DEFAULT_PROFILES_FILE", str(own))
    assert not participants.ignore_participants_of_this_process()      # the user's: respected
    assert os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] == str(own)
