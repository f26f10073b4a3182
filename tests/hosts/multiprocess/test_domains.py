"""Spreading robots over ROS domains (pure, no ROS traffic) and the world file's multi_process section."""
from collections import Counter

import pytest

from composed_sim.hosts.multiprocess.domains import MAX_DOMAIN, DomainError, assign_domains, capacity
from composed_sim.world import dump_world, load_world

NAMES = [f"bot{i}" for i in range(5)]


def names(n):
    return [f"bot{i}" for i in range(n)]


def test_robots_fill_domains_in_order_k_per_domain():
    assert assign_domains(NAMES, 2, 10) == {"bot0": 10, "bot1": 10, "bot2": 11, "bot3": 11, "bot4": 12}
    # The paper's setting: 50 per domain.
    assert Counter(assign_domains(names(120), 50, 0).values()) == {0: 50, 1: 50, 2: 20}
    assert set(assign_domains(names(7), 50, 3).values()) == {3}


def test_explicit_assignment_wins_and_counts_towards_its_domain():
    got = assign_domains(NAMES, 2, 10, {"bot4": 10, "bot0": 3})
    assert got == {"bot0": 3, "bot1": 10, "bot2": 11, "bot3": 11, "bot4": 10}
    # Every robot explicit: nothing balanced, even beyond k (it is the user's choice).
    assert assign_domains(NAMES[:3], 1, 0, {n: 7 for n in NAMES[:3]}) == {n: 7 for n in NAMES[:3]}


def test_too_many_robots_for_the_domain_range_is_a_clear_error():
    with pytest.raises(DomainError) as err:
        assign_domains(names(100), 2, 200)
    text = str(err.value)
    for part in ("100 robots", "2 per domain", "from domain 200", f"0..{MAX_DOMAIN}"):
        assert part in text, text
    assert len(assign_domains(names(66), 2, 200)) == 66       # 200..232: 33 domains × 2 fit


def test_out_of_range_and_unknown_names_in_explicit_assignment():
    with pytest.raises(DomainError, match=r"domain ids must be within 0\.\.232 \(got bot1: 300\)"):
        assign_domains(NAMES, 2, 0, {"bot1": 300})
    with pytest.raises(DomainError, match="robots the world does not have: robot9"):
        assign_domains(NAMES, 2, 0, {"robot9": 1})
    with pytest.raises(DomainError, match="first domain 233 is outside"):
        assign_domains(NAMES, 2, 233)


def test_fast_dds_participants_per_domain_bound_the_robots_per_domain():
    # 120 participants per domain (the simulator is one), only 63 in the last domain, 232.
    assert capacity(0) == capacity(231) == 119 and capacity(232) == 62
    with pytest.raises(DomainError, match="domain 5 would hold 130 robots, but at most 119"):
        assign_domains(names(130), 1, 0, {n: 5 for n in names(130)})
    with pytest.raises(DomainError, match=r"robots per domain must be within 1\.\.119.*\(got 150\)"):
        assign_domains(names(300), 150, 0)
    # The last domain takes fewer.
    assert Counter(assign_domains(names(150), 100, 231).values()) == {231: 100, 232: 50}
    assert Counter(assign_domains(names(62), 100, 232).values()) == {232: 62}
    with pytest.raises(DomainError, match="cannot fit 63 robots at 100 per domain from domain 232"):
        assign_domains(names(63), 100, 232)


def test_multi_process_section_loads_round_trips_and_reaches_the_host(tmp_path):
    from composed_sim.hosting import HostError
    from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost

    path = tmp_path / "w.yaml"
    path.write_text("robots: [{count: 4, controller: flocking}]\n"
                    "multi_process: {robots_per_domain: 3, first_domain: 120, domains: {bot3: 7}}\n")
    world = load_world(path)
    assert world.multi_process.robots_per_domain == 3 and world.multi_process.domains == {"bot3": 7}
    again = tmp_path / "again.yaml"
    again.write_text(dump_world(world))
    assert load_world(again) == world
    host = MultiProcessHost(world, domain_id=5)               # no ROS until entered
    assert host.domains == {"bot0": 120, "bot1": 120, "bot2": 120, "bot3": 7}
    assert MultiProcessHost(world, robots_per_domain=1).domains["bot2"] == 122   # the CLI's override
    far = world.model_copy(update={"multi_process": world.multi_process.model_copy(update={"first_domain": 232})})
    with pytest.raises(HostError, match="multi-process mode: cannot fit 4 robots at 1 per domain"):
        MultiProcessHost(far, robots_per_domain=1)


def test_multi_process_section_is_checked(tmp_path):
    from composed_sim.world import WorldFileError

    path = tmp_path / "w.yaml"
    path.write_text("robots: [{count: 1, controller: flocking}]\nmulti_process: {domains: {bot0: 500}}\n")
    with pytest.raises(WorldFileError, match=r"multi_process\.domains\.bot0: must be <= 232"):
        load_world(path)
    path.write_text("robots: [{count: 1, controller: flocking}]\nmulti_process: {robots_per_domain: 0}\n")
    with pytest.raises(WorldFileError, match=r"multi_process\.robots_per_domain: must be >= 1"):
        load_world(path)
