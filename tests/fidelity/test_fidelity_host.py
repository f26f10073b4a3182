"""The fidelity suite's ROS-free driver (tests/fidelity/driver.py) runs what the composed ROS host
runs: the same experiments from ARGoS's start, through real rclpy nodes, give the same robots' paths
(the readings travel as float32 in the messages, hence a tolerance; the tick order is the loop's)."""
from __future__ import annotations

import numpy as np
import pytest

from composed_sim.hosts.composed import ComposedHost
from tests.fidelity import driver, reference


@pytest.mark.parametrize("name", ["flocking_10", "kheperaiv_20", "epuck_30"])
def test_the_ros_host_runs_as_the_driver(name, domain_id):
    ref = reference.load(name)
    world = driver.world_from_argos(name, ref, 0)
    ticks = 30
    with ComposedHost(world, domain_id=domain_id) as host:
        hosted = host.run(ticks)
    assert hosted.violations == []
    ours = driver.run(world, ticks)
    np.testing.assert_allclose(hosted.trajectories.positions, ours, atol=1e-6, rtol=0)
    # and both are ARGoS's, robot for robot, at tick 1 (nothing moved: the first step's zero command)
    np.testing.assert_allclose(hosted.trajectories.positions[1], ref["track"][0][0], atol=1e-6, rtol=0)
