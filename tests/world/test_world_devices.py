"""World file sections for the device set: floor, range-and-bearing medium, per-group devices,
movable obstacles; their errors name file, line, field and value. No ROS."""
from __future__ import annotations

import textwrap
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from composed_sim.world.robot_models import EPUCK, FOOTBOT, THYMIO2, TURTLEBOT3_BURGER
from composed_sim.world import WorldFileError, dump_world, load_world
from composed_sim.devices import WITH_LAYOUT
from composed_sim.world.schema import Devices


def write(tmp_path: Path, text: str, name: str = "w.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def error_of(path: Path) -> str:
    with pytest.raises(WorldFileError) as info:
        load_world(path)
    return str(info.value)


FULL = """\
    arena: {size: [6, 6], walls: true}
    floor:
      color: [20, 20, 20]
      image: tiles/floor.png
      image_size_m: [4, 4]
      shapes:
        - {type: circle, position: [1, 1], radius_m: 0.5, color: [255, 255, 255]}
        - {type: rectangle, position: [-1, 1], size: [1, 0.2], yaw_rad: 0.5, color: [0, 0, 255]}
    range_and_bearing: {mode: global, payload_bytes: 16, check_occlusions: false}
    obstacles:
      - {type: box, position: [2, 2], size: [0.3, 0.3], movable: true, mass_kg: 2.0}
      - {type: cylinder, position: [-2, 2], radius_m: 0.2, movable: true}
    robots:
      - model: foot-bot
        count: 3
        controller: flocking
        devices:
          range_and_bearing: {range_m: 1.5, packet_drop_probability: 0.1, noise_std_m: 0.02}
          ground: {noise: 0.05}
          light: {enabled: false}
          wheels: {bias_std_mps: 0.001, factor_std: 0.05, velocity_noise_mps: 0.001}
          positioning: {position_noise_m: 0.01, yaw_noise_rad: 0.02}
      - {model: turtlebot3-burger, count: 2, controller: flocking, name_prefix: tb,
         devices: {lidar: {noise_std_m: 0.01}}}
    """


def test_every_device_section_loads_and_round_trips(tmp_path):
    (tmp_path / "tiles").mkdir()
    iio.imwrite(tmp_path / "tiles" / "floor.png", np.zeros((4, 4, 3), np.uint8))
    world = load_world(write(tmp_path, FULL))
    # the image path is made absolute, relative to the world file
    assert world.floor.image == str(tmp_path / "tiles" / "floor.png")
    assert world.range_and_bearing.mode == "global" and world.range_and_bearing.payload_bytes == 16
    assert [o.movable for o in world.obstacles] == [True, True] and world.obstacles[0].mass_kg == 2.0
    fb, tb = world.robots
    assert fb.devices.running(FOOTBOT) == ("proximity", "camera", "ground", "range_and_bearing")
    assert tb.devices.running(TURTLEBOT3_BURGER) == ("lidar",)
    assert fb.devices.config("range_and_bearing").range_m == 1.5
    again = write(tmp_path, dump_world(world), "again.yaml")
    assert load_world(again) == world


def test_models_declare_their_devices_and_defaults():
    assert Devices().running(FOOTBOT) == ("proximity", "light", "camera")     # the flocking set
    assert Devices().running(EPUCK) == ("proximity", "ground")
    assert Devices().running(THYMIO2) == ("proximity", "ground")
    assert Devices().running(TURTLEBOT3_BURGER) == ("lidar",)
    for model in (FOOTBOT, EPUCK, THYMIO2, TURTLEBOT3_BURGER):
        assert set(model.default_devices) <= set(model.devices)
        for name in WITH_LAYOUT:
            assert (name in model.devices) == (getattr(model, name) is not None)


def test_a_device_the_model_lacks_is_an_error_naming_the_field(tmp_path):
    text = error_of(write(tmp_path, """\
        robots:
          - model: turtlebot3-burger
            count: 2
            controller: x
            devices:
              range_and_bearing: {range_m: 2}
        """))
    assert ":6: robots[0].devices.range_and_bearing: the turtlebot3-burger has no range_and_bearing " \
           "device (it has: lidar)" in text
    # switching it off is fine
    load_world(write(tmp_path, """\
        robots:
          - {model: turtlebot3-burger, count: 2, controller: x, devices: {range_and_bearing: {enabled: false}}}
        """, "ok.yaml"))


@pytest.mark.parametrize("snippet, where, message", [
    ("range_and_bearing: {mode: radio}", "range_and_bearing.mode", "must be one of 'local' or 'global'"),
    ("range_and_bearing: {payload_bytes: 0}", "range_and_bearing.payload_bytes", "must be >= 1"),
    ("obstacles: [{type: box, position: [1, 1], size: [1, 1], movable: true, mass_kg: -1}]",
     "obstacles[0].mass_kg", "must be > 0"),
    ("floor: {shapes: [{type: star, position: [0, 0], color: [1, 2, 3]}]}", "floor.shapes[0].type",
     "must be one of"),
    ("floor: {color: [0, 300, 0]}", "floor.color[1]", "must be <= 255"),
    ("floor: {image: f.png}", "floor.image_size_m", "an image floor needs its size in metres"),
])
def test_section_errors_name_the_field(tmp_path, snippet, where, message):
    text = error_of(write(tmp_path, snippet + "\nrobots: [{count: 1, controller: x}]\n"))
    assert f"w.yaml:1: {where}: {message}" in text


@pytest.mark.parametrize("devices, where, message", [
    ("{range_and_bearing: {packet_drop_probability: 1.5}}", "range_and_bearing.packet_drop_probability",
     "must be <= 1"),
    ("{ground: {noise: -0.1}}", "ground.noise", "must be >= 0"),
    ("{wheels: {factor_std: -1}}", "wheels.factor_std", "must be >= 0"),
    ("{sonar: {}}", "sonar", "unknown field"),
])
def test_device_setting_errors_name_the_field(tmp_path, devices, where, message):
    text = error_of(write(tmp_path, f"robots: [{{count: 1, controller: x, devices: {devices}}}]\n"))
    assert f"robots[0].devices.{where}: {message}" in text


def test_floor_image_must_exist_and_be_an_image(tmp_path):
    text = error_of(write(tmp_path, """\
        arena: {size: [4, 4]}
        floor:
          image: missing.png
        robots: [{count: 1, controller: x}]
        """))
    assert f"w.yaml:3: floor.image: no such image file {tmp_path / 'missing.png'}" in text
    (tmp_path / "not_an_image.png").write_text("hello")
    text = error_of(write(tmp_path, """\
        arena: {size: [4, 4]}
        floor: {image: not_an_image.png}
        robots: [{count: 1, controller: x}]
        """))
    assert "w.yaml:2: floor.image: cannot read" in text and '(got "not_an_image.png")' in text
