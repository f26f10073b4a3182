"""The ``<arena>`` section: its size, walls and obstacles (boxes, cylinders), lights and robots,
explicit or in ``<distribute>`` blocks (their position and orientation generators: generators.py),
placed as ARGoS places them (composed_sim/core/placement.py checks each distributed obstacle against
everything placed before it)."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from composed_sim.argos_import.controllers import ControllerChoice, ControllerTranslator
from composed_sim.argos_import.devices import require_devices
from composed_sim.argos_import.generators import GeneratorReader, draw_yaw
from composed_sim.argos_import.xml_reader import XmlElement
from composed_sim.core.placement import CLEARANCE_M, Statics
from composed_sim.world.robot_models import get_model
from composed_sim.world.schema import Box, Cylinder

# ARGoS robot entity tag → our robot model.
ROBOT_MODELS = {"foot-bot": "foot-bot", "e-puck": "e-puck", "kheperaiv": "kheperaiv"}
# ARGoS robots we do not model: one sentence each.
UNMODELLED_ROBOTS = {
    "eye-bot": "the eye-bot is a flying robot; the simulation is planar, with ground robots only",
    "kilobot": "the Kilobot (vibration drive, infrared messaging) is not modelled",
    "spiri": "the Spiri is a flying robot; the simulation is planar, with ground robots only",
    "builderbot": "the BuilderBot (a 3D lifting robot) is not modelled",
    "drone": "drones fly; the simulation is planar, with ground robots only",
    "pipuck": "the Pi-puck is not modelled",
    "prototype": "prototype entities (robots built from links and joints) are not modelled",
}


@dataclass
class _Pose:
    x: float
    y: float
    yaw_deg: float


class EntityTranslator(ControllerTranslator, GeneratorReader):
    def __init__(self, source: str, choice: ControllerChoice):
        super().__init__(source, choice)
        self.lines: dict[tuple, int] = {}     # world field path → ARGoS line, for the schema's checks
        self.statics = Statics()              # what is placed so far, for distributed obstacles
        self.rab_data_sizes: list[int] = []   # the robots' rab_data_size, for the world's payload

    # -- arena --

    def arena(self, node: XmlElement, rng: np.random.Generator) -> dict:
        self.unknown(node, {"size", "center", "positional_grid_size"}, "arena")
        size = self.vector(node, "size", positive=True, unit=" in m")
        center = self.vector(node, "center", (0.0, 0.0, 0.0), unit=" in m")
        self.lines[("arena",)] = node.line
        out: dict[str, Any] = {"arena": {"center": [center[0], center[1]], "size": [size[0], size[1]],
                                         "walls": False},
                               "lights": [], "obstacles": [], "robots": []}
        # In the file's order, as ARGoS adds entities to its space: a <distribute> avoids what
        # came before it (random robots are placed at the start of the run, avoiding every obstacle).
        for child in node.children:
            if child.tag == "box":
                self.add_obstacle(out, child, self.box(child, None))
            elif child.tag == "cylinder":
                self.add_obstacle(out, child, self.cylinder(child, None))
            elif child.tag == "light":
                out["lights"].append(self.light(child, None))
                self.lines[("lights", len(out["lights"]) - 1)] = child.line
            elif child.tag in ROBOT_MODELS:
                self.explicit_robot(child, out["robots"])
            elif child.tag == "distribute":
                self.distribute(child, out, rng)
            elif child.tag == "floor":
                out.update(self.floor(child, size, center))
            elif child.tag in UNMODELLED_ROBOTS:
                self.warn(child, child.tag, f"{UNMODELLED_ROBOTS[child.tag]}: not simulated")
            else:
                self.warn(child, child.tag, "this entity type is not simulated, ignored")
        self.name_robots(out["robots"])
        if self.rab_data_sizes:
            out["range_and_bearing"] = {"payload_bytes": max(self.rab_data_sizes)}
        return out

    def floor(self, node: XmlElement, size: tuple, center: tuple) -> dict:
        """<floor source="image" path=..> → the floor image stretched over the arena (as ARGoS)."""
        self.unknown(node, {"id", "source", "path", "pixels_per_meter"}, "floor")
        source = self.text(node, "source")
        if source == "image":
            self.lines[("floor", "image")] = node.line
            return {"floor": {"image": self.text(node, "path"), "image_size_m": [size[0], size[1]],
                              "image_center": [center[0], center[1]]}}
        if source == "loop_functions":
            self.warn(node, "floor", "painted by the loop functions, which are not run: a white floor")
        else:
            raise self.error(node, "floor/source", 'must be "image" or "loop_functions"', source)
        return {}

    def add_obstacle(self, out: dict, node: XmlElement, item: dict) -> None:
        out["obstacles"].append(item)
        self.lines[("obstacles", len(out["obstacles"]) - 1)] = node.line
        self.statics.add(_schema_obstacle(item))

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
                    self.warn(node, f"{node.tag}/id", f'"{ident}" is named {prefix}{start + i} here '
                              f"(robot names are a prefix and a running number)")

    def body(self, entity: XmlElement, pose: Optional[_Pose]) -> _Pose:
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

    def obstacle_common(self, node: XmlElement) -> dict:
        """The movable flag and mass (kg; ARGoS requires it for a movable body)."""
        for child in node.children:
            if child.tag != "body":
                self.warn(child, f"{node.tag}/{child.tag}", "not supported, ignored")
        if not self.boolean(node, "movable", False):
            return {}
        return {"movable": True, "mass_kg": self.number(node, "mass", positive=True, unit=" (kg)")}

    def box(self, node: XmlElement, pose: Optional[_Pose]) -> dict:
        self.unknown(node, {"id", "size", "movable", "mass"}, "box")
        size = self.vector(node, "size", positive=True, unit=" in m")
        movable = self.obstacle_common(node)
        p = self.body(node, pose)
        return {"type": "box", "position": [p.x, p.y], "size": [size[0], size[1]],
                "height_m": size[2], "yaw_rad": math.radians(p.yaw_deg), **movable}

    def cylinder(self, node: XmlElement, pose: Optional[_Pose]) -> dict:
        self.unknown(node, {"id", "radius", "height", "movable", "mass"}, "cylinder")
        radius = self.number(node, "radius", positive=True, unit=" (m)")
        height = self.number(node, "height", positive=True, unit=" (m)")
        movable = self.obstacle_common(node)
        p = self.body(node, pose)
        return {"type": "cylinder", "position": [p.x, p.y], "radius_m": radius, "height_m": height,
                **movable}

    def light(self, node: XmlElement, pose: Optional[_Pose], z: float = 0.0) -> dict:
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

    def robot(self, node: XmlElement, *, explicit: bool) -> tuple[str, dict]:
        """(name prefix, group fields shared by every robot this element makes)."""
        tag, model = node.tag, ROBOT_MODELS[node.tag]
        known = {"id", "rab_range", "rab_data_size"}
        if tag == "foot-bot":
            known.add("omnidirectional_camera_aperture")
        self.unknown(node, known, tag)
        ident = self.text(node, "id")
        for child in node.children:
            if child.tag not in ("body", "controller"):
                self.warn(child, f"{tag}/{child.tag}", "not supported, ignored")
        ref = node.find("controller")
        if ref is None:
            raise self.error(node, f"{tag}/controller", 'is required (<controller config="ID"/>)')
        self.unknown(ref, {"config"}, f"{tag}/controller")
        control = self.controller_for(ref, self.text(ref, "config"))
        devices = require_devices(self, node, model, control.devices, control.topics, control.plugin)
        if "rab_range" in node.attrib:
            rab_range = self.number(node, "rab_range", positive=True, unit=" (m)")
            if "range_and_bearing" in devices:
                devices["range_and_bearing"] = {**devices["range_and_bearing"], "range_m": rab_range}
        if "rab_data_size" in node.attrib:
            self.rab_data_sizes.append(self.integer(node, "rab_data_size", low=1))
        group: dict[str, Any] = {"model": model, "controller": control.plugin,
                                 "params": dict(control.params), "devices": devices}
        if "omnidirectional_camera_aperture" in node.attrib:
            aperture = self.number(node, "omnidirectional_camera_aperture", positive=True,
                                   unit=" (degrees)")
            if aperture >= 90:
                raise self.error(node, "foot-bot/omnidirectional_camera_aperture",
                                 "must be below 90 degrees", node.attrib["omnidirectional_camera_aperture"])
            group["camera"] = {"aperture_deg": aperture}
        prefix = _name_prefix(re.sub(r"\d+$", "", ident) if explicit else ident)
        if not explicit and prefix != ident:
            self.warn(node, f"{tag}/id", f'robots are named {prefix}0, {prefix}1, ... (a ROS '
                      f'name needs a letter first, then letters, digits or _)')
        return prefix, group

    def explicit_robot(self, node: XmlElement, groups: list[dict]) -> None:
        prefix, group = self.robot(node, explicit=True)
        pose = self.body(node, None)
        self.statics.add_disc([pose.x, pose.y], get_model(group["model"]).body_radius_m + CLEARANCE_M)
        heading = {"method": "constant", "value_rad": math.radians(pose.yaw_deg)}
        last = groups[-1] if groups else None
        shared = ("model", "controller", "params", "camera", "devices")
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

    def distribute(self, node: XmlElement, out: dict, rng: np.random.Generator) -> None:
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
        if template.tag in ROBOT_MODELS:
            prefix, group = self.robot(template, explicit=False)
            group.update(name_prefix=prefix, count=quantity)
            group["placement"] = self.placement(position, quantity, max(1, max_trials))
            group["heading"] = self.heading(orientation)
            out["robots"].append(group)
            self.lines[("robots", len(out["robots"]) - 1)] = node.line
        elif template.tag in ("box", "cylinder", "light"):
            self.distribute_static(template, position, orientation, quantity, max_trials, out, rng)
        else:
            why = UNMODELLED_ROBOTS.get(template.tag, "this entity type is not simulated")
            self.warn(template, template.tag, f"{why}: {quantity} distributed entities ignored")

    # -- distributed obstacles and lights: drawn once, here --

    def distribute_static(self, template: XmlElement, position: XmlElement, orientation: XmlElement,
                          quantity: int, max_trials: int, out: dict, rng: np.random.Generator) -> None:
        """Boxes, cylinders or lights drawn here, once. As ARGoS's CSpace::Distribute, an obstacle
        that touches anything placed before it (walls, obstacles, explicit robots) is re-drawn,
        up to max_trials times, and the import fails when one cannot be placed."""
        method = self.text(position, "method")
        grid = self.grid(position, quantity) if method == "grid" else None
        yaw_spec = self.heading(orientation)
        for i in range(quantity):
            for _ in range(max(1, max_trials)):
                x, y, z = grid[i] if grid else self.draw_position(position, rng)
                pose = _Pose(x, y, math.degrees(draw_yaw(yaw_spec, rng)))
                if template.tag == "light":
                    out["lights"].append(self.light(template, pose, z))
                    self.lines[("lights", len(out["lights"]) - 1)] = template.line
                    break
                item = self.box(template, pose) if template.tag == "box" else self.cylinder(template, pose)
                if self.statics.obstacle_fits(_schema_obstacle(item)):
                    self.add_obstacle(out, template, item)
                    break
            else:
                raise self.error(template, f"distribute/{template.tag}", f"could place only {i} of "
                                 f"{quantity} without touching what was placed before, in "
                                 f"max_trials = {max_trials} draws each (ARGoS fails too)")


# --- helpers -------------------------------------------------------------------------

def _schema_obstacle(item: dict) -> Box | Cylinder:
    fields = {k: item[k] for k in item if k not in ("movable", "mass_kg")}
    return Box(**fields) if item["type"] == "box" else Cylinder(**fields)


def _name_prefix(ident: str) -> str:
    """A ROS name token from an ARGoS id: other characters become _, a letter first."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", ident)
    return token if re.match(r"[A-Za-z]", token) else f"r{token}"

