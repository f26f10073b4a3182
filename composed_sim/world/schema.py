"""The world file schema (pydantic v2): one model per section, unknown fields rejected.

A loaded ``World`` is the resolved description of a run: the core, the hosts and the
results all read it, and ``World.model_dump(mode="json")`` writes it back out so a run can
be reproduced from its saved configuration. ``composed_sim.world.loader`` reads and writes
the YAML files and turns validation errors into messages with file, line and field path.

The arena's models are in world/arena.py, the robot groups' in world/robot_groups.py, the way
their checks report problems in world/validation.py; this module holds the world and its run
settings, and names them all.
"""
from __future__ import annotations

from typing import Annotated, Any, Literal, Optional, Union

from pydantic import Field, field_validator, model_validator

from composed_sim.devices.common.settings import NonNegativeFloat, PositiveFloat, Strict
from composed_sim.entry_points import installed
from composed_sim.world.arena import (Arena, Box, Cylinder, Floor, FloorCircle, FloorRectangle, Light, Obstacle,
                                      RangeAndBearingMedium)
from composed_sim.world.flight import Flight
from composed_sim.world.robot_groups import CameraConfig, Devices, Heading, NodeSpec, Placement, RobotGroup
from composed_sim.world.validation import RGB, Vec2, invalid

__all__ = ["Arena", "Box", "CameraConfig", "Cylinder", "Devices", "Flight", "Floor", "FloorCircle", "FloorRectangle", "Heading",
           "LOOP_FUNCTIONS_GROUP", "Light", "Lockstep", "LoopFunctionsRef", "MAX_DOMAIN", "MultiProcess",
           "NodeSpec", "Obstacle", "Physics", "Placement", "RGB", "ROBOTS_PER_DOMAIN", "RangeAndBearingMedium",
           "RobotGroup", "Vec2", "World"]

class RegionCuts(Strict):
    """Regions named by the lines between them: strips cut at x values (``x_m``) or at y values (``y_m``)."""
    x_m: list[float] = []
    y_m: list[float] = []

    @model_validator(mode="after")
    def _one_axis_increasing(self) -> "RegionCuts":
        if bool(self.x_m) == bool(self.y_m):
            raise invalid([((), "give the cuts between the regions along one axis: x_m or y_m, "
                             "a list of increasing values in m", self.model_dump())])
        name, cuts = ("x_m", self.x_m) if self.x_m else ("y_m", self.y_m)
        if any(b <= a for a, b in zip(cuts, cuts[1:])):
            raise invalid([((name,), "the cuts must increase", cuts)])
        if len(cuts) >= MAX_REGIONS:
            raise invalid([((name,), f"at most {MAX_REGIONS} regions ({MAX_REGIONS - 1} cuts)", cuts)])
        return self

    @property
    def count(self) -> int:
        return len(self.x_m or self.y_m) + 1


MAX_REGIONS = 64


class Physics(Strict):
    substeps: Annotated[int, Field(ge=1, le=100)] = 10
    iterations: Annotated[int, Field(ge=1, le=100)] = 10
    # Regions of the arena, each stepped by a physics engine in a process of its own (ARGoS's
    # several engines): a count (strips with about as many robots each, cut along the wider side
    # of the robots' start), or the cuts between them. 1: the physics in this process.
    regions: Union[Annotated[int, Field(ge=1, le=MAX_REGIONS)], RegionCuts] = 1
    # A contact across a region's border: "ghosts" resolves it (each region also simulates copies of
    # the robots within ghost_margin_m of it); "ignore" does not see it, as ARGoS's engines.
    border_contacts: Literal["ghosts", "ignore"] = "ghosts"
    ghost_margin_m: NonNegativeFloat = 0.4
    # Robots per pymunk space (cell) in a region; 0: one space per region. Chipmunk's cost per
    # robot grows once a space outgrows the cache (docs/speed.md, "Physics that scales").
    robots_per_cell: Annotated[int, Field(ge=0)] = 1024
    # Processes that step the cells of a one-region world: "auto", one per usable core up to one
    # per cell; 1: the cells in the simulator's process. The cells do not change with it, nor the
    # run (docs/speed.md, "Every core by default"). With regions > 1: one process per region.
    processes: Union[Annotated[int, Field(ge=1, le=MAX_REGIONS)], Literal["auto"]] = "auto"

    @field_validator("regions", mode="before")
    @classmethod
    def _count_or_cuts(cls, value: Any) -> Any:
        if isinstance(value, bool) or not isinstance(value, (int, dict, RegionCuts)):
            raise invalid([((), f"a count of regions (1 to {MAX_REGIONS}) or the cuts between them "
                             "({x_m: [...]} or {y_m: [...]})", value)])
        return value

    @property
    def region_count(self) -> int:
        return self.regions if isinstance(self.regions, int) else self.regions.count


class Lockstep(Strict):
    # Wall-clock seconds the simulator waits for a controller's answer to a tick before it
    # injects the fallback command and records a violation.
    watchdog_s: PositiveFloat = 10.0
    fallback: Literal["zero", "previous"] = "zero"
    # A robot with no accepted answer for this many wall-clock seconds (a hung or silent
    # controller) is marked failed: stopped, no longer waited for, its callbacks no longer run
    # (its process is stopped in multi-process mode). None: three watchdog periods.
    unresponsive_after_s: Optional[PositiveFloat] = None
    # A robot with this many violations is stopped and marked failed. None: never.
    max_violations: Optional[Annotated[int, Field(ge=1)]] = None

    @property
    def unresponsive_s(self) -> float:
        return self.unresponsive_after_s if self.unresponsive_after_s is not None else 3.0 * self.watchdog_s

    @model_validator(mode="after")
    def _unresponsive_after_the_watchdog(self) -> "Lockstep":
        if self.unresponsive_after_s is not None and self.unresponsive_after_s < self.watchdog_s:
            raise invalid([(("unresponsive_after_s",), f"must be at least watchdog_s "
                             f"({self.watchdog_s})", self.unresponsive_after_s)])
        return self


# Fast DDS on Linux: a domain's ports start at 7400 + 250 * domain, so 232 is the last domain
# whose ports stay below 65535 (see composed_sim.hosts.multiprocess.domains).
MAX_DOMAIN = 232
ROBOTS_PER_DOMAIN = 50      # multi-process mode's default: the paper's
DomainId = Annotated[int, Field(ge=0, le=MAX_DOMAIN)]


class MultiProcess(Strict):
    """Multi-process mode only: how the robots' controller processes spread over ROS domains."""
    # Robots per domain when balancing automatically (the paper's 50); each also costs the
    # domain a DDS participant, and Fast DDS fits at most 120 participants in one domain.
    robots_per_domain: Annotated[int, Field(ge=1, le=119)] = ROBOTS_PER_DOMAIN
    first_domain: Optional[DomainId] = None     # None: the run's domain id (--domain-id)
    domains: dict[str, DomainId] = {}           # explicit robot name -> domain; the rest balanced


LOOP_FUNCTIONS_GROUP = "composed_sim.loop_functions"


class LoopFunctionsRef(Strict):
    """The world's loop functions (composed_sim/loop_functions.py): an entry point of the group
    ``composed_sim.loop_functions``, the keyword arguments its class is made with, and how often
    its metrics are taken (every tick by default)."""
    name: Annotated[str, Field(min_length=1)]
    params: dict[str, Any] = {}
    every_ticks: Annotated[int, Field(ge=1)] = 1

    @field_validator("name")
    @classmethod
    def _installed(cls, value: str) -> str:
        known = installed(LOOP_FUNCTIONS_GROUP, "loop functions", ValueError)   # names only: nothing imported
        if value not in known:
            raise invalid([((), f"unknown loop functions; installed: {', '.join(known) or 'none'} "
                             f"(entry points of the group {LOOP_FUNCTIONS_GROUP!r})", value)])
        return value


class World(Strict):
    name: str = "world"
    seed: Annotated[int, Field(ge=0, lt=2**32)] = 0
    ticks_per_second: Annotated[int, Field(ge=1, le=1000)] = 10
    length_ticks: Annotated[int, Field(ge=1)] = 600
    physics: Physics = Physics()
    lockstep: Lockstep = Lockstep()
    multi_process: MultiProcess = MultiProcess()
    arena: Arena = Arena()
    floor: Floor = Floor()
    range_and_bearing: RangeAndBearingMedium = RangeAndBearingMedium()
    flight: Flight = Flight()            # the drones' motion and near misses (a world with drones)
    lights: list[Light] = []
    obstacles: list[Obstacle] = []
    robots: list[RobotGroup]
    # Run-wide nodes, hosted once outside every robot's namespace (a mission control, a logger):
    # they talk to the robots on run-wide topics (docs/contract.md).
    nodes: list[NodeSpec] = []
    loop_functions: Optional[LoopFunctionsRef] = None
    # ROS 2 interface package folders (package.xml, msg/, srv/) the run's nodes use, built and made
    # importable before the nodes load (composed_sim/interfaces/). Relative paths are relative to
    # the world file; the loader makes them absolute and checks each is a package. In order: a
    # package may use the messages of those before it.
    interfaces: list[str] = []

    @model_validator(mode="after")
    def _consistent(self) -> World:
        problems = [(("lights", i, "position"), f"outside the arena (size {list(self.arena.size)} "
                     f"centred at {list(self.arena.center)})", list(light.position))
                    for i, light in enumerate(self.lights)
                    if not self.arena.contains(*light.position)]
        if self.floor.image is not None and self.floor.image_size_m is None and self.arena.size is None:
            problems.append((("floor", "image_size_m"), "an image floor needs its size in metres "
                             "(floor.image_size_m, or arena.size to stretch it over the arena)", None))
        # Numbering runs on per prefix, so prefixes "bot" and "bot1" can both make "bot10".
        seen: dict[str, int] = {}
        for name, gi in zip(self.robot_names(), self.group_of_robot()):
            first = seen.setdefault(name, gi)
            if first != gi:
                problems.append((("robots", gi, "name_prefix"), f"robot name {name} is also made "
                                 f"by robots[{first}]", self.robots[gi].name_prefix))
                break
        problems += self._remapping_problems()
        movable = [i for i, ob in enumerate(self.obstacles) if ob.movable]
        if self.physics.region_count > 1 and movable:
            problems.append((("physics", "regions"), f"regions need a world without movable objects "
                             f"(obstacles[{movable[0]}] is movable): give physics.regions: 1",
                             self.physics.model_dump()["regions"]))
        if problems:
            raise invalid(problems)
        return self

    def _remapping_problems(self) -> list[tuple[tuple, str, Any]]:
        """A robot's node remaps within its own namespace only: an absolute name in a robot's
        namespace would be the same robot's topic for every robot of the group."""
        names = set(self.robot_names())
        problems = []
        for gi, group in enumerate(self.robots):
            for ni, spec in enumerate(group.nodes):
                for source, target in spec.remappings.items():
                    owner = target.split("/")[1] if target.startswith("/") and target.count("/") >= 2 else None
                    if owner in names:
                        problems.append((("robots", gi, "nodes", ni, "remappings", source),
                                         f"{target} is in robot {owner}'s namespace: a robot's node remaps onto "
                                         f"its own topics only (a relative name, e.g. {target.split('/', 2)[2]}, "
                                         f"resolves in each robot's namespace)", target))
        return problems

    @property
    def robot_count(self) -> int:
        return sum(g.count for g in self.robots)

    @property
    def tick_s(self) -> float:
        return 1.0 / self.ticks_per_second

    @property
    def tick_ns(self) -> int:
        """A tick in integer nanoseconds: sim-time stamps are tick · tick_ns exactly."""
        return round(1e9 / self.ticks_per_second)

    def robot_names(self) -> list[str]:
        """Names in group order; numbering per prefix runs on across groups (bot0 … botN-1); drones
        whose group lists their radio ids are named by them, as Crazyswarm2 names them (cf231)."""
        counters: dict[str, int] = {}
        names = []
        for group in self.robots:
            if group.crazyflie is not None and group.crazyflie.ids is not None:
                names += [f"{group.name_prefix}{i}" for i in group.crazyflie.ids]
                continue
            start = counters.get(group.name_prefix, 0)
            names += [f"{group.name_prefix}{start + i}" for i in range(group.count)]
            counters[group.name_prefix] = start + group.count
        return names

    def group_of_robot(self) -> list[int]:
        """[n] index into ``robots`` of each robot's group."""
        return [gi for gi, group in enumerate(self.robots) for _ in range(group.count)]
