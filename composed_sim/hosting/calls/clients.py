"""A hosted node's clients: where a call goes (in process, through the call relay to another place of
the run, or through DDS), a blocking ``Client.call()`` set aside while it waits, and waits for a
service while the nodes are built."""
from __future__ import annotations

from typing import Callable, Optional

from rclpy.client import Client
from rclpy.node import Node
from rclpy.task import Future

from composed_sim.hosting.calls.served import CallFuture, completing, hand_over
from composed_sim.ros.message_copy import copy_message


def host_client(directory, node: Node, client: Client, origin: Optional[int]) -> None:
    """``client``'s calls as its own process would make them, through ``directory`` (the node's
    ServiceDirectory); ``origin``: the node's place in the run. Calls it made before it was hosted
    (from its node's constructor) are sent now, completing the futures they returned."""
    executor = directory.executor
    name = client.service_name
    relay = directory.relay
    if relay is not None and origin is not None and relay.leaves(origin, name):
        relay.clients_leave = True

    def send(request, future: Optional[CallFuture] = None):
        entry = directory.lookup(name, client.srv_type)
        if entry is None:
            relay = directory.relay
            if relay is not None and origin is not None and relay.leaves(origin, name):
                return relay.call(origin, client, request, directory, future)
            sent = Client.call_async(client, request)          # through DDS: another process's service
            return sent if future is None else _chained(sent, future)
        future = CallFuture(executor=executor) if future is None else future
        entry.submit(copy_message(request), lambda response: hand_over(
            executor, client.callback_group, completing(future, copy_message(response))))
        return future

    def call_async(request):
        if not isinstance(request, client.srv_type.Request):
            raise TypeError()
        return send(request)

    def call(request, timeout_sec: Optional[float] = None):
        if not directory.may_block(node, f"{name} (Client.call)"):
            return Client.call(client, request, timeout_sec)
        future = call_async(request)
        directory.wait(node, client.callback_group, future, f"{name} (Client.call)", timeout_sec)
        if not future.done():
            client.remove_pending_request(future)
            if directory.relay is not None:
                directory.relay.forget(future)
            return None
        if future.exception() is not None:
            raise future.exception()
        return future.result()

    def service_is_ready() -> bool:
        # What its own process would see on the ROS graph: a service served here, or by another
        # place of the run (hosting/calls/between_places.py), else through DDS. rclpy's waits
        # (wait_for_service, AsyncParameterClient.wait_for_services) ask this.
        if directory.lookup(name, client.srv_type) is not None:
            return True
        relay = directory.relay
        if relay is not None and origin is not None and relay.leaves(origin, name):
            return relay.serves(name)
        return Client.service_is_ready(client)

    client.call_async, client.call, client.service_is_ready = call_async, call, service_is_ready
    client.__dict__.pop("wait_for_service", None)          # rclpy's own, polling the above
    for request, future in getattr(client, "calls_before_hosted", ()):
        future._set_executor(executor)
        send(request, future)
    client.calls_before_hosted = ()


def _chained(sent: Future, future: CallFuture) -> CallFuture:
    """``future`` completes as ``sent`` does."""
    sent.add_done_callback(lambda done: future.done() or (future.set_exception(done.exception())
                                                          if done.exception() is not None
                                                          else future.set_result(done.result())))
    return future


def wait_during_construction(node: Node, will_be_served: Callable[[str], bool]) -> None:
    """Before ``node``'s constructor: a client it makes there may wait for its service (the ROS 2
    tutorials' ``while not client.wait_for_service(timeout_sec=1.0)``), then call it. Hosted, the
    service may belong to a node built after it, or in another process, and is served by tick 0,
    when calls can first be made: such a wait ends at once (``will_be_served(name)``, true only
    while the nodes are built), instead of for ever, and a call made before the client is hosted
    is kept and sent once it is (``host_client``), instead of lost."""
    create_client = node.create_client

    def hosted_create_client(srv_type, srv_name, *args, **kwargs):
        client = create_client(srv_type, srv_name, *args, **kwargs)
        client.calls_before_hosted = []

        def service_is_ready() -> bool:
            return will_be_served(client.service_name) or Client.service_is_ready(client)

        def call_async(request):
            if not isinstance(request, client.srv_type.Request):
                raise TypeError()
            future = CallFuture()
            client.calls_before_hosted.append((copy_message(request), future))
            return future
        client.service_is_ready, client.call_async = service_is_ready, call_async
        return client
    node.create_client = hosted_create_client
