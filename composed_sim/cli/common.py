"""What the run and host subcommands share: the ROS domain, Ctrl-C handling, loading a world
file or an ARGoS experiment with errors that name the file, and the discovery settings."""
from __future__ import annotations

import os
import signal
import sys

from composed_sim.command_line import EXIT_INTERRUPTED, UserError



def pick_domain(arg: int | None) -> int:
    text = str(arg) if arg is not None else os.environ.get("ROS_DOMAIN_ID", "0") or "0"
    try:
        value = int(text)
    except ValueError:
        raise UserError(f"ROS_DOMAIN_ID: expected a whole number, got {text!r}") from None
    from composed_sim.world.schema import MAX_DOMAIN
    if not 0 <= value <= MAX_DOMAIN:
        raise UserError(f"--domain-id: must be within 0..{MAX_DOMAIN} (got {value})")
    return value


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
    from composed_sim.hosting.building import node_field
    from composed_sim.interfaces import InterfaceError, activate
    try:
        activate(world.interfaces)      # the nodes may import their messages
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
    from composed_sim.world.loader import field_line, format_path
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


def load_any_world(args):
    """A YAML world file or an ARGoS experiment file, with the command line's overrides."""
    from composed_sim.argos_import import ArgosFileError, is_argos_file, load_argos, warning_text
    from composed_sim.world.loader import WorldFileError, load_world, with_overrides

    try:
        if is_argos_file(args.world):
            try:
                world, warnings = load_argos(args.world, controller=args.controller, ticks=args.ticks)
            except ArgosFileError as e:      # the reason first, then what else the import noticed
                text = warning_text(str(args.world), list(e.warnings))
                raise UserError(str(e) + (f"\ncomposed-sim: warning: {text}" if text else "")) from None
            text = warning_text(str(args.world), warnings)
            if text:
                print(f"composed-sim: warning: {text}", file=sys.stderr)
            return with_overrides(world, robots=args.robots, ticks=args.ticks, seed=args.seed,
                                  source=str(args.world))
        if args.controller is not None:
            raise UserError("--controller: only for ARGoS .argos files (a YAML world names its controllers)")
        return load_world(args.world, robots=args.robots, ticks=args.ticks, seed=args.seed)
    except WorldFileError as e:
        raise UserError(str(e)) from None


def distributed_settings(args) -> str:
    """Check the flags of a distributed run and put its discovery settings into the environment."""
    from composed_sim.hosts.distributed.discovery import DiscoveryError, configure
    if args.command == "run" and args.mode != "composed":
        raise UserError("--external-controllers: the controllers are in `composed-sim host` shards, "
                        "so --mode multi-process does not apply")
    try:
        description, warning = configure(discovery_range=args.discovery_range, static_peers=args.static_peers,
                                         discovery_server=args.discovery_server)
    except DiscoveryError as e:
        raise UserError(str(e)) from None
    if warning:
        print(f"composed-sim: note: {warning}", file=sys.stderr)
    return description


def check_no_distributed_flags(args) -> None:
    given = [flag for flag, value in (("--discovery-range", args.discovery_range), ("--static-peers", args.static_peers),
                                      ("--discovery-server", args.discovery_server)) if value is not None]
    if given:
        raise UserError(f"{given[0]}: only for a distributed run (with --external-controllers)")
