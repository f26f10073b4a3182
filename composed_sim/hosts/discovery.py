"""DDS discovery settings for runs spread over machines (pure: no ROS import).

rcl and Fast DDS read them from the environment when a context is initialised, so they are
set here, in this process's environment, before ``rclpy.init``:

ROS_AUTOMATIC_DISCOVERY_RANGE  SUBNET (multicast on the local network; our default for distributed
                               runs), LOCALHOST (this machine only: what the tests and benchmarks use
                               for single-machine runs, and why a controller on another machine
                               would never be found), OFF, SYSTEM_DEFAULT
ROS_STATIC_PEERS               addresses to discover by unicast, ``;``-separated: for networks without
                               multicast (clouds, some Wi-Fi), reached even with LOCALHOST
ROS_DISCOVERY_SERVER           a Fast DDS discovery server (``fastdds discovery -i 0``): for many
                               machines, or none of the above
"""
from __future__ import annotations

import os
from typing import Mapping, MutableMapping, Optional

RANGES = ("subnet", "localhost", "off", "system_default")
MAX_STATIC_PEERS = 32        # RMW_DISCOVERY_PARAMS_MAX_PEERS in rmw


class DiscoveryError(ValueError):
    """A discovery setting that cannot work: the message names it."""


def configure(*, discovery_range: Optional[str] = None, static_peers: Optional[str] = None,
              discovery_server: Optional[str] = None,
              environ: MutableMapping[str, str] = os.environ) -> tuple[str, Optional[str]]:
    """Put the settings for a distributed run into ``environ``; returns (a description for
    messages, a warning or None). Unset options keep what the environment says, except that an
    unset range becomes SUBNET: the one that finds other machines without further setup."""
    if discovery_range is not None:
        if discovery_range.lower() not in RANGES:
            raise DiscoveryError(f"--discovery-range: expected one of {', '.join(RANGES)}, got {discovery_range!r}")
        environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = discovery_range.upper()
        environ.pop("ROS_LOCALHOST_ONLY", None)      # deprecated; would contradict the range
    elif "ROS_AUTOMATIC_DISCOVERY_RANGE" not in environ and environ.get("ROS_LOCALHOST_ONLY") != "1":
        environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    range_ = environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST").upper()
    if range_.lower() not in RANGES:
        raise DiscoveryError(f"ROS_AUTOMATIC_DISCOVERY_RANGE: expected one of {', '.join(r.upper() for r in RANGES)}, "
                             f"got {range_!r}")
    if static_peers is not None:
        environ["ROS_STATIC_PEERS"] = static_peers
    peers = [p.strip() for p in environ.get("ROS_STATIC_PEERS", "").split(";") if p.strip()]
    if static_peers is not None and not peers:
        raise DiscoveryError(f"--static-peers: expected addresses separated by ';', got {static_peers!r}")
    if len(peers) > MAX_STATIC_PEERS:
        raise DiscoveryError(f"ROS_STATIC_PEERS: at most {MAX_STATIC_PEERS} peers (got {len(peers)}); "
                             f"use a discovery server for more machines")
    if discovery_server is not None:
        if not discovery_server.strip():
            raise DiscoveryError("--discovery-server: expected ADDRESS:PORT, e.g. 10.0.0.1:11811")
        environ["ROS_DISCOVERY_SERVER"] = discovery_server
    server = environ.get("ROS_DISCOVERY_SERVER", "").strip()
    warning = None
    if range_ in ("LOCALHOST", "OFF") and not peers and not server:
        reach = "only controllers on this machine" if range_ == "LOCALHOST" else "no controller"
        warning = (f"discovery range is {range_}: {reach} can be found; use --discovery-range subnet, "
                   f"--static-peers or --discovery-server across machines")
    return describe(environ), warning


def describe(environ: Mapping[str, str] = os.environ) -> str:
    """The discovery settings ``environ`` holds, for messages: ``SUBNET + static peers A;B``."""
    description = environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST").upper()
    peers = [p.strip() for p in environ.get("ROS_STATIC_PEERS", "").split(";") if p.strip()]
    if peers:
        description += f" + static peers {';'.join(peers)}"
    if server := environ.get("ROS_DISCOVERY_SERVER", "").strip():
        description += f" + discovery server {server}"
    return description
