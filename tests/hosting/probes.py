"""One small node of a test's own, probing one hosting rule: its source written as a package of
its own, importable while the test runs, and the one-robot world that runs it."""
from __future__ import annotations

import textwrap
from pathlib import Path

from composed_sim.world.loader import load_world
from composed_sim.world.schema import NodeSpec, World
from tests.conftest import importable

FLOCKING = Path(__file__).resolve().parents[2] / "worlds" / "flocking.yaml"


def probe_package(tmp_path: Path, monkeypatch, name: str, source: str):
    """For a fixture to ``yield from``: ``source`` as the package ``name``, importable; yields ``name``."""
    package = tmp_path / name / name
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(textwrap.dedent(source))
    for _ in importable(monkeypatch, tmp_path / name):
        yield name


def one_robot_world(node: NodeSpec, ticks: int, **group) -> World:
    """The flocking arena with one foot-bot running ``node`` alone; ``group``: the robot group's
    other fields (``answers="when_published"``)."""
    world = load_world(FLOCKING, robots=1, ticks=ticks, seed=3)
    robots = world.robots[0].model_copy(update={"count": 1, "controller": None, "params": {}, "nodes": [node],
                                                **group})
    return world.model_copy(update={"robots": [robots]})
