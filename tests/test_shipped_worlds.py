"""Every world that ships in worlds/ runs as shipped, from a fresh install: 6 robots (or as many as
the file places, where it lists their positions) for 5 ticks, in a process of its own whose
environment has no interface package of the tests' and an empty interface cache, as a new user's
first run has. The drone worlds need the drones' messages, which ship with composed_sim and are
built on first use (composed_sim/interfaces/activate.py, SHIPPED)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from composed_sim.world.loader import WorldFileError, load_world

ROOT = Path(__file__).resolve().parents[1]
WORLDS = sorted(p for p in (ROOT / "worlds").iterdir() if p.suffix in (".yaml", ".argos"))
ROBOTS, TICKS = 6, 5


@pytest.fixture(scope="module")
def fresh_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("xdg_cache")


def resizable(path: Path) -> bool:
    if path.suffix != ".yaml":
        return True
    try:
        load_world(path, robots=ROBOTS)
    except WorldFileError:       # its placement lists explicit positions: run as many as it places
        return False
    return True


def test_the_drone_worlds_are_among_them():
    assert {"crazyflie_flocking.yaml", "flocking.yaml", "flocking.argos"} <= {p.name for p in WORLDS}


@pytest.mark.parametrize("path", WORLDS, ids=lambda p: p.name)
def test_a_shipped_world_runs_as_shipped_from_a_fresh_install(path, fresh_cache, tmp_path, domain_id):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AMENT_PREFIX_PATH")}
    env["XDG_CACHE_HOME"] = str(fresh_cache)
    size = ["--robots", str(ROBOTS)] if resizable(path) else []
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(path), *size, "--ticks", str(TICKS),
                           "--domain-id", str(domain_id), "--out", str(out), "--no-progress", "--no-picture"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ticks"] == TICKS
    if size:
        assert summary["robots"] == ROBOTS
