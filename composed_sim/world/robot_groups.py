"""The world file's robot groups: how many of which model, placed and headed how, running which
nodes with which parameters and devices (world/schema.py holds the whole world)."""
from __future__ import annotations

from typing import Annotated, Any, Literal, Optional, Union

from pydantic import Field, StrictInt, create_model, field_validator, model_validator

from composed_sim.devices import DEVICES, TOPIC_SWITCHED, WITH_LAYOUT
from composed_sim.devices.common.settings import NonNegativeFloat, PositiveFloat, Strict
from composed_sim.devices.differential_steering import WheelsConfig
from composed_sim.world.robot_models import MODELS, RobotModel
from composed_sim.world.validation import ROS_TOKEN, Vec2, finite, invalid

WHEELED = ("differential_steering", "odometry")     # the devices a model that flies does not have
POSE_DEVICE = "positioning"     # a drone publishes its pose unless its world file switches it off


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
            raise invalid([(("method",), "explicit placement needs a `positions` list",
                             self.method)])
        if self.method != "explicit" and self.positions is not None:
            raise invalid([(("positions",), f"positions are only read by method: explicit "
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
            raise invalid([(("values_rad",), "explicit headings need a `values_rad` list, and only "
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
            if (getattr(self, name).enabled if getattr(self, name) is not None
                else model.flies and name == POSE_DEVICE))

    def config(self, name: str):
        """The device's settings: the world file's, else the defaults."""
        given = getattr(self, name)
        return given if given is not None else _SETTINGS[name]()


_SETTINGS = {d.name: d.settings for d in DEVICES}
Devices = create_model("Devices", __base__=_Devices, __module__=__name__,
                       **{name: (Optional[settings], None) for name, settings in _SETTINGS.items()})


ParamValue = Union[float, int, str, bool, list[float], list[str], list[bool]]


def _check_param_values(value: Any) -> Any:
    """A parameters mapping: names are text, values numbers, strings, booleans or lists of one of
    them (a ROS parameter array is of one type).
    Checked by hand rather than by the Union so that a bad value gets one message, not one per
    member of the Union."""
    if not isinstance(value, dict):
        return value    # the dict validator reports it
    problems = []
    for key, item in value.items():
        scalar = isinstance(item, (bool, int, float, str))
        number_list = isinstance(item, list) and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in item)
        other_list = isinstance(item, list) and item and any(
            all(isinstance(x, kind) for x in item) for kind in (str, bool))
        numbers = item if number_list else [item] if isinstance(item, float) else []
        if not isinstance(key, str):
            problems.append(((key,), "parameter names must be text", key))
        elif not (scalar or number_list or other_list):
            problems.append(((key,), "must be a number, a string, true/false or a list "
                             "of numbers, of strings or of true/false", item))
        elif not all(finite(x) for x in numbers):
            problems.append(((key,), "must be finite", item))
    if problems:
        raise invalid(problems)
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
    # A lifecycle node (rclpy.lifecycle): "autostart" configures and activates it before tick 0, as
    # a lifecycle manager's autostart does; "manual" leaves its transitions to itself or to
    # another node (through its lifecycle services).
    lifecycle: Literal["manual", "autostart"] = "manual"

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
            raise invalid(problems)
        return value


FirmwareParams = dict[str, dict[str, Union[StrictInt, float]]]


class CrazyflieSettings(Strict):
    """A drone group as Crazyswarm2's crazyflies.yaml describes its robots: their type, their radio
    ids (the last byte of each one's radio address: ``crazyfliesById`` of a script), and the
    firmware parameters set at start (``<group>: {<name>: value}``), read and set at run time as
    the ``crazyflie_server`` node's ``<cf>.params.<group>.<name>`` (docs/crazyflie.md)."""
    type: Annotated[str, Field(min_length=1)] = "cf21"
    # Each drone's id, 0-255; None: the number in its name (cf7: 7), modulo 256.
    ids: Optional[list[Annotated[int, Field(ge=0, le=255)]]] = None
    firmware_params: FirmwareParams = {}

    @field_validator("firmware_params")
    @classmethod
    def _finite_values(cls, value: FirmwareParams) -> FirmwareParams:
        problems = [((group, name), "must be finite", item) for group, names in value.items()
                    for name, item in names.items() if not finite(item)]
        problems += [((group,), "a firmware parameter group's name is a word (led, hlCommander)", group)
                     for group in value if not ROS_TOKEN.fullmatch(group)]
        problems += [((group, name), "a firmware parameter's name is a word (bitmask, groupmask)", name)
                     for group, names in value.items() for name in names if not ROS_TOKEN.fullmatch(name)]
        if problems:
            raise invalid(problems)
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
    # A model that flies: its robots as Crazyswarm2 names and configures them (docs/crazyflie.md).
    crazyflie: Optional[CrazyflieSettings] = None

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
            raise invalid([((), f"unknown robot model; known: {', '.join(sorted(MODELS))}",
                             value)])
        return value

    @field_validator("name_prefix")
    @classmethod
    def _ros_name(cls, value: str) -> str:
        if not ROS_TOKEN.fullmatch(value):
            raise invalid([((), "must be a ROS name: a letter, then letters, digits or _",
                             value)])
        return value

    @field_validator("params", mode="before")
    @classmethod
    def _param_values(cls, value: Any) -> Any:
        return _check_param_values(value)

    @model_validator(mode="after")
    def _one_way_to_name_the_nodes(self) -> RobotGroup:
        # A drone needs no software of its own: its firmware flies it, commanded through its
        # Crazyswarm2 services and topics (docs/crazyflie.md); its nodes, if any, are never waited for.
        if self.controller is None and not self.nodes and not MODELS[self.model].flies:
            raise invalid([(("controller",), "is required: the robots' software, `controller: NAME` "
                             "(one node) or `nodes: [{node: NAME}, …]` (only a model that flies may have none)",
                             ...)])
        if self.controller is not None and self.nodes:
            raise invalid([(("nodes",), "give either `controller` (one node) or `nodes`, not both",
                             [spec.node for spec in self.nodes])])
        if self.params and self.controller is None:
            raise invalid([(("params",), "`params` belong to `controller`; with `nodes`, give each "
                             "node its `parameters`", self.params)])
        return self

    @model_validator(mode="after")
    def _explicit_count(self) -> RobotGroup:
        positions = self.placement.positions
        if positions is not None and len(positions) != self.count:
            raise invalid([(("placement", "positions"), f"must list exactly count = "
                             f"{self.count} positions, lists {len(positions)}", positions)])
        values = self.heading.values_rad
        if values is not None and len(values) != self.count:
            raise invalid([(("heading", "values_rad"), f"must list exactly count = "
                             f"{self.count} headings, lists {len(values)}", values)])
        model = MODELS[self.model]
        problems = [(("devices", name), f"the {self.model} has no {name} device (it has: "
                     f"{', '.join(d for d in model.devices if d in WITH_LAYOUT) or 'none'})",
                     getattr(self.devices, name).model_dump())
                    for name in WITH_LAYOUT
                    if getattr(self.devices, name) is not None and getattr(self.devices, name).enabled
                    and getattr(model, name) is None]
        if self.crazyflie is not None and not model.flies:
            problems.append((("crazyflie",), f"only a model that flies has Crazyswarm2 settings (this group's "
                             f"model is {self.model})", self.crazyflie.model_dump()))
        ids = self.crazyflie.ids if self.crazyflie is not None else None
        if ids is not None and len(ids) != self.count:
            problems.append((("crazyflie", "ids"), f"must list exactly count = {self.count} ids, lists {len(ids)}",
                             ids))
        elif ids is not None and len(set(ids)) != len(ids):
            problems.append((("crazyflie", "ids"), "two drones of the group have one id", ids))
        if model.flies:      # its firmware moves it: no wheels to steer, count or turn into odometry
            problems += [(("devices", name), f"the {self.model} flies: it has no wheels, so no {name}",
                          getattr(self.devices, name).model_dump())
                         for name in WHEELED if getattr(self.devices, name) is not None
                         and getattr(self.devices, name).enabled]
        if problems:
            raise invalid(problems)
        return self
