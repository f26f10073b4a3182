"""A reading model per ARGoS sensor element: the generic light sensor, the Khepera IV's light sensor,
and the model a world file or an imported ARGoS file picks (docs/devices.md)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from composed_sim.argos_import import loads_argos
from composed_sim.core.scene import static_scene
from composed_sim.core.simulation import Simulation
from composed_sim.devices.light import light_ring
from composed_sim.world.robot_models import EPUCK, KHEPERAIV
from composed_sim.world.schema import Box, Light, World


def one(model, heading=0.0):
    return (np.zeros((1, 2)), np.array([heading]), np.array([model.body_radius_m]),
            np.array([model.body_height_m]))


EMPTY = static_scene(World(robots=[]))


def test_generic_light_is_intensity_squared_over_the_sensor_distance_and_the_body_hides_what_is_behind():
    ring = EPUCK.light                       # the e-puck's own light model is ARGoS's generic one
    assert ring.model == "generic"
    light = Light(position=(1.0, 0.0), height_m=0.06, intensity=0.8)
    read = light_ring(*one(EPUCK), ring, [light], EMPTY)[0]
    angles = np.asarray(ring.angles_rad)
    sensors = EPUCK.body_radius_m * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    d2 = ((np.array([1.0, 0.0]) - sensors) ** 2).sum(axis=1)           # same height: planar
    facing = (np.array([1.0, 0.0]) - sensors) @ np.stack([np.cos(angles), np.sin(angles)], axis=1).T
    facing = np.diag(facing) >= 0
    np.testing.assert_allclose(read[facing], 0.64 / d2[facing])
    assert facing.tolist() == [True, True, False, False, False, False, True, True]
    assert not read[~facing].any()           # the sensors at ±112.5° and ±157.5° face away: hidden


def test_generic_light_clamps_and_another_body_hides_it():
    ring = EPUCK.light
    near = Light(position=(0.2, 0.0), height_m=0.06, intensity=1.0)      # I²/d² > 1 at 16.5 cm
    assert light_ring(*one(EPUCK), ring, [near], EMPTY)[0, 0] == 1.0
    wall = static_scene(World(robots=[], obstacles=[Box(position=(0.5, 0.0), size=(0.05, 2.0), height_m=0.5)]))
    far = Light(position=(1.0, 0.0), height_m=0.06, intensity=1.0)
    assert not light_ring(*one(EPUCK), ring, [far], wall).any()


def test_kheperaiv_light_lights_five_sensors_by_the_foot_bots_index():
    # A light at 45°: the plugin's index is round(45° / 15°) = 3, so sensors 1…5 (45°…225°) are
    # lit by max(0, 1 − 2Δ/π): sensor 1 (Δ = 0) fully, sensor 2 (90°) half; sensor 0 (Δ = 45°) is
    # outside the window and gets nothing, where the foot-bot's model (nearest ± 6) gives it half.
    light = Light(position=(math.cos(math.pi / 4) * 2, math.sin(math.pi / 4) * 2), height_m=0.0, intensity=3.0)
    read = light_ring(*one(KHEPERAIV), KHEPERAIV.light, [light], EMPTY)[0]
    base = math.exp(-2.0 * 2.0 / 3.0)
    np.testing.assert_allclose(read, [0, base, base / 2, 0, 0, 0, 0, 0], atol=1e-12)
    as_footbot = light_ring(*one(KHEPERAIV), replace(KHEPERAIV.light, model="foot-bot"), [light], EMPTY)[0]
    np.testing.assert_allclose(as_footbot, [base / 2, base, base / 2, 0, 0, 0, 0, 0], atol=1e-12)


def test_a_world_file_picks_the_reading_model():
    def world(model=None):
        devices = {"proximity": {} if model is None else {"model": model}}
        return World.model_validate({
            "arena": {"size": (4, 4)}, "seed": 1,
            "obstacles": [{"type": "box", "position": (0.14, 0.0), "size": (0.1, 1.0)}],
            "robots": [{"model": "e-puck", "count": 1, "controller": "diffusion", "devices": devices,
                        "placement": {"method": "explicit", "positions": [(0.0, 0.0)]},
                        "heading": {"method": "explicit", "values_rad": [0.0]}}]})
    own = Simulation(world()).sense().groups[0]
    generic = Simulation(world("generic")).sense().groups[0]
    d = own.proximity_distances[0, 0]          # the ±17° sensor, 6 cm from the wall's face
    assert 0.05 < d < 0.07
    assert own.proximity[0, 0] == 0.0                        # beyond the e-puck calibration's 5 cm
    assert generic.proximity[0, 0] == pytest.approx(math.exp(-d))


ARGOS = """<argos-configuration>
  <framework><experiment length="10" ticks_per_second="10" random_seed="3" /></framework>
  <controllers>
    <epuck_obstacleavoidance_controller id="a" library="x">
      <actuators><differential_steering implementation="default" /></actuators>
      <sensors><{tag} implementation="default" /></sensors>
      <params velocity="5" />
    </epuck_obstacleavoidance_controller>
  </controllers>
  <arena size="3,3,1" center="0,0,0.5">
    <e-puck id="ep"><body position="0,0,0" orientation="0,0,0" /><controller config="a" /></e-puck>
  </arena>
  <physics_engines><dynamics2d id="d" /></physics_engines>
</argos-configuration>"""


@pytest.mark.parametrize("tag,model", [("proximity", "generic"), ("epuck_proximity", "e-puck")])
def test_the_importer_gives_each_argos_sensor_element_its_model(tag, model):
    world, _ = loads_argos(ARGOS.format(tag=tag))
    assert world.robots[0].devices.proximity.model == model
