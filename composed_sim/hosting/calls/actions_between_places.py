"""Actions between places of the run: a robot's action client and a run-wide node's server (a fleet
manager's goals to its robots, a robot's request to a run-wide planner), or two robots'.

Within a place an action stays rclpy's, in one participant where DDS delivers at once
(hosting/calls/directory.py). Between places, as for a service call (between_places.py), DDS alone
would carry a goal sent in tick k to a server that the host drives only at the start of tick k + 1.
So an action's three services and two topics go through the call relay, in the rounds of calls
between places, and a goal is accepted, fed back and finished within the tick, in every layout:

- the client's rcl handle is wrapped (``RelayedActionClient``): its goal, cancel and result requests
  go to the relay, and rclpy's ``ActionClient`` takes the responses, feedback and status that the
  relay delivers, as it would take them from DDS. Its own feedback and status subscriptions still
  hear the server through DDS a tick late: drained unread;
- at the server's place, a client handle of the server's node (``ActionServerSide``) sends the
  relayed requests to the server, within the participant, and relays back what the server answers
  and the feedback and status of the relayed goals, to the places that sent them.

rclpy's stock executors (kept for comparison) are not walked by the host: their actions stay DDS's.
"""
from __future__ import annotations

import itertools
from collections import deque
from typing import Callable, Optional

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.qos import QoSProfile, qos_profile_action_status_default, qos_profile_services_default
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.waitable import NumberOfEntities

# An action's services, by the kind of request (rclpy's names for their takes and sends).
ACTION_SERVICES = {"goal": "send_goal", "cancel": "cancel_goal", "result": "get_result"}
# What rcl's ActionClient.is_ready says is ready, in its order.
READY_ORDER = ("feedback", "status", "goal", "cancel", "result")


def action_service(action: str, kind: str) -> str:
    """The resolved name of an action's service: ``/bot0/navigate/_action/send_goal`` for "goal"."""
    return f"{action}/_action/{ACTION_SERVICES[kind]}"


def split_action_service(service: str) -> Optional[tuple[str, str]]:
    """(action, kind) of an action's service name; None for another service."""
    action, _, leaf = service.rpartition("/_action/")
    kind = next((k for k, name in ACTION_SERVICES.items() if name == leaf), None)
    return (action, kind) if action and kind is not None else None


def action_type_name(action_type: type) -> str:
    """``example_interfaces/action/Fibonacci`` for its class."""
    return f"{action_type.__module__.split('.')[0]}/action/{action_type.__name__}"


def action_wait_set(counts: NumberOfEntities, context):
    """An empty wait set sized for an action endpoint of ``counts`` (its entities), in ``context``."""
    return _rclpy.WaitSet(counts.num_subscriptions, counts.num_guard_conditions, counts.num_timers,
                          counts.num_clients, counts.num_services, counts.num_events, context.handle)


def _service_types(action_type) -> dict[str, object]:
    impl = action_type.Impl
    return {"goal": impl.SendGoalService, "cancel": impl.CancelGoalService, "result": impl.GetResultService}


def _topic_types(action_type) -> dict[str, object]:
    return {"feedback": action_type.Impl.FeedbackMessage, "status": action_type.Impl.GoalStatusMessage}


class RelayedActionClient:
    """Stands for an ``ActionClient``'s rcl handle, whose server is in another place of the run:
    requests go through ``relay`` (a CallRelay) as calls of place ``origin``; what the relay delivers
    waits here until rclpy's client takes it. ``wake``: the executor polls the client again."""

    def __init__(self, handle, action_type, action: str, relay, origin: int, wake: Callable[[], None]):
        self._handle, self._action, self._relay, self._origin, self._wake = handle, action, relay, origin, wake
        self._services = _service_types(action_type)
        self._messages = _topic_types(action_type)
        self._sequence = itertools.count(1)
        self._ready: dict[str, deque] = {kind: deque() for kind in READY_ORDER}
        relay.listen(origin, action, self._heard)

    def __getattr__(self, name):             # the rest of the handle: wait sets, graph, destruction
        return getattr(self._handle, name)

    def __enter__(self):
        return self._handle.__enter__()

    def __exit__(self, *exc):
        return self._handle.__exit__(*exc)

    # --- requests, through the relay ------------------------------------------------------------

    def send_goal_request(self, request) -> int:
        return self._send("goal", request)

    def send_cancel_request(self, request) -> int:
        return self._send("cancel", request)

    def send_result_request(self, request) -> int:
        return self._send("result", request)

    def _send(self, kind: str, request) -> int:
        sequence = next(self._sequence)
        response_type = self._services[kind].Response

        def answered(data: bytes) -> None:
            self._heard(kind, (sequence, deserialize_message(data, response_type)))
        self._relay.ask(self._origin, action_service(self._action, kind), serialize_message(request), answered)
        return sequence

    def is_action_server_available(self) -> bool:
        return self._relay.serves(action_service(self._action, "goal"))

    # --- what rclpy's client takes --------------------------------------------------------------

    def _heard(self, kind: str, item) -> None:
        if kind in self._messages:
            item = deserialize_message(item, self._messages[kind])
        self._ready[kind].append(item)
        self._wake()

    def is_ready(self, wait_set) -> tuple[bool, ...]:
        through_dds = self._handle.is_ready(wait_set)
        for kind, ready in zip(READY_ORDER[:2], through_dds):
            if ready:           # a copy of what the relay brought: dropped
                getattr(self._handle, f"take_{kind}")(self._messages[kind])
        return tuple(bool(self._ready[kind]) for kind in READY_ORDER)

    def _take(self, kind: str, none):
        ready = self._ready[kind]
        return ready.popleft() if ready else none

    def take_goal_response(self, _type):
        return self._take("goal", (None, None))

    def take_cancel_response(self, _type):
        return self._take("cancel", (None, None))

    def take_result_response(self, _type):
        return self._take("result", (None, None))

    def take_feedback(self, _type):
        return self._take("feedback", None)

    def take_status(self, _type):
        return self._take("status", None)


class ActionServerSide:
    """At an action server's place: the requests relayed to it from other places, sent to the
    server by a client handle of its node; its responses, and the feedback and status of those
    goals, relayed back (``poll``, by the walk before it polls the server)."""

    def __init__(self, node, server, action: str, relay, place: int):
        self._action, self._relay, self._place = action, relay, place
        self._services = _service_types(server._action_type)
        self._messages = _topic_types(server._action_type)
        with node.handle:
            self._handle = _rclpy.ActionClient(
                node.handle, server._action_type, action,
                qos_profile_services_default.get_c_qos_profile(), qos_profile_services_default.get_c_qos_profile(),
                qos_profile_services_default.get_c_qos_profile(), QoSProfile(depth=10).get_c_qos_profile(),
                qos_profile_action_status_default.get_c_qos_profile())
        self._wait_set = None
        self._waiting: dict[tuple[str, int], Callable[[bytes], None]] = {}   # (kind, sequence) → reply
        self._goal_places: dict[bytes, int] = {}     # goal id → the place that sent it, until its result
        self._results: dict[int, bytes] = {}         # result request's sequence → its goal id

    def request(self, kind: str, data: bytes, origin: int, reply: Callable[[bytes], None]) -> None:
        """A relayed request of place ``origin``: sent to the server; ``reply`` relays its response."""
        request = deserialize_message(data, self._services[kind].Request)
        if kind == "goal":
            self._goal_places[bytes(request.goal_id.uuid)] = origin
        with self._handle:
            sequence = getattr(self._handle, f"send_{kind}_request")(request)
        self._waiting[(kind, sequence)] = reply
        if kind == "result":
            self._results[sequence] = bytes(request.goal_id.uuid)

    def poll(self, context) -> None:
        """What the server sent since: its responses, the relayed goals' feedback, then its status."""
        if not self._waiting and not self._goal_places:
            return
        if self._wait_set is None:
            self._wait_set = action_wait_set(NumberOfEntities(*self._handle.get_num_entities()), context)
        wait_set = self._wait_set
        with self._handle:
            wait_set.clear_entities()
            self._handle.add_to_waitset(wait_set)
            wait_set.wait(0)
            ready = dict(zip(READY_ORDER, self._handle.is_ready(wait_set)))
            finished = [goal for kind in ("goal", "cancel", "result") if ready[kind]
                        for goal in self._take_responses(kind)]
            if ready["feedback"]:
                self._relay_feedback()
            if ready["status"]:
                status = self._handle.take_status(self._messages["status"])
                if status is not None:
                    data = serialize_message(status)
                    for place in sorted(set(self._goal_places.values())):
                        self._relay.tell(self._place, place, self._action, "status", data)
        for goal in finished:           # its result is out: no feedback follows; its final status went with it
            self._goal_places.pop(goal, None)

    def _take_responses(self, kind: str) -> list[bytes]:
        """Relays the server's responses of ``kind``; returns the goals whose results they were."""
        take, finished = getattr(self._handle, f"take_{kind}_response"), []
        while True:
            sequence, response = take(self._services[kind].Response)
            if sequence is None:
                return finished
            reply = self._waiting.pop((kind, sequence), None)
            if reply is not None:
                reply(serialize_message(response))
            if kind == "result" and sequence in self._results:
                finished.append(self._results.pop(sequence))

    def _relay_feedback(self) -> None:
        while (feedback := self._handle.take_feedback(self._messages["feedback"])) is not None:
            place = self._goal_places.get(bytes(feedback.goal_id.uuid))
            if place is not None:
                self._relay.tell(self._place, place, self._action, "feedback", serialize_message(feedback))
