"""Counter-based noise: a draw is fixed by (seed, device, tick, robot, slot), whoever draws it."""
import numpy as np
import pytest
from scipy import stats

from composed_sim.devices.common.noise import NoiseStream


def test_a_robots_draws_do_not_depend_on_the_other_rows_or_their_order():
    stream = NoiseStream(7, "proximity")
    everyone = stream.at(3, np.arange(100)).uniform(-1.0, 1.0, (100, 24))
    block = stream.at(3, np.arange(40, 60)).uniform(-1.0, 1.0, (20, 24))
    shuffled = stream.at(3, [59, 40]).uniform(-1.0, 1.0, (2, 24))
    np.testing.assert_array_equal(block, everyone[40:60])
    np.testing.assert_array_equal(shuffled, everyone[[59, 40]])


def test_ticks_devices_seeds_and_slots_draw_apart():
    robots = np.arange(50)
    base = NoiseStream(7, "proximity").at(3, robots).random((50, 8))
    others = [NoiseStream(7, "proximity").at(4, robots).random((50, 8)),
              NoiseStream(7, "light").at(3, robots).random((50, 8)),
              NoiseStream(8, "proximity").at(3, robots).random((50, 8))]
    for other in others:
        assert not np.isclose(base, other).any()
    assert len(np.unique(base)) == base.size          # every robot and slot its own value


def test_an_entrys_draws_depend_on_its_robot_and_slot_only():
    noise = NoiseStream(1, "camera").at(9, ())
    a = noise.entries(np.array([3, 5, 3]), np.array([10, 10, 11]))
    b = noise.entries(np.array([3]), np.array([11]))
    assert a.random(0)[2] == b.random(0)[0] and a.random(1)[2] == b.random(1)[0]
    assert a.random(0)[0] != a.random(1)[0]            # two draws of one entry differ


@pytest.mark.parametrize("draw", ["uniform", "normal"])
def test_the_draws_have_their_distribution(draw):
    noise = NoiseStream(5, "wheels").at(0, np.arange(2000))
    if draw == "uniform":
        x = noise.uniform(-2.0, 3.0, (2000, 10)).ravel()
        assert x.min() >= -2.0 and x.max() < 3.0
        assert stats.kstest(x, stats.uniform(-2.0, 5.0).cdf).pvalue > 1e-3
    else:
        x = noise.normal(1.0, 0.5, (2000, 10)).ravel()
        assert stats.kstest(x, stats.norm(1.0, 0.5).cdf).pvalue > 1e-3
