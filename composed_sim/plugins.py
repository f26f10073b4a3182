"""Controller plugins: rclpy Node classes declared in the entry-point group ``composed_sim.controllers``,
or named by ``module:Class`` (any importable Node class, no entry point needed)."""
from __future__ import annotations

import importlib
import inspect
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint
from typing import Mapping

from rclpy.node import Node

from composed_sim import entry_points

GROUP = "composed_sim.controllers"


class PluginError(Exception):
    """A plugin cannot be found, imported or used; the message says which and why. ``field``:
    the world file's field it concerns, e.g. ("robots", 0, "controller"), when known.
    ``user_traceback``: where the user's own code raised (a constructor's), to show once above the
    error's line."""

    def __init__(self, message: str, field: tuple = (), user_traceback: str = ""):
        super().__init__(message)
        self.field = field
        self.user_traceback = user_traceback


def installed() -> dict[str, EntryPoint]:
    """Every installed controller plugin by name; two distributions claiming one name is an error."""
    return entry_points.installed(GROUP, "controller plugin", PluginError)


def load(name: str) -> type[Node]:
    """The Node class ``name`` names: ``module:Class`` (``pkg.module:Class``), or an entry point."""
    if ":" in name:
        cls, origin = _import_class(name), name
    else:
        cls = entry_points.load(GROUP, name, "controller plugin", PluginError,
                                f"; a plugin is an entry point in the group {GROUP!r}, or name a class as module:Class")
        origin = f"controller plugin {name!r} ({installed()[name].value})"
    if not (isinstance(cls, type) and issubclass(cls, Node)):
        raise PluginError(f"{origin} is not an rclpy Node subclass")
    return cls


def _import_class(name: str) -> object:
    module_name, _, attribute = name.partition(":")
    if not module_name or not attribute:
        raise PluginError(f"{name!r}: write a node class as module:Class, e.g. my_pkg.talker:Talker")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if e.name is not None and module_name.startswith(e.name):
            raise PluginError(f"{name!r}: no module named {e.name!r} (is its package installed, or on PYTHONPATH?)") from e
        raise PluginError(f"{name!r}: importing {module_name} failed: {type(e).__name__}: {e}") from e
    except Exception as e:  # any import-time failure is the module's, reported as such
        raise PluginError(f"{name!r}: importing {module_name} failed: {type(e).__name__}: {e}") from e
    cls = module
    for part in attribute.split("."):
        if not hasattr(cls, part):
            nodes = sorted(n for n, v in vars(module).items()
                           if isinstance(v, type) and issubclass(v, Node) and v.__module__ == module.__name__)
            raise PluginError(f"{name!r}: module {module_name} has no {attribute!r} (its Node classes: "
                              f"{', '.join(nodes) or 'none'})")
        cls = getattr(cls, part)
    if not inspect.isclass(cls):
        raise PluginError(f"{name!r} is not a class: a node is an rclpy Node subclass")
    return cls


@dataclass(frozen=True)
class ArgosPort:
    """What a plugin declares when it ports an ARGoS controller, so that the ARGoS importer
    (composed_sim/argos_import) runs an experiment file's controller with it and translates its
    ``<params>``. ``controller``: the ARGoS controller's XML tag (its REGISTER_CONTROLLER label).
    ``params``: ARGoS attribute path under ``<params>`` ("velocity", or "child.attr" for an
    attribute of a nested element) → (the plugin's parameter, factor from ARGoS's unit to ours,
    e.g. 0.01 for cm → m). Attributes not listed are reported as not translated."""
    controller: str
    params: Mapping[str, tuple[str, float]] = field(default_factory=dict)


def argos_ports() -> dict[str, tuple[str, ArgosPort]]:
    """ARGoS controller tag → (plugin name, its port), over every installed plugin that
    declares one (a class attribute ``argos = ArgosPort(...)``). Loads every plugin."""
    found: dict[str, tuple[str, ArgosPort]] = {}
    for name in installed():
        port = getattr(load(name), "argos", None)
        if isinstance(port, ArgosPort):
            found.setdefault(port.controller, (name, port))
    return found


def argos_port(name: str) -> ArgosPort | None:
    """The ARGoS port plugin ``name`` declares, or None."""
    port = getattr(load(name), "argos", None)
    return port if isinstance(port, ArgosPort) else None
