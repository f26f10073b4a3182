"""How a run hosts its controllers: the choices of ``composed-sim run`` and their defaults, typed
once (no rclpy: the command line and the benchmark read them)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Mapping, Optional, Union

from composed_sim.hosting import DEFAULT_EXECUTOR, ROBOTS_PER_PARTICIPANT

MODES = ("composed", "multi-process")
DEFAULT_MODE = MODES[0]
AUTO_WORKERS = "auto"        # --workers auto: from the swarm size and the usable cores (workers/host.py)
DEFAULT_DISCOVERY_TIMEOUT_S = 120.0   # simulator waiting for outside controllers or machines
DEFAULT_LISTEN = "0.0.0.0:0"           # remote workers: every interface, a free port (printed)


@dataclass(frozen=True)
class DiscoverySettings:
    """A distributed run's DDS discovery (hosts/discovery.py); None fields keep what
    the environment says."""
    timeout_s: float = DEFAULT_DISCOVERY_TIMEOUT_S
    range: Optional[str] = None          # ROS_AUTOMATIC_DISCOVERY_RANGE
    static_peers: Optional[str] = None   # ROS_STATIC_PEERS
    server: Optional[str] = None         # ROS_DISCOVERY_SERVER


@dataclass(frozen=True)
class LinkSecurity:
    """How a run over machines guards its port (hosts/machines/credentials.py): mutual TLS with
    credentials of its own (written to ``fresh_into``) or with a file made beforehand; plain
    tcp:// only when ``insecure``."""
    credentials: Optional[str] = None     # a file made beforehand (composed-sim credentials make)
    fresh_into: Optional[str] = None      # else where the run writes its own: OUT/credentials.pem
    insecure: bool = False                # --insecure: no TLS, anyone who reaches the port is in

    def argv(self) -> list[str]:
        return ["--insecure"] if self.insecure else ["--credentials", self.credentials] if self.credentials else []


@dataclass(frozen=True)
class HostSettings:
    """Which host runs the controllers and how (``hosts/make.py`` builds it)."""
    mode: str = DEFAULT_MODE
    workers: Union[int, str] = AUTO_WORKERS     # composed mode: worker processes, or AUTO_WORKERS
    executor: str = DEFAULT_EXECUTOR
    domain_id: int = 0                          # the run's ROS domain (multi-process mode: the first)
    domain_given: bool = False                  # by the user: taken, it is an error, not a reason to pick another
    robots_per_participant: int = ROBOTS_PER_PARTICIPANT    # composed mode in one process
    robots_per_domain: Optional[int] = None     # multi-process mode; None: the world's
    discovery: Optional[DiscoverySettings] = None    # --external-controllers: DDS discovery
    machines: Union[int, tuple[str, ...], None] = None  # remote workers: how many machines, or which
    listen: str = DEFAULT_LISTEN                # remote workers: the simulator's address for the machines
    link: LinkSecurity = LinkSecurity()         # remote workers: mutual TLS, or --insecure
    join_timeout_s: float = DEFAULT_DISCOVERY_TIMEOUT_S

    def argv(self) -> list[str]:
        """The flags of ``composed-sim run`` that ask for these settings (a benchmark's runs)."""
        args = ["--mode", self.mode, "--executor", self.executor]
        if self.domain_given:
            args += ["--domain-id", str(self.domain_id)]
        if self.machines is not None:
            machines = self.machines if isinstance(self.machines, int) else ",".join(self.machines)
            args += ["--machines", str(machines), "--listen", self.listen, *self.link.argv()]
        elif self.mode == "composed":
            args += ["--workers", str(self.workers)]
            if self.robots_per_participant != ROBOTS_PER_PARTICIPANT:
                args += ["--robots-per-participant", str(self.robots_per_participant)]
        elif self.robots_per_domain is not None:
            args += ["--robots-per-domain", str(self.robots_per_domain)]
        return args


def environment_domain(environ: Mapping[str, str] = os.environ) -> Optional[int]:
    """``$ROS_DOMAIN_ID`` as a number, None where it is unset or empty; a ValueError naming it
    where it is no whole number."""
    text = environ.get("ROS_DOMAIN_ID", "")
    if not text:
        return None
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"ROS_DOMAIN_ID: expected a whole number, got {text!r}") from None
