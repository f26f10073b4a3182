"""Import an ARGoS 3 experiment file (``.argos``) as a World.

``load_argos(path, controller=...)`` returns ``(world, warnings)``: the World to run and one line
per ARGoS element or attribute that the import does not simulate (the CLI prints them as one
warning). Problems that make the file unusable raise ``ArgosFileError``, one line each:
``file:line: element/attribute: what is wrong (got "value")``.

The XML is parsed with expat directly: no DTD is accepted (a DOCTYPE is an error), so no entity
can be declared or expanded (no "billion laughs", no external entities), and every element keeps
its line for the messages.

What maps to what (ARGoS units → SI; ARGoS angles are degrees "yaw,pitch,roll"):

  <experiment length (s) ticks_per_second random_seed>
                     → length_ticks = length × ticks_per_second (truncated, as ARGoS), seed
  <arena size center>                    → arena.size, arena.center (x, y; no walls: ARGoS walls
                                           are boxes, and import as boxes)
  <box size movable mass><body position orientation/>   → a box (size x, y; height z; yaw),
                                                      movable with its mass when ARGoS's is
  <cylinder radius height movable mass><body .../>     → a cylinder, likewise
  <light position color intensity>       → a light (z → height_m)
  <foot-bot id omnidirectional_camera_aperture><body/><controller config/>
                     → a group with explicit placement and a constant heading (consecutive
                       foot-bots that share name prefix, controller, aperture and yaw form one group)
  <distribute> of foot-bots (ids base id + index → name_prefix = base id; quantity → count;
  max_trials → placement.max_trials):
      position uniform min/max   → placement uniform, center = (min+max)/2, size = max−min: exact
      position gaussian mean/std_dev → placement gaussian (an unequal x/y std_dev becomes their
                                   geometric mean, with a warning: the schema has one std)
      position constant values   → explicit, one robot (more could never be placed, in ARGoS too)
      position grid center/distances/layout → explicit positions computed exactly as ARGoS's
                                   grid generator (its order, its spacing per axis); the schema's
                                   grid has one spacing and another fill order
      orientation constant values → heading constant
      orientation gaussian mean/std_dev → heading gaussian
      orientation uniform min/max → heading uniform when the range covers 360°, constant when
                                   empty, else a gaussian of the same mean and variance (warned)
  <distribute> of boxes, cylinders or lights: drawn here, once, from the experiment's seed
      (uniform/gaussian/constant/grid as above; boxes and cylinders re-drawn while they overlap
      an earlier one, up to max_trials) → fixed obstacles / lights
  <dynamics2d iterations>                → physics.substeps (ARGoS's physics steps per tick)
  controller: ``controller=`` (one plugin name for every robot, or a mapping from the ARGoS
      controller id or tag to a plugin name), else ``<params plugin="NAME">`` of the controller
      definition. Params: for the ``flocking`` plugin the ARGoS flocking example's
      ``<flocking target_distance gain exponent/>`` and ``<wheel_turning max_speed
      hard/soft/no_turn_angle_threshold/>`` (cm, cm/s, degrees) become target_distance_m, gain,
      exponent, max_speed_mps, hard_turn_deg, soft_turn_deg, no_turn_deg; for any other plugin
      every attribute under ``<params>`` is passed on unchanged, nested ones as "child.attr".

Ignored without a warning because they do not change what is simulated: <system> (threads),
<profiling>, <visualization>, the controllers' ``library``, sensors'/actuators'
``implementation``/``show_rays``/``medium``, the arena's ``positional_grid_size``, a light's
``orientation``/``medium``, ids of obstacles and lights, <media><led/>.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Optional, Union
from xml.parsers import expat

import numpy as np

from composed_sim.world.loader import WorldFileError
from composed_sim.world.schema import World

ARGOS_SUFFIXES = (".argos",)
FLOCKING_PLUGIN = "flocking"

# ARGoS's named colours (core/utility/datatypes/color.cpp).
_COLORS = {
    "black": (0, 0, 0), "white": (255, 255, 255), "red": (255, 0, 0), "green": (0, 255, 0),
    "blue": (0, 0, 255), "magenta": (255, 0, 255), "cyan": (0, 255, 255),
    "yellow": (255, 255, 0), "orange": (255, 140, 0), "brown": (160, 82, 45),
    "purple": (160, 32, 240), "gray10": (26, 26, 26), "gray20": (51, 51, 51),
    "gray30": (77, 77, 77), "gray40": (102, 102, 102), "gray50": (127, 127, 127),
    "gray60": (153, 153, 153), "gray70": (179, 179, 179), "gray80": (204, 204, 204),
    "gray90": (229, 229, 229),
}
# Sensors and actuators the simulator provides to controllers (as the topics of the contract).
_SENSORS = {"footbot_proximity", "footbot_light", "colored_blob_omnidirectional_camera"}
_ACTUATORS = {"differential_steering", "leds"}
_DEVICE_ATTRS = {"implementation", "show_rays", "medium"}      # no effect here
# ARGoS flocking example's <params> → the flocking plugin's parameters (name, factor).
_FLOCKING_PARAMS = {
    ("flocking", "target_distance"): ("target_distance_m", 0.01),   # cm → m
    ("flocking", "gain"): ("gain", 1.0),
    ("flocking", "exponent"): ("exponent", 1.0),
    ("wheel_turning", "max_speed"): ("max_speed_mps", 0.01),        # cm/s → m/s
    ("wheel_turning", "hard_turn_angle_threshold"): ("hard_turn_deg", 1.0),
    ("wheel_turning", "soft_turn_angle_threshold"): ("soft_turn_deg", 1.0),
    ("wheel_turning", "no_turn_angle_threshold"): ("no_turn_deg", 1.0),
}
_TINY_M = 1e-6      # stands for a zero extent where the schema needs a positive one

ControllerChoice = Union[str, Mapping[str, str], None]


class ArgosFileError(WorldFileError):
    """An ARGoS file that cannot be imported; ``problems`` holds one
    ``file:line: element/attribute: message (got "value")`` per problem."""


# --- public API ----------------------------------------------------------------------

def is_argos_file(path: str | os.PathLike) -> bool:
    """True for a path that names an ARGoS experiment file (by its suffix)."""
    return Path(path).suffix.lower() in ARGOS_SUFFIXES


def load_argos(path: str | os.PathLike, *, controller: ControllerChoice = None) -> tuple[World, list[str]]:
    """Read an ARGoS experiment file → (World, warnings). See the module docstring."""
    source = os.fspath(path)
    root = parse_xml(_read(source), source)
    return _Importer(source, controller).run(root)


def loads_argos(text: str | bytes, *, controller: ControllerChoice = None,
                source: str = "<argos>") -> tuple[World, list[str]]:
    """``load_argos`` for a file's contents."""
    data = text.encode("utf-8") if isinstance(text, str) else text
    return _Importer(source, controller).run(parse_xml(data, source))


def warning_text(source: str, warnings: list[str]) -> Optional[str]:
    """The one warning the CLI prints for an import's warnings (None when there are none)."""
    if not warnings:
        return None
    head = (f"{source}: {len(warnings)} ARGoS setting{'s' if len(warnings) != 1 else ''} "
            f"not simulated as written:")
    return head + "".join(f"\n  {w}" for w in warnings)


# --- safe XML with line numbers ------------------------------------------------------

@dataclass
class Node:
    tag: str
    attrib: dict[str, str]
    line: int
    children: list["Node"] = field(default_factory=list)

    def find(self, tag: str) -> Optional["Node"]:
        return next((c for c in self.children if c.tag == tag), None)

    def findall(self, tag: str) -> list["Node"]:
        return [c for c in self.children if c.tag == tag]


class _Forbidden(Exception):
    def __init__(self, line: int, what: str):
        super().__init__(what)
        self.line, self.what = line, what


def parse_xml(data: bytes, source: str) -> Node:
    """Parse XML into Nodes with line numbers; DTDs (and so entity declarations) are refused."""
    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: list[Node] = []
    roots: list[Node] = []

    def forbid(what: str):
        def handler(*_args):
            raise _Forbidden(parser.CurrentLineNumber, what)
        return handler

    def start(tag: str, attrib: dict[str, str]) -> None:
        node = Node(tag, dict(attrib), parser.CurrentLineNumber)
        (stack[-1].children if stack else roots).append(node)
        stack.append(node)

    def end(_tag: str) -> None:
        stack.pop()

    parser.StartDoctypeDeclHandler = forbid("a DOCTYPE (DTD) is not accepted in an ARGoS file")
    parser.EntityDeclHandler = forbid("entity declarations are not accepted")
    parser.ExternalEntityRefHandler = forbid("external entities are not accepted")
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(data, True)
    except _Forbidden as e:
        raise ArgosFileError(f"{source}:{e.line}: unsafe XML: {e.what}") from None
    except expat.ExpatError as e:
        raise ArgosFileError(f"{source}:{e.lineno}: not well-formed XML: "
                             f"{expat.ErrorString(e.code)} (column {e.offset + 1})") from None
    if not roots:
        raise ArgosFileError(f"{source}: no XML element in the file")
    return roots[0]


def _read(source: str) -> bytes:
    try:
        with open(source, "rb") as file:
            return file.read()
    except FileNotFoundError:
        raise ArgosFileError(f"{source}: no such ARGoS file") from None
    except IsADirectoryError:
        raise ArgosFileError(f"{source}: is a directory, not an ARGoS file") from None
    except OSError as e:
        raise ArgosFileError(f"{source}: cannot read the ARGoS file: {e.strerror or e}") from None


# --- the import ----------------------------------------------------------------------

@dataclass
class _ControllerDef:
    node: Node
    ident: str
    tag: str


@dataclass
class _Pose:
    x: float
    y: float
    yaw_deg: float


class _Importer:
    def __init__(self, source: str, controller: ControllerChoice):
        self.source = source
        self.choice = controller
        self.warnings: list[tuple[int, str]] = []   # (line, message)
        self.lines: dict[tuple, int] = {}     # world field path → ARGoS line, for the schema's checks
        self.controllers: dict[str, _ControllerDef] = {}
        self.plugin_params: dict[str, tuple[str, dict[str, Any]]] = {}   # controller id → (plugin, params)

    # -- messages --

    def error(self, node: Node, what: str, message: str, value: Any = None) -> ArgosFileError:
        got = "" if value is None else f' (got "{value}")'
        return ArgosFileError(f"{self.source}:{node.line}: {what}: {message}{got}")

    def warn(self, node: Node, what: str, message: str) -> None:
        self.warnings.append((node.line, f"{self.source}:{node.line}: {what}: {message}"))

    def unknown(self, node: Node, known: set[str], what: Optional[str] = None,
                message: str = "not supported, ignored") -> None:
        """Warn about attributes of ``node`` outside ``known``."""
        for name in node.attrib:
            if name not in known:
                self.warn(node, f"{what or node.tag}/{name}", message)

    # -- values --

    def text(self, node: Node, attr: str, default: Optional[str] = None) -> str:
        value = node.attrib.get(attr)
        if value is None:
            if default is None:
                raise self.error(node, f"{node.tag}/{attr}", "is required")
            return default
        return value

    def number(self, node: Node, attr: str, default: Optional[float] = None, *,
               low: Optional[float] = None, positive: bool = False, unit: str = "") -> float:
        raw = node.attrib.get(attr)
        if raw is None:
            if default is None:
                raise self.error(node, f"{node.tag}/{attr}", "is required")
            return default
        try:
            value = float(raw)
        except ValueError:
            value = math.nan
        kind = "a positive number" if positive else "a number"
        if not math.isfinite(value) or (positive and value <= 0) or (low is not None and value < low):
            need = f"a number >= {low:g}" if low is not None else kind
            raise self.error(node, f"{node.tag}/{attr}", f"must be {need}{unit}", raw)
        return value

    def integer(self, node: Node, attr: str, default: Optional[int] = None, *, low: int = 0) -> int:
        raw = node.attrib.get(attr)
        if raw is None:
            if default is None:
                raise self.error(node, f"{node.tag}/{attr}", "is required")
            return default
        try:
            value = int(raw.strip())
        except ValueError:
            raise self.error(node, f"{node.tag}/{attr}", f"must be a whole number >= {low}", raw) from None
        if value < low:
            raise self.error(node, f"{node.tag}/{attr}", f"must be a whole number >= {low}", raw)
        return value

    def vector(self, node: Node, attr: str, default: Optional[tuple] = None, *,
               positive: bool = False, nonnegative: bool = False, unit: str = "") -> tuple[float, float, float]:
        raw = node.attrib.get(attr)
        if raw is None:
            if default is None:
                raise self.error(node, f"{node.tag}/{attr}", "is required")
            return default
        parts = raw.split(",")
        try:
            values = tuple(float(p) for p in parts)
        except ValueError:
            values = ()
        sign = " positive" if positive else " non-negative" if nonnegative else ""
        if len(values) != 3 or not all(math.isfinite(v) for v in values) \
                or (positive and min(values) <= 0) or (nonnegative and min(values) < 0):
            raise self.error(node, f"{node.tag}/{attr}",
                             f'must be three{sign} numbers "x,y,z"{unit}', raw)
        return values

    def boolean(self, node: Node, attr: str, default: bool) -> bool:
        raw = node.attrib.get(attr)
        if raw is None:
            return default
        value = raw.strip().lower()
        if value in ("true", "1"):
            return True
        if value in ("false", "0"):
            return False
        raise self.error(node, f"{node.tag}/{attr}", 'must be "true" or "false"', raw)

    def color(self, node: Node, attr: str, default: tuple[int, int, int]) -> tuple[int, int, int]:
        raw = node.attrib.get(attr)
        if raw is None:
            return default
        if raw.strip() in _COLORS:
            return _COLORS[raw.strip()]
        try:
            values = [int(p) for p in raw.split(",")]
        except ValueError:
            values = []
        if len(values) not in (3, 4) or not all(0 <= v <= 255 for v in values):
            raise self.error(node, f"{node.tag}/{attr}", f'must be a colour name '
                             f'({", ".join(_COLORS)}) or "r,g,b[,a]" with values 0..255', raw)
        if len(values) == 4 and values[3] != 255:
            self.warn(node, f"{node.tag}/{attr}", "the alpha channel is not simulated, ignored")
        return tuple(values[:3])

    # -- document --

    def run(self, root: Node) -> tuple[World, list[str]]:
        if root.tag != "argos-configuration":
            raise self.error(root, root.tag, "the root element of an ARGoS file must be "
                             "<argos-configuration>", root.tag)
        known = {"framework", "controllers", "loop_functions", "arena", "physics_engines", "media",
                 "visualization"}
        for child in root.children:
            if child.tag not in known:
                self.warn(child, child.tag, "unknown element, ignored")
        data: dict[str, Any] = {"name": _world_name(self.source)}
        framework = root.find("framework")
        if framework is None:
            raise self.error(root, "argos-configuration", "needs a <framework> with an <experiment>")
        data.update(self.framework(framework))
        controllers = root.find("controllers")
        if controllers is not None:
            self.read_controllers(controllers)
        loops = root.find("loop_functions")
        if loops is not None:
            self.warn(loops, "loop_functions", "loop functions (C++ code) are not run")
        engines = root.find("physics_engines")
        if engines is not None:
            data["physics"] = self.physics(engines)
        media = root.find("media")
        if media is not None:
            for medium in media.children:
                if medium.tag != "led":
                    self.warn(medium, f"media/{medium.tag}", "this medium is not simulated")
        arena = root.find("arena")
        if arena is None:
            raise self.error(root, "argos-configuration", "needs an <arena>")
        rng = np.random.default_rng(data.get("seed", 0))   # only for distributed obstacles and lights
        data.update(self.arena(arena, rng))
        if not any(g["count"] for g in data["robots"]):
            raise self.error(arena, "arena", "has no foot-bot to simulate")
        ordered = sorted(dict.fromkeys(self.warnings), key=lambda w: w[0])   # by line, once each
        return self.validate(data), [text for _, text in ordered]

    def validate(self, data: dict) -> World:
        from composed_sim.world import loader
        try:
            return loader.validate(data, self.source, self.lines)
        except ArgosFileError:
            raise
        except WorldFileError as e:
            raise ArgosFileError(str(e), e.problems) from None

    def framework(self, node: Node) -> dict:
        out: dict[str, Any] = {}
        for child in node.children:
            if child.tag not in ("system", "experiment", "profiling"):
                self.warn(child, f"framework/{child.tag}", "unknown element, ignored")
        exp = node.find("experiment")
        if exp is None:
            raise self.error(node, "framework", "needs an <experiment length=.. ticks_per_second=..>")
        self.unknown(exp, {"length", "ticks_per_second", "random_seed"}, "experiment")
        tps = self.integer(exp, "ticks_per_second", low=1)
        if tps > 1000:
            raise self.error(exp, "experiment/ticks_per_second", "must be at most 1000", exp.attrib["ticks_per_second"])
        length_s = self.number(exp, "length", 0.0, low=0.0, unit=" (seconds)")
        ticks = math.floor(length_s * tps + 1e-9)
        for key in ("ticks_per_second", "length_ticks", "seed"):
            self.lines[(key,)] = exp.line
        out["ticks_per_second"] = tps
        if length_s == 0:
            default = World.model_fields["length_ticks"].default
            self.warn(exp, "experiment/length", f"0 (run until stopped) is not supported: "
                      f"{default} ticks are run (give --ticks to change it)")
        elif ticks < 1:
            raise self.error(exp, "experiment/length", f"is shorter than one tick (1/{tps} s)",
                             exp.attrib["length"])
        else:
            out["length_ticks"] = ticks
        seed = self.integer(exp, "random_seed", 0)
        if seed >= 2**32:
            raise self.error(exp, "experiment/random_seed", "must be below 2^32", seed)
        if seed == 0:
            self.warn(exp, "experiment/random_seed", "0 or missing: ARGoS would seed from the "
                      "clock; seed 0 is used (give --seed to change it)")
        out["seed"] = seed
        return out

    def physics(self, node: Node) -> dict:
        out: dict[str, Any] = {}
        for engine in node.children:
            if engine.tag != "dynamics2d":
                self.warn(engine, f"physics_engines/{engine.tag}", "only a dynamics2d engine is "
                          "simulated (as a 2D engine over the whole arena)")
                continue
            self.unknown(engine, {"id", "iterations"}, "dynamics2d")
            for child in engine.children:
                self.warn(child, f"dynamics2d/{child.tag}", "not supported, ignored")
            if "iterations" in engine.attrib:
                steps = self.integer(engine, "iterations", low=1)
                if steps > 100:
                    raise self.error(engine, "dynamics2d/iterations", "must be at most 100", steps)
                out["substeps"] = steps
                self.lines[("physics",)] = engine.line
        return out

    # -- controllers --

    def read_controllers(self, node: Node) -> None:
        for definition in node.children:
            ident = definition.attrib.get("id")
            if not ident:
                raise self.error(definition, f"{definition.tag}/id", "a controller needs an id")
            self.controllers[ident] = _ControllerDef(definition, ident, definition.tag)

    def controller_for(self, ref: Node, config: str) -> tuple[str, dict[str, Any]]:
        """(plugin name, params) for the controller definition with id ``config``."""
        if config in self.plugin_params:
            return self.plugin_params[config]
        definition = self.controllers.get(config)
        if definition is None:
            known = ", ".join(self.controllers) or "none"
            raise self.error(ref, "controller/config", f"no controller with this id in "
                             f"<controllers> (defined: {known})", config)
        node = definition.node
        params = node.find("params")
        plugin = None
        if isinstance(self.choice, str):
            plugin = self.choice
        elif isinstance(self.choice, Mapping):
            plugin = self.choice.get(config) or self.choice.get(definition.tag)
        if plugin is None and params is not None:
            plugin = params.attrib.get("plugin")
        if not plugin:
            raise self.error(node, f"{definition.tag} id=\"{config}\"", 'which controller plugin '
                             'runs it? give --controller NAME or <params plugin="NAME">')
        self.unknown(node, {"id", "library"}, definition.tag)
        for child in node.children:
            if child.tag == "sensors":
                self.devices(child, _SENSORS, config, "sensor")
            elif child.tag == "actuators":
                self.devices(child, _ACTUATORS, config, "actuator")
            elif child.tag != "params":
                self.warn(child, f"{definition.tag}/{child.tag}", "not supported, ignored")
        values = self.params(params, plugin, config) if params is not None else {}
        self.plugin_params[config] = (plugin, values)
        return plugin, values

    def devices(self, node: Node, supported: set[str], config: str, kind: str) -> None:
        for device in node.children:
            if device.tag not in supported:
                self.warn(device, f"{device.tag}", f"{kind} of controller {config} is not simulated")
            else:
                self.unknown(device, _DEVICE_ATTRS, device.tag)
                for child in device.children:
                    self.warn(child, f"{device.tag}/{child.tag}", "not supported, ignored")

    def params(self, node: Node, plugin: str, config: str) -> dict[str, Any]:
        if plugin == FLOCKING_PLUGIN:
            return self.flocking_params(node)
        out: dict[str, Any] = {}

        def walk(n: Node, prefix: str) -> None:
            for name, raw in n.attrib.items():
                if not prefix and name == "plugin":
                    continue
                out[prefix + name] = _param_value(raw)
            for child in n.children:
                walk(child, f"{prefix}{child.tag}.")
        walk(node, "")
        return out

    def flocking_params(self, node: Node) -> dict[str, Any]:
        out: dict[str, Any] = {}
        self.unknown(node, {"plugin"}, "params", "not a parameter of the flocking plugin, ignored")
        for child in node.children:
            if child.tag not in ("flocking", "wheel_turning"):
                self.warn(child, f"params/{child.tag}", "not a parameter of the flocking plugin, ignored")
                continue
            for attr in child.attrib:
                target = _FLOCKING_PARAMS.get((child.tag, attr))
                if target is None:
                    self.warn(child, f"{child.tag}/{attr}", "not a parameter of the flocking plugin, ignored")
                    continue
                name, factor = target
                if name in ("target_distance_m", "max_speed_mps"):
                    value = self.number(child, attr, positive=True, unit=" (cm or cm/s)")
                elif name.endswith("_deg"):
                    value = self.number(child, attr, low=0.0, unit=" (degrees)")
                else:
                    value = self.number(child, attr)
                out[name] = value * factor
        return out

    # -- arena --

    def arena(self, node: Node, rng: np.random.Generator) -> dict:
        self.unknown(node, {"size", "center", "positional_grid_size"}, "arena")
        size = self.vector(node, "size", positive=True, unit=" in m")
        center = self.vector(node, "center", (0.0, 0.0, 0.0), unit=" in m")
        self.lines[("arena",)] = node.line
        out: dict[str, Any] = {"arena": {"center": [center[0], center[1]], "size": [size[0], size[1]],
                                         "walls": False},
                               "lights": [], "obstacles": [], "robots": []}
        for child in node.children:
            if child.tag == "box":
                out["obstacles"].append(self.box(child, None))
                self.lines[("obstacles", len(out["obstacles"]) - 1)] = child.line
            elif child.tag == "cylinder":
                out["obstacles"].append(self.cylinder(child, None))
                self.lines[("obstacles", len(out["obstacles"]) - 1)] = child.line
            elif child.tag == "light":
                out["lights"].append(self.light(child, None))
                self.lines[("lights", len(out["lights"]) - 1)] = child.line
            elif child.tag == "foot-bot":
                self.explicit_robot(child, out["robots"])
            elif child.tag == "distribute":
                pass        # after the explicit entities, as ARGoS places them
            elif child.tag == "floor":
                self.warn(child, "floor", "the floor (ground sensor colours) is not simulated")
            else:
                self.warn(child, child.tag, "this entity type is not simulated, ignored")
        for child in node.findall("distribute"):
            self.distribute(child, out, rng)
        self.name_robots(out["robots"])
        return out

    def name_robots(self, groups: list[dict]) -> None:
        """Drop the bookkeeping of explicit groups; warn where a robot's name is not its ARGoS id."""
        counters: dict[str, int] = {}
        for group in groups:
            prefix = group["name_prefix"]
            start = counters.get(prefix, 0)
            counters[prefix] = start + group["count"]
            ids = group.pop("_ids", None)
            group.pop("_explicit", None)
            for i, (node, ident) in enumerate(ids or []):
                if ident != f"{prefix}{start + i}":
                    self.warn(node, "foot-bot/id", f'"{ident}" is named {prefix}{start + i} here '
                              f"(robot names are a prefix and a running number)")

    def body(self, entity: Node, pose: Optional[_Pose]) -> _Pose:
        if pose is not None:
            return pose
        body = entity.find("body")
        if body is None:
            raise self.error(entity, f"{entity.tag}/body", "is required (<body position=\"x,y,z\" "
                             "orientation=\"yaw,pitch,roll\"/>)")
        self.unknown(body, {"position", "orientation"}, f"{entity.tag}/body")
        x, y, z = self.vector(body, "position", unit=" in m")
        yaw, pitch, roll = self.vector(body, "orientation", (0.0, 0.0, 0.0), unit=" in degrees")
        if z != 0:
            self.warn(body, f"{entity.tag}/body/position", f"z = {z:g} m: the simulation is planar, "
                      "placed on the floor")
        if pitch or roll:
            self.warn(body, f"{entity.tag}/body/orientation", "pitch and roll are not simulated; "
                      "only the yaw is used")
        return _Pose(x, y, yaw)

    def obstacle_common(self, node: Node) -> dict:
        """The movable flag and mass (kg; ARGoS requires it for a movable body)."""
        for child in node.children:
            if child.tag != "body":
                self.warn(child, f"{node.tag}/{child.tag}", "not supported, ignored")
        if not self.boolean(node, "movable", False):
            return {}
        return {"movable": True, "mass_kg": self.number(node, "mass", positive=True, unit=" (kg)")}

    def box(self, node: Node, pose: Optional[_Pose]) -> dict:
        self.unknown(node, {"id", "size", "movable", "mass"}, "box")
        size = self.vector(node, "size", positive=True, unit=" in m")
        movable = self.obstacle_common(node)
        p = self.body(node, pose)
        return {"type": "box", "position": [p.x, p.y], "size": [size[0], size[1]],
                "height_m": size[2], "yaw_rad": math.radians(p.yaw_deg), **movable}

    def cylinder(self, node: Node, pose: Optional[_Pose]) -> dict:
        self.unknown(node, {"id", "radius", "height", "movable", "mass"}, "cylinder")
        radius = self.number(node, "radius", positive=True, unit=" (m)")
        height = self.number(node, "height", positive=True, unit=" (m)")
        movable = self.obstacle_common(node)
        p = self.body(node, pose)
        return {"type": "cylinder", "position": [p.x, p.y], "radius_m": radius, "height_m": height,
                **movable}

    def light(self, node: Node, pose: Optional[_Pose], z: float = 0.0) -> dict:
        self.unknown(node, {"id", "position", "orientation", "color", "intensity", "medium"}, "light")
        for child in node.children:
            self.warn(child, f"light/{child.tag}", "not supported, ignored")
        if pose is None:
            x, y, z = self.vector(node, "position", unit=" in m")
        else:
            x, y = pose.x, pose.y
        if z < 0:
            raise self.error(node, "light/position", "z (the light's height) must be >= 0",
                             node.attrib.get("position"))
        return {"position": [x, y], "height_m": z,
                "intensity": self.number(node, "intensity", 1.0, low=0.0),
                "color": list(self.color(node, "color", (255, 255, 0)))}

    # -- robots --

    def footbot(self, node: Node, *, explicit: bool) -> tuple[str, dict]:
        """(name prefix, group fields shared by every robot this element makes)."""
        self.unknown(node, {"id", "omnidirectional_camera_aperture"}, "foot-bot")
        ident = self.text(node, "id")
        for child in node.children:
            if child.tag not in ("body", "controller"):
                self.warn(child, f"foot-bot/{child.tag}", "not supported, ignored")
        ref = node.find("controller")
        if ref is None:
            raise self.error(node, "foot-bot/controller", 'is required (<controller config="ID"/>)')
        self.unknown(ref, {"config"}, "foot-bot/controller")
        plugin, params = self.controller_for(ref, self.text(ref, "config"))
        group: dict[str, Any] = {"model": "foot-bot", "controller": plugin, "params": dict(params)}
        if "omnidirectional_camera_aperture" in node.attrib:
            aperture = self.number(node, "omnidirectional_camera_aperture", positive=True,
                                   unit=" (degrees)")
            if aperture >= 90:
                raise self.error(node, "foot-bot/omnidirectional_camera_aperture",
                                 "must be below 90 degrees", node.attrib["omnidirectional_camera_aperture"])
            group["camera"] = {"aperture_deg": aperture}
        prefix = _name_prefix(re.sub(r"\d+$", "", ident) if explicit else ident)
        if not explicit and prefix != ident:
            self.warn(node, "foot-bot/id", f'robots are named {prefix}0, {prefix}1, ... (a ROS '
                      f'name needs a letter first, then letters, digits or _)')
        return prefix, group

    def explicit_robot(self, node: Node, groups: list[dict]) -> None:
        prefix, group = self.footbot(node, explicit=True)
        pose = self.body(node, None)
        heading = {"method": "constant", "value_rad": math.radians(pose.yaw_deg)}
        last = groups[-1] if groups else None
        shared = ("model", "controller", "params", "camera")
        if (last is not None and last.get("_explicit") and last["name_prefix"] == prefix
                and last["heading"] == heading
                and all(last.get(k) == group.get(k) for k in shared)):
            last["count"] += 1
            last["placement"]["positions"].append([pose.x, pose.y])
            last["_ids"].append((node, node.attrib["id"]))
        else:
            groups.append({**group, "count": 1, "name_prefix": prefix, "_explicit": True,
                           "_ids": [(node, node.attrib["id"])],
                           "placement": {"method": "explicit", "positions": [[pose.x, pose.y]]},
                           "heading": heading})
            self.lines[("robots", len(groups) - 1)] = node.line

    def distribute(self, node: Node, out: dict, rng: np.random.Generator) -> None:
        position, orientation, entity = (node.find(t) for t in ("position", "orientation", "entity"))
        for tag, child in (("position", position), ("orientation", orientation), ("entity", entity)):
            if child is None:
                raise self.error(node, f"distribute/{tag}", "is required")
        for child in node.children:
            if child.tag not in ("position", "orientation", "entity"):
                self.warn(child, f"distribute/{child.tag}", "unknown element, ignored")
        self.unknown(entity, {"quantity", "max_trials", "base_num"}, "distribute/entity")
        quantity = self.integer(entity, "quantity", low=0)
        max_trials = self.integer(entity, "max_trials", low=0)
        if self.integer(entity, "base_num", 0) != 0:
            self.warn(entity, "entity/base_num", "robot numbering always starts at 0 here")
        if not entity.children:
            raise self.error(entity, "distribute/entity", "needs the entity to distribute inside it")
        template = entity.children[0]
        for extra in entity.children[1:]:
            self.warn(extra, f"entity/{extra.tag}", "ARGoS distributes only the first entity, "
                      "ignored (as in ARGoS)")
        if template.tag == "foot-bot":
            prefix, group = self.footbot(template, explicit=False)
            group.update(name_prefix=prefix, count=quantity)
            group["placement"] = self.placement(position, quantity, max(1, max_trials))
            group["heading"] = self.heading(orientation)
            out["robots"].append(group)
            self.lines[("robots", len(out["robots"]) - 1)] = node.line
        elif template.tag in ("box", "cylinder", "light"):
            self.distribute_static(template, position, orientation, quantity, max_trials, out, rng)
        else:
            self.warn(template, template.tag, f"this entity type is not simulated: {quantity} "
                      "distributed entities ignored")

    def placement(self, node: Node, count: int, max_trials: int) -> dict:
        method = self.text(node, "method")
        what = "position"
        if method == "uniform":
            self.unknown(node, {"method", "min", "max"}, what)
            lo, hi = self.vector(node, "min", unit=" in m"), self.vector(node, "max", unit=" in m")
            if any(a > b for a, b in zip(lo, hi)):
                raise self.error(node, "position/min", "must not exceed max in any coordinate",
                                 node.attrib["min"])
            self.planar(node, lo[2], hi[2])
            sx, sy = hi[0] - lo[0], hi[1] - lo[1]
            if min(sx, sy) == 0 and count > 0:
                self.warn(node, "position", "a zero-width range: placed on a line (as ARGoS)")
            return {"method": "uniform", "center": [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2],
                    "size": [max(sx, _TINY_M), max(sy, _TINY_M)], "max_trials": max_trials}
        if method == "gaussian":
            self.unknown(node, {"method", "mean", "std_dev"}, what)
            mean = self.vector(node, "mean", unit=" in m")
            std = self.vector(node, "std_dev", nonnegative=True, unit=" in m")
            self.planar(node, mean[2], mean[2] + std[2])
            s = std[0]
            if std[0] != std[1]:
                s = math.sqrt(std[0] * std[1])
                self.warn(node, "position/std_dev", f"different x and y spreads: one std of "
                          f"{s:.4g} m (their geometric mean) is used")
            return {"method": "gaussian", "center": [mean[0], mean[1]], "std_m": max(s, _TINY_M),
                    "max_trials": max_trials}
        if method == "constant":
            self.unknown(node, {"method", "values"}, what)
            x, y, z = self.vector(node, "values", unit=" in m")
            self.planar(node, z, z)
            if count > 1:
                raise self.error(node, "position/values", f"{count} robots at one constant position "
                                 "can never be placed without overlap (ARGoS fails too)",
                                 node.attrib["values"])
            return {"method": "explicit", "positions": [[x, y]] * count}
        if method == "grid":
            return {"method": "explicit", "positions": [[x, y] for x, y, _ in self.grid(node, count)]}
        raise self.error(node, "position/method", "must be uniform, gaussian, constant or grid", method)

    def grid(self, node: Node, count: int) -> list[tuple[float, float, float]]:
        """ARGoS's GridGenerator: the i-th value, exactly as ARGoS computes it."""
        self.unknown(node, {"method", "center", "distances", "layout"}, node.tag)
        center = self.vector(node, "center")
        dist = self.vector(node, "distances")
        raw = self.text(node, "layout")
        try:
            layout = [int(v) for v in raw.split(",")]
        except ValueError:
            layout = []
        if len(layout) != 3 or min(layout) < 1:
            raise self.error(node, f"{node.tag}/layout", 'must be three whole numbers >= 1 "nx,ny,nz"', raw)
        nx, ny, nz = layout
        if count > nx * ny * nz:
            raise self.error(node, f"{node.tag}/layout", f"holds {nx * ny * nz} entities, fewer than "
                             f"the quantity {count}", raw)
        if node.tag == "position" and count > nx * ny:
            raise self.error(node, "position/layout", "more than one layer (nz > 1) would stack "
                             "robots on top of each other; the simulation is planar", raw)
        out = []
        for i in range(count):
            out.append((center[0] + (nx - 1) * dist[0] * 0.5 - (i % nx) * dist[0],
                        center[1] + (ny - 1) * dist[1] * 0.5 - (i // nx) % ny * dist[1],
                        center[2] + (nz - 1) * dist[2] * 0.5 - (i // (nx * ny)) * dist[2]))
        return out

    def planar(self, node: Node, z_lo: float, z_hi: float) -> None:
        if z_lo != 0 or z_hi != 0:
            self.warn(node, f"{node.tag}", "z is not simulated (planar): placed on the floor")

    def heading(self, node: Node) -> dict:
        method = self.text(node, "method")
        if method == "constant":
            self.unknown(node, {"method", "values"}, "orientation")
            yaw, pitch, roll = self.vector(node, "values", unit=" in degrees")
            self.flat(node, pitch, roll)
            return {"method": "constant", "value_rad": math.radians(yaw)}
        if method == "gaussian":
            self.unknown(node, {"method", "mean", "std_dev"}, "orientation")
            mean = self.vector(node, "mean", unit=" in degrees")
            std = self.vector(node, "std_dev", nonnegative=True, unit=" in degrees")
            self.flat(node, mean[1] or std[1], mean[2] or std[2])
            return {"method": "gaussian", "value_rad": math.radians(mean[0]),
                    "std_rad": math.radians(std[0])}
        if method == "uniform":
            self.unknown(node, {"method", "min", "max"}, "orientation")
            lo, hi = self.vector(node, "min", unit=" in degrees"), self.vector(node, "max", unit=" in degrees")
            if any(a > b for a, b in zip(lo, hi)):
                raise self.error(node, "orientation/min", "must not exceed max in any coordinate",
                                 node.attrib["min"])
            self.flat(node, lo[1] or hi[1], lo[2] or hi[2])
            span = hi[0] - lo[0]
            if span >= 360:
                return {"method": "uniform"}
            if span == 0:
                return {"method": "constant", "value_rad": math.radians(lo[0])}
            self.warn(node, "orientation", f"a uniform yaw in [{lo[0]:g}, {hi[0]:g}] degrees is "
                      f"drawn from a gaussian of the same mean and spread (headings are uniform "
                      f"over the full circle, constant or gaussian)")
            return {"method": "gaussian", "value_rad": math.radians((lo[0] + hi[0]) / 2),
                    "std_rad": math.radians(span / math.sqrt(12))}
        if method == "grid":
            self.grid(node, 0)
            self.warn(node, "orientation/method", "grid orientations are not supported: every "
                      "robot gets the grid's center yaw")
            return {"method": "constant", "value_rad": math.radians(self.vector(node, "center")[0])}
        raise self.error(node, "orientation/method", "must be uniform, gaussian, constant or grid", method)

    def flat(self, node: Node, pitch: float, roll: float) -> None:
        if pitch or roll:
            self.warn(node, "orientation", "pitch and roll are not simulated; only the yaw is used")

    # -- distributed obstacles and lights: drawn once, here --

    def distribute_static(self, template: Node, position: Node, orientation: Node, quantity: int,
                          max_trials: int, out: dict, rng: np.random.Generator) -> None:
        method = self.text(position, "method")
        grid = self.grid(position, quantity) if method == "grid" else None
        yaw_spec = self.heading(orientation)
        placed: list[tuple[float, float, float]] = []          # x, y, bounding radius
        for i in range(quantity):
            for trial in range(max(1, max_trials) + 1):
                x, y, z = grid[i] if grid else self.draw_position(position, rng)
                yaw = _draw_yaw(yaw_spec, rng)
                pose = _Pose(x, y, math.degrees(yaw))
                if template.tag == "light":
                    out["lights"].append(self.light(template, pose, z))
                    self.lines[("lights", len(out["lights"]) - 1)] = template.line
                    break
                item = self.box(template, pose) if template.tag == "box" else self.cylinder(template, pose)
                reach = item["radius_m"] if item["type"] == "cylinder" else math.hypot(*item["size"]) / 2
                if all(math.hypot(x - px, y - py) >= reach + pr for px, py, pr in placed) or grid:
                    placed.append((x, y, reach))
                    out["obstacles"].append(item)
                    self.lines[("obstacles", len(out["obstacles"]) - 1)] = template.line
                    break
            else:
                raise self.error(template, f"distribute/{template.tag}", f"could place only {i} of "
                                 f"{quantity} without overlap in max_trials = {max_trials} draws")

    def draw_position(self, node: Node, rng: np.random.Generator) -> tuple[float, float, float]:
        method = self.text(node, "method")
        if method == "uniform":
            lo, hi = self.vector(node, "min"), self.vector(node, "max")
            if any(a > b for a, b in zip(lo, hi)):
                raise self.error(node, "position/min", "must not exceed max in any coordinate",
                                 node.attrib["min"])
            return tuple(float(rng.uniform(a, b)) for a, b in zip(lo, hi))
        if method == "gaussian":
            mean, std = self.vector(node, "mean"), self.vector(node, "std_dev", nonnegative=True)
            return tuple(float(rng.normal(m, d)) for m, d in zip(mean, std))
        if method == "constant":
            return self.vector(node, "values")
        raise self.error(node, "position/method", "must be uniform, gaussian, constant or grid", method)


# --- helpers -------------------------------------------------------------------------

def _draw_yaw(spec: dict, rng: np.random.Generator) -> float:
    if spec["method"] == "constant":
        return spec["value_rad"]
    if spec["method"] == "gaussian":
        return float(rng.normal(spec["value_rad"], spec["std_rad"]))
    return float(rng.uniform(-math.pi, math.pi))


def _param_value(raw: str) -> Any:
    """An ARGoS attribute as a parameter value: a whole number, a number, true/false or text."""
    text = raw.strip()
    if re.fullmatch(r"[+-]?\d+", text):
        return int(text)
    try:
        value = float(text)
        if math.isfinite(value):
            return value
    except ValueError:
        pass
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    return raw


def _name_prefix(ident: str) -> str:
    """A ROS name token from an ARGoS id: other characters become _, a letter first."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", ident)
    return token if re.match(r"[A-Za-z]", token) else f"r{token}"


def _world_name(source: str) -> str:
    stem = Path(source).stem
    return stem if stem and not stem.startswith("<") else "argos"
