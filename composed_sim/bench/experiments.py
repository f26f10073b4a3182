"""The experiments ``composed-sim bench --experiments`` knows: each names a shipped world file and,
where the paper measured it, the paper's CSVs (composed_sim/data/paper_results/)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional


@dataclass(frozen=True)
class Experiment:
    name: str
    world: str                              # a file in the shipped worlds/ folder
    about: str                              # one line for the report
    # The paper's CSVs of this experiment, 1 thread and 12 threads; None: the paper did not run it.
    paper: Optional[tuple[str, str]] = None


EXPERIMENTS = {e.name: e for e in (
    Experiment("flocking", "flocking.yaml", "foot-bots flocking towards a light, the paper's first experiment",
               ("flocking.csv", "flocking_mt.csv")),
    Experiment("synchronization", "firefly.yaml", "foot-bots flashing their LEDs in synchrony over range and "
               "bearing, the paper's second experiment", ("synchronization.csv", "synchronization_mt.csv")),
    Experiment("plain-nodes", "plain_nodes.yaml", "TurtleBot 3s running an ordinary rclpy node (message "
               "objects, Twist, a 10 Hz timer) that avoids obstacles and one another"),
    Experiment("planner-service", "planner_service.yaml", "foot-bots whose behaviour node calls its planner "
               "node's service on every scan and waits for the answer (Client.call in a reentrant group)"),
    Experiment("planner-inline", "planner_inline.yaml", "the planner-service robots' decision made in one node, "
               "with no call: what the call costs is the difference"),
)}
DEFAULT_EXPERIMENT = "flocking"

PAPER_LABELS = ("paper: ARGoS + ROS 2, 1 thread", "paper: ARGoS + ROS 2, 12 threads")


def shipped_world(experiment: Experiment) -> Path:
    from composed_sim.world.loader import SHIPPED_WORLDS
    return SHIPPED_WORLDS / experiment.world


def experiment_of_world(world: Path | str) -> Optional[Experiment]:
    """The experiment whose shipped world file this is (by file name), or None."""
    name = Path(world).name
    return next((e for e in EXPERIMENTS.values() if e.world == name), None)


def experiment_name(row: dict, settings: dict) -> str:
    """A row's experiment: its own ``experiment`` field; a row of an older sweep (which ran one
    world) is named after that sweep's world."""
    if row.get("experiment"):
        return row["experiment"]
    world = settings.get("world")
    if not world:
        return DEFAULT_EXPERIMENT
    known = experiment_of_world(world)
    return known.name if known else Path(world).stem


def paper_files(name: str) -> Optional[tuple[str, str]]:
    experiment = EXPERIMENTS.get(name)
    return experiment.paper if experiment else None
