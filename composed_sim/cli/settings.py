"""``composed-sim run``'s settings, typed once from its arguments: what the run reads below the
command line instead of the argparse namespace. Their defaults are the parser's (cli/__init__.py
reads them from here)."""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

from composed_sim.command_line import UserError
from composed_sim.hosts.settings import DEFAULT_LISTEN, DiscoverySettings, HostSettings, LinkSecurity, environment_domain


@dataclass(frozen=True)
class WorldSource:
    """A world file (YAML or ARGoS) and what the command line overrides in it."""
    path: Path
    robots: Optional[int] = None
    ticks: Optional[int] = None
    seed: Optional[int] = None
    controller: Optional[str] = None     # an ARGoS file's controller plugin (--controller)


@dataclass(frozen=True)
class LockstepOverrides:
    watchdog_s: Optional[float] = None
    fallback: Optional[str] = None

    def applied_to(self, world):
        """``world`` with these of its lockstep settings replaced."""
        given = {k: v for k, v in (("watchdog_s", self.watchdog_s), ("fallback", self.fallback)) if v is not None}
        return world.model_copy(update={"lockstep": world.lockstep.model_copy(update=given)}) if given else world


@dataclass(frozen=True)
class OutputSettings:
    out: Path = Path("out")
    record: Optional[Path] = None                 # a rosbag2 directory
    record_topics: tuple[str, ...] = ()           # per-robot topic globs recorded too
    picture: bool = True                          # arena.png
    json: bool = False                            # the summary as JSON on stdout
    log_level: str = "warn"                       # the nodes' lines shown on the console


@dataclass(frozen=True)
class LiveSettings:
    markers: bool = False                         # /swarm/markers
    foxglove: Optional[tuple[str, int]] = None    # (host, port) of the Foxglove server
    foxglove_topics: tuple[str, ...] = ()
    wait_for_viewer_s: float = 0.0
    rate: Optional[float] = None                  # at most this many times real time


@dataclass(frozen=True)
class ControlSettings:
    progress: bool = True
    fail_fast: bool = False
    # A program of its own (not called from Python): once everything is written it ends at once
    # (Host.end_before_exit), without destroying its nodes one by one.
    exit_when_done: bool = False


@dataclass(frozen=True)
class RunSettings:
    world: WorldSource
    hosting: HostSettings
    lockstep: LockstepOverrides = field(default_factory=LockstepOverrides)
    outputs: OutputSettings = field(default_factory=OutputSettings)
    live: LiveSettings = field(default_factory=LiveSettings)
    control: ControlSettings = field(default_factory=ControlSettings)

    @property
    def mode(self) -> str:
        """The mode summary.json names: composed, multi-process, external-controllers or machines."""
        if self.hosting.machines is not None:
            return "machines"
        return "external-controllers" if self.hosting.discovery is not None else self.hosting.mode


def typed(cls, args: argparse.Namespace):
    """A frozen settings dataclass (``BenchSettings``, ``SweepSettings``) from the arguments of its
    fields' names."""
    return cls(**{f.name: getattr(args, f.name) for f in dataclasses.fields(cls)})


def run_domain(arg: Optional[int]) -> tuple[int, bool]:
    """The ROS domain of --domain-id, else of $ROS_DOMAIN_ID, else 0; and whether one was given."""
    from composed_sim.world.schema import MAX_DOMAIN
    try:
        value = arg if arg is not None else environment_domain()
    except ValueError as e:
        raise UserError(str(e)) from None
    if value is not None and not 0 <= value <= MAX_DOMAIN:
        raise UserError(f"--domain-id: must be within 0..{MAX_DOMAIN} (got {value})")
    return (0, False) if value is None else (value, True)


def world_source(args: argparse.Namespace, robots: Optional[int]) -> WorldSource:
    return WorldSource(args.world, robots=robots, ticks=getattr(args, "ticks", None), seed=args.seed,
                       controller=args.controller)


def discovery_settings(args: argparse.Namespace) -> DiscoverySettings:
    return DiscoverySettings(args.discovery_timeout, args.discovery_range, args.static_peers, args.discovery_server)


def parse_machines(text: Optional[str]) -> Union[int, tuple[str, ...], None]:
    """--machines: a number of machines, or their addresses or host names, comma-separated."""
    if text is None:
        return None
    text = text.strip()
    if text.isdigit():
        if int(text) < 1:
            raise UserError(f"--machines: at least one machine (got {text})")
        return int(text)
    names = tuple(name.strip() for name in text.split(","))
    if not all(names) or len(set(names)) != len(names):
        raise UserError(f"--machines: expected a number, or addresses or host names separated by commas, each "
                        f"once (got {text!r})")
    return names


def run_settings(args: argparse.Namespace, *, exit_when_done: bool) -> RunSettings:
    """The run's settings from ``composed-sim run``'s arguments; a UserError for a flag that
    needs another or does not apply."""
    domain_id, given = run_domain(args.domain_id)
    if args.record is not None and args.record.exists():
        raise UserError(f"--record {args.record}: already exists; a recording goes into a new directory")
    if args.record_topics and args.record is None:
        raise UserError("--record-topics: needs --record DIR")
    if (args.foxglove_topics or args.wait_for_viewer) and args.foxglove is None:
        raise UserError("--foxglove-topics and --wait-for-viewer: need --foxglove")
    foxglove = None
    if args.foxglove is not None:
        from composed_sim.live.foxglove_server import parse_address
        try:
            foxglove = parse_address(args.foxglove)
        except ValueError as e:
            raise UserError(f"--foxglove: {e}") from None
    discovery = discovery_settings(args)
    machines = parse_machines(args.machines)
    if machines is not None and (args.external_controllers or args.mode != "composed"):
        raise UserError("--machines: the robots' nodes are hosted on those machines' worker processes, so "
                        "--external-controllers and --mode multi-process do not apply")
    for flag, value in (("--listen", args.listen), ("--credentials", args.credentials), ("--insecure", args.insecure)):
        if value and machines is None:
            raise UserError(f"{flag}: only for a run over machines (with --machines)")
    if args.insecure and args.credentials is not None:
        raise UserError("--credentials: not with --insecure (plain tcp:// uses none)")
    if not args.external_controllers:
        given_flags = [flag for flag, value in (("--discovery-range", discovery.range),
                                                ("--static-peers", discovery.static_peers),
                                                ("--discovery-server", discovery.server)) if value is not None]
        if given_flags:
            raise UserError(f"{given_flags[0]}: only for a distributed run (with --external-controllers)")
    elif args.mode != "composed":
        raise UserError("--external-controllers: the controllers are processes outside the run, "
                        "so --mode multi-process does not apply")
    return RunSettings(
        world=world_source(args, args.robots),
        hosting=HostSettings(mode=args.mode, workers=args.workers, executor=args.executor, domain_id=domain_id,
                             domain_given=given, robots_per_participant=args.robots_per_participant,
                             robots_per_domain=args.robots_per_domain,
                             discovery=discovery if args.external_controllers else None, machines=machines,
                             listen=args.listen or DEFAULT_LISTEN, join_timeout_s=discovery.timeout_s,
                             link=LinkSecurity(None if args.credentials is None else str(args.credentials),
                                               str(args.out), args.insecure)),
        lockstep=LockstepOverrides(args.watchdog, args.fallback),
        outputs=OutputSettings(args.out, args.record, tuple(args.record_topics), not args.no_picture, args.json,
                               args.log_level),
        live=LiveSettings(args.markers, foxglove, tuple(args.foxglove_topics), args.wait_for_viewer, args.rate),
        control=ControlSettings(not args.no_progress, args.fail_fast, exit_when_done))
