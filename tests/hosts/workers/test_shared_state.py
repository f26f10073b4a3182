"""The world's state shared with the workers (hosts/workers/shared_state.py): a worker's view of it
reads what the main process wrote, the tick's tree of the robots included, and senses its block
as if it had built everything itself. No ROS."""
import numpy as np
import pytest

from composed_sim.core.senses import Senses
from composed_sim.core.simulation import Simulation
from composed_sim.hosts.workers import shared_state
from composed_sim.hosts.workers.shared_state import SharedState
from composed_sim.world.loader import load_world
from tests.hosts.test_tick_loop import WORLD


def _readings(frame) -> dict:
    out = {}
    for g in frame.groups:
        for name in list(g._unread):
            value = getattr(g, name)
            out[name] = value.offsets.tolist() + value.angles.tolist() if hasattr(value, "offsets") else value
    return out


@pytest.mark.parametrize("share_tree", [True, False])
def test_a_worker_senses_its_block_from_the_shared_state_as_from_the_simulation(share_tree):
    world = load_world(WORLD, robots=200, seed=4)
    sim = Simulation(world)
    rng = np.random.default_rng(1)
    for _ in range(20):
        sim.set_velocity_commands(np.full(200, 0.05), rng.uniform(-0.5, 0.5, 200))
        sim.step()
    main = SharedState(Senses(world), world.range_and_bearing.payload_bytes, share_tree=share_tree)
    inputs = sim.sensing_inputs()
    main.write(inputs, sim.robot_rows())
    worker = SharedState(Senses(world), world.range_and_bearing.payload_bytes, fd=main.fd)
    got = worker.inputs(inputs.tick, inputs.route_messages, inputs.scene, inputs.floor, inputs.lights)
    assert (got.tree is not None) == share_tree
    block = slice(50, 120)
    senses = Senses(world)
    shared = _readings(senses.frame(got, worker.rows(block), block))
    alone = _readings(senses.frame(inputs, sim.robot_rows(50, 120), block))
    assert shared.keys() == alone.keys() and shared
    for name in alone:
        np.testing.assert_array_equal(np.asarray(shared[name]), np.asarray(alone[name]), err_msg=name)


def test_a_tree_too_big_for_its_room_is_left_to_the_workers(monkeypatch):
    world = load_world(WORLD, robots=30, seed=4)
    sim = Simulation(world)
    monkeypatch.setattr(shared_state, "TREE_BYTES_PER_ROBOT", 0)
    monkeypatch.setattr(shared_state.pickle, "dumps", lambda tree, protocol: b"x" * 5000)   # over the 4096 spare
    main = SharedState(Senses(world), world.range_and_bearing.payload_bytes)
    main.write(sim.sensing_inputs(), sim.robot_rows())
    assert main.inputs(0, False, None, None, []).tree is None
