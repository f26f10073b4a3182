"""What the run and host subcommands share: Ctrl-C handling, loading a world file or an ARGoS
experiment with errors that name the file, and the discovery settings."""
from __future__ import annotations

import os
import signal
import sys

from composed_sim.cli.settings import WorldSource
from composed_sim.command_line import EXIT_INTERRUPTED, UserError
from composed_sim.hosts.settings import DiscoverySettings


class Interrupts:
    """First Ctrl-C/SIGTERM: stop at the next tick boundary and write results. Second: exit now."""

    def __init__(self, message: str = "stopping at the next tick"):
        self.requested = False
        self.on_second = None    # called before a hard quit, e.g. to close a recording
        self.message = message

    def __enter__(self):
        self._old = {s: signal.signal(s, self._handle) for s in (signal.SIGINT, signal.SIGTERM)}
        return self

    def _handle(self, signum, frame):
        if self.requested:
            if self.on_second is not None:
                self.on_second()
            os._exit(EXIT_INTERRUPTED)
        self.requested = True
        print(f"\ncomposed-sim: {self.message} (again to quit at once)", file=sys.stderr)

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)


def check_plugins(world_path, world) -> None:
    """Every node class the world names loads: one error naming the world file's line and field,
    before any node or process is started."""
    from composed_sim import plugins
    from composed_sim.hosting import before_node_imports, node_field
    from composed_sim.interfaces import InterfaceError, activate
    from composed_sim.world.crazyflies import interfaces_needed
    before_node_imports()
    try:
        activate(world.interfaces, interfaces_needed(world))      # the nodes may import their messages
    except InterfaceError as e:
        raise UserError(str(e)) from None
    places = [(node_field(group, gi, ni), spec) for gi, group in enumerate(world.robots)
              for ni, spec in enumerate(group.node_specs)]
    places += [(("nodes", ni), spec) for ni, spec in enumerate(world.nodes)]
    for field, spec in places:
        try:
            plugins.load(spec.node)
        except plugins.PluginError as e:
            e.field = field
            raise UserError(located(world_path, e)) from None
    from composed_sim.loop_functions import LoopFunctionsError, make
    try:
        make(world)        # loads the class and checks its params; init() comes with the run
    except LoopFunctionsError as e:
        raise UserError(located(world_path, e)) from None


def located(world_path, error: Exception) -> str:
    """The error's message, prefixed with the world file's line of the field it concerns."""
    from composed_sim.world.loader import field_line
    from composed_sim.world.problems import format_path
    field = getattr(error, "field", ())
    if not field and getattr(error, "group_index", None) is not None:    # a PlacementError
        field = ("robots", error.group_index, "placement")
    if not field:
        return str(error)
    message = str(error)
    path = format_path(field)
    if not message.startswith(path.split(".")[0]):
        message = f"{path}: {message}"
    return f"{field_line(world_path, field)}: {message}"


def load_any_world(source: WorldSource):
    """A YAML world file or an ARGoS experiment file, with the command line's overrides."""
    from composed_sim.argos_import import ArgosFileError, is_argos_file, load_argos, warning_text
    from composed_sim.world.loader import WorldFileError, load_world, with_overrides

    try:
        if is_argos_file(source.path):
            try:
                world, warnings = load_argos(source.path, controller=source.controller, ticks=source.ticks)
            except ArgosFileError as e:      # the reason first, then what else the import noticed
                text = warning_text(str(source.path), list(e.warnings))
                raise UserError(str(e) + (f"\ncomposed-sim: warning: {text}" if text else "")) from None
            text = warning_text(str(source.path), warnings)
            if text:
                print(f"composed-sim: warning: {text}", file=sys.stderr)
            return with_overrides(world, robots=source.robots, ticks=source.ticks, seed=source.seed,
                                  source=str(source.path))
        if source.controller is not None:
            raise UserError("--controller: only for ARGoS .argos files (a YAML world names its controllers)")
        return load_world(source.path, robots=source.robots, ticks=source.ticks, seed=source.seed)
    except WorldFileError as e:
        raise UserError(str(e)) from None


def configure_discovery(settings: DiscoverySettings) -> str:
    """Put a distributed run's discovery settings into the environment; what they are, in words."""
    from composed_sim.hosts.discovery import DiscoveryError, configure
    try:
        description, warning = configure(discovery_range=settings.range, static_peers=settings.static_peers,
                                         discovery_server=settings.server)
    except DiscoveryError as e:
        raise UserError(str(e)) from None
    if warning:
        print(f"composed-sim: note: {warning}", file=sys.stderr)
    return description
