"""ARGoS experiment files run as ARGoS runs them: every ported controller and every robot entity
through a real run, placement without overlaps (1000 robots), and what the user is told."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from composed_sim.argos_import import ArgosFileError, load_argos, loads_argos
from composed_sim.core.placement import place_robots
from composed_sim.core.seeding import STREAM_PLACEMENT, stream
from composed_sim.world.loader import load_world
from composed_sim.world.robot_models import get_model
from composed_sim.world.schema import Box

ROOT = Path(__file__).resolve().parents[2]

WALLS = """
    <box id="wall_north" size="4,0.1,0.5" movable="false"><body position="0,2,0" orientation="0,0,0" /></box>
    <box id="wall_south" size="4,0.1,0.5" movable="false"><body position="0,-2,0" orientation="0,0,0" /></box>
    <box id="wall_east" size="0.1,4,0.5" movable="false"><body position="2,0,0" orientation="0,0,0" /></box>
    <box id="wall_west" size="0.1,4,0.5" movable="false"><body position="-2,0,0" orientation="0,0,0" /></box>"""

# One controller of each ported kind, as the ARGoS examples write them (units: cm, cm/s, degrees).
CONTROLLERS = """
  <controllers>
    <footbot_diffusion_controller id="fdc" library="libfootbot_diffusion">
      <actuators><differential_steering implementation="default" /></actuators>
      <sensors><footbot_proximity implementation="default" show_rays="true" noise_level="0.05" /></sensors>
      <params alpha="7.5" delta="0.1" velocity="5" />
    </footbot_diffusion_controller>
    <footbot_flocking_controller id="ffc" library="libfootbot_flocking">
      <actuators><differential_steering implementation="default" /><leds implementation="default" medium="leds" /></actuators>
      <sensors>
        <footbot_light implementation="rot_z_only" show_rays="false" />
        <colored_blob_omnidirectional_camera implementation="rot_z_only" medium="leds" />
      </sensors>
      <params>
        <wheel_turning hard_turn_angle_threshold="90" soft_turn_angle_threshold="70" no_turn_angle_threshold="10" max_speed="10" />
        <flocking target_distance="75" gain="1000" exponent="2" />
      </params>
    </footbot_flocking_controller>
    <footbot_synchronization_controller id="fsc" library="libfootbot_synchronization">
      <actuators><leds implementation="default" medium="leds" /></actuators>
      <sensors><colored_blob_omnidirectional_camera implementation="rot_z_only" medium="leds" /></sensors>
      <params />
    </footbot_synchronization_controller>
    <epuck_obstacleavoidance_controller id="eoa" library="libepuck_obstacleavoidance">
      <actuators><differential_steering implementation="default" /></actuators>
      <sensors><proximity implementation="default" show_rays="true" /></sensors>
      <params velocity="5" />
    </epuck_obstacleavoidance_controller>
    <footbot_foraging_controller id="ffo" library="libfootbot_foraging">
      <actuators><differential_steering implementation="default" /><leds implementation="default" medium="leds" /></actuators>
      <sensors>
        <footbot_proximity implementation="default" />
        <footbot_light implementation="rot_z_only" />
        <footbot_motor_ground implementation="rot_z_only" />
      </sensors>
      <params><wheel_turning max_speed="8" /><state minimum_resting_time="50" /></params>
    </footbot_foraging_controller>
    <footbot_diffusion_controller id="kdc" library="libkheperaiv_diffusion">
      <actuators><differential_steering implementation="default" /><leds implementation="default" medium="leds" /></actuators>
      <sensors>
        <kheperaiv_proximity implementation="default" show_rays="true" />
        <kheperaiv_lidar implementation="default" num_readings="100" />
        <kheperaiv_ultrasound implementation="default" />
      </sensors>
      <params alpha="7.5" delta="0.1" velocity="5" />
    </footbot_diffusion_controller>
  </controllers>"""


def experiment(arena: str, *, length: str = "1", controllers: str = CONTROLLERS, extra: str = "") -> str:
    return (f'<?xml version="1.0" ?>\n<argos-configuration>\n  <framework>\n'
            f'    <experiment length="{length}" ticks_per_second="10" random_seed="124" />\n  </framework>'
            f'{controllers}{extra}\n  <arena size="5,5,1" center="0,0,0.5">{WALLS}{arena}\n  </arena>\n'
            f'</argos-configuration>\n')


def distribute(entity: str, quantity: int, low: str = "-2,-2,0", high: str = "2,2,0") -> str:
    return f"""
    <distribute>
      <position method="uniform" min="{low}" max="{high}" />
      <orientation method="uniform" min="0,0,0" max="360,0,0" />
      <entity quantity="{quantity}" max_trials="100">{entity}</entity>
    </distribute>"""


def cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "composed_sim.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_every_ported_controller_and_robot_entity_runs(tmp_path):
    arena = (distribute('<foot-bot id="fd"><controller config="fdc" /></foot-bot>', 3, "-1.8,-1.8,0", "0,0,0")
             + distribute('<foot-bot id="ff"><controller config="ffc" /></foot-bot>', 3, "0,0,0", "1.8,1.8,0")
             + """
    <foot-bot id="fs0" rab_range="2" rab_data_size="4"><body position="-1.5,1.5,0" orientation="0,0,0" /><controller config="fsc" /></foot-bot>
    <foot-bot id="fs1"><body position="-1.2,1.5,0" orientation="0,0,0" /><controller config="fsc" /></foot-bot>
    <light id="light" position="1.5,-1.5,0.5" orientation="0,0,0" color="yellow" intensity="3.0" />"""
             + distribute('<e-puck id="ep"><controller config="eoa" /></e-puck>', 3, "0.2,-1.8,0", "1.8,-0.2,0")
             + distribute('<foot-bot id="fo"><controller config="ffo" /></foot-bot>', 2, "-1.8,0.2,0", "-0.2,1.8,0")
             + """
    <kheperaiv id="kh0"><body position="-1.5,-0.3,0" orientation="90,0,0" /><controller config="kdc" /></kheperaiv>"""
             + distribute('<cylinder id="c" height="0.5" radius="0.1" movable="false" />', 3)
             + distribute('<box id="b" size="0.2,0.2,0.5" movable="false" />', 3))
    path = tmp_path / "all.argos"
    path.write_text(experiment(arena, length="1.5"))
    out = tmp_path / "out"
    r = cli("run", path, "--out", out, "--no-progress", "--no-picture", "--json")
    assert r.returncode == 0, r.stderr[-3000:]
    for plugin in ("diffusion", "flocking", "firefly", "epuck-obstacle-avoidance", "foraging"):
        assert f'runs with the installed plugin "{plugin}"' in r.stderr, r.stderr
    summary = json.loads(r.stdout)
    assert summary["ticks"] == 15 and summary["robots"] == 14 and summary["violations"] == 0
    for omitted in ("1 ARGoS parameter dropped (no counterpart in the plugin \"foraging\"): state.minimum_resting_time",
                    "kheperaiv_ultrasound: sensor of controller kdc is not simulated",
                    "kheperaiv_lidar/num_readings: not simulated"):
        assert omitted in r.stderr
    world = load_world(out / "world.yaml")
    by_model = {g.model: g for g in world.robots}
    assert by_model["kheperaiv"].devices.lidar is not None
    assert by_model["e-puck"].params == {"speed_mps": pytest.approx(0.05)}
    assert world.robots[1].params["target_distance_m"] == pytest.approx(0.75)
    (foraging,) = [g for g in world.robots if g.controller == "foraging"]
    assert foraging.params == {"speed_mps": pytest.approx(0.08)} and foraging.devices.ground is not None
    with np.load(out / "trajectories.npz") as t:
        moved = np.linalg.norm(t["positions"][-1] - t["positions"][0], axis=1)
    # Diffusion and the e-pucks drive at 5 cm/s for 1.5 s; the fireflies stand still.
    # (order: 3 diffusion, 3 flocking, 2 fireflies, 3 e-pucks, 2 foraging, 1 Khepera IV)
    assert (moved[:3] > 0.02).all() and (moved[8:] > 0.02).all() and (moved[6:8] < 1e-6).all()


def _box_corners(box: Box) -> np.ndarray:
    c, s = np.cos(box.yaw_rad), np.sin(box.yaw_rad)
    hx, hy = np.asarray(box.size) / 2
    local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    return local @ np.array([[c, s], [-s, c]]) + box.position


def _disc_box_gap(center, radius, box: Box) -> float:
    c, s = np.cos(box.yaw_rad), np.sin(box.yaw_rad)
    rel = np.asarray(center) - box.position
    local = np.array([c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1]])
    return float(np.linalg.norm(np.maximum(np.abs(local) - np.asarray(box.size) / 2, 0))) - radius


def _boxes_overlap(a: Box, b: Box) -> bool:
    """Separating axis test of two rotated rectangles."""
    ca, cb = _box_corners(a), _box_corners(b)
    for corners in (ca, cb):
        for i in range(2):
            axis = corners[i + 1] - corners[i]
            pa, pb = ca @ axis, cb @ axis
            if pa.max() <= pb.min() or pb.max() <= pa.min():
                return False
    return True


def _shapes_overlap(a, b) -> bool:
    if isinstance(a, Box) and isinstance(b, Box):
        return _boxes_overlap(a, b)
    if isinstance(a, Box) or isinstance(b, Box):
        box, disc = (a, b) if isinstance(a, Box) else (b, a)
        return _disc_box_gap(disc.position, disc.radius_m, box) < 0
    return np.hypot(*np.subtract(a.position, b.position)) < a.radius_m + b.radius_m


def test_a_thousand_robots_and_distributed_obstacles_start_without_overlap():
    arena = (distribute('<box id="b" size="0.3,0.3,0.5" movable="false" />', 30)
             + distribute('<cylinder id="c" height="0.5" radius="0.15" movable="false" />', 30)
             + distribute('<foot-bot id="fb"><controller config="fdc" /></foot-bot>', 1000)
             .replace('"-2,-2,0"', '"-20,-20,0"').replace('"2,2,0"', '"20,20,0"'))
    text = experiment(arena).replace('size="5,5,1"', 'size="45,45,1"')
    text = text.replace('size="4,0.1,0.5"', 'size="40,0.1,0.5"').replace('size="0.1,4,0.5"', 'size="0.1,40,0.5"')
    for old, new in (('"0,2,0"', '"0,20,0"'), ('"0,-2,0"', '"0,-20,0"'), ('"2,0,0"', '"20,0,0"'), ('"-2,0,0"', '"-20,0,0"')):
        text = text.replace(old, new, 1)
    world, _ = loads_argos(text, source="t.argos")
    walls, placed = world.obstacles[:4], world.obstacles[4:]
    assert len(placed) == 60 and world.robot_count == 1000
    for i, a in enumerate(placed):       # every distributed obstacle against everything before it
        for b in walls + placed[:i]:
            assert not _shapes_overlap(a, b), (a, b)
    positions, _ = place_robots(world, stream(world.seed, STREAM_PLACEMENT))
    radius = get_model("foot-bot").body_radius_m
    d = np.linalg.norm(positions[:, None] - positions[None], axis=2) + np.eye(len(positions)) * 9
    assert d.min() >= 2 * radius
    for o in world.obstacles:
        if isinstance(o, Box):
            gaps = [_disc_box_gap(p, radius, o) for p in positions]
        else:
            gaps = np.linalg.norm(positions - o.position, axis=1) - radius - o.radius_m
        assert min(gaps) >= 0


def test_an_obstacle_that_cannot_be_placed_fails_like_argos():
    arena = distribute('<cylinder id="c" height="0.5" radius="0.4" movable="false" />', 40)
    with pytest.raises(ArgosFileError) as info:
        loads_argos(experiment(arena), source="t.argos")
    message = str(info.value)
    line = experiment(arena)[:experiment(arena).index("<cylinder")].count("\n") + 1
    assert message.startswith(f"t.argos:{line}: distribute/cylinder: could place only ")
    assert "max_trials = 100" in message


def test_devices_map_with_their_parameters_and_the_rest_is_not_simulated():
    controllers = CONTROLLERS.replace(
        '<sensors><footbot_proximity implementation="default" show_rays="true" noise_level="0.05" /></sensors>',
        """<sensors>
        <footbot_proximity implementation="default" noise_level="0.05" />
        <footbot_motor_ground implementation="rot_z_only" noise_level="0.1" />
        <range_and_bearing implementation="medium" medium="rab" noise_std="2" packet_drop_prob="0.25" />
        <footbot_distance_scanner implementation="rot_z_only" />
      </sensors>""").replace('<actuators><differential_steering implementation="default" /></actuators>',
                             '<actuators><differential_steering implementation="default" />'
                             '<footbot_gripper implementation="default" /></actuators>', 1)
    arena = '\n    <foot-bot id="fb0" rab_range="1.5"><body position="0,0,0" /><controller config="fdc" /></foot-bot>'
    text = experiment(arena, controllers=controllers)
    world, warnings = loads_argos(text, source="t.argos")
    devices = world.robots[0].devices
    assert devices.proximity.noise == 0.05 and devices.ground.noise == 0.1
    rab = devices.range_and_bearing
    assert (rab.range_m, rab.noise_std_m, rab.packet_drop_probability) == (1.5, 0.02, 0.25)
    not_simulated = sorted(w.split(": ")[1] for w in warnings if "is not simulated" in w)
    assert not_simulated == ["footbot_distance_scanner", "footbot_gripper"]


def test_a_failed_import_says_why_first_then_every_warning_and_writes_nothing(tmp_path):
    text = experiment("", length="0", extra='\n  <loop_functions library="liblf" label="lf" />')
    path = tmp_path / "loops.argos"
    path.write_text(text)
    r = cli("run", path, "--ticks", 3, "--out", tmp_path / "out", "--no-progress")
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert lines[0].startswith(f"composed-sim: error: {path}:") and "loop functions" in lines[0]
    assert lines[1].startswith("composed-sim: warning:")
    assert any("--ticks 3 are run" in line for line in lines) and any("loop_functions:" in line for line in lines)
    assert not (tmp_path / "out").exists()


def test_an_image_floor_is_stretched_over_the_arena_and_a_loop_functions_floor_is_warned(tmp_path):
    import imageio.v3 as iio
    iio.imwrite(tmp_path / "floor.png", np.full((20, 20), 128, np.uint8))
    robot = '\n    <foot-bot id="fb0"><body position="0,0,0" /><controller config="fdc" /></foot-bot>'
    path = tmp_path / "f.argos"
    path.write_text(experiment('\n    <floor id="f" source="image" path="floor.png" pixels_per_meter="50" />' + robot))
    world, _ = load_argos(path)
    assert world.floor.image == str(tmp_path / "floor.png") and world.floor.image_size_m == (5.0, 5.0)
    text = experiment('\n    <floor id="f" source="loop_functions" pixels_per_meter="50" />' + robot)
    _, warnings = loads_argos(text, source="t.argos")
    assert any(": floor: painted by the loop functions" in w for w in warnings)


FLOCKING_PARAMS = ("wheel_turning.hard_turn_angle_threshold, wheel_turning.soft_turn_angle_threshold, "
                   "wheel_turning.no_turn_angle_threshold, wheel_turning.max_speed, flocking.target_distance, "
                   "flocking.gain, flocking.exponent")


@pytest.mark.parametrize("plugin", ["diffusion", "aggregation"])   # a port of another controller; no port
def test_another_controller_on_the_shipped_flocking_argos_runs_with_its_defaults(tmp_path, plugin):
    """--controller NAME on a real .argos file whose <params> are footbot_flocking's: the run goes on
    with the plugin's defaults, and one warning line lists what was dropped."""
    out = tmp_path / "out"
    r = cli("run", ROOT / "worlds" / "flocking.argos", "--controller", plugin, "--robots", 4, "--ticks", 3,
            "--no-progress", "--no-picture", "--out", out)
    assert r.returncode == 0, r.stderr[-3000:]
    dropped = [line.strip() for line in r.stderr.splitlines() if "dropped" in line]
    assert dropped == [f"{ROOT / 'worlds' / 'flocking.argos'}:38: params: 7 ARGoS parameters dropped "
                       f"(footbot_flocking_controller's; the plugin \"{plugin}\" runs with its own defaults): "
                       f"{FLOCKING_PARAMS}"]
    (group,) = load_world(out / "world.yaml").robots
    assert (group.controller, group.params) == (plugin, {})
