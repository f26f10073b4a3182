"""composed_sim's side of the fidelity suite: an experiment of tools/fidelity/experiments/, imported
as composed-sim imports it, started from ARGoS's own tick-0 poses and obstacle placements, and run
through the lockstep tick loop (``hosts/tick_loop.run_lockstep``, ARGoS's tick order included).

The controllers answer without ROS: each ported controller's own decision code (its plugin
module's functions, the flocking node's ``on_tick`` on a stand-in object) is called on the frame's
readings, so a 600-tick run of 50 robots takes seconds. ``test_fidelity_host.py`` checks that a
run through the composed ROS host gives the same trajectories.
"""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Callable

import numpy as np

from composed_sim.argos_import import loads_argos
from composed_sim.core.simulation import SensorFrame, Simulation
from composed_sim.devices.camera import Blobs
from composed_sim.hosts.tick_loop import run_lockstep
from composed_sim.ros.contract import twist_of_wheels
from composed_sim.world.robot_models import get_model
from composed_sim.world.schema import Box, Cylinder, World
from controller_plugins import flocking
from controller_plugins.diffusion import diffusion_wheels
from controller_plugins.epuck_obstacle_avoidance import avoidance_wheels
from controller_plugins.kheperaiv_diffusion import kheperaiv_diffusion_wheels
from tests.fidelity.reference import EXPERIMENTS_DIR


def imported_world(name: str, seed: int) -> World:
    """The experiment file as composed-sim imports it (ARGoS's seed; the loop functions that
    log poses are ARGoS's side only, and their warning is dropped)."""
    text = (EXPERIMENTS_DIR / f"{name}.argos").read_text()
    text = (text.replace("@SEED@", str(seed)).replace("@OUTPUT@", "poses.csv").replace("@LOGGER@", "libpose_logger")
            .replace("@CONTROLLERS@", "controllers").replace("@KHEPERAIV_CONTROLLER@", "libkheperaiv_diffusion"))
    world, _ = loads_argos(text, source=f"{name}.argos", ticks=600)
    return world


def world_from_argos(name: str, ref: dict, run: int, *, edit: Callable[[World], World] = lambda w: w) -> World:
    """The experiment's world started where ARGoS's run ``run`` (index into ``ref["seeds"]``) started:
    every robot at its logged tick-0 pose, the boxes and cylinders where ARGoS put them."""
    world = imported_world(name, int(ref["seeds"][run]))
    (group,) = world.robots
    poses = ref["initial"][run]
    group = group.model_copy(update={
        "placement": group.placement.model_copy(update={"method": "explicit",
                                                        "positions": [tuple(p) for p in poses[:, :2]]}),
        "heading": group.heading.model_copy(update={"method": "explicit", "values_rad": list(poses[:, 2])}),
    })
    obstacles = [Box(position=(b[0], b[1]), yaw_rad=b[2], size=(b[3], b[4]), height_m=b[5]) for b in ref["boxes"][run]]
    obstacles += [Cylinder(position=(c[0], c[1]), radius_m=c[2], height_m=c[3]) for c in ref["cylinders"][run]]
    data = world.model_dump()
    data["robots"] = [group.model_dump()]
    data["obstacles"] = [o.model_dump() for o in obstacles]
    return edit(World.model_validate(data))


# --- the controllers, without ROS -------------------------------------------------------------

def _deciders(world: World) -> Callable[[SensorFrame], tuple[np.ndarray, np.ndarray]]:
    """frame → (v [n], ω [n]) as the group's ported controller answers it."""
    (group,) = world.robots
    model = get_model(group.model)
    n, p = group.count, group.params
    angles = np.asarray(model.proximity.angles_rad) if model.proximity else None

    def by_wheels(wheels: Callable[[np.ndarray], tuple[float, float]]):
        def decide(frame):
            out = np.array([twist_of_wheels(*wheels(frame.groups[0].proximity[i]), model) for i in range(n)])
            return out[:, 0].copy(), out[:, 1].copy()
        return decide

    speed = min(float(p.get("speed_mps", 0.1)), model.max_wheel_speed_mps)
    if group.controller == "epuck-obstacle-avoidance":
        return by_wheels(lambda r: avoidance_wheels(r, speed))
    if group.controller == "diffusion":
        alpha, delta = math.radians(float(p.get("alpha_deg", 7.5))), float(p.get("delta", 0.1))
        return by_wheels(lambda r: diffusion_wheels(r, angles, alpha, delta, speed))
    if group.controller == "kheperaiv-diffusion":
        alpha, delta = math.radians(float(p.get("alpha_deg", 10.0))), float(p.get("delta", 0.5))
        return by_wheels(lambda r: kheperaiv_diffusion_wheels(r, angles, alpha, delta, speed))
    if group.controller == "flocking":
        nodes = [_flocking_node(p, model) for _ in range(n)]

        def decide(frame):
            g = frame.groups[0]
            out = np.empty((n, 2))
            for i, node in enumerate(nodes):
                a, d, c = g.blobs.of(i)
                tick = SimpleNamespace(light=g.light[i], blobs=Blobs(a, d, colors=c))
                out[i] = flocking.FlockingController.on_tick(node, tick)
            return out[:, 0].copy(), out[:, 1].copy()
        return decide
    raise ValueError(f"no ROS-free stand-in for the controller {group.controller!r}")


def _flocking_node(p: dict, model) -> SimpleNamespace:
    """What FlockingController.__init__ sets up, for its on_tick."""
    max_speed_cm = 100.0 * float(p.get("max_speed_mps", 0.10))
    light = np.asarray(model.light.angles_rad)
    return SimpleNamespace(
        target_cm=100.0 * float(p.get("target_distance_m", 0.75)), gain=float(p.get("gain", 1000.0)),
        exponent=float(p.get("exponent", 2.0)), max_speed_cm=max_speed_cm, model=model,
        turning=flocking.TurningMachine(max_speed_cm, math.radians(float(p.get("hard_turn_deg", 90.0))),
                                        math.radians(float(p.get("soft_turn_deg", 70.0))),
                                        math.radians(float(p.get("no_turn_deg", 10.0)))),
        _light_cos=np.cos(light), _light_sin=np.sin(light))


class DirectExchange:
    """The lockstep loop's ``Exchange`` with the controllers called in-process, without ROS."""

    def __init__(self, world: World, *, decide_at_tick_0: bool = True):
        self.violations = []
        # False: the controllers first decide on tick 1, as ARGoS's do (a measurement only: the
        # hosts' controllers answer tick 0 too, docs/fidelity.md "Tick order").
        self._decide_at_tick_0 = decide_at_tick_0
        self._decide = _deciders(world)
        self._answer = None
        (group,) = world.robots
        # The flocking robots light their beacon red from the start (its node's __init__).
        self._leds = ({i: np.array([[0, 0, 0]] * flocking.BEACON_LED + [list(flocking.RED)], dtype=np.uint8)
                       for i in range(group.count)} if group.controller == "flocking" else {})

    senses_itself = False      # the loop hands it sim.frame

    def gathering_s(self) -> float:
        return 0.0

    def controllers_time_s(self) -> tuple[float, float]:
        return 0.0, 0.0

    def publish_tick(self, frame: SensorFrame) -> None:
        if frame.tick == 0 and not self._decide_at_tick_0:
            self._answer = (np.zeros(len(frame.pose.yaws)), np.zeros(len(frame.pose.yaws)))
        else:
            self._answer = self._decide(frame)

    def publish_clock(self, tick: int) -> None:
        pass

    def close_tick(self, fallback, previous, commands) -> None:
        commands[0][:], commands[1][:] = self._answer

    def take_led_commands(self):
        leds, self._leds = self._leds, {}
        return leds

    def take_rab_payloads(self):
        return {}

    def take_drone_commands(self):
        return []

    def another_simulator(self):
        return None


def run(world: World, ticks: int, **exchange) -> np.ndarray:
    """Positions [ticks + 1, n, 2] of a run of ``world`` through the lockstep loop."""
    sim = Simulation(world)
    result = run_lockstep(sim, DirectExchange(world, **exchange), lambda timeout: True, ticks)
    return result.trajectories.positions
