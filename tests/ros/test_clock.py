"""/clock on the wire: every tick's time, and the time of the state after the last tick (which the
recordings and the markers show), in the single-process host and with worker processes."""
import time
from pathlib import Path

import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosts.workers import WorkerHost
from composed_sim.world.loader import load_world
from listener import Listener

FLOCKING = Path(__file__).resolve().parents[2] / "worlds" / "flocking.yaml"


@pytest.mark.parametrize("workers", [1, 2])
def test_clock_reaches_the_last_simulated_state(workers, domain_id):
    world = load_world(FLOCKING, robots=4, ticks=12, seed=1)
    listener = Listener(domain_id, ["/clock"])
    host = ComposedHost(world, domain_id=domain_id) if workers == 1 else \
        WorkerHost(world, workers=2, domain_id=domain_id)
    with host:
        listener.wait_matched()
        if workers == 1:      # and matched on the simulator's side too (discovery is two-way)
            clock = next(p for node in host.simulator_nodes for p in node.publishers if p.topic_name == "/clock")
            deadline = time.monotonic() + 30
            while clock.get_subscription_count() == 0 and time.monotonic() < deadline:
                time.sleep(0.01)
        result = host.run()
    heard = listener.stop()["got"]["/clock"]
    assert result.trajectories.ticks_done == 12
    assert heard[-1] == 12 * 100_000_000                   # tick 12: the state after the last step
    if workers == 1:                                       # matched before tick 0: every tick
        assert heard == [t * 100_000_000 for t in range(13)]
