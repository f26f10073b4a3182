"""Importing ARGoS experiment files (.argos): mapping, distributions, warnings, safe XML. No ROS."""
import math
from pathlib import Path

import numpy as np
import pytest

from composed_sim.argos_import import (ArgosFileError, is_argos_file, load_argos, loads_argos,
                                       warning_text)
from composed_sim.core.placement import place_robots
from composed_sim.world.loader import WorldFileError, dump_world, load_world, with_overrides

ROOT = Path(__file__).resolve().parents[2]

CONTROLLER = """
  <controllers>
    <footbot_flocking_controller id="ffc" library="build/libfootbot_flocking">
      <actuators>
        <differential_steering implementation="default" />
        <leds implementation="default" medium="leds" />
      </actuators>
      <sensors>
        <footbot_light implementation="rot_z_only" show_rays="false" />
        <colored_blob_omnidirectional_camera implementation="rot_z_only" medium="leds" />
      </sensors>
      <params>
        <wheel_turning hard_turn_angle_threshold="80" soft_turn_angle_threshold="60"
                       no_turn_angle_threshold="5" max_speed="12" />
        <flocking target_distance="50" gain="900" exponent="3" />
      </params>
    </footbot_flocking_controller>
  </controllers>"""

ROBOTS = """
    <distribute>
      <position method="uniform" min="-1,-1,0" max="1,2,0" />
      <orientation method="uniform" min="0,0,0" max="360,0,0" />
      <entity quantity="5" max_trials="50">
        <foot-bot id="fb"><controller config="ffc" /></foot-bot>
      </entity>
    </distribute>"""


def argos(arena: str = ROBOTS, *, experiment: str = 'length="10" ticks_per_second="10" random_seed="7"',
          controllers: str = CONTROLLER, arena_attrs: str = 'size="10,10,1" center="0,0,0.5"',
          extra: str = "") -> str:
    return (f'<?xml version="1.0" ?>\n<argos-configuration>\n'
            f'  <framework>\n    <system threads="0" />\n    <experiment {experiment} />\n  </framework>'
            f'{controllers}\n  <arena {arena_attrs}>{arena}\n  </arena>{extra}\n</argos-configuration>\n')


def load(text: str, controller="flocking"):
    return loads_argos(text, controller=controller, source="t.argos")


def error(text: str, controller="flocking") -> str:
    with pytest.raises(ArgosFileError) as info:
        load(text, controller)
    return str(info.value)


def line_of(text: str, needle: str) -> int:
    return text[:text.index(needle)].count("\n") + 1


# --- the shipped experiment ----------------------------------------------------------------

def test_shipped_flocking_experiment_maps_to_the_paper_world():
    world, warnings = load_argos(ROOT / "worlds" / "flocking.argos", controller="flocking")
    assert warnings == []
    assert (world.ticks_per_second, world.length_ticks, world.seed) == (10, 600, 1)
    assert world.physics.substeps == 10
    (light,) = world.lights
    assert light.position == (0.0, 10.0) and light.height_m == 0.5 and light.intensity == 3.0
    assert light.color == (255, 255, 0)
    (group,) = world.robots
    assert (group.count, group.name_prefix, group.controller) == (30, "bot", "flocking")
    assert group.placement.method == "uniform" and group.placement.max_trials == 100
    assert group.placement.center == pytest.approx((0.0, 4.0))
    assert group.placement.size == pytest.approx((2.4494, 2.4494))          # 30 robots at 5 /m^2
    assert group.heading.method == "uniform" and group.camera.aperture_deg == 80.0
    yaml_world = load_world(ROOT / "worlds" / "flocking.yaml")
    assert group.params == yaml_world.robots[0].params    # the same controller parameters
    assert world.lights == yaml_world.lights


def test_shipped_flocking_experiment_runs_with_the_plugin_that_ports_it():
    world, warnings = load_argos(ROOT / "worlds" / "flocking.argos")
    assert world.robots[0].controller == "flocking"
    assert any('runs with the installed plugin "flocking"' in w for w in warnings)


def test_a_controller_no_plugin_ports_needs_a_choice():
    text = argos(ROBOTS).replace("footbot_flocking_controller", "my_controller")
    message = error(text, controller=None)
    assert "--controller" in message and "ffc" in message and "no installed plugin ports" in message


def test_imported_world_round_trips_and_places_its_robots(tmp_path):
    from composed_sim.core.simulation import Simulation
    world, _ = load_argos(ROOT / "worlds" / "flocking.argos", controller="flocking")
    (tmp_path / "w.yaml").write_text(dump_world(world))
    assert load_world(tmp_path / "w.yaml") == world
    sim = Simulation(with_overrides(world, robots=12))
    assert sim.n == 12


def test_is_argos_file():
    assert is_argos_file("x/EXP.argos") and not is_argos_file("worlds/flocking.yaml")


# --- elements ------------------------------------------------------------------------------

def test_framework_arena_obstacles_and_lights_map_right():
    world, warnings = load(argos(ROBOTS + """
    <box id="b" size="2,0.2,0.4" movable="false"><body position="1,2,0" orientation="30,0,0" /></box>
    <cylinder id="c" radius="0.25" height="0.6" movable="false"><body position="-2,-3,0" /></cylinder>
    <light id="l1" position="1,4,0.75" orientation="0,0,0" color="orange" intensity="2.5" medium="leds" />
    <light id="l2" position="0,0,0" color="10,20,30,255" />""",
        experiment='length="12.5" ticks_per_second="4" random_seed="99"',
        arena_attrs='size="12,10,2" center="1,-1,1"'))
    assert warnings == []
    assert (world.ticks_per_second, world.length_ticks, world.seed) == (4, 50, 99)
    assert world.arena.size == (12.0, 10.0) and world.arena.center == (1.0, -1.0)
    assert not world.arena.walls
    box, cylinder = world.obstacles
    assert box.type == "box" and box.position == (1.0, 2.0) and box.size == (2.0, 0.2)
    assert box.height_m == 0.4 and box.yaw_rad == pytest.approx(math.radians(30))
    assert cylinder.position == (-2.0, -3.0) and cylinder.radius_m == 0.25 and cylinder.height_m == 0.6
    l1, l2 = world.lights
    assert l1.position == (1.0, 4.0) and l1.height_m == 0.75 and l1.intensity == 2.5
    assert l1.color == (255, 140, 0) and l2.color == (10, 20, 30) and l2.intensity == 1.0


def test_flocking_params_convert_from_cm_and_degrees():
    world, _ = load(argos())
    assert world.robots[0].params == {
        "target_distance_m": 0.5, "gain": 900.0, "exponent": 3.0, "max_speed_mps": 0.12,
        "hard_turn_deg": 80.0, "soft_turn_deg": 60.0, "no_turn_deg": 5.0}


def test_controller_from_params_plugin_mapping_and_pass_through_params():
    controllers = """
  <controllers>
    <footbot_diffusion_controller id="fdc" library="libfootbot_diffusion.so">
      <actuators><differential_steering implementation="default" /></actuators>
      <sensors><footbot_proximity implementation="default" show_rays="true" /></sensors>
      <params plugin="diffusion" alpha="7.5" delta="0.1" velocity="5" mode="fast">
        <wheels max="10" />
      </params>
    </footbot_diffusion_controller>
  </controllers>"""
    robots = ROBOTS.replace('config="ffc"', 'config="fdc"')
    world, warnings = load(argos(robots, controllers=controllers), controller=None)
    (group,) = world.robots
    # The diffusion plugin declares its port of footbot_diffusion: units converted, the rest listed.
    assert group.controller == "diffusion"
    assert group.params == pytest.approx({"alpha_deg": 7.5, "delta": 0.1, "speed_mps": 0.05})
    assert [w.split(": ", 1)[1] for w in warnings] == [
        'params: 2 ARGoS parameters dropped (no counterpart in the plugin "diffusion"): mode, wheels.max']
    # --controller names a plugin that ports no ARGoS controller: the <params> (written for the
    # diffusion plugin) are not its own, so it runs with its defaults and the drop is one warning.
    dropped, warnings = load(argos(robots, controllers=controllers), controller="aggregation")
    assert dropped.robots[0].params == {}
    assert [w.split(": ", 1)[1] for w in warnings if "params" in w] == [
        "params: 5 ARGoS parameters dropped (footbot_diffusion_controller's; the plugin \"aggregation\" runs with "
        "its own defaults): alpha, delta, velocity, mode, wheels.max"]
    # <params plugin="NAME"> naming the plugin that runs: written for it, passed on unchanged.
    own = controllers.replace('plugin="diffusion"', 'plugin="aggregation"')
    passed, _ = load(argos(robots, controllers=own), controller="aggregation")
    assert passed.robots[0].params == {"alpha": 7.5, "delta": 0.1, "velocity": 5, "mode": "fast",
                                       "wheels.max": 10}
    mapped, _ = load(argos(robots, controllers=controllers), controller={"fdc": "plain"})
    assert mapped.robots[0].controller == "plain"
    by_tag, _ = load(argos(robots, controllers=controllers),
                     controller={"footbot_diffusion_controller": "other"})
    assert by_tag.robots[0].controller == "other"


def test_explicit_foot_bots_become_explicit_groups():
    text = argos("""
    <foot-bot id="fb0" omnidirectional_camera_aperture="75">
      <body position="1,1,0" orientation="90,0,0" /><controller config="ffc" />
    </foot-bot>
    <foot-bot id="fb1" omnidirectional_camera_aperture="75">
      <body position="2,1,0" orientation="90,0,0" /><controller config="ffc" />
    </foot-bot>
    <foot-bot id="leader">
      <body position="0,-2,0" orientation="-45,0,0" /><controller config="ffc" />
    </foot-bot>""" + ROBOTS)
    world, warnings = load(text)
    first, leader, distributed = world.robots
    assert first.count == 2 and first.name_prefix == "fb" and first.camera.aperture_deg == 75
    assert first.placement.method == "explicit" and first.placement.positions == [(1.0, 1.0), (2.0, 1.0)]
    assert first.heading.method == "constant" and first.heading.value_rad == pytest.approx(math.pi / 2)
    assert leader.placement.positions == [(0.0, -2.0)]
    assert leader.heading.value_rad == pytest.approx(-math.pi / 4)
    assert world.robot_names()[:3] == ["fb0", "fb1", "leader0"]
    # The distributed "fb" robots continue the numbering after the explicit ones.
    assert world.robot_names()[3:] == [f"fb{i}" for i in range(2, 7)] and distributed.count == 5
    leader_line = line_of(text, '<foot-bot id="leader"')
    assert [w for w in warnings if "leader" in w] == [
        f't.argos:{leader_line}: foot-bot/id: "leader" is named leader0 here '
        f"(robot names are a prefix and a running number)"]


# --- <distribute> ----------------------------------------------------------------------------

def distribute(position: str, orientation: str = '<orientation method="constant" values="0,0,0" />',
               quantity: int = 6, entity: str = '<foot-bot id="fb"><controller config="ffc" /></foot-bot>') -> str:
    return argos(f"""
    <distribute>
      {position}
      {orientation}
      <entity quantity="{quantity}" max_trials="20">{entity}</entity>
    </distribute>""")


def test_distribute_uniform_is_exact():
    world, _ = load(distribute('<position method="uniform" min="-2,1,0" max="3,2,0" />'))
    p = world.robots[0].placement
    assert (p.method, p.center, p.size, p.max_trials) == ("uniform", (0.5, 1.5), (5.0, 1.0), 20)


def test_distribute_gaussian_position_and_anisotropic_warning():
    world, warnings = load(distribute('<position method="gaussian" mean="1,2,0" std_dev="0.5,0.5,0" />'))
    p = world.robots[0].placement
    assert (p.method, p.center, p.std_m) == ("gaussian", (1.0, 2.0), 0.5) and warnings == []
    world, warnings = load(distribute('<position method="gaussian" mean="1,2,0" std_dev="0.5,2,0" />'))
    assert world.robots[0].placement.std_m == pytest.approx(1.0)
    assert len(warnings) == 1 and "position/std_dev" in warnings[0] and "geometric mean" in warnings[0]


def test_distribute_constant_position_one_robot_or_an_error():
    world, _ = load(distribute('<position method="constant" values="1.5,-2,0" />', quantity=1))
    assert world.robots[0].placement.positions == [(1.5, -2.0)]
    text = distribute('<position method="constant" values="1.5,-2,0" />', quantity=3)
    message = error(text)
    assert message.startswith(f"t.argos:{line_of(text, '<position method')}: position/values: ")
    assert 'never be placed' in message and '(got "1.5,-2,0")' in message


def test_distribute_grid_matches_argos_generator_order():
    world, _ = load(distribute('<position method="grid" center="1,1,0" distances="0.5,0.4,0" '
                               'layout="3,2,1" />', quantity=5))
    # ARGoS: x = cx + (nx-1)*dx/2 - (i % nx)*dx, y = cy + (ny-1)*dy/2 - (i // nx % ny)*dy
    positions = [c for p in world.robots[0].placement.positions for c in p]
    assert positions == pytest.approx([1.5, 1.2, 1.0, 1.2, 0.5, 1.2, 1.5, 0.8, 1.0, 0.8])
    message = error(distribute('<position method="grid" center="0,0,0" distances="1,1,0" '
                               'layout="2,2,1" />', quantity=5))
    assert "position/layout" in message and "fewer than the quantity 5" in message


@pytest.mark.parametrize("orientation, expected", [
    ('<orientation method="constant" values="90,0,0" />', ("constant", math.pi / 2, None)),
    ('<orientation method="gaussian" mean="10,0,0" std_dev="360,0,0" />',
     ("gaussian", math.radians(10), 2 * math.pi)),
    ('<orientation method="uniform" min="-180,0,0" max="180,0,0" />', ("uniform", None, None)),
    ('<orientation method="uniform" min="45,0,0" max="45,0,0" />', ("constant", math.pi / 4, None)),
])
def test_distribute_orientations(orientation, expected):
    world, warnings = load(distribute('<position method="uniform" min="0,0,0" max="3,3,0" />', orientation))
    heading = world.robots[0].heading
    method, value, std = expected
    assert heading.method == method and warnings == []
    if value is not None:
        assert heading.value_rad == pytest.approx(value)
    if std is not None:
        assert heading.std_rad == pytest.approx(std)


def test_partial_uniform_orientation_is_uniform_over_its_range():
    world, warnings = load(distribute('<position method="uniform" min="0,0,0" max="3,3,0" />',
                                      '<orientation method="uniform" min="30,0,0" max="90,0,0" />'))
    h = world.robots[0].heading
    assert h.method == "uniform" and h.range_rad == pytest.approx((math.pi / 6, math.pi / 2))
    assert warnings == []
    _, headings = place_robots(world, np.random.default_rng(3))
    assert ((headings >= math.pi / 6) & (headings <= math.pi / 2)).all()


def test_distributed_obstacles_are_drawn_once_from_the_seed():
    boxes = distribute('<position method="uniform" min="-4,-4,0" max="4,4,0" />',
                       '<orientation method="uniform" min="0,0,0" max="360,0,0" />', quantity=8,
                       entity='<box id="b" size="0.3,0.3,0.5" movable="false" />')
    text = boxes.replace("</arena>", ROBOTS + "\n  </arena>")
    world, warnings = load(text)
    assert len(world.obstacles) == 8 and warnings == []
    assert all(-4 <= b.position[0] <= 4 and -4 <= b.position[1] <= 4 for b in world.obstacles)
    assert load(text)[0].obstacles == world.obstacles                  # same seed, same obstacles
    other = load(text.replace('random_seed="7"', 'random_seed="8"'))[0]
    assert other.obstacles != world.obstacles


# --- warnings for what is not simulated -----------------------------------------------------

def test_unsupported_elements_and_attributes_are_listed_not_dropped():
    controllers = CONTROLLER.replace(
        "<footbot_light", '<range_and_bearing implementation="medium" medium="rab" />\n        <footbot_light')
    text = argos(ROBOTS.replace('<foot-bot id="fb">', '<foot-bot id="fb" rab_range="3">') + """
    <floor id="floor" source="loop_functions" pixels_per_meter="50" />
    <e-puck id="ep0"><body position="0,0,0" orientation="0,0,0" /><controller config="ffc" /></e-puck>
    <box id="m" size="1,1,1" movable="true" mass="2"><body position="3,3,0" /></box>""",
                 controllers=controllers, extra="""
  <loop_functions library="liblf" label="lf" />
  <physics_engines><dynamics3d id="dyn3d" /></physics_engines>
  <media><led id="leds" /><range_and_bearing id="rab" /><tag id="tags" /></media>""")
    world, warnings = load(text)
    assert world.robot_count == 6 and len(world.obstacles) == 1
    assert world.robots[-1].model == "e-puck"
    assert world.robots[0].devices.range_and_bearing.range_m == 3.0
    assert world.obstacles[0].movable and world.obstacles[0].mass_kg == 2.0   # imported, not a warning
    expected = {
        "floor": "<floor",
        "e-puck": "<e-puck",
        "loop_functions": "<loop_functions",
        "physics_engines/dynamics3d": "<dynamics3d",
        "media/tag": '<tag id="tags"',
    }
    for what, needle in expected.items():
        hits = [w for w in warnings if f": {what}: " in w]
        assert hits, f"no warning for {what}: {warnings}"
        assert hits[0].startswith(f"t.argos:{line_of(text, needle)}: "), hits[0]
    assert {w.split(": ")[1] for w in warnings} == set(expected)
    text_block = warning_text("t.argos", warnings)
    assert text_block.startswith(f"t.argos: {len(warnings)} ARGoS settings not simulated as written:")
    assert text_block.count("\n  ") == len(warnings)
    assert warning_text("t.argos", []) is None


def test_length_zero_and_seed_zero_are_warned():
    world, warnings = load(argos(experiment='length="0" ticks_per_second="10" random_seed="0"'))
    assert world.length_ticks == 600 and world.seed == 0
    assert [w.split(": ")[1] for w in warnings] == ["experiment/length", "experiment/random_seed"]


# --- errors: malformed, unsafe, bad values --------------------------------------------------

def test_malformed_xml_names_the_line():
    text = argos().replace('<arena size="10,10,1"', '<arena size="10,10,1" size="1"', 1)
    message = error(text)
    assert message.startswith(f"t.argos:{line_of(text, '<arena')}: not well-formed XML: duplicate attribute")
    message = error("<argos-configuration>\n  <framework>\n</argos-configuration>\n")
    assert message.startswith("t.argos:3: not well-formed XML: mismatched tag")


@pytest.mark.parametrize("attack", [
    # billion laughs: entity expansion
    '<?xml version="1.0"?>\n<!DOCTYPE lolz [\n <!ENTITY lol "lol">\n <!ENTITY lol2 "&lol;&lol;">\n]>\n'
    '<argos-configuration>&lol2;</argos-configuration>\n',
    # external entity (file disclosure)
    '<?xml version="1.0"?>\n<!DOCTYPE x [ <!ENTITY xxe SYSTEM "file:///etc/passwd"> ]>\n'
    '<argos-configuration>&xxe;</argos-configuration>\n',
    # a bare DOCTYPE with an external DTD
    '<?xml version="1.0"?>\n<!DOCTYPE argos-configuration SYSTEM "http://example.com/a.dtd">\n'
    '<argos-configuration/>\n',
])
def test_doctype_and_entities_are_refused_with_a_line(attack):
    message = error(attack)
    assert message.startswith("t.argos:2: unsafe XML: a DOCTYPE (DTD) is not accepted")


def test_undeclared_entity_is_an_error_with_its_line():
    text = argos().replace('<system threads="0" />', '<system threads="&bomb;" />')
    message = error(text)
    assert message.startswith(f"t.argos:{line_of(text, '<system')}: not well-formed XML: undefined entity")


@pytest.mark.parametrize("old, new, what, needle", [
    ('size="2,0.2,0.4"', 'size="2,0.2"', 'box/size: must be three positive numbers "x,y,z" in m '
     '(got "2,0.2")', "<box"),
    ('size="2,0.2,0.4"', 'size="2,-1,0.4"', "box/size: must be three positive numbers", "<box"),
    ('radius="0.25"', 'radius="wide"', 'cylinder/radius: must be a positive number (m) (got "wide")',
     "<cylinder"),
    ('intensity="2.5"', 'intensity="-1"', 'light/intensity: must be a number >= 0 (got "-1")', "<light"),
    ('color="orange"', 'color="chartreuse"', "light/color: must be a colour name", "<light"),
    ('ticks_per_second="10"', 'ticks_per_second="ten"',
     'experiment/ticks_per_second: must be a whole number >= 1 (got "ten")', "<experiment"),
    ('config="ffc"', 'config="nope"', 'controller/config: no controller with this id in <controllers> '
     '(defined: ffc) (got "nope")', '<controller config="nope"'),
    ('max="1,2,0"', 'max="-3,2,0"', 'position/min: must not exceed max in any coordinate', "<position"),
    ('method="uniform" min="0,0,0" max="360,0,0"', 'method="spiral"',
     'orientation/method: must be uniform, gaussian, constant or grid (got "spiral")', "<orientation"),
    ('target_distance="50"', 'target_distance="far"', "flocking/target_distance: must be a number",
     "<flocking"),
    ('<foot-bot id="fb">', '<foot-bot id="fb" omnidirectional_camera_aperture="95">',
     'foot-bot/omnidirectional_camera_aperture: must be below 90 degrees (got "95")', "<foot-bot"),
])
def test_bad_values_name_element_attribute_and_line(old, new, what, needle):
    base = argos(ROBOTS.replace('max="360,0,0"', 'max="360,0,0"') + """
    <box id="b" size="2,0.2,0.4"><body position="1,2,0" /></box>
    <cylinder id="c" radius="0.25" height="0.6"><body position="-2,-3,0" /></cylinder>
    <light id="l1" position="1,4,0.75" color="orange" intensity="2.5" />""")
    assert old in base
    text = base.replace(old, new, 1)
    message = error(text)
    assert message.startswith(f"t.argos:{line_of(text, needle)}: {what}"), message


def test_schema_problems_point_at_the_argos_line():
    text = argos(ROBOTS + '\n    <light id="far" position="40,0,0.5" />')
    message = error(text)
    assert message.startswith(f"t.argos:{line_of(text, '<light')}: lights[0].position: outside the arena")


def test_missing_pieces_and_wrong_root():
    assert "root element" in error("<config/>")
    assert "needs an <arena>" in error(argos().split("  <arena")[0] + "</argos-configuration>")
    assert "has no robot we simulate" in error(argos(""))
    assert "no such ARGoS file" in str(pytest.raises(ArgosFileError, load_argos, "/nonexistent.argos").value)


def test_argos_errors_are_world_file_errors():
    assert issubclass(ArgosFileError, WorldFileError)
