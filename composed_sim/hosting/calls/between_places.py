"""Service calls between places of the run: a robot's nodes, another robot's, the run-wide nodes.

A robot's own nodes always share a process and an executor: their calls are served in process
(hosting/calls/directory.py). A call that leaves the robot, to a run-wide node (a fleet manager, a
swarm's ``all/takeoff``) or from a run-wide node to a robot (``set_parameters``, a lifecycle
transition), may cross executors, processes and machines, depending on the host's layout. So
such calls go through the host, in rounds, and are answered within the tick in every layout:

- a tick's callbacks run until every place is idle; then the calls made since are handed over,
  requests and responses each in one order (by caller: run-wide nodes first, then robot by
  robot; each caller's in the order made), and served by their places, which run until idle
  again; until no call is left in flight (docs/contract.md, "What a node may do");
- a run-wide node's calls made in its part of the tick (at the tick's start) reach the robots
  with the tick's run-wide batch, before the tick's sensors.

An action between places takes the same way: its requests and responses as calls, its feedback and
status as ``ActionMessage`` (hosting/calls/actions_between_places.py).

A place is a robot's index in the run or ``RUN_WIDE_ORIGIN``. The relay of each process keeps
its places' services and clients; requests and responses travel as CDR bytes, so the host moves
them between processes as it moves the run-wide batch.
"""
from __future__ import annotations

import itertools
import threading
from dataclasses import dataclass
from typing import Callable, Collection, Optional

from rclpy.serialization import deserialize_message, serialize_message

from composed_sim.hosting.calls.directory import ServiceDirectory
from composed_sim.hosting.calls.served import CallFuture, completing, hand_over
from composed_sim.ros import contract as c

RUN_WIDE_ORIGIN = -1     # the place of the run-wide nodes: before every robot's (robot i's place is i)


@dataclass(frozen=True)
class Served:
    """Services that a process's places serve, as (place, resolved name, type name): every
    process's clients then find them on the run's graph (``CallRelay.serves``)."""
    services: tuple[tuple[int, str, str], ...]
    rank = 0                     # in a round's handover: first, before the calls that may use them
    call = (RUN_WIDE_ORIGIN - 1, 0)
    destination = None           # every process


@dataclass(frozen=True)
class Request:
    call: tuple[int, int]        # (caller's place, sequence): the call's identity and its order
    place: int                   # the serving place
    service: str                 # resolved name
    data: bytes
    rank = 2

    @property
    def destination(self) -> int:
        return self.place


@dataclass(frozen=True)
class Response:
    call: tuple[int, int]
    data: bytes
    rank = 1

    @property
    def destination(self) -> int:
        return self.call[0]


@dataclass(frozen=True)
class ActionMessage:
    """An action's feedback or status for the clients of place ``destination``
    (hosting/calls/actions_between_places.py): after the responses, as a goal's acceptance comes
    before its first feedback."""
    call: tuple[int, int]        # (server's place, sequence): its order
    destination: int
    action: str
    kind: str                    # "feedback" or "status"
    data: bytes
    rank = 1.5


def service_type_name(srv_type: type) -> str:
    """``std_srvs/srv/Trigger`` for its class."""
    return f"{srv_type.__module__.split('.')[0]}/srv/{srv_type.__name__}"


def handover_order(items: list) -> list:
    """The one order of a round's handover, whatever process made each item: what is served
    first, then responses, then requests, each by caller (run-wide nodes, then robot by robot) and
    the caller's order. An item's ``destination`` is the place it goes to; None: every process."""
    return sorted(items, key=lambda item: (item.rank, item.call))


class CallRelay:
    """One process's side of the calls between places."""

    def __init__(self, robots: Collection[str], relays_actions: bool = True):
        """``relays_actions``: the robots' executor is the host's (lockstep), which polls their
        action servers for clients of other places (hosting/calls/actions_between_places.py); with
        rclpy's stock executors, kept for comparison, actions between places stay DDS's."""
        self.relays_actions = relays_actions
        self._place_of_robot = {name: i for i, name in enumerate(robots)}
        self._directories: dict[int, ServiceDirectory] = {}     # place → the directory serving it here
        self._outbox: list = []
        # Callbacks on an executor's threads (rclpy's multi-threaded) add to it while the host takes it.
        self._outbox_lock = threading.Lock()
        self._pending: dict[tuple[int, int], tuple[CallFuture, object, ServiceDirectory]] = {}
        self._replies: dict[tuple[int, int], Callable[[bytes], None]] = {}    # an action's requests
        self._listeners: dict[tuple[int, str], list[Callable[[str, bytes], None]]] = {}   # (place, action) →
        self._sequence = itertools.count()
        self._served: dict[str, str] = {}        # every service of the run's places known here → its type
        self.clients_leave = False               # has a client here been hosted whose calls leave its place?

    # --- set-up -------------------------------------------------------------------------------

    def serve(self, places: Collection[int], directory: ServiceDirectory) -> None:
        """``directory`` serves the calls to ``places`` in this process."""
        for place in places:
            self._directories[place] = directory

    def announce(self, services: list[tuple[int, str, str]]) -> None:
        """Services of places this process hosts (or hears of first), as (place, name, type name):
        known here at once, and to the other processes with the next handover."""
        new = tuple(s for s in services if s[1] not in self._served)
        if new:
            self._served.update((name, kind) for _, name, kind in new)
            self._send(Served(new))

    def serves(self, service: str) -> bool:
        """Does a place of the run serve ``service``, as far as this process has heard?"""
        return service in self._served

    @property
    def services(self) -> dict[str, str]:
        """The run's services served in process, by name: their type names."""
        return self._served

    def place_of(self, service: str) -> int:
        """The place a service name belongs to: its robot's, by namespace; the run-wide nodes'
        outside every robot's namespace."""
        return self._place_of_robot.get(c.namespace_head(service), RUN_WIDE_ORIGIN)

    def leaves(self, origin: int, service: str) -> bool:
        """Does a call of place ``origin`` to ``service`` leave it (through the relay)?"""
        return self.place_of(service) != origin

    # --- calls out ------------------------------------------------------------------------------

    def call(self, origin: int, client, request, directory: ServiceDirectory,
             future: Optional[CallFuture] = None) -> CallFuture:
        """A client of place ``origin`` calls a service of another place: the request waits for
        the next handover; ``future`` (a new one if None) completes when its response is delivered."""
        call = (origin, next(self._sequence))
        future = CallFuture(executor=directory.executor) if future is None else future
        self._pending[call] = (future, client, directory)
        self._send(Request(call, self.place_of(client.service_name), client.service_name,
                           serialize_message(request)))
        return future

    def ask(self, origin: int, service: str, data: bytes, on_reply: Callable[[bytes], None]) -> None:
        """An action client's request (CDR ``data``) of place ``origin`` to ``service`` of another
        place; ``on_reply`` gets the response's CDR bytes once delivered."""
        call = (origin, next(self._sequence))
        self._replies[call] = on_reply
        self._send(Request(call, self.place_of(service), service, data))

    def listen(self, place: int, action: str, heard: Callable[[str, bytes], None]) -> None:
        """``heard(kind, data)``: a client of ``place`` hears ``action``'s feedback and status from
        another place."""
        self._listeners.setdefault((place, action), []).append(heard)

    def tell(self, origin: int, place: int, action: str, kind: str, data: bytes) -> None:
        """``action``'s server, at ``origin``, sends its feedback or status to the clients of ``place``."""
        self._send(ActionMessage((origin, next(self._sequence)), place, action, kind, data))

    def forget(self, future: CallFuture) -> None:
        """A call given up (its ``Client.call`` timed out): a response that still comes is dropped."""
        self._pending = {call: p for call, p in self._pending.items() if p[0] is not future}

    def _send(self, item) -> None:
        with self._outbox_lock:
            self._outbox.append(item)

    def take_outbox(self) -> list:
        """Requests and responses made since the last take, in the handover's order."""
        with self._outbox_lock:
            taken, self._outbox = self._outbox, []
        return handover_order(taken)

    @property
    def in_flight(self) -> bool:
        return bool(self._outbox)

    # --- calls in -------------------------------------------------------------------------------

    def deliver(self, items: list) -> list:
        """Requests to this process's places, queued at their services; responses to its clients,
        completing their futures. Returns what is not for this process (another process's)."""
        elsewhere = []
        for item in items:
            if isinstance(item, Served):
                self._served.update((name, kind) for _, name, kind in item.services)
                continue
            if isinstance(item, ActionMessage):
                listeners = self._listeners.get((item.destination, item.action))
                if listeners is None:
                    if item.destination not in self._directories:
                        elsewhere.append(item)
                    continue
                for heard in listeners:
                    heard(item.kind, item.data)
                continue
            if isinstance(item, Response) and item.call in self._replies:
                self._replies.pop(item.call)(item.data)
                continue
            if isinstance(item, Response):
                pending = self._pending.pop(item.call, None)
                if pending is None:
                    elsewhere.append(item)
                    continue
                future, client, directory = pending
                response = deserialize_message(item.data, client.srv_type.Response)
                hand_over(directory.executor, client.callback_group, completing(future, response))
                continue
            directory = self._directories.get(item.place)
            if directory is None:
                elsewhere.append(item)
                continue
            self._queue(directory, item)
        return elsewhere

    def _queue(self, directory: ServiceDirectory, request: Request) -> None:
        entry = directory.lookup(request.service)
        if entry is None:
            # An action's, or nobody serves it: the caller waits, as for a service that never comes up.
            directory.relay_action_request(request.service, request.data, request.call[0],
                                           lambda data, call=request.call: self._send(Response(call, data)))
            return
        message = deserialize_message(request.data, entry.srv_type.Request)
        entry.submit(message, lambda response, call=request.call:
                     self._send(Response(call, serialize_message(response))))
