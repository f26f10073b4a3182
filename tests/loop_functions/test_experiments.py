"""Loop functions: the world-file field, the world edits, the hooks in a real run, the foraging
score agreeing with the robots, a loop function that raises."""
import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from composed_sim.core.simulation import Simulation
from composed_sim.world.loader import WorldFileError, load_world, world_from_dict
from composed_sim.world.schema import Box, FloorCircle
from tests.conftest import install_plugin

ROOT = Path(__file__).resolve().parents[2]


def _cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "composed_sim.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_an_unknown_loop_functions_name_is_one_error_at_its_line(tmp_path):
    text = (ROOT / "worlds" / "flocking.yaml").read_text().replace("  name: flocking\n  params:", "  name: flockin\n  params:")
    world = tmp_path / "w.yaml"
    world.write_text(text)
    line = text.splitlines().index("  name: flockin") + 1
    with pytest.raises(WorldFileError) as e:
        load_world(world)
    assert f"w.yaml:{line}: loop_functions.name: unknown loop functions; installed: aggregation, " in str(e.value)


def test_world_edits_are_seen_by_the_next_sensing():
    world = world_from_dict({
        "arena": {"size": [3.0, 3.0]}, "lights": [{"position": [1.0, 0.0], "intensity": 2.0}],
        "obstacles": [{"type": "cylinder", "position": [-1.0, 1.0], "radius_m": 0.1, "movable": True}],
        "robots": [{"count": 1, "controller": "diffusion", "placement": {"method": "explicit", "positions": [[0.0, 0.0]]},
                    "devices": {"ground": {"enabled": True}}}]})
    sim = Simulation(world)
    before = sim.sense()
    assert before.groups[0].ground.min() > 0.99 and before.light.max() > 0
    sim.add_floor_shape(FloorCircle(position=(0.0, 0.0), radius_m=0.3, color=(0, 0, 0)))
    sim.set_light(0, intensity=0.0)
    after = sim.sense()
    assert after.groups[0].ground.max() == 0.0          # the robot stands on the new black disc
    assert after.light.max() == 0.0                     # the light is off
    sim.set_floor_shape(0, color=(255, 255, 255))
    assert sim.sense().groups[0].ground.min() > 0.99
    sim.move_object(0, (0.5, 0.5))
    index = sim.add_object(Box(position=(-1.0, -1.0), size=(0.2, 0.2), movable=True))
    sim.step()
    positions, _ = sim.physics.movable_poses()
    assert index == 1 and np.allclose(positions, [[0.5, 0.5], [-1.0, -1.0]], atol=1e-6)


def test_flocking_metrics_and_an_end_by_is_finished(tmp_path):
    """metrics.csv every 10 ticks and at the last; summary's final row; is_finished ends the run
    normally (exit 0, finished, fewer ticks than asked)."""
    data = yaml.safe_load((ROOT / "worlds" / "flocking.yaml").read_text())
    data["loop_functions"]["params"]["stop_within_m"] = 5.7
    world = tmp_path / "w.yaml"
    world.write_text(yaml.safe_dump(data))
    r = _cli("run", world, "--robots", 4, "--ticks", 400, "--workers", 1, "--no-picture", "--no-progress",
             "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr[-2000:]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    rows = list(csv.DictReader(open(tmp_path / "out" / "metrics.csv")))
    assert summary["ended_by_loop_functions"] is True and 0 < summary["ticks"] < 400
    assert summary["finished"] is True            # deprecated, the same value, for old readers
    assert float(rows[-1]["centroid_to_light_m"]) <= 5.7 < float(rows[-2]["centroid_to_light_m"])
    assert [int(r["tick"]) for r in rows[:-1]] == list(range(0, summary["ticks"], 10))
    assert int(rows[-1]["tick"]) == summary["ticks"]
    assert summary["metrics"]["final"]["lattice_order"] == float(rows[-1]["lattice_order"])
    assert "lattice order" in r.stdout and "ended by the loop functions" in r.stdout


def test_a_run_that_ran_its_length_was_not_ended_by_the_loop_functions(tmp_path):
    """"finished": false read as "did not finish" on a complete run: the field that says what it
    means is ended_by_loop_functions; finished stays, with the same value, for one release."""
    r = _cli("run", ROOT / "worlds" / "flocking.yaml", "--robots", 3, "--ticks", 5, "--workers", 1, "--no-picture",
             "--no-progress", "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr[-2000:]
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert (summary["ticks"], summary["ticks_requested"], summary["interrupted"]) == (5, 5, False)
    assert summary["ended_by_loop_functions"] is False and summary["finished"] is False
    assert "ended by the loop functions" not in r.stdout


def test_foraging_scores_and_the_robots_agree_on_who_carries(tmp_path):
    data = yaml.safe_load((ROOT / "worlds" / "foraging.yaml").read_text())
    data["robots"][0]["count"] = 6
    data["loop_functions"]["params"].update(items=25, food_area=[-1.4, -0.3, -2.3, 2.3])   # food near the nest
    data["loop_functions"]["every_ticks"] = 1
    world = tmp_path / "w.yaml"
    world.write_text(yaml.safe_dump(data))
    r = _cli("run", world, "--ticks", 500, "--workers", 1, "--no-picture", "--no-progress", "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr[-2000:]
    rows = list(csv.DictReader(open(tmp_path / "out" / "metrics.csv")))
    leds = np.load(tmp_path / "out" / "trajectories.npz")["led_colors"]      # [T+1, n, 3] display colours
    green = (leds == (0, 255, 0)).all(axis=2).sum(axis=1)
    # The controllers light green while they think they carry; the loop functions count the same
    # from the same readings. The loop functions decide on tick t's readings at its end; the
    # controllers answer them in tick t + 1, with their LEDs.
    carrying = [int(r["carrying"]) for r in rows]
    assert carrying[:-1] == green[1:].tolist()
    assert int(rows[-1]["score"]) >= 1 and max(green) >= 1
    assert "items delivered" in r.stdout


def test_a_loop_function_that_raises_ends_its_run_with_the_traceback(tmp_path, monkeypatch):
    name = install_plugin(tmp_path, monkeypatch, "raising_loop", "RaisingLoopFunctions", ("raising",),
                          group="composed_sim.loop_functions")
    data = yaml.safe_load((ROOT / "worlds" / "flocking.yaml").read_text())
    data["loop_functions"] = {"name": name, "params": {"raise_at_tick": 4}}
    world = tmp_path / "w.yaml"
    world.write_text(yaml.safe_dump(data))
    r = _cli("run", world, "--robots", 3, "--ticks", 20, "--workers", 1, "--no-picture", "--no-progress",
             "--out", tmp_path / "out")
    assert r.returncode == 1
    assert "Traceback" in r.stderr and "RuntimeError: the experiment's own bug at tick 4" in r.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())   # what ran is kept
    assert summary["ticks"] == 4 and len(list(csv.DictReader(open(tmp_path / "out" / "metrics.csv")))) == 4
    data["loop_functions"]["params"] = {"raise_at": 4}
    world.write_text(yaml.safe_dump(data))
    bad = _cli("run", world, "--robots", 3, "--ticks", 2, "--out", tmp_path / "o2")
    assert bad.returncode == 2 and "loop_functions.params.raise_at: loop functions 'raising': " in bad.stderr
    assert "raise_at: not a parameter of theirs (they take: raise_at_tick)" in bad.stderr


SHIPPED_LOOP_WORLDS = sorted(p for p in (Path(__file__).resolve().parents[2] / "worlds").glob("*.yaml")
                             if "loop_functions" in yaml.safe_load(p.read_text()))


@pytest.mark.parametrize("bad", [float("inf"), float("nan"), "many", [1, 2], {"a": 1}])
@pytest.mark.parametrize("path", SHIPPED_LOOP_WORLDS, ids=lambda p: p.name)
def test_a_bad_loop_function_parameter_is_one_line_naming_the_file_and_field(path, bad):
    """Each shipped world's loop-function parameters, one at a time set to a value of the wrong
    kind or not finite, and an unknown key: one error line naming the file, the line and the
    field, before any run starts (was: a Python traceback from deep in the run for food_area inf)."""
    from composed_sim.cli.common import check_plugins
    from composed_sim.command_line import UserError
    world = yaml.safe_load(path.read_text())
    for key in [*world["loop_functions"].get("params", {}), "no_such_parameter"]:
        edited = yaml.safe_load(path.read_text())
        edited["loop_functions"].setdefault("params", {})[key] = bad
        loaded = world_from_dict(edited, source=path)
        with pytest.raises(UserError) as refused:
            check_plugins(path, loaded)
        line = str(refused.value)
        assert line.startswith(f"{path}:") and f"loop_functions.params.{key}" in line and "\n" not in line, line
