"""The world file schema (pydantic v2): one model per section, unknown fields rejected.

A loaded ``World`` is the resolved description of a run: the core, the hosts and the
results all read it, and ``World.model_dump(mode="json")`` writes it back out so a run can
be reproduced from its saved configuration. ``composed_sim.world.loader`` reads and writes
the YAML files and turns validation errors into messages with file, line and field path.

Checks that span several fields raise a ``PydanticCustomError`` of type ``"world"`` whose
context carries ``problems``: ``(sub-path, message, value)`` triples relative to the model
that raised it, so the loader can point at the exact field (and its line) of each problem.
"""
from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal, Optional, Union

from pydantic import Field, create_model, field_validator, model_validator
from pydantic_core import PydanticCustomError

from composed_sim.devices import DEVICES, TOPIC_SWITCHED, WITH_LAYOUT
from composed_sim.devices.common.settings import NonNegativeFloat, PositiveFloat, Strict
from composed_sim.devices.differential_steering import WheelsConfig
from composed_sim.entry_points import installed
from composed_sim.world.robot_models import MODELS, RobotModel

Vec2 = tuple[float, float]
RGB = tuple[Annotated[int, Field(ge=0, le=255)], Annotated[int, Field(ge=0, le=255)],
            Annotated[int, Field(ge=0, le=255)]]

# Robot names become ROS namespaces (<prefix><index>), so the prefix must be a ROS name token.
_ROS_TOKEN = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


def _invalid(problems: list[tuple[tuple, str, Any]]) -> PydanticCustomError:
    """One validation error carrying several (sub-path, message, value) problems."""
    text = "; ".join(".".join(map(str, path)) + (": " if path else "") + message
                     for path, message, _ in problems)
    return PydanticCustomError("world", "{text}", {"text": text, "problems": problems})


def _finite(x: float) -> bool:
    try:
        return math.isfinite(x)
    except OverflowError:   # an int too large for a float
        return False


class Arena(Strict):
    center: Vec2 = (0.0, 0.0)
    # Arena side lengths in metres. Required when walls are on; without walls it only
    # bounds where lights may stand (None = unbounded). The walls stand inside this
    # rectangle (outer faces on its edge): see inner_bounds() and wall_boxes().
    size: Optional[tuple[PositiveFloat, PositiveFloat]] = None
    walls: bool = False
    wall_thickness_m: PositiveFloat = 0.1
    wall_height_m: PositiveFloat = 0.5

    @model_validator(mode="after")
    def _walls_need_size(self) -> Arena:
        if self.walls and self.size is None:
            raise _invalid([(("walls",), "walls need arena.size (the side lengths in m)", True)])
        if self.walls and 2 * self.wall_thickness_m >= min(self.size):
            raise _invalid([(("wall_thickness_m",), f"two walls must fit in the arena size "
                             f"{list(self.size)}", self.wall_thickness_m)])
        return self

    def contains(self, x: float, y: float) -> bool:
        """True when (x, y) is inside the arena rectangle (always, when size is None)."""
        if self.size is None:
            return True
        return (abs(x - self.center[0]) <= self.size[0] / 2
                and abs(y - self.center[1]) <= self.size[1] / 2)

    def inner_bounds(self) -> Optional[tuple[float, float, float, float]]:
        """(x_min, y_min, x_max, y_max) of the floor inside the walls; None without walls."""
        if not self.walls:
            return None
        hx = self.size[0] / 2 - self.wall_thickness_m
        hy = self.size[1] / 2 - self.wall_thickness_m
        cx, cy = self.center
        return (cx - hx, cy - hy, cx + hx, cy + hy)

    def wall_boxes(self) -> list[Box]:
        """The four walls as static boxes (east, west, north, south); [] without walls."""
        if not self.walls:
            return []
        (cx, cy), (sx, sy), t = self.center, self.size, self.wall_thickness_m
        h = self.wall_height_m
        return [Box(position=(cx + (sx - t) / 2, cy), size=(t, sy), height_m=h),
                Box(position=(cx - (sx - t) / 2, cy), size=(t, sy), height_m=h),
                Box(position=(cx, cy + (sy - t) / 2), size=(sx, t), height_m=h),
                Box(position=(cx, cy - (sy - t) / 2), size=(sx, t), height_m=h)]


class Light(Strict):
    position: Vec2
    height_m: NonNegativeFloat = 0.5
    intensity: NonNegativeFloat = 1.0
    color: RGB = (255, 255, 0)


class Box(Strict):
    type: Literal["box"] = "box"
    position: Vec2
    size: tuple[PositiveFloat, PositiveFloat]   # along its own x and y
    height_m: PositiveFloat = 0.5
    yaw_rad: float = 0.0
    # A movable body is pushed by robots and held back by ground friction (ARGoS dynamics2d);
    # its mass only matters when it moves.
    movable: bool = False
    mass_kg: PositiveFloat = 1.0


class Cylinder(Strict):
    type: Literal["cylinder"] = "cylinder"
    position: Vec2
    radius_m: PositiveFloat
    height_m: PositiveFloat = 0.5
    movable: bool = False
    mass_kg: PositiveFloat = 1.0


Obstacle = Annotated[Union[Box, Cylinder], Field(discriminator="type")]


class FloorCircle(Strict):
    type: Literal["circle"] = "circle"
    position: Vec2
    radius_m: PositiveFloat
    color: RGB


class FloorRectangle(Strict):
    type: Literal["rectangle"] = "rectangle"
    position: Vec2
    size: tuple[PositiveFloat, PositiveFloat]   # along its own x and y
    yaw_rad: float = 0.0
    color: RGB


FloorShape = Annotated[Union[FloorCircle, FloorRectangle], Field(discriminator="type")]


class Floor(Strict):
    """What the ground sensors read: a colour, an image stretched over a rectangle, shapes on top."""
    color: RGB = (255, 255, 255)
    # An image file (PNG, JPEG, ...; read with imageio). A relative path is relative to the
    # world file; the loader makes it absolute and checks that it is a readable image.
    image: Optional[str] = None
    image_size_m: Optional[tuple[PositiveFloat, PositiveFloat]] = None   # None: the arena's size
    image_center: Vec2 = (0.0, 0.0)
    shapes: list[FloorShape] = []               # painted in this order, over the image


class RangeAndBearingMedium(Strict):
    """How range-and-bearing messages travel between the robots whose device is on."""
    # local: within the sender's range and line of sight; global: everyone hears everyone.
    mode: Literal["local", "global"] = "local"
    payload_bytes: Annotated[int, Field(ge=1, le=65535)] = 10   # docs/architecture.md: 10 by default
    check_occlusions: bool = True


class Placement(Strict):
    """Where a group's robots start. Overlapping draws are re-drawn up to max_trials."""
    method: Literal["uniform", "gaussian", "grid", "explicit"] = "uniform"
    center: Vec2 = (0.0, 0.0)
    # uniform: a rectangle of this size, or (when size is None) a square whose side grows
    # with the count so that the density stays at `density` robots per square metre.
    size: Optional[tuple[PositiveFloat, PositiveFloat]] = None
    density: PositiveFloat = 5.0
    std_m: PositiveFloat = 1.0                  # gaussian
    # grid: ceil(sqrt(count)) columns, filled row-major (x first) from the lower-left,
    # the whole block centred at `center`. Grid and explicit positions are never re-drawn.
    spacing_m: PositiveFloat = 0.5
    positions: Optional[list[Vec2]] = None      # explicit: exactly `count` positions
    max_trials: Annotated[int, Field(ge=1)] = 100

    @model_validator(mode="after")
    def _positions_match_method(self) -> Placement:
        if self.method == "explicit" and self.positions is None:
            raise _invalid([(("method",), "explicit placement needs a `positions` list",
                             self.method)])
        if self.method != "explicit" and self.positions is not None:
            raise _invalid([(("positions",), f"positions are only read by method: explicit "
                             f"(method is {self.method})", self.positions)])
        return self


class Heading(Strict):
    method: Literal["uniform", "constant", "gaussian", "explicit"] = "uniform"
    value_rad: float = 0.0      # constant, and the gaussian's mean
    std_rad: NonNegativeFloat = 0.5
    # uniform: over [low, high] rad (an ARGoS <orientation method="uniform"> range); None: the full circle
    range_rad: Optional[tuple[float, float]] = None
    # explicit: exactly `count` headings, one per robot (e.g. the poses another simulator logged)
    values_rad: Optional[list[float]] = None

    @model_validator(mode="after")
    def _explicit_values(self) -> Heading:
        if (self.method == "explicit") != (self.values_rad is not None):
            raise _invalid([(("values_rad",), "explicit headings need a `values_rad` list, and only "
                             "method: explicit reads one", self.values_rad)])
        return self


class CameraConfig(Strict):
    aperture_deg: Annotated[float, Field(gt=0, lt=90)] = 70.0


class _Devices(Strict):
    """A group's devices: a switched device left out runs when its model runs it by default; an
    always-computed one present (and not enabled: false) gives the robot its topics. One field
    per device (its module's settings class), added below."""
    wheels: WheelsConfig = WheelsConfig()           # the actuator and sensor noise of the wheels

    def running(self, model: RobotModel) -> tuple[str, ...]:
        """The switched devices that run on robots of ``model``, in WITH_LAYOUT order."""
        out = []
        for name in WITH_LAYOUT:
            config = getattr(self, name)
            if (name in model.default_devices) if config is None else config.enabled:
                out.append(name)
        return tuple(out)

    def published(self, model: RobotModel) -> tuple[str, ...]:
        """Every device that has topics on robots of ``model``: the running switched devices,
        then the always-computed ones the world file switches on (TOPIC_SWITCHED order)."""
        return self.running(model) + tuple(
            name for name in TOPIC_SWITCHED
            if getattr(self, name) is not None and getattr(self, name).enabled)

    def config(self, name: str):
        """The device's settings: the world file's, else the defaults."""
        given = getattr(self, name)
        return given if given is not None else _SETTINGS[name]()


_SETTINGS = {d.name: d.settings for d in DEVICES}
Devices = create_model("Devices", __base__=_Devices, __module__=__name__,
                       **{name: (Optional[settings], None) for name, settings in _SETTINGS.items()})


ParamValue = Union[float, int, str, bool, list[float]]


def _check_param_values(value: Any) -> Any:
    """A parameters mapping: names are text, values numbers, strings, booleans or number lists.
    Checked by hand rather than by the Union so that a bad value gets one message, not one per
    member of the Union."""
    if not isinstance(value, dict):
        return value    # the dict validator reports it
    problems = []
    for key, item in value.items():
        scalar = isinstance(item, (bool, int, float, str))
        number_list = isinstance(item, list) and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in item)
        numbers = item if number_list else [item] if isinstance(item, float) else []
        if not isinstance(key, str):
            problems.append(((key,), "parameter names must be text", key))
        elif not (scalar or number_list):
            problems.append(((key,), "must be a number, a string, true/false or a list "
                             "of numbers", item))
        elif not all(_finite(x) for x in numbers):
            problems.append(((key,), "must be finite", item))
    if problems:
        raise _invalid(problems)
    return value


class NodeSpec(Strict):
    """One hosted ROS node as its package ships it: the class (an entry-point name of the group
    ``composed_sim.controllers``, or ``module:Class``), the parameters it is given (over those of
    its parameters file), a ROS 2 parameters file (``/**: ros__parameters: …``, relative to the
    world file) and topic remappings (from → to, as ``--ros-args -r from:=to``)."""
    node: Annotated[str, Field(min_length=1)]
    parameters: dict[str, ParamValue] = {}
    params_file: Optional[str] = None
    remappings: dict[str, str] = {}

    @field_validator("parameters", mode="before")
    @classmethod
    def _parameter_values(cls, value: Any) -> Any:
        return _check_param_values(value)

    @field_validator("remappings")
    @classmethod
    def _names(cls, value: dict[str, str]) -> dict[str, str]:
        problems = [((source,), "a remapping is a topic name to another (from: to)", target)
                    for source, target in value.items() if not source or not target]
        if problems:
            raise _invalid(problems)
        return value


class RobotGroup(Strict):
    model: str = "foot-bot"                          # a key of world.robot_models.MODELS
    count: Annotated[int, Field(ge=0)]
    name_prefix: str = "bot"
    # Each robot runs ``nodes`` (its ROS software: one node or several, docs/contract.md); the
    # one-node shorthand is ``controller`` (an entry-point name or module:Class) with ``params``.
    controller: Optional[Annotated[str, Field(min_length=1)]] = None
    params: dict[str, ParamValue] = {}
    nodes: list[NodeSpec] = []
    placement: Placement = Placement()
    heading: Heading = Heading()
    camera: CameraConfig = CameraConfig()
    devices: Devices = Devices()
    # What the controllers publish on cmd_vel: "stamped" (TwistStamped, stamped like the readings
    # it answers), "unstamped" (Twist, answering the tick whose sensors it follows), or "auto":
    # read from the controller's publisher (docs/contract.md).
    cmd_vel: Literal["auto", "stamped", "unstamped"] = "auto"
    # A controller that decides on a timer slower than the tick answers every k-th tick (ticks
    # 0, k, 2k …); in between its robot keeps its last command, and that is no violation.
    answers_every_ticks: Annotated[int, Field(ge=1)] = 1
    # "every_tick": each tick needs the robot's cmd_vel (a missing one is a violation).
    # "when_published": its nodes publish cmd_vel when they choose, as much ROS software does (a
    # pattern that only steers around obstacles, a discussion phase that sends nothing); a tick
    # closes for the robot once its nodes have nothing left to do, and its base keeps the last
    # command, as a real robot's does (docs/contract.md).
    answers: Literal["every_tick", "when_published"] = "every_tick"

    @property
    def node_specs(self) -> list[NodeSpec]:
        """The nodes each robot of the group runs, in the order the host builds and walks them."""
        return self.nodes if self.controller is None else [NodeSpec(node=self.controller, parameters=self.params)]

    @property
    def label(self) -> str:
        """The group's software in one phrase, for messages: its controller, or its nodes."""
        return self.controller or "+".join(spec.node for spec in self.nodes)

    @field_validator("model")
    @classmethod
    def _known_model(cls, value: str) -> str:
        if value not in MODELS:
            raise _invalid([((), f"unknown robot model; known: {', '.join(sorted(MODELS))}",
                             value)])
        return value

    @field_validator("name_prefix")
    @classmethod
    def _ros_name(cls, value: str) -> str:
        if not _ROS_TOKEN.fullmatch(value):
            raise _invalid([((), "must be a ROS name: a letter, then letters, digits or _",
                             value)])
        return value

    @field_validator("params", mode="before")
    @classmethod
    def _param_values(cls, value: Any) -> Any:
        return _check_param_values(value)

    @model_validator(mode="after")
    def _one_way_to_name_the_nodes(self) -> RobotGroup:
        if self.controller is None and not self.nodes:
            raise _invalid([(("controller",), "is required: the robots' software, `controller: NAME` "
                             "(one node) or `nodes: [{node: NAME}, …]`", ...)])
        if self.controller is not None and self.nodes:
            raise _invalid([(("nodes",), "give either `controller` (one node) or `nodes`, not both",
                             [spec.node for spec in self.nodes])])
        if self.params and self.controller is None:
            raise _invalid([(("params",), "`params` belong to `controller`; with `nodes`, give each "
                             "node its `parameters`", self.params)])
        return self

    @model_validator(mode="after")
    def _explicit_count(self) -> RobotGroup:
        positions = self.placement.positions
        if positions is not None and len(positions) != self.count:
            raise _invalid([(("placement", "positions"), f"must list exactly count = "
                             f"{self.count} positions, lists {len(positions)}", positions)])
        values = self.heading.values_rad
        if values is not None and len(values) != self.count:
            raise _invalid([(("heading", "values_rad"), f"must list exactly count = "
                             f"{self.count} headings, lists {len(values)}", values)])
        model = MODELS[self.model]
        problems = [(("devices", name), f"the {self.model} has no {name} device (it has: "
                     f"{', '.join(d for d in model.devices if d in WITH_LAYOUT) or 'none'})",
                     getattr(self.devices, name).model_dump())
                    for name in WITH_LAYOUT
                    if getattr(self.devices, name) is not None and getattr(self.devices, name).enabled
                    and getattr(model, name) is None]
        if problems:
            raise _invalid(problems)
        return self


class Physics(Strict):
    substeps: Annotated[int, Field(ge=1, le=100)] = 10
    iterations: Annotated[int, Field(ge=1, le=100)] = 10


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
            raise _invalid([(("unresponsive_after_s",), f"must be at least watchdog_s "
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
            raise _invalid([((), f"unknown loop functions; installed: {', '.join(known) or 'none'} "
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
        if problems:
            raise _invalid(problems)
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
        """Names in group order; numbering per prefix runs on across groups (bot0 … botN-1)."""
        counters: dict[str, int] = {}
        names = []
        for group in self.robots:
            start = counters.get(group.name_prefix, 0)
            names += [f"{group.name_prefix}{start + i}" for i in range(group.count)]
            counters[group.name_prefix] = start + group.count
        return names

    def group_of_robot(self) -> list[int]:
        """[n] index into ``robots`` of each robot's group."""
        return [gi for gi, group in enumerate(self.robots) for _ in range(group.count)]
