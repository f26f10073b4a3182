"""World files: loading, writing back, overrides and error messages. No ROS."""
import copy
import math
import os
import textwrap
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from composed_sim.world import (World, WorldFileError, dump_world, load_world, split_count,
                                world_from_dict)

WORLDS = sorted((Path(__file__).resolve().parents[2] / "worlds").glob("*.yaml"))
FLOCKING = WORLDS[0].parent / "flocking.yaml"


def write(tmp_path: Path, text: str, name: str = "w.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def error_of(path: Path, **overrides) -> str:
    with pytest.raises(WorldFileError) as info:
        load_world(path, **overrides)
    return str(info.value)


# --- shipped worlds, round trip, overrides ---------------------------------------------

def test_worlds_are_shipped():
    assert {p.name for p in WORLDS} >= {"flocking.yaml", "flocking_walls.yaml"}


@pytest.mark.parametrize("path", WORLDS, ids=lambda p: p.name)
def test_shipped_world_loads_and_round_trips(path, tmp_path):
    world = load_world(path)
    assert world.robot_count > 0
    again = write(tmp_path, dump_world(world))
    assert load_world(again) == world
    assert world_from_dict(yaml.safe_load(dump_world(world))) == world


def test_flocking_world_is_the_papers_experiment():
    w = load_world(FLOCKING)
    assert (w.seed, w.ticks_per_second, w.length_ticks, w.physics.substeps) == (1, 10, 600, 10)
    assert not w.arena.walls and w.obstacles == []
    [light] = w.lights
    assert (light.position, light.height_m, light.intensity) == ((0.0, 10.0), 0.5, 3.0)
    [g] = w.robots
    assert (g.model, g.count, g.name_prefix, g.controller) == ("foot-bot", 30, "bot", "flocking")
    assert g.params == {"target_distance_m": 0.75, "gain": 1000, "exponent": 2,
                        "max_speed_mps": 0.10, "hard_turn_deg": 90, "soft_turn_deg": 70,
                        "no_turn_deg": 10}
    assert (g.placement.method, g.placement.center, g.placement.size,
            g.placement.density) == ("uniform", (0.0, 4.0), None, 5.0)
    # The start centre is within the light sensor's reach (2.5 × intensity) of the light.
    assert math.dist(g.placement.center, w.lights[0].position) < 2.5 * w.lights[0].intensity
    assert g.heading.method == "uniform" and g.camera.aperture_deg == 80.0
    assert w.robot_names() == [f"bot{i}" for i in range(30)]


def test_every_feature_round_trips(tmp_path):
    path = write(tmp_path, """
        name: all
        arena: {size: [8, 6], center: [1, 0], walls: true, wall_thickness_m: 0.2}
        lights: [{position: [1, 2], color: [1, 2, 3]}]
        obstacles:
          - {type: box, position: [2, 2], size: [1, 0.5], yaw_rad: 0.3}
          - {type: cylinder, position: [-1, 1], radius_m: 0.25, height_m: 1}
        robots:
          - count: 2
            controller: c
            params: {f: 0.5, i: 3, s: text, b: true, l: [1, 2.5], e: []}
            placement: {method: explicit, positions: [[0, 0], [1, 1]]}
            heading: {method: constant, value_rad: 1.5}
          - {count: 5, controller: c, name_prefix: r, placement: {method: grid, spacing_m: 0.3}}
          - {count: 5, controller: c, placement: {method: gaussian, std_m: 0.4}}
    """)
    world = load_world(path)
    assert world.robots[0].params["i"] == 3 and world.robots[0].params["b"] is True
    assert load_world(write(tmp_path, dump_world(world), "again.yaml")) == world
    assert world.robot_names()[:3] == ["bot0", "bot1", "r0"]
    assert world.robot_names()[-1] == "bot6"


def test_overrides_on_one_group():
    w = load_world(FLOCKING, robots=1280, ticks=12, seed=99)
    assert (w.robot_count, w.length_ticks, w.seed) == (1280, 12, 99)
    assert w.robot_names()[-1] == "bot1279"


def test_robots_override_splits_groups_proportionally(tmp_path):
    path = write(tmp_path, """
        robots:
          - {count: 30, controller: flocking, name_prefix: a}
          - {count: 10, controller: flocking, name_prefix: b}
    """)
    # 9 * 30/40 = 6.75 and 9 * 10/40 = 2.25: floors 6 and 2, the spare one to the larger remainder.
    assert [g.count for g in load_world(path, robots=9).robots] == [7, 2]
    assert [g.count for g in load_world(path, robots=400).robots] == [300, 100]


@pytest.mark.parametrize("total, counts, shares", [
    (4, [1, 1, 1], [2, 1, 1]),      # a tie goes to the earlier group
    (3, [0, 0], [2, 1]),            # all empty: split equally
    (5, [0, 7], [0, 5]),
    (10, [1, 2, 3], [2, 3, 5]),     # quotas 1.67, 3.33, 5: remainders .67 > .33
])
def test_split_count(total, counts, shares):
    assert split_count(total, counts) == shares


def test_robots_override_cannot_resize_an_explicit_group(tmp_path):
    path = write(tmp_path, """
        robots:
          - {count: 4, controller: flocking}
          - {count: 2, controller: flocking, placement: {method: explicit, positions: [[5, 5], [6, 6]]}}
    """)
    message = error_of(path, robots=12)
    assert message.startswith("--robots: cannot resize robots[1]")
    assert "explicit" in message and "12" in message
    assert load_world(path, robots=6).robot_count == 6      # the same total is fine


@pytest.mark.parametrize("overrides, expected", [
    ({"robots": 0}, "--robots: must be >= 1 (got 0)"),
    ({"robots": "10"}, '--robots: must be a whole number (got "10")'),
    ({"robots": 2.5}, "--robots: must be a whole number (got 2.5)"),
    ({"ticks": 0}, "--ticks: must be >= 1 (got 0)"),
    ({"ticks": True}, "--ticks: must be a whole number (got true)"),
    ({"seed": -1}, "--seed: must be >= 0 (got -1)"),
    ({"seed": 2**32}, "--seed: must be < 4294967296 (got 4294967296)"),
])
def test_bad_override_values(overrides, expected):
    assert error_of(FLOCKING, **overrides) == expected


# --- bad input: file, line, field path and value in the message --------------------------

BASE = """\
name: test
seed: 3
arena:
  size: [6, 6]
  walls: {walls}
lights:
  - position: {light}
robots:
  - model: {model}
    count: {count}
    controller: flocking
    placement:
      method: {method}
      {placement_extra}
    camera:
      aperture_deg: {aperture}
"""
GOOD = dict(walls="false", light="[1, 1]", model="foot-bot", count=3, method="uniform",
            placement_extra="density: 5", aperture=80)


def base(**changes) -> str:
    return BASE.format(**{**GOOD, **changes})


def test_base_world_is_valid(tmp_path):
    assert load_world(write(tmp_path, base())).robot_count == 3


@pytest.mark.parametrize("changes, line, path, message, got", [
    ({"count": -3}, 10, "robots[0].count", "must be >= 0", "(got -3)"),
    ({"count": "three"}, 10, "robots[0].count", "must be a whole number", '(got "three")'),
    ({"count": 2.5}, 10, "robots[0].count", "must be a whole number", "(got 2.5)"),
    ({"placement_extra": "density: -1"}, 14, "robots[0].placement.density", "must be > 0",
     "(got -1)"),
    ({"placement_extra": "densty: 5"}, 14, "robots[0].placement.densty",
     "unknown field (allowed here: method, center, size, density", "(got 5)"),
    ({"placement_extra": "center: [1, 2, 3]"}, 14, "robots[0].placement.center",
     "must have exactly 2 items", "(got [1, 2, 3])"),
    ({"placement_extra": "center: .nan"}, 14, "robots[0].placement.center", "must be a list",
     "(got NaN)"),
    ({"placement_extra": "center: [.inf, 0]"}, 14, "robots[0].placement.center[0]",
     "must be a finite number", "(got Infinity)"),
    ({"method": "spiral"}, 13, "robots[0].placement.method",
     "must be one of 'uniform', 'gaussian', 'grid' or 'explicit'", '(got "spiral")'),
    ({"aperture": 95}, 16, "robots[0].camera.aperture_deg", "must be < 90", "(got 95)"),
    ({"light": "[1, 10]"}, 7, "lights[0].position", "outside the arena", "(got [1.0, 10.0])"),
    ({"model": "rover"}, 9, "robots[0].model", "unknown robot model; known: crazyflie, e-puck, foot-bot, kheperaiv, thymio2, turtlebot3-burger",
     '(got "rover")'),
    ({"method": "explicit", "placement_extra": "positions: [[0, 0], [1, 1]]"}, 14,
     "robots[0].placement.positions", "must list exactly count = 3 positions, lists 2",
     "(got [[0.0, 0.0], [1.0, 1.0]])"),
    ({"method": "explicit"}, 13, "robots[0].placement.method",
     "explicit placement needs a `positions` list", '(got "explicit")'),
])
def test_field_errors_name_file_line_path_and_value(tmp_path, changes, line, path, message, got):
    file = write(tmp_path, base(**changes))
    text = error_of(file)
    assert text.startswith(f"{file}:{line}: {path}: {message}")
    assert text.endswith(f" {got}") and "\n" not in text


def test_walls_without_size(tmp_path):
    file = write(tmp_path, base(walls="true").replace("  size: [6, 6]\n", ""))
    assert error_of(file) == (f"{file}:4: arena.walls: walls need arena.size (the side lengths "
                              f"in m) (got true)")


def test_obstacle_errors(tmp_path):
    file = write(tmp_path, """
        obstacles:
          - type: box
            position: [0, 0]
          - {type: cone, position: [1, 1]}
          - position: [2, 2]
        robots: [{count: 1, controller: flocking}]
    """)
    lines = error_of(file).splitlines()
    assert lines == [f"{file}: 3 problems:",
                     f"  {file}:3: obstacles[0].size: is required",
                     f"  {file}:5: obstacles[1].type: must be one of 'box', 'cylinder' (got \"cone\")",
                     f"  {file}:6: obstacles[2].type: is required: one of 'box', 'cylinder'"]


def test_several_errors_give_one_message_with_a_line_each(tmp_path):
    file = write(tmp_path, """
        seed: -1
        ticks_per_second: fast
        robots:
          - count: 3
            controller: flocking
            colour: red
    """)
    assert error_of(file).splitlines() == [
        f"{file}: 3 problems:",
        f"  {file}:2: seed: must be >= 0 (got -1)",
        f"  {file}:3: ticks_per_second: must be a whole number (got \"fast\")",
        f"  {file}:7: robots[0].colour: unknown field (allowed here: model, count, name_prefix, "
        f"controller, params, nodes, placement, heading, camera, devices, cmd_vel, answers_every_ticks, answers, "
            f"crazyflie) (got \"red\")"]


def test_missing_required_fields(tmp_path):
    file = write(tmp_path, """
        name: x
        robots:
          - count: 3
    """)
    assert error_of(file) == (f"{file}:4: robots[0].controller: is required: the robots' software, "
                              f"`controller: NAME` (one node) or `nodes: [{{node: NAME}}, …]` (only a model that "
                              f"flies may have none)")
    file = write(tmp_path, "name: x\n")
    assert error_of(file) == f"{file}: robots: is required"


def test_yaml_syntax_error_names_the_line(tmp_path):
    file = write(tmp_path, "name: x\nrobots:\n  - count: 3\n    controller: [flocking\n")
    message = error_of(file)
    assert message.startswith(f"{file}:5: not valid YAML: ")
    file = write(tmp_path, "name: x\n\tseed: 3\n")
    assert error_of(file).startswith(f"{file}:2: not valid YAML: ")


def test_python_tags_are_refused(tmp_path):
    file = write(tmp_path, "name: !!python/object/apply:os.getcwd []\nrobots: []\n")
    assert error_of(file).startswith(f"{file}:1: not valid YAML: could not determine a constructor")


@pytest.mark.parametrize("text, expected", [
    ("- 1\n- 2\n", ":1: the top level must be a mapping of world fields (name, seed, robots, "
                   "...), got a list [1, 2]"),
    ("just text\n", ':1: the top level must be a mapping of world fields (name, seed, robots, '
                    '...), got text "just text"'),
    ("", ": the world file is empty; it needs at least `robots:`"),
    ("# only a comment\n", ": the world file is empty; it needs at least `robots:`"),
])
def test_top_level_must_be_a_mapping(tmp_path, text, expected):
    file = write(tmp_path, text)
    assert error_of(file) == f"{file}{expected}"


def test_missing_and_unreadable_files(tmp_path):
    assert error_of(tmp_path / "nope.yaml") == f"{tmp_path / 'nope.yaml'}: no such world file"
    assert error_of(tmp_path) == f"{tmp_path}: is a directory, not a world file"
    binary = tmp_path / "b.yaml"
    binary.write_bytes(b"name: \xff\xfe\n")
    assert error_of(binary) == f"{binary}: not a UTF-8 text file (byte 0xff at offset 6)"


def test_file_without_read_permission(tmp_path, monkeypatch):
    # Faked: the tests may run as root, who can read any file.
    def refuse(path, *args, **kwargs):
        raise PermissionError(13, "Permission denied", path)
    monkeypatch.setattr("composed_sim.world.loader.open", refuse, raising=False)
    file = tmp_path / "w.yaml"
    assert error_of(file) == f"{file}: cannot read the world file: Permission denied"


def test_robot_names_must_not_collide(tmp_path):
    file = write(tmp_path, """
        robots:
          - {count: 11, controller: flocking}
          - {count: 1, controller: flocking, name_prefix: bot1}
    """)
    assert error_of(file) == (f"{file}:4: robots[1].name_prefix: robot name bot10 is also made "
                              f"by robots[0] (got \"bot1\")")


def test_overrides_are_validated_again(tmp_path):
    # bot0 and bot10 at first; with 40 robots the first group also makes bot10.
    file = write(tmp_path, """
        robots:
          - {count: 1, controller: flocking}
          - {count: 1, controller: flocking, name_prefix: bot1}
    """)
    assert error_of(file, robots=40) == (f"{file} (with --robots 40): robots[1].name_prefix: "
                                         f"robot name bot10 is also made by robots[0] (got \"bot1\")")


def test_world_from_dict_reports_paths_without_lines():
    with pytest.raises(WorldFileError) as info:
        world_from_dict({"robots": [{"count": -1, "controller": "c"}]}, source="run.json")
    assert str(info.value) == "run.json: robots[0].count: must be >= 0 (got -1)"
    with pytest.raises(WorldFileError, match=r"^<dict>:.*top level must be a mapping"):
        world_from_dict([1])


def test_merge_keys_and_aliases_keep_lines(tmp_path):
    file = write(tmp_path, """
        defaults: &group
          controller: flocking
          count: 4
        robots:
          - <<: *group
            count: -4
    """)
    assert f"{file}:2: defaults: unknown field" in error_of(file)
    assert f"{file}:7: robots[0].count: must be >= 0 (got -4)" in error_of(file)


# --- junk: the only exception ever raised is WorldFileError --------------------------------

FIELD_NAMES = ["name", "seed", "ticks_per_second", "length_ticks", "physics", "lockstep",
               "arena", "lights", "obstacles", "robots", "model", "count", "name_prefix",
               "controller", "params", "placement", "heading", "camera", "method", "center",
               "size", "density", "std_m", "spacing_m", "positions", "max_trials", "type",
               "position", "radius_m", "walls", "value_rad", "aperture_deg", "substeps"]
scalars = st.one_of(st.none(), st.booleans(), st.integers(), st.integers(-10, 10),
                    st.floats(), st.text(max_size=8), st.sampled_from(
                        ["box", "cylinder", "explicit", "grid", "foot-bot", "uniform"]))
keys = st.one_of(st.sampled_from(FIELD_NAMES), st.text(max_size=6), st.integers(-2, 2))
junk = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(keys, inner, max_size=5)), max_leaves=25)
YAMLISH = ["robots:", "\n", "  ", "- ", "count: ", ": ", "[", "]", "{", "}", ",", "&a ", "*a",
           "!!", "!!int ", "!!python/object ", "<<: ", "---\n", "...\n", "\t", "'", '"', "#",
           "3", "-1", ".nan", "1e9", "2021-02-30", "null", "yes", "controller: f",
           "placement:", "positions: ", "%YAML 1.1\n", "? ", "|", ">", "\x00", "é"]
yamlish = st.one_of(st.text(max_size=60),
                    st.lists(st.sampled_from(YAMLISH), max_size=30).map("".join))
overrides = st.one_of(st.none(), st.integers(-3, 50), st.text(max_size=3), st.floats(),
                      st.booleans())


VALID = yaml.safe_load(dump_world(load_world(WORLDS[0].parent / "flocking_walls.yaml")))


def load_or_world_file_error(loader, *args, **kwargs):
    try:
        assert isinstance(loader(*args, **kwargs), World)
    except WorldFileError as exc:
        assert str(exc)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("junk") / "junk.yaml"


@settings(max_examples=int(os.environ.get("JUNK_EXAMPLES", 300)), deadline=None)
@given(text=yamlish, robots=overrides, ticks=overrides, seed=overrides)
def test_junk_text_raises_only_world_file_errors(scratch, text, robots, ticks, seed):
    scratch.write_text(text, encoding="utf-8", errors="surrogatepass")
    load_or_world_file_error(load_world, scratch, robots=robots, ticks=ticks, seed=seed)


@settings(max_examples=int(os.environ.get("JUNK_EXAMPLES", 300)), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=junk)
def test_junk_data_raises_only_world_file_errors(scratch, data):
    load_or_world_file_error(world_from_dict, data)
    scratch.write_text(yaml.safe_dump(data))
    load_or_world_file_error(load_world, scratch)


@settings(max_examples=int(os.environ.get("JUNK_EXAMPLES", 300)), deadline=None)
@given(choices=st.data())
def test_junk_in_known_fields_raises_only_world_file_errors(scratch, choices):
    # A valid world with a few values, at random places, replaced by junk of any type.
    data = copy.deepcopy(VALID)
    for _ in range(choices.draw(st.integers(1, 3))):
        node = data
        while node:
            key = choices.draw(st.sampled_from(list(node) if isinstance(node, dict)
                                               else range(len(node))))
            child = node[key]
            if not isinstance(child, (dict, list)) or not child or choices.draw(st.booleans()):
                node[key] = choices.draw(junk)
                break
            node = child
    load_or_world_file_error(world_from_dict, data)
    scratch.write_text(yaml.safe_dump(data))
    load_or_world_file_error(load_world, scratch, robots=choices.draw(overrides))
