"""/clock on the wire: every tick's time, and the time of the state after the last tick (which the
recordings and the markers show). (With worker processes the same SimulatorNode.publish_clock runs
in the worker of robot 0; an outside listener cannot be sure to be matched with it before a short
run ends, so that path is not checked on the wire here.)"""
import time
from pathlib import Path

from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.loader import load_world
from listener import Listener

FLOCKING = Path(__file__).resolve().parents[2] / "worlds" / "flocking.yaml"


def test_clock_reaches_the_last_simulated_state(domain_id):
    world = load_world(FLOCKING, robots=4, ticks=12, seed=1)
    listener = Listener(domain_id, ["/clock"])
    with ComposedHost(world, domain_id=domain_id) as host:
        listener.wait_matched()
        # … and matched on the simulator's side too (discovery is two-way)
        clock = next(p for node in host.simulator_nodes for p in node.publishers if p.topic_name == "/clock")
        deadline = time.monotonic() + 30
        while clock.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        result = host.run()
    heard = listener.stop()["got"]["/clock"]
    assert result.trajectories.ticks_done == 12
    # ticks 0 … 11 before their sensors, and tick 12: the state after the last step
    assert heard == [t * 100_000_000 for t in range(13)]
