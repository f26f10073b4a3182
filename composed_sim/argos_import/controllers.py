"""The ``<controllers>`` section: which plugin runs each ARGoS controller, its ``<params>``
translated by the plugin's own declaration (composed_sim.plugins.ArgosPort), and its
``<sensors>``/``<actuators>`` mapped onto our devices (composed_sim/argos_import/devices.py)."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Union

from composed_sim import plugins
from composed_sim.argos_import.attributes import AttributeReader
from composed_sim.argos_import.devices import device_settings
from composed_sim.argos_import.xml_reader import XmlElement

ControllerChoice = Union[str, Mapping[str, str], None]


@dataclass
class _ControllerDef:
    node: XmlElement
    ident: str
    tag: str


@dataclass(frozen=True)
class RobotController:
    """What a robot's ``<controller config=ID>`` makes of its group: the plugin, its params and
    the device settings (Devices fields of the world schema)."""
    plugin: str
    params: dict[str, Any]
    devices: dict[str, dict]
    topics: tuple[str, ...]                  # the sensor topics the plugin reads


class ControllerTranslator(AttributeReader):
    def __init__(self, source: str, choice: ControllerChoice):
        super().__init__(source)
        self.choice = choice
        self.controllers: dict[str, _ControllerDef] = {}
        self.translated: dict[str, RobotController] = {}   # controller id → its translation
        self._ports: Optional[dict[str, tuple[str, plugins.ArgosPort]]] = None

    def read_controllers(self, node: XmlElement) -> None:
        for definition in node.children:
            ident = definition.attrib.get("id")
            if not ident:
                raise self.error(definition, f"{definition.tag}/id", "a controller needs an id")
            self.controllers[ident] = _ControllerDef(definition, ident, definition.tag)

    def ports(self) -> dict[str, tuple[str, plugins.ArgosPort]]:
        if self._ports is None:
            try:
                self._ports = plugins.argos_ports()
            except plugins.PluginError:
                self._ports = {}     # a broken plugin is reported when it is asked for by name
        return self._ports

    def controller_for(self, ref: XmlElement, config: str) -> RobotController:
        """The translation of the controller definition with id ``config``."""
        if config in self.translated:
            return self.translated[config]
        definition = self.controllers.get(config)
        if definition is None:
            known = ", ".join(self.controllers) or "none"
            raise self.error(ref, "controller/config", f"no controller with this id in "
                             f"<controllers> (defined: {known})", config)
        node = definition.node
        params = node.find("params")
        plugin = self.choose_plugin(definition, params)
        self.unknown(node, {"id", "library"}, definition.tag)
        sensors, actuators = (), ()
        for child in node.children:
            if child.tag == "sensors":
                sensors = tuple(child.children)
            elif child.tag == "actuators":
                actuators = tuple(child.children)
            elif child.tag != "params":
                self.warn(child, f"{definition.tag}/{child.tag}", "not supported, ignored")
        for group in (sensors, actuators):
            for device in group:
                if device.tag in ("lua_controller", "buzz_controller"):
                    self.warn(device, device.tag, "Lua and Buzz controllers are not run")
        devices = device_settings(self, sensors, actuators, config)
        values = self.params(params, plugin, definition.tag) if params is not None else {}
        result = RobotController(plugin, values, devices, _sensor_topics(plugin))
        self.translated[config] = result
        return result

    def choose_plugin(self, definition: _ControllerDef, params: Optional[XmlElement]) -> str:
        """--controller, else <params plugin=..>, else the installed plugin that ports it."""
        node, config = definition.node, definition.ident
        if isinstance(self.choice, str):
            return self.choice
        if isinstance(self.choice, Mapping):
            chosen = self.choice.get(config) or self.choice.get(definition.tag)
            if chosen:
                return chosen
        if params is not None and params.attrib.get("plugin"):
            return params.attrib["plugin"]
        found = self.ports().get(definition.tag)
        if found is not None:
            self.warn(node, f'{definition.tag} id="{config}"', f"runs with the installed plugin "
                      f'"{found[0]}", its port of this ARGoS controller')
            return found[0]
        ported = ", ".join(f"{tag} ({name})" for tag, (name, _) in sorted(self.ports().items()))
        raise self.error(node, f'{definition.tag} id="{config}"', "no installed plugin ports this "
                         "ARGoS controller; give --controller NAME (a plugin that does the same "
                         f'job) or <params plugin="NAME"> (ported: {ported or "none"})')

    def params(self, node: XmlElement, plugin: str, controller: str) -> dict[str, Any]:
        """The plugin's parameters from ARGoS's <params> of ``controller`` (its XML tag): through
        the plugin's ArgosPort when it ports this controller (units converted); unchanged (nested
        ones as "child.attr") where <params plugin=NAME> says they were written for this plugin;
        else they are another controller's and the plugin runs with its own defaults. Whatever is
        dropped is listed in one warning: the run goes on, and the user sees what it lost."""
        raw: dict[str, tuple[XmlElement, str, str]] = {}     # path → (element, attribute, text)

        def walk(n: XmlElement, prefix: str) -> None:
            for name, value in n.attrib.items():
                if not (n is node and name == "plugin"):
                    raw[prefix + name] = (n, name, value)
            for child in n.children:
                walk(child, f"{prefix}{child.tag}.")
        walk(node, "")
        try:
            port = plugins.argos_port(plugin)
        except plugins.PluginError:
            port = None          # the run reports an unknown or broken plugin by name
        if port is not None and port.controller == controller:
            out = {port.params[path][0]: self.number(element, attr) * port.params[path][1]
                   for path, (element, attr, _) in raw.items() if path in port.params}
            self._dropped(node, [path for path in raw if path not in port.params],
                          f'no counterpart in the plugin "{plugin}"')
            return out
        if node.attrib.get("plugin") == plugin:
            return {path: _param_value(text) for path, (_, _, text) in raw.items()}
        self._dropped(node, list(raw), f'{controller}\'s; the plugin "{plugin}" runs with its own defaults')
        return {}

    def _dropped(self, node: XmlElement, paths: list[str], why: str) -> None:
        """One warning for the <params> attributes a run goes without."""
        if paths:
            self.warn(node, "params", f"{len(paths)} ARGoS parameter{'s' if len(paths) > 1 else ''} dropped "
                                      f"({why}): {', '.join(paths)}")


def _sensor_topics(plugin: str) -> tuple[str, ...]:
    try:
        return tuple(getattr(plugins.load(plugin), "sensors", ()))
    except plugins.PluginError:
        return ()        # the run reports an unknown or broken plugin by name


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
