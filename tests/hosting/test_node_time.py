"""The CPU time of the nodes' own code (hosting/guard/node_time.py), which the benchmark's host cost per
robot-tick leaves out: counted by the participant groups that host the nodes, in this process or
in worker processes, for a SwarmController (its on_tick) and for a plain node (its callbacks)."""
from pathlib import Path

import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosts.workers.worker_host import WorkerHost
from composed_sim.world.loader import load_world

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("world_file", ["flocking.yaml", "plain_nodes.yaml"])
@pytest.mark.parametrize("workers", [1, 2])
def test_the_nodes_own_code_is_timed_where_they_run(world_file, workers, domain_id):
    world = load_world(ROOT / "worlds" / world_file, robots=4, ticks=10, seed=3)
    host = ComposedHost(world, domain_id=domain_id) if workers == 1 else \
        WorkerHost(world, workers=workers, domain_id=domain_id)
    with host:
        times = host.run().times
    assert 0.0 < times.node_code_s < times.cpu_s


def test_a_sampled_count_adds_up_to_the_cpu_time_of_all_calls():
    """After its first calls, one call in SAMPLED is timed and counts SAMPLED times: over many calls
    the sum is the thread's CPU time spent in them, as one clock around them all reads it."""
    import time

    from composed_sim.hosting.guard.node_time import SAMPLED, TIMED_FIRST, NodeTime

    node_time = NodeTime()
    calls = TIMED_FIRST + 400 * SAMPLED
    outside = 0.0
    for i in range(calls):
        began = time.thread_time()
        started = node_time.start()
        deadline = time.perf_counter() + (20e-6 if i % 2 else 60e-6)    # two costs, alternated
        while time.perf_counter() < deadline:
            pass
        node_time.stop(started)
        outside += time.thread_time() - began
    assert abs(node_time.seconds - outside) < 0.15 * outside
