"""The tick loop alone (hosts/tick_loop.run_lockstep), over a fake exchange with no ROS: the order
of a tick, the commands reaching the physics, stops, checkpoints and a failing exchange."""
from pathlib import Path

import numpy as np
import pytest

from composed_sim.core.simulation import Simulation
from composed_sim.hosts.tick_loop import run_lockstep
from composed_sim.core.violations import Violation
from composed_sim.world.loader import load_world

WORLD = Path(__file__).resolve().parents[2] / "worlds" / "flocking.yaml"


class FakeExchange:
    """Every robot answers (v, ω) = (0.05 · robot index / n, 0.2); robot 1 also sets its LEDs blue
    at tick 2; tick 3 records a violation of robot 0. Logs every call."""

    def __init__(self, n: int, fail_at: int = -1):
        self.n, self.fail_at = n, fail_at
        self.calls: list[tuple] = []
        self.violations: list[Violation] = []
        self.tick = -1

    senses_itself = False

    def gathering_s(self) -> float:
        return 0.0

    def controllers_time_s(self) -> tuple[float, float]:
        return 0.0, 0.0

    def publish_tick(self, frame) -> None:
        self.tick = frame.tick
        if frame.tick == self.fail_at:
            raise RuntimeError("exchange broke")
        self.calls.append(("publish", frame.tick))

    def publish_clock(self, tick: int) -> None:
        self.calls.append(("clock", tick))

    def another_simulator(self):
        return None

    def wait(self, timeout_s: float) -> bool:
        self.calls.append(("wait", self.tick))
        return True

    def close_tick(self, fallback, previous, commands) -> None:
        self.calls.append(("close", self.tick))
        commands[0][:] = 0.05 * np.arange(self.n) / self.n
        commands[1][:] = 0.2
        if self.tick == 3:
            self.violations.append(Violation(3, "bot0", "late"))

    def take_led_commands(self) -> dict:
        self.calls.append(("leds", self.tick))
        return {1: np.tile([0, 0, 255], (13, 1)).astype(np.uint8)} if self.tick == 2 else {}

    def take_rab_payloads(self) -> dict:
        return {}

    def take_drone_commands(self) -> list:
        return []


def world(ticks=6):
    return load_world(WORLD, robots=4, ticks=ticks, seed=2)


def test_a_tick_publishes_waits_closes_then_acts_and_the_physics_follows_the_commands():
    w = world()
    sim, exchange = Simulation(w), FakeExchange(4)
    result = run_lockstep(sim, exchange, exchange.wait, 6)
    assert [c for c in exchange.calls if c[1] == 0] == [("publish", 0), ("wait", 0), ("close", 0), ("leds", 0)]
    assert [t for kind, t in exchange.calls if kind == "publish"] == [0, 1, 2, 3, 4, 5]
    assert exchange.calls[-1] == ("clock", 6)         # the state after the last tick, on /clock alone
    assert result.trajectories.positions.shape == (7, 4, 2) and not result.interrupted
    assert [(v.tick, v.robot) for v in result.violations] == [(3, "bot0")]
    # The same commands given to a Simulation directly give the same trajectories, bit for bit; the
    # first step applies the initial zero command, as ARGoS's (hosts/tick_loop.acted_commands).
    assert (result.trajectories.positions[1] == result.trajectories.positions[0]).all()
    alone = Simulation(w)
    for t in range(6):
        scale = 0.0 if t == 0 else 1.0
        alone.set_velocity_commands(scale * 0.05 * np.arange(4) / 4, np.full(4, 0.2 * scale))
        if t == 2:
            alone.set_led_colors(1, np.tile([0, 0, 255], (13, 1)).astype(np.uint8))
        alone.step()
    np.testing.assert_array_equal(result.trajectories.positions[-1], alone.positions)
    assert (result.trajectories.led_colors[3:, 1] == (0, 0, 255)).all()      # from tick 2's act on


def test_a_stop_request_ends_at_a_tick_boundary_and_checkpoints_start_at_tick_0():
    sim, exchange = Simulation(world(10)), FakeExchange(4)
    checkpoints = []
    result = run_lockstep(sim, exchange, exchange.wait, 10, should_stop=lambda: exchange.tick >= 4,
                          checkpoint=checkpoints.append)
    assert result.interrupted and result.trajectories.ticks_done == 5
    assert [c.trajectories.ticks_done for c in checkpoints] == [0]


def test_a_failing_exchange_leaves_the_result_so_far_on_the_error():
    sim, exchange = Simulation(world(10)), FakeExchange(4, fail_at=3)
    with pytest.raises(RuntimeError, match="exchange broke") as caught:
        run_lockstep(sim, exchange, exchange.wait, 10)
    partial = caught.value.partial_result
    assert partial.interrupted and partial.trajectories.ticks_done == 3
