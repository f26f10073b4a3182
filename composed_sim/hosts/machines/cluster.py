"""The distributed engine under a run's machines: Dask distributed (docs/distributed.md, "Which
engine carries the tick", says why).

The simulator's process runs the run's Dask scheduler, with no Dask worker of its own; each other
machine runs ``composed-sim join ADDRESS`` (``join``), a Dask worker of one thread, and the
simulator places one actor there, the machine's agent (agent.py). The worker host's messages to a
worker (launcher.py lists them) then travel as calls of that actor, one per message: the call's
result is the machine's next message back (``ActorConnection``). A machine that leaves the run (its
process killed: its TCP connection closes; silent: no heartbeat for the watchdog) is reported by
the scheduler at once, and its connection reads as closed, as a dead worker's socket does.

Every link is mutual TLS with the run's credentials (credentials.py) unless the run was started
with ``--insecure``: a peer without them is refused at the handshake, and said so in one line
(``JoinLog``), as is every machine that joins.

Dask is the optional ``cluster`` dependency: imported only here, when a run has machines.
"""
from __future__ import annotations

import asyncio
import json
import logging
import os
import socket
import sys
import time
from collections import deque
from dataclasses import dataclass
from typing import Callable, Optional

from composed_sim.hosting import HostError
from composed_sim.hosts.machines.credentials import Credentials

RUN_KEY = "composed_sim_run"           # the scheduler's metadata: which run it serves
# Dask's HTTP servers (a scheduler's and a worker's: metrics and state, plain HTTP, no credentials)
# start whatever the dashboard setting: on the loopback only, a port no other machine reaches.
LOOPBACK_HTTP = "127.0.0.1:0"
# The messages that get no answer: their calls are waited for before the next one goes, so that
# a machine sees them in the order sent (Dask may carry concurrent calls on separate connections).
ONE_WAY = ("clock", "tap", "stop")
ONE_WAY_TIMEOUT_S = 60.0


def needs_dask() -> None:
    try:
        import distributed  # noqa: F401 - imported only to see that it is installed
    except ImportError:
        raise HostError("a run over machines needs Dask distributed on every machine: "
                        "pip install 'composed_sim[cluster]'") from None


@dataclass(frozen=True)
class Machine:
    """A machine that joined: its Dask worker's address, its host name and its --workers."""
    address: str
    host: str
    workers: object          # a number, or "auto"

    @property
    def ip(self) -> str:
        return self.address.split("://")[-1].rsplit(":", 1)[0]

    def known_as(self, name: str) -> bool:
        return name in (self.ip, self.host, self.address)


class RunScheduler:
    """The run's Dask scheduler, in this process (a thread of Dask's own), and a client of it."""

    def __init__(self, listen: str, run_id: str, silent_after_s: float, credentials: Optional[Credentials],
                 say: Callable[[str], None]):
        """``silent_after_s``: a machine without heartbeats for this long (at least Dask's floor,
        10 heartbeats: 5 s) is lost; checked every as many seconds. ``credentials``: None for plain
        tcp:// (--insecure). ``say(line)``: where each join and each refused peer is told."""
        needs_dask()
        from distributed import Client, LocalCluster
        from distributed.diagnostics.plugin import SchedulerPlugin

        host, _, port = listen.rpartition(":") if ":" in listen else (listen, "", "0")
        self.run_id = run_id
        security = credentials.security() if credentials is not None else None
        self.join_log = JoinLog(say)
        self.cluster = LocalCluster(n_workers=0, processes=False, protocol="tcp" if security is None else "tls",
                                    host=host or None, scheduler_port=int(port or 0), dashboard_address=LOOPBACK_HTTP,
                                    security=security, scheduler_kwargs={"worker_ttl": silent_after_s})
        self.client = Client(self.cluster, security=security)
        self.client.set_metadata(RUN_KEY, run_id)
        self.address = self.cluster.scheduler_address
        self.links: dict[str, ActorConnection] = {}      # Dask worker address → its agent's connection

        class Departures(SchedulerPlugin):
            def add_worker(plugin, scheduler, worker):      # the scheduler's thread
                self.join_log.joined(worker, scheduler.workers[worker].name)

            def remove_worker(plugin, scheduler, worker, *, stimulus_id="", **kwargs):   # the scheduler's thread
                link = self.links.get(worker)
                if link is not None:
                    link.lost("it stopped answering the scheduler's heartbeats" if "worker-ttl" in stimulus_id
                              else "its connection to the simulator closed")
        self.cluster.scheduler.add_plugin(Departures(), name="composed_sim_departures")

    def joined(self) -> list[Machine]:
        """The machines of this run that joined so far, in the order they joined."""
        machines = []
        for address, info in self.client.scheduler_info(n_workers=-1)["workers"].items():
            try:
                about = json.loads(info.get("name", ""))
            except (TypeError, ValueError):
                continue
            if isinstance(about, dict) and about.get("run") == self.run_id:
                machines.append(Machine(address, about.get("host", "?"), about.get("workers", "auto")))
        return machines

    def wait_for(self, expected, timeout_s: float, interrupted: Callable[[], bool], join_command: str
                 ) -> list[Machine]:
        """``expected``: a number of machines, or their names (address or host name), in block
        order. The machines, in block order; a HostError naming those missing after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not interrupted():
            joined = self.joined()
            if isinstance(expected, int):
                if len(joined) >= expected:
                    return sorted(joined, key=lambda m: m.address)[:expected]
                missing = f"{expected - len(joined)} of {expected} machines"
            else:
                found = [next((m for m in joined if m.known_as(name)), None) for name in expected]
                if all(found):
                    return found
                missing = "machine " + ", ".join(n for n, m in zip(expected, found) if m is None)
            if time.monotonic() > deadline:
                seen = ", ".join(f"{m.ip} ({m.host})" for m in joined) or "none"
                raise HostError(f"{missing} did not join the run within {timeout_s:g} s (joined: {seen}); on each "
                                f"one: {join_command}")
            time.sleep(0.05)
        return []

    def place(self, cls, machine: Machine, key: str, connection: Callable[..., "ActorConnection"]):
        """An actor of ``cls`` on ``machine``, and ``connection(actor, loop, forget)`` to it."""
        future = self.client.submit(cls, actor=True, workers=[machine.address], allow_other_workers=False,
                                    key=key, pure=False)
        link = connection(future.result(), self.client.loop, lambda: self.client.cancel(future, force=True))
        self.links[machine.address] = link
        return link

    def close(self) -> None:
        for link in self.links.values():
            link.lost("the run ended")
        self.client.close(timeout=5)
        self.cluster.close(timeout=5)
        self.join_log.close()


class JoinLog(logging.Filter):
    """One line for each peer that joins the run and for each refused at the TLS handshake (its
    address), instead of Dask's own warning, for as long as the run's scheduler is up."""
    LOGGER = "distributed.comm.tcp"        # where Dask's listener says a handshake failed

    def __init__(self, say: Callable[[str], None]):
        super().__init__()
        self.say = say
        logging.getLogger(self.LOGGER).addFilter(self)

    def joined(self, address: str, name) -> None:
        try:
            about = json.loads(name)
        except (TypeError, ValueError):
            about = None
        if isinstance(about, dict):
            self.say(f"composed-sim: machine joined from {address} (host {about.get('host', '?')}, "
                     f"pid {about.get('pid', '?')})")
        else:
            self.say(f"composed-sim: a Dask worker not started by `composed-sim join` connected from {address} "
                     f"(name {name!r}); it is given no robots")

    def filter(self, record: logging.LogRecord) -> bool:
        if "TLS handshake failed" not in str(record.msg):
            return True
        # Dask's arguments: the listener's address, the peer's, the error.
        args = record.args if isinstance(record.args, tuple) and len(record.args) == 3 else ("?", "?", "?")
        remote, reason = args[1], args[2]
        self.say(f"composed-sim: refused a connection from {remote}: no credentials of this run "
                 f"(TLS handshake failed: {reason})")
        return False

    def close(self) -> None:
        logging.getLogger(self.LOGGER).removeFilter(self)


class ActorConnection:
    """What the worker host uses of a worker's ``Connection`` (send, recv, fileno, close), over a
    Dask actor: each message sent is a call of the actor's ``step``, whose result is the next
    message received. Readable (``fileno``) once a result is in, or the machine is lost: then
    ``recv`` raises EOFError, as a dead worker's socket does."""

    def __init__(self, actor, loop, forget: Callable[[], None]):
        self._actor, self._loop, self._forget = actor, loop, forget
        self._ready_r, self._ready_w = os.pipe()
        self._calls: deque = deque()
        self.gone: Optional[str] = None

    def fileno(self) -> int:
        return self._ready_r

    def send(self, message) -> None:
        if self.gone is not None:
            raise OSError(self.gone)
        call = self._actor.step(message)
        if message[0] in ONE_WAY:
            try:
                call.result(timeout=ONE_WAY_TIMEOUT_S)
            except Exception as e:    # noqa: BLE001 - Dask's and the agent's errors alike end the link
                raise OSError(f"{message[0]}: {e}") from None
            return
        self._calls.append(call)

        async def ready():
            try:
                await call
            except Exception:           # noqa: BLE001 - its error, whatever it is, is raised by recv
                pass
            finally:
                self._signal()
        self._loop.add_callback(ready)

    def recv(self):
        os.read(self._ready_r, 1)
        if self.gone is not None:
            raise EOFError(self.gone)
        call = self._calls.popleft()
        try:
            return call.result()
        except Exception as e:    # noqa: BLE001 - Dask's and the agent's errors alike end the link
            self.gone = f"its agent failed: {type(e).__name__}: {e}"
            raise EOFError(self.gone) from None

    def lost(self, reason: str) -> None:
        """The machine left the run (from the scheduler's thread): recv raises from now on."""
        if self.gone is None:
            self.gone = reason
            self._signal()

    def forget(self) -> None:
        """Its actor is not to be placed again elsewhere (Dask would wait for its machine)."""
        if self._forget is not None:
            forget, self._forget = self._forget, None
            forget()

    def _signal(self) -> None:
        try:
            os.write(self._ready_w, b"\0")
        except OSError:          # closed: nobody reads any more
            pass

    def close(self) -> None:
        self.gone = self.gone or "closed"
        for fd in (self._ready_r, self._ready_w):
            try:
                os.close(fd)
            except OSError:
                pass
        self._ready_r = self._ready_w = -1


def join(address: str, run_id: Optional[str], workers, timeout_s: float, should_stop: Callable[[], bool],
         credentials: Optional[Credentials]) -> str:
    """This machine serves the run whose scheduler is at ``address`` (and whose id is ``run_id``,
    where given): a Dask worker of one thread here, until the run ends ("run ended") or
    ``should_stop()`` ("stopped"). ``credentials``: the run's, for a tls:// address; None for a
    tcp:// one (--insecure). A HostError when the scheduler is not found within ``timeout_s``,
    does not hold the run's credentials, or serves another run."""
    needs_dask()
    from distributed import Client, Worker
    logging.getLogger("distributed").setLevel(logging.WARNING)     # its start and stop lines are not news
    logging.getLogger(JoinLog.LOGGER).setLevel(logging.CRITICAL)    # a refused handshake is our error below

    security = credentials.security() if credentials is not None else None
    try:
        client = Client(address, timeout=timeout_s, security=security)
    except (OSError, TimeoutError) as e:
        check = "the address, the credentials file (the run's own) and the network" if credentials is not None \
            else "the address and the network"
        raise HostError(f"no simulator of this run at {address} within {timeout_s:g} s ({type(e).__name__}): start "
                        f"`composed-sim run … --machines …` first, or check {check}") from None
    serves = client.get_metadata(RUN_KEY, None)
    client.close()
    if serves is None or (run_id is not None and serves != run_id):
        raise HostError(f"the simulator at {address} runs {serves!r}, not run {run_id!r}: use the command "
                        f"that your simulator printed")
    name = json.dumps({"run": serves, "host": socket.gethostname(), "pid": os.getpid(), "workers": workers})

    async def serve() -> str:
        async with Worker(address, nthreads=1, name=name, dashboard=False, dashboard_address=LOOPBACK_HTTP,
                          security=security) as worker:
            while worker.status.name in ("init", "running", "paused"):
                if should_stop():
                    return "stopped"
                await asyncio.sleep(0.2)
        return "run ended"
    try:
        return asyncio.run(serve())
    finally:
        sys.stdout.flush()
