"""Whether the simulator and the hosted nodes see each other: before tick 0 every contract
endpoint must be matched on both sides, or a tick-0 sensor, an answer or the first LED message
could go to an endpoint not matched yet and be lost (the topics are volatile)."""
from __future__ import annotations

import time
from typing import Callable, Optional, Sequence

from rclpy.node import Node

from composed_sim.ros import contract as c
from composed_sim.ros.crazyflie.messages import SETPOINTS


def publishes(endpoint) -> bool:
    """Is ``endpoint`` a publisher (else a subscription)?"""
    return hasattr(endpoint, "get_subscription_count")


def matched_count(endpoint) -> int:
    """How many endpoints of the other side DDS matched with ``endpoint``: a publisher's
    subscriptions, a subscription's publishers."""
    return endpoint.get_subscription_count() if publishes(endpoint) else endpoint.get_publisher_count()


def matched(endpoint) -> bool:
    """A publisher with a matched subscription, a subscription with a matched publisher; True for
    None (a topic the caller does not serve, e.g. /clock, shared by all)."""
    return endpoint is None or matched_count(endpoint) >= 1


def contract_endpoints(nodes: Sequence[Node], robot: str) -> list:
    """The robot's nodes' publishers and subscriptions on contract topics and a drone's setpoint
    topics (their own other topics and the parameter/rosout plumbing are not the simulator's business)."""
    topics = {c.topic_name(robot, t) for t in c.SENSOR_TOPICS + c.ACTUATOR_TOPICS} | {c.CLOCK_TOPIC} \
        | {f"/{robot}/{name}" for name in SETPOINTS}
    return [e for node in nodes for e in list(node.publishers) + list(node.subscriptions) if e.topic_name in topics]


def poll_until(done: Callable[[], bool], timeout_s: float, should_stop: Callable[[], bool]) -> Optional[bool]:
    """Ask ``done()`` until it holds (True), a stop is requested (False) or ``timeout_s`` passed
    (None), pausing from 2 ms to 50 ms, doubling: hundreds of processes may be waiting at once."""
    deadline = time.monotonic() + timeout_s
    pause = 0.002
    while not done():
        if should_stop():
            return False
        if time.monotonic() > deadline:
            return None
        time.sleep(pause)
        pause = min(2 * pause, 0.05)
    return True
