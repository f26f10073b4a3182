"""A run owns its ROS domain, or does not start.

Two simulators in one domain answer each other's robots: both runs finish, both are wrong. Before
tick 0 a run claims its domain twice over:

- on this machine, with a lock file per domain (``flock``: race-free between runs started
  together, released by the kernel when the process ends, however it ends), which also names the
  holder (pid, host, world) for the error message;
- in the ROS graph, for what the lock cannot see (another machine, an older build, a controller
  process left over from a killed run): a short probe looks for another ``/clock`` publisher, a
  simulator's sensor publishers on robot topics, and a controller's publishers on robot actuator
  topics (``/bot0/cmd_vel``). The simulator would take such a controller for its robot's own when
  the first tick opens. With --external-controllers the controllers may start before their
  simulator, so there only simulators count. Watchers (``ros2 topic echo``, a recorder) only subscribe and are fine.

With a domain given (``--domain-id`` or ``ROS_DOMAIN_ID``) a taken domain is an error; without,
the run takes the first free domain from 0 up.
"""
from __future__ import annotations

import fcntl
import json
import os
import socket
import tempfile
import time
from pathlib import Path
from typing import Optional

LOCK_DIR = Path(tempfile.gettempdir()) / "composed_sim_domains"
# Domains an automatic choice may take: 0..101 never reach Linux's ephemeral ports (32768 on),
# well inside the highest domain (world.schema.MAX_DOMAIN).
AUTO_DOMAINS = range(0, 102)
PROBE_S = 0.3              # how long the graph probe listens: discovery on one host takes ~0.2 s, at times seconds
NAME_WAITS = 20            # × 50 ms at most, for the names of nodes whose endpoints were seen


class DomainTaken(Exception):
    """The domain has another simulator; the message names it and the fix."""


class DomainClaim:
    """The lock files of the domains a run uses, held until ``release`` (or the process ends)."""

    def __init__(self):
        self.domains: list[int] = []
        self._files = []

    def take(self, domain: int, about: dict) -> Optional[dict]:
        """Claim ``domain``; None on success, else what its holder wrote (pid, host, world)."""
        LOCK_DIR.mkdir(parents=True, exist_ok=True)
        try:
            os.chmod(LOCK_DIR, 0o1777)        # shared by every user of the machine, like /tmp
        except OSError:
            pass
        path = LOCK_DIR / f"domain_{domain}.lock"
        f = open(path, "a+")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            text = f.read()
            f.close()
            try:
                return json.loads(text)
            except ValueError:
                return {"pid": "?", "host": socket.gethostname()}
        f.seek(0)
        f.truncate()
        f.write(json.dumps(about))
        f.flush()
        self._files.append(f)
        self.domains.append(domain)
        return None

    def release(self) -> None:
        for f in self._files:
            f.close()
        self._files, self.domains = [], []


def run_identity(world_name: str) -> dict:
    return {"pid": os.getpid(), "host": socket.gethostname(), "world": world_name}


def describe(holder: dict) -> str:
    return f"pid {holder.get('pid', '?')} on {holder.get('host', '?')}" + \
        (f", world {holder['world']!r}" if holder.get("world") else "")


def foreign_nodes(domain: int, probe_s: float = PROBE_S, *, controllers_expected: bool = False) -> list[str]:
    """What another run left in ``domain``'s ROS graph, seen within ``probe_s`` (by a throwaway
    participant of ours, made and gone here): each node publishing ``/clock``, a robot's sensor
    topic or, unless ``controllers_expected``, a robot's actuator topic, as "node (topic)"."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    from composed_sim.ros import contract as c
    from composed_sim.ros.answer_subscription import NODE_NAME_UNKNOWN, node_path
    from composed_sim.hosting import ignore_participants_of_this_process
    from composed_sim.ros.robot_settings import quiet_node_options

    ignore_participants_of_this_process()     # before this process's first participant (profile loaded once)
    names = {t.name for t in c.SENSOR_TOPICS + (() if controllers_expected else c.ACTUATOR_TOPICS)}
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        node = Node("composed_sim_domain_probe", context=context, **quiet_node_options())
        time.sleep(probe_s)
        for _ in range(NAME_WAITS):    # a node's name arrives a moment after its endpoints
            found = {}
            for topic, _ in node.get_topic_names_and_types():
                namespace, name = topic.rsplit("/", 1)
                if topic == c.CLOCK_TOPIC or (namespace and name in names):      # a robot topic: /bot0/cmd_vel
                    for e in node.get_publishers_info_by_topic(topic):
                        found.setdefault(node_path(e), topic)
            if not any(NODE_NAME_UNKNOWN in n for n in found):
                break
            time.sleep(0.05)
        node.destroy_node()
        return sorted(f"{n} ({topic})" for n, topic in found.items())
    finally:
        context.shutdown()


def claim_domains(domains: list[int], about: dict, *, given: bool, probe: bool = True,
                  controllers_expected: bool = False) -> DomainClaim:
    """Claim ``domains`` (a run's, given by the user when ``given``), or raise DomainTaken.
    ``controllers_expected``: the run's controllers may be in the graph already (--external-controllers)."""
    claim = DomainClaim()
    for d in domains:
        holder = claim.take(d, about)
        if holder is None and probe:
            others = foreign_nodes(d, controllers_expected=controllers_expected)
            if others:
                holder = {"nodes": others}
        if holder is not None:
            claim.release()
            who = (f"the node{'s' if len(holder['nodes']) > 1 else ''} {', '.join(holder['nodes'][:3])}, seen in "
                   f"the ROS graph" if "nodes" in holder else f"another composed-sim run ({describe(holder)})")
            raise DomainTaken(f"ROS domain {d} is in use by {who}; give this run another domain "
                              f"(--domain-id N or ROS_DOMAIN_ID=N), or leave both unset to pick a free one"
                              if given else f"ROS domain {d} is in use by {who}")
    return claim


def claim_free_domain(width: int, about: dict, *, probe: bool = True,
                      controllers_expected: bool = False) -> tuple[DomainClaim, int]:
    """The first block of ``width`` consecutive free domains from 0 up: (claim, first domain)."""
    for first in range(AUTO_DOMAINS.start, AUTO_DOMAINS.stop - width + 1):
        try:
            return claim_domains(list(range(first, first + width)), about, given=False, probe=probe,
                                 controllers_expected=controllers_expected), first
        except DomainTaken:
            continue
    raise DomainTaken(f"no {width} free consecutive ROS domain{'s' if width > 1 else ''} in "
                      f"{AUTO_DOMAINS.start}..{AUTO_DOMAINS.stop - 1}: every one has a simulator")
