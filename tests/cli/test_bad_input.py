"""Bad input on the command line: one message naming the file, line, field and value, exit code
2, never a traceback (loader-level cases in tests/world/test_loader.py)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import install_plugin

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"


def world_with(tmp_path, **changes) -> Path:
    """worlds/flocking.yaml with fields changed; keys are paths with "__" between the parts,
    e.g. robots__0__count (the file is rewritten, so lines are the new file's)."""
    data = yaml.safe_load(FLOCKING.read_text())
    for key, value in changes.items():
        *parents, last = [int(k) if k.isdigit() else k for k in key.split("__")]
        target = data
        for k in parents:
            target = target[k]
        target[last] = value
    path = tmp_path / "w.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def plain_world(tmp_path, controller: str, count: int = 2) -> Path:
    """A world of ``count`` robots run by ``controller`` with no parameters."""
    return world_with(tmp_path, robots__0__controller=controller, robots__0__count=count, robots__0__params={})


def line_of(path: Path, key: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1)
                if line.strip().removeprefix("- ").startswith(f"{key}:"))


def fails(*args) -> str:
    r = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", *map(str, args), "--ticks", "2",
                        "--no-progress", "--no-picture"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, (r.returncode, r.stderr[-3000:])
    assert "Traceback" not in r.stderr, r.stderr
    return r.stderr.strip()


def test_unknown_plugin(tmp_path):
    w = world_with(tmp_path, robots__0__controller="nosuch")
    assert fails(w, "--out", tmp_path / "o") == (
        f"composed-sim: error: {w}:{line_of(w, 'controller')}: robots[0].controller: unknown controller plugin "
        f"'nosuch' (installed: aggregation, avoidance-planner, diffusion, drone-flocking, epuck-obstacle-avoidance, firefly, flocking, "
        f"foraging, inline-planning, kheperaiv-diffusion, obstacle-avoidance, planning-behaviour, turtlebot-flocking); "
        f"a plugin is an "
        f"entry point in the group 'composed_sim.controllers', or name a class as module:Class")


@pytest.mark.parametrize("module, entry, message", [
    ("broken_import", "Anything", "failed to import: ModuleNotFoundError: No module named "
                                  "'composed_sim_missing_dependency'"),
    ("broken", "NotANode", "(broken:NotANode) is not an rclpy Node subclass"),
    ("broken", "ExplodesOnConstruct", "failed to construct for bot0: ValueError: calibration file robot.cfg not found"),
    ("broken", "PublishesAnothersTopic", "for bot1: /bot0/cmd_vel is a topic of bot0, not of bot1"),
])
def test_plugins_that_cannot_be_used(tmp_path, monkeypatch, module, entry, message):
    name = install_plugin(tmp_path, monkeypatch, module, entry, names=("bad",))
    w = plain_world(tmp_path, name)
    error = fails(w, "--out", tmp_path / "o")
    if entry == "ExplodesOnConstruct":      # the node's own code that raised, once, above the line
        where, error = error.rsplit("\n", 1)
        raising = (ROOT / "tests" / "plugin_pkg" / "broken.py").read_text().splitlines().index(
            '        raise ValueError("calibration file robot.cfg not found")') + 1
        assert where.splitlines()[0] == "composed-sim: where it raised:", where
        assert where.count(f'broken.py", line {raising}, in __init__') == 1 and "composed_sim/" not in where, where
    assert error.startswith(f"composed-sim: error: {w}:{line_of(w, 'controller')}: robots[0].controller: ")
    assert message in error and len(error.splitlines()) == 1, error


def test_a_plugin_that_cannot_construct_in_multi_process_mode_says_so_as_in_one_process(tmp_path, monkeypatch):
    # Its controller process's PluginError comes back whole: the user's frames once, then the
    # world file's line (it said only "the controller process of bot0 ended during start-up").
    name = install_plugin(tmp_path, monkeypatch, "broken", "ExplodesOnConstruct", names=("bad",))
    w = plain_world(tmp_path, name)
    where, error = fails(w, "--mode", "multi-process", "--out", tmp_path / "o").rsplit("\n", 1)
    raising = (ROOT / "tests" / "plugin_pkg" / "broken.py").read_text().splitlines().index(
        '        raise ValueError("calibration file robot.cfg not found")') + 1
    assert where.splitlines()[0] == "composed-sim: where it raised:", where
    assert where.count(f'broken.py", line {raising}, in __init__') == 1 and "composed_sim/" not in where, where
    assert re.fullmatch(rf"composed-sim: error: {re.escape(str(w))}:{line_of(w, 'controller')}: robots\[0\]\.controller: "
                        r".*failed to construct for bot[01]: ValueError: calibration file robot.cfg not found", error), error


def test_two_installed_plugins_with_one_name(tmp_path, monkeypatch):
    install_plugin(tmp_path, monkeypatch, "broken", "NotANode", names=("flocking",), dist="impostor")
    error = fails(FLOCKING, "--out", tmp_path / "o")
    assert "controller plugin 'flocking' is declared twice" in error and "package impostor-plugin" in error


def test_robots_that_cannot_be_placed(tmp_path):
    w = world_with(tmp_path, robots__0__count=3000, robots__0__placement__density=1000.0,
                   robots__0__placement__max_trials=3)
    error = fails(w, "--out", tmp_path / "o")
    assert error.startswith(f"composed-sim: error: {w}:{line_of(w, 'placement')}: robots[0] (foot-bot, bot*): "
                            f"could not place ")
    assert "of 3000 robots in 3 trials each" in error


@pytest.mark.parametrize("replacements, expected", [
    ({"robots__0__count": -3}, "robots[0].count: must be >= 0 (got -3)"),
    ({"seed": "one"}, "seed: must be a whole number (got \"one\")"),
    ({"lights__0__position": [0.0, 1000.0], "arena__size": [20.0, 20.0]}, "lights[0].position: outside the arena"),
    ({"arena__walls": "maybe"}, "arena.walls: must be true or false (got \"maybe\")"),
])
def test_bad_world_values_name_file_line_field_and_value(tmp_path, replacements, expected):
    w = world_with(tmp_path, **replacements)
    error = fails(w, "--out", tmp_path / "o")
    assert re.match(rf"composed-sim: error: {re.escape(str(w))}:\d+: ", error) and expected in error, error


def test_an_unwritable_output_directory(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert fails(FLOCKING, "--robots", 2, "--out", blocker / "out") == (
        f"composed-sim: error: --out {blocker / 'out'}: cannot write there (Not a directory)")


@pytest.mark.parametrize("changes, field, says", [
    ({"robots__0__count": 0}, "count", "robots[0].count: every group's count is 0; a run needs at least one robot"),
    ({"robots": []}, "robots", "robots: lists no robot group; a run needs at least one robot"),
])
def test_a_world_with_no_robot_is_refused_at_its_line(tmp_path, changes, field, says):
    w = world_with(tmp_path, **changes)
    assert fails(w, "--out", tmp_path / "o") == f"composed-sim: error: {w}:{line_of(w, field)}: {says}"
    assert not (tmp_path / "o").exists()


def main_fails(capsys, *args) -> str:
    """``main(args)`` as the command line calls it: exit 2 and one line on stderr, argparse's
    errors included (they exit through SystemExit)."""
    from composed_sim.cli import main
    try:
        code = main([str(a) for a in args])
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, (code, err)
    return err


@pytest.mark.parametrize("args, says", [
    (("--seeds", "1-x"), "--seeds: '1-x' is not a whole number (give e.g. 1-5 or 1,2,7)"),
    (("--seeds", "true"), "--seeds: True is not a whole number (give e.g. 1-5 or 1,2,7)"),
    (("--seeds", "-3"), "--seeds: must be >= 0 (got -3)"),
    (("--seeds", "5-1"), "--seeds: the range 5-1 runs backwards"),
    (("--seeds", "1,,2"), "--seeds: an empty value in '1,,2'"),
    (("--robots", "-4"), "--robots: must be >= 1 (got -4)"),
    (("--robots", "1.5"), "--robots: 1.5 is not a whole number (give e.g. 20,80)"),
    (("--set", "gain"), "--set 'gain': expected PATH=V1,V2,... e.g. robots.0.params.gain=500,1000"),
    (("--set", "robots.0.count=0"), "--set robots.0.count=0: the field is int >= 0; every group's count is 0; "
                                    "a run needs at least one robot"),
    (("--cluster", "nonsense"), "--cluster nonsense: missing port number in address 'nonsense'"),
])
def test_every_sweep_argument_mistake_is_one_line(tmp_path, capsys, args, says):
    err = main_fails(capsys, "sweep", FLOCKING, *args, "--out", tmp_path / "out")
    assert err == f"composed-sim sweep: error: {says}"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("text, says", [
    ("world: flocking.yaml\nseeds: [1, x]\n", "seeds: 'x' is not a whole number (give e.g. 1-5 or 1,2,7)"),
    ("world: flocking.yaml\nrobots: -3\n", "robots: must be >= 1 (got -3)"),
    ("world: flocking.yaml\nset: 5\n", "set: must map dotted paths to values, e.g. {robots.0.params.gain: "
                                       "[500, 1000]} (got 5)"),
])
def test_every_sweep_file_mistake_is_one_line(tmp_path, capsys, text, says):
    sweep_file = tmp_path / "sweep.yaml"
    sweep_file.write_text(text)
    (tmp_path / "flocking.yaml").write_text(FLOCKING.read_text())
    assert main_fails(capsys, "sweep", sweep_file) == f"composed-sim sweep: error: {sweep_file}: {says}"


def test_a_sweep_file_that_is_not_yaml_names_its_line(tmp_path, capsys):
    sweep_file = tmp_path / "sweep.yaml"
    sweep_file.write_text("world: [\n")
    assert main_fails(capsys, "sweep", sweep_file).startswith(
        f"composed-sim sweep: error: {sweep_file}:2: not valid YAML: ")


@pytest.mark.parametrize("args, says", [
    (("run", FLOCKING, "--ticks", "abc"), "argument --ticks: expected a whole number, got 'abc'"),
    (("run", FLOCKING, "--robots", "-5"), "argument --robots: must be >= 1 (got -5)"),
    (("run", FLOCKING, "--mode", "fast"), "argument --mode: invalid choice: 'fast' (choose from 'composed', "
                                          "'multi-process')"),
    (("run", FLOCKING, "--bogus"), "unrecognized arguments: --bogus"),
    (("run",), "the following arguments are required: world"),
    (("sweep", FLOCKING, "--ticks", "0"), "argument --ticks: must be >= 1 (got 0)"),
    (("sweep", FLOCKING, "--jobs", "x"), "argument --jobs: expected a whole number, got 'x'"),
    (("sweep", FLOCKING, "--seeds", "1", "--bogus", "x"), "unrecognized arguments: --bogus x"),
    (("join",), "the following arguments are required: address"),
    (("render", ROOT), "the following arguments are required: --out"),
    (("replay",), "the following arguments are required: recording"),
    (("export", ROOT, "--format", "xls"), "argument --format: invalid choice: 'xls' (choose from 'csv', 'parquet')"),
    (("bench", "--sizes", "x"), "argument --sizes: expected whole numbers separated by commas, got 'x'"),
    (("plugins", "--bogus"), "unrecognized arguments: --bogus"),
    (("worlds", "extra"), "unrecognized arguments: extra"),
])
def test_an_argparse_mistake_is_one_line_naming_the_command_and_its_help(capsys, args, says):
    command = f"composed-sim {args[0]}"
    assert main_fails(capsys, *args) == f"{command}: error: {says} (see {command} --help)"


def test_a_mistake_before_the_command_is_one_line_too(capsys):
    assert main_fails(capsys) == "composed-sim: error: the following arguments are required: COMMAND " \
                                 "(see composed-sim --help)"
    assert main_fails(capsys, "nosuch").startswith("composed-sim: error: argument COMMAND: invalid choice: 'nosuch'")


def test_a_sweep_of_a_missing_world_or_into_an_unwritable_folder_is_one_line(tmp_path, capsys):
    missing = tmp_path / "nosuch.yaml"
    assert main_fails(capsys, "sweep", missing, "--seeds", "1") == (
        f"composed-sim sweep: error: {missing}: no such world file")
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main_fails(capsys, "sweep", FLOCKING, "--seeds", "1", "--out", blocker / "out") == (
        f"composed-sim sweep: error: --out {blocker / 'out'}: cannot write there (Not a directory)")


# --- a robot's nodes (robots[i].nodes), run-wide nodes and interface packages -------------------

def nodes_world(tmp_path, nodes, **changes) -> Path:
    """worlds/flocking.yaml whose robots run ``nodes`` (a robots[0].nodes list) instead of their controller."""
    data = yaml.safe_load(FLOCKING.read_text())
    group = data["robots"][0]
    group.pop("controller"), group.pop("params", None)
    group["nodes"], group["count"] = nodes, 2
    data.update(changes)
    path = tmp_path / "w.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.mark.parametrize("node, message", [
    ("no_such_module:Talker", "robots[0].nodes[0]: 'no_such_module:Talker': no module named 'no_such_module' "
                              "(is its package installed, or on PYTHONPATH?)"),
    ("composed_sim.ros.controller:NoSuchClass", "robots[0].nodes[0]: 'composed_sim.ros.controller:NoSuchClass': "
                                                 "module composed_sim.ros.controller has no 'NoSuchClass' (its Node "
                                                 "classes: SwarmController)"),
    ("composed_sim.ros.controller:Tick", "robots[0].nodes[0]: composed_sim.ros.controller:Tick is not an rclpy "
                                         "Node subclass"),
    ("flocking", None),
])
def test_a_node_class_that_cannot_be_found_or_is_not_a_node(tmp_path, node, message):
    w = nodes_world(tmp_path, [{"node": node}, {"node": "composed_sim.ros.controller:Tick"}])
    error = fails(w, "--out", tmp_path / "o")
    nodes_line = line_of(w, "node")
    if message is None:       # the first loads: the second is the one named
        nodes_line = [i for i, line in enumerate(w.read_text().splitlines(), 1) if "node:" in line][1]
        message = "robots[0].nodes[1]: composed_sim.ros.controller:Tick is not an rclpy Node subclass"
    assert error == f"composed-sim: error: {w}:{nodes_line}: {message}", error


def test_a_params_file_that_is_missing_or_not_a_parameters_file(tmp_path):
    w = nodes_world(tmp_path, [{"node": "flocking", "params_file": "nowhere.yaml"}])
    error = fails(w, "--out", tmp_path / "o")
    assert error == (f"composed-sim: error: {w}:{line_of(w, 'params_file')}: robots[0].nodes[0].params_file: no such "
                     f"parameters file {tmp_path / 'nowhere.yaml'} (got \"nowhere.yaml\")")
    (tmp_path / "plain.yaml").write_text("speed: 0.1\n")
    w = nodes_world(tmp_path, [{"node": "flocking", "params_file": "plain.yaml"}])
    error = fails(w, "--out", tmp_path / "o")
    assert error == (f"composed-sim: error: {w}:{line_of(w, 'params_file')}: robots[0].nodes[0].params_file: "
                     f"{tmp_path / 'plain.yaml'} is not a ROS 2 parameters file: it must map node names (or /**) to "
                     f"`ros__parameters:` mappings (got \"plain.yaml\")")


def test_a_remapping_onto_another_robots_namespace(tmp_path):
    w = nodes_world(tmp_path, [{"node": "flocking", "remappings": {"cmd_vel": "/bot1/cmd_vel"}}])
    error = fails(w, "--out", tmp_path / "o")
    assert error == (f"composed-sim: error: {w}:{line_of(w, 'cmd_vel')}: robots[0].nodes[0].remappings.cmd_vel: "
                     f"/bot1/cmd_vel is in robot bot1's namespace: a robot's node remaps onto its own topics only "
                     f"(a relative name, e.g. cmd_vel, resolves in each robot's namespace) (got \"/bot1/cmd_vel\")")


def test_a_run_wide_node_that_cannot_be_found(tmp_path):
    w = world_with(tmp_path, nodes=[{"node": "mission:Control"}])
    error = fails(w, "--out", tmp_path / "o")
    assert error == (f"composed-sim: error: {w}:{line_of(w, 'node')}: nodes[0]: 'mission:Control': no module named "
                     f"'mission' (is its package installed, or on PYTHONPATH?)")


def test_an_interface_package_that_does_not_build(tmp_path):
    package = tmp_path / "bad_interfaces"
    (package / "msg").mkdir(parents=True)
    (package / "package.xml").write_text(
        '<?xml version="1.0"?><package format="3"><name>bad_interfaces</name><version>0.0.1</version>'
        '<description>x</description><maintainer email="a@b.c">a</maintainer><license>MIT</license></package>')
    (package / "msg" / "Opinion.msg").write_text("string sender\nflaot32 x\n")
    w = world_with(tmp_path, interfaces=["bad_interfaces"])
    error = fails(w, "--out", tmp_path / "o")
    assert error.startswith(f"composed-sim: error: {package / 'msg' / 'Opinion.msg'}:2: 'flaot32 x'"), error
    assert len(error.splitlines()) == 1, error


def _controller_parameters() -> list:
    """(world, group, parameter) of every controller parameter the shipped worlds write."""
    found = []
    for path in sorted((ROOT / "worlds").glob("*.yaml")):
        for g, group in enumerate(yaml.safe_load(path.read_text()).get("robots", [])):
            found += [pytest.param(path, g, key, id=f"{path.stem}-{g}-{key}",
                                   marks=() if k == 0 and path.stem in ("flocking", "diffusion") else pytest.mark.slow)
                      for k, key in enumerate(group.get("params") or {})]
    return found


@pytest.mark.parametrize("path, group, key", _controller_parameters())
def test_a_controller_parameter_of_the_wrong_type_is_one_line_naming_its_field(tmp_path, path, group, key,
                                                                                 domain_id):
    # rclpy refuses a value of another type than the parameter's declared one (a string for a
    # double, a list for a bool); the world file's field says so in one line, with no traceback of
    # the controller's constructor: the value is the file's mistake, not the code's.
    from composed_sim.hosts.composed import ComposedHost
    from composed_sim.plugins import PluginError
    from composed_sim.world.loader import load_world
    data = yaml.safe_load(path.read_text())
    params = data["robots"][group]["params"]
    params[key] = {"many": 1} if isinstance(params[key], str) else "many"
    edited = tmp_path / path.name
    edited.write_text(yaml.safe_dump(data, sort_keys=False))
    world = load_world(edited, robots=2, ticks=1)
    with pytest.raises(PluginError) as refused:
        with ComposedHost(world, domain_id=domain_id):
            pass
    assert refused.value.field == ("robots", group, "params", key), str(refused.value)
    assert str(refused.value).startswith(f"robots[{group}].params.{key}: controller ") and "refuses" in str(refused.value)
    assert refused.value.user_traceback == ""


def test_an_integer_for_a_double_parameter_is_refused_at_its_line_saying_how_to_write_it(tmp_path):
    w = world_with(tmp_path, robots__0__params__gain=1000)
    assert fails(w, "--out", tmp_path / "o") == (
        f"composed-sim: error: {w}:{line_of(w, 'gain')}: robots[0].params.gain: controller 'flocking' refuses 1000: "
        f"Trying to set parameter 'gain' to '1000' of type 'INTEGER', expecting type 'DOUBLE' (write 1000.0)")
