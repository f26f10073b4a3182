"""Separate network stacks on one machine, as separate machines would be: a bridge in a network
namespace of its own and one namespace per role, joined by veth pairs, on a private subnet with a
multicast route (DDS discovery is multicast). Nothing touches the host's own network namespace.
Needs root; used by the distributed tests, the engines' probe (tools/distributed_engines.py) and
the benchmark's distributed row."""
from __future__ import annotations

import os
import secrets
import signal
import subprocess


class Netns:
    def __init__(self, roles: list[str]):
        self.tag = f"cs{os.getpid() % 100000}{secrets.token_hex(2)}"
        self.roles = roles
        self.created: list[str] = []
        self.address = {role: f"10.{77 + os.getpid() % 100}.0.{k + 1}" for k, role in enumerate(roles)}

    def name(self, role: str) -> str:
        return f"{self.tag}-{role}"

    def create(self) -> None:
        bridge = self.name("br")
        self._ns(bridge)
        ip("-n", bridge, "link", "add", "br0", "type", "bridge")
        ip("-n", bridge, "link", "set", "br0", "up")
        for k, role in enumerate(self.roles):
            ns = self.name(role)
            self._ns(ns)
            ip("-n", bridge, "link", "add", f"p{k}", "type", "veth", "peer", "name", "eth0", "netns", ns)
            ip("-n", bridge, "link", "set", f"p{k}", "master", "br0", "up")
            ip("-n", ns, "addr", "add", f"{self.address[role]}/24", "dev", "eth0")
            ip("-n", ns, "link", "set", "eth0", "up")
            ip("-n", ns, "link", "set", "lo", "up")
            ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")

    def _ns(self, ns: str) -> None:
        ip("netns", "add", ns)
        self.created.append(ns)

    def exec(self, role: str, cmd: list[str]) -> list[str]:
        return ["ip", "netns", "exec", self.name(role), *cmd]

    def counters(self, role: str) -> dict[str, int]:
        """Bytes through the role's link so far, each way."""
        base = "/sys/class/net/eth0/statistics"
        out = subprocess.run(self.exec(role, ["cat", f"{base}/rx_bytes", f"{base}/tx_bytes"]),
                             capture_output=True, text=True, check=True).stdout.split()
        return {"rx_bytes": int(out[0]), "tx_bytes": int(out[1])}

    def kill_all(self, role: str) -> None:
        """SIGKILL every process in the role's namespace: the machine is gone."""
        _kill_in(self.name(role))

    def destroy(self) -> None:
        """Kill whatever still runs in our namespaces (only our own processes can), then delete
        them; deleting a namespace deletes its veth ends, and so the pairs."""
        for ns in self.created:
            _kill_in(ns)
        for ns in reversed(self.created):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        self.created = []

    def __enter__(self) -> "Netns":
        try:
            self.create()
        except BaseException:
            self.destroy()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.destroy()


def ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise OSError(f"ip {' '.join(args)}: {done.stderr.strip()}")


def _kill_in(ns: str) -> None:
    pids = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True).stdout.split()
    for pid in pids:
        try:
            os.kill(int(pid), signal.SIGKILL)
        except ProcessLookupError:
            pass
