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
