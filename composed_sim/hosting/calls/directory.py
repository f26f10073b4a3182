"""Services, clients and actions between hosted nodes, as a process of their own would have them.

A node's own process calls a service through DDS and gets the response on another of the
executor's threads. Between the nodes of one hosting process the host hands a call over itself:
the request (a copy, as DDS would deliver it) goes into the service's queue, the lockstep walk
runs the service's callback in its place in the fixed order (a stock executor runs it as a task),
and the response (a copy) completes the client's future once the client's callback group may
run, as rclpy's executors require. A blocking ``Client.call()`` sets its callback aside meanwhile
(hosting/executors/scheduler.py). Every service and client still exists on DDS: calls from and to
other processes take that path: their requests are taken as a tick starts
(hosting/calls/outside.py), the responses to calls made to them by the walk. A call to
another place of the run (a run-wide node's service, a robot's from a run-wide node) goes
through the host's call relay (hosting/calls/between_places.py).

Actions (``rclpy.action``) keep rclpy's implementation, whose goal, cancel and result services and
feedback and status topics stay inside the hosting participant, where DDS delivers at once: the
walk polls each action server and client through a wait set of its own, and their blocking calls
(``send_goal``, ``get_result``) set the callback aside like ``Client.call()``. An action between
places goes through the call relay (hosting/calls/actions_between_places.py).
"""
from __future__ import annotations

from typing import Callable, Optional

from rclpy.action import ActionClient, ActionServer
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.client import Client
from rclpy.exceptions import InvalidHandle
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.service import Service
from rclpy.task import Future

from composed_sim.hosting.calls.actions_between_places import (ActionServerSide, RelayedActionClient,
                                                              action_service, action_type_name,
                                                              action_wait_set, split_action_service)
from composed_sim.hosting.calls.clients import host_client
from composed_sim.hosting.calls.served import (HostedCallError, NodeServices, ServiceEntry, completing,
                                              hand_over)
from composed_sim.hosting.sim_time.sleeps import can_set_aside, wait_on_clock


class ServiceDirectory:
    """The services served in process by one executor, and its nodes' clients and action
    endpoints: what the lockstep walk serves, and where calls go."""

    def __init__(self, executor, relay=None):
        """``relay``: where calls to services of other places go (hosting/calls/between_places.py)."""
        self.executor = executor
        self.relay = relay
        self._walked = hasattr(executor, "when_free")      # the lockstep executor
        self._by_name: dict[str, ServiceEntry] = {}      # the first service of each name
        self._entries: list[ServiceEntry] = []
        self._of_node: dict[Node, NodeServices] = {}
        self._served: set[int] = set()            # ids of the rclpy Services served here
        self._clients: set[int] = set()           # ids of the clients hosted here
        self._client_names: dict[str, int] = {}   # how many of them call each service name
        self._outside: Optional[set[int]] = None  # ids of the entries another process may call (None: any)
        self._polled: dict[int, object] = {}      # action servers and clients: their wait sets
        self._node_names: set[str] = set()        # the names of the nodes it serves (a run-wide node's is its own)
        self._entries_of: dict[int, list[ServiceEntry]] = {}     # id(node) → the services it serves
        self._action_servers: dict[str, tuple[Node, ActionServer, Optional[int]]] = {}   # polled here, by resolved name
        self._sides_of: dict[int, ActionServerSide] = {}   # id(server) → its side for clients of other places
        if self._walked:
            executor.services = self

    # --- what the walk asks -----------------------------------------------------------------------

    def services_of(self, node: Node) -> Optional[NodeServices]:
        return self._of_node.get(node)

    def serves(self, service: Service) -> bool:
        return id(service) in self._served

    def takes_responses(self, client: Client) -> bool:
        return id(client) in self._clients

    def polls(self, waitable) -> bool:
        return id(waitable) in self._polled

    @property
    def in_use(self) -> bool:
        """Do its nodes have services, clients or actions of their own (parameter services aside)?
        Then a robot's work may go on after its answer (a response, a result), within the tick."""
        return bool(self._served or self._clients or self._polled)

    def lookup(self, name: str, srv_type=None) -> Optional[ServiceEntry]:
        entry = self._by_name.get(name)
        return entry if entry is not None and (srv_type is None or entry.srv_type is srv_type) else None

    # --- hosting a node's services and clients ----------------------------------------------------

    def host_service(self, node: Node, service: Service) -> None:
        """Serve ``service`` (created by ``node``) in process; DDS requests from other processes are
        taken by ``take_outside_requests``."""
        if id(service) in self._served:
            return
        self._add(ServiceEntry(service.handle.name, service.srv_type, node, service.callback_group,
                               self._owner(node), service=service))
        self._served.add(id(service))

    def add_in_process(self, node: Node, name: str, srv_type, callback: Callable, group) -> ServiceEntry:
        """A service with no DDS endpoint (a node's parameter services, hosting/calls/parameters.py)."""
        entry = ServiceEntry(name, srv_type, node, group, self._owner(node), callback=callback)
        self._add(entry)
        return entry

    def _owner(self, node: Node) -> Optional[NodeServices]:
        return self._of_node.setdefault(node, NodeServices()) if self._walked else None

    def attach_dds(self, entry: ServiceEntry, service: Service) -> None:
        """An in-process service gets its DDS endpoint (``service``), whose requests it serves too."""
        entry.service = service
        self._served.add(id(service))
        self.executor.wake()

    def served_by(self, node: Node) -> list[ServiceEntry]:
        """The services ``node`` serves here, in the order hosted."""
        return self._entries_of.get(id(node), [])

    def _add(self, entry: ServiceEntry) -> None:
        self._entries_of.setdefault(id(entry.node), []).append(entry)
        self._node_names.add(entry.node.get_name())
        self._by_name.setdefault(entry.name, entry)
        self._entries.append(entry)
        if entry._owner is not None:
            entry._owner.entries.append(entry)
        self.executor.wake()

    def host_client(self, node: Node, client: Client, origin: Optional[int] = None) -> None:
        """Calls of ``client`` to a service served here go in process; to another place of the run
        (``origin``: the node's place, hosting/calls/between_places.py) through the relay; others through
        DDS, whose responses the walk takes (hosting/calls/clients.py)."""
        if id(client) in self._clients:
            return
        self._clients.add(id(client))
        self._client_names[client.service_name] = self._client_names.get(client.service_name, 0) + 1
        host_client(self, node, client, origin)
        self.executor.wake()

    def may_block(self, node: Node, what: str) -> bool:
        """May a callback of ``node`` block here on a call? Set aside by the lockstep executor; on
        a MultiThreadedExecutor's thread as rclpy blocks; never in an executor of one thread,
        where it would wait forever (in its own process too): refused."""
        executor = self.executor
        if can_set_aside(executor):
            return True
        if isinstance(executor, MultiThreadedExecutor):
            return False
        raise HostedCallError(f"{node.get_fully_qualified_name()} waits for {what} in a callback of a "
                              f"{type(executor).__name__}, which runs one callback at a time: it would wait "
                              f"forever, in its own process too. Use call_async, or the lockstep executor")

    def wait(self, node: Node, taking_group, future: Future, what: str, timeout_sec: Optional[float]) -> None:
        """A callback of ``node`` blocks on ``future``, whose completion a callback of
        ``taking_group`` must take: set it aside meanwhile, or refuse a wait that could never end."""
        executor = self.executor
        group = executor.group_of_caller()
        if isinstance(group, MutuallyExclusiveCallbackGroup) and group is taking_group:
            raise HostedCallError(
                f"{node.get_fully_qualified_name()} waits for {what} in a callback of the mutually exclusive "
                f"callback group that must also take its response: it would wait forever, in any process. "
                f"Give the client (or the calling callback) another group, e.g. a ReentrantCallbackGroup")
        wait_on_clock(node, executor, future, group, timeout_sec, future.cancel)

    # --- actions ------------------------------------------------------------------------------------

    @staticmethod
    def is_action(waitable) -> bool:
        return isinstance(waitable, (ActionServer, ActionClient))

    def host_action(self, node: Node, waitable, place: Optional[int] = None) -> None:
        """With the lockstep executor: poll an action server or client in the walk; its blocking
        calls set the caller aside; one between places (``place``: the node's) goes through the
        relay (hosting/calls/actions_between_places.py). A stock executor waits on it as rclpy does."""
        if id(waitable) in self._polled or not self._walked:
            return
        self._polled[id(waitable)] = None
        if isinstance(waitable, ActionClient):
            self._host_action_client(node, waitable, place)
        elif getattr(waitable, "hosted_name", None) is not None:
            name = node.resolve_service_name(waitable.hosted_name)
            self._action_servers[name] = (node, waitable, place)
            if self.relay is not None and self.relay.relays_actions and place is not None:
                self.relay.announce([(place, action_service(name, "goal"), action_type_name(waitable._action_type))])
        self.executor.wake()

    def relay_action_request(self, service: str, data: bytes, origin: int, reply) -> None:
        """A request relayed from place ``origin`` to an action server's service here (else dropped:
        nobody serves it); ``reply`` relays the response (between_places.py)."""
        action = split_action_service(service)
        server = self._action_servers.get(action[0]) if action is not None else None
        if server is None:
            return
        node, waitable, place = server
        side = self._sides_of.get(id(waitable))
        if side is None:
            side = self._sides_of[id(waitable)] = ActionServerSide(node, waitable, action[0], self.relay, place)
        side.request(action[1], data, origin, reply)
        self.executor.wake()

    def _host_action_client(self, node: Node, client: ActionClient, place: Optional[int]) -> None:
        directory = self
        name = getattr(client, "_action_name", "an action")
        resolved = node.resolve_service_name(name)
        relay = self.relay
        if relay is not None and relay.relays_actions and place is not None and relay.leaves(place, resolved):
            relay.clients_leave = True
            client._client_handle = RelayedActionClient(client._client_handle, client._action_type, resolved,
                                                        relay, place, self.executor.wake)

        def blocking(method_async, original, what):
            def call(*args, **kwargs):
                if not directory.may_block(node, f"{name} ({what})"):
                    return original(*args, **kwargs)
                future = method_async(*args, **kwargs)
                directory.wait(node, client.callback_group, future, f"{name} ({what})", None)
                return future.result()
            return call
        client.send_goal = blocking(client.send_goal_async, client.send_goal, "send_goal")
        client._get_result = blocking(client._get_result_async, client._get_result, "get_result")
        client._cancel_goal = blocking(client._cancel_goal_async, client._cancel_goal, "cancel_goal")
        # Ready as its own process would find it once discovered: at once for a server of this
        # executor's nodes (rclpy's wait_for_server asks this).
        client.server_is_ready = lambda: resolved in directory._action_servers or ActionClient.server_is_ready(client)

    def poll(self, entity, node: Node, executor) -> int:
        """Take what is ready for a polled entity (an action server or client, or a client with
        requests out through DDS) and start handling it; returns how many things it started."""
        if isinstance(entity, Client):
            return self._take_responses(entity, executor)
        side = self._sides_of.get(id(entity))
        if side is not None:            # what the server sent to other places since its last poll
            side.poll(executor.context)
        wait_set = self._polled.get(id(entity))
        if wait_set is None:
            wait_set = self._polled[id(entity)] = action_wait_set(entity.get_num_entities(), executor.context)
        try:
            wait_set.clear_entities()
            entity.add_to_wait_set(wait_set)
            wait_set.wait(0)
            if not entity.is_ready(wait_set):
                return 0
            data = entity.take_data()
        except InvalidHandle:            # destroyed by a callback of this walk
            return 0
        if not data:
            return 0
        parts = _in_order_made(entity, data) if isinstance(entity, ActionClient) else [data]
        group = entity.callback_group
        executor.running_group = group
        executor.start_coroutine(entity.execute(parts[0]), group, node)
        for part in parts[1:]:
            # Each after what the part before made ready (a goal's done callbacks, say): as tasks.
            executor.scheduler.tasks.append(
                lambda part=part: executor.start_coroutine(entity.execute(part), group, node))
        return len(parts)

    def _take_responses(self, client: Client, executor) -> int:
        """A client's responses through DDS (a service of another process)."""
        if not client._pending_requests:
            return 0
        taken = 0
        while True:
            with client.handle:
                header, response = client.handle.take_response(client.srv_type.Response)
            if header is None:
                return taken
            taken += 1
            try:
                future = client.get_pending_request(header.request_id.sequence_number)
            except KeyError:
                continue                      # given up on (a timeout)
            future._set_executor(executor)
            hand_over(executor, client.callback_group, completing(future, response))

    def find_outside_clients(self, run_namespaces: frozenset[str]) -> None:
        """Which services served here have a client that is not the run's (``ros2 param``'s, a
        tool's, another program's), by the ROS graph: asked again whenever the graph changed. An
        in-process service that one wants gets its DDS endpoint then (``on_outside``).
        ``run_namespaces``: the robots' namespaces, whose nodes are all the run's."""
        if not self._entries:
            return
        graph = self._entries[0].node
        wanted: set[str] = set()
        for name, namespace in graph.get_node_names_and_namespaces():
            if namespace in run_namespaces or name.startswith("composed_sim") or name in self._node_names:
                continue
            try:
                wanted.update(service for service, _ in graph.get_client_names_and_types_by_node(name, namespace))
            except Exception:            # noqa: BLE001 - gone meanwhile
                continue
        for entry in self._entries:
            if entry.name in wanted and entry.service is None and entry.on_outside is not None:
                entry.on_outside()
        self._outside = {id(entry) for entry in self._entries if entry.service is not None
                         and (entry.name in wanted or entry.node.count_clients(entry.name)
                              > self._client_names.get(entry.name, 0))}

    def take_outside_requests(self) -> int:
        """Requests through DDS (from other processes) to the services served here: queued, to be
        served like the others; returns how many. Only the services with a client elsewhere
        (``find_outside_clients``) are asked, once it was called."""
        taken, outside = 0, self._outside
        for entry in self._entries:
            service = entry.service
            if service is None or (outside is not None and id(entry) not in outside):
                continue
            while True:
                with service.handle:
                    request, header = service.handle.service_take_request(entry.srv_type.Request)
                if header is None:
                    break
                entry.submit(request, lambda response, service=service, header=header:
                             service.send_response(response, header))
                taken += 1
        return taken


def _in_order_made(client: ActionClient, data: dict) -> list[dict]:
    """What an action client took at once, in the order its own process would hear it: the goal's
    acceptance, every feedback, then the rest (cancel, result, status). In its own process the
    client hears each as it comes, while the server still runs; here the server may have accepted
    the goal, sent feedback and finished by the time the client is polled."""
    parts = [{"goal": data.pop("goal")}] if "goal" in data else []
    if "feedback" in data:
        parts.append({"feedback": data.pop("feedback")})
        feedback_type = client._action_type.Impl.FeedbackMessage
        while (more := client._client_handle.take_feedback(feedback_type)) is not None:
            parts.append({"feedback": more})
    return parts + ([data] if data else [])


def remember_action_server_names() -> None:
    """rclpy's ``ActionServer`` keeps no name (its client does): each remembers it as
    ``hosted_name``, so that a client of the same executor finds it ready (``server_is_ready``)."""
    init = ActionServer.__init__
    if getattr(init, "remembers", False):
        return

    def remembering(self, node, action_type, action_name, *args, **kwargs):
        self.hosted_name = action_name
        init(self, node, action_type, action_name, *args, **kwargs)
    remembering.remembers = True
    ActionServer.__init__ = remembering
