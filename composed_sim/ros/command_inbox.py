"""A simulator node's inbox: every robot's ``leds`` and ``rab_tx`` subscriptions, on a node of their
own that no executor spins, drained by the host at the act phase.

Draining them there rather than in callbacks is what makes an LED change published before a
tick's answer land on that same tick, whatever the executor.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
from rclpy.context import Context
from rclpy.node import Node

from composed_sim.ros import contract as c, decoding
from composed_sim.ros.answer_ledger import AnswerLedger
from composed_sim.ros.in_process import inbox_of
from composed_sim.ros.robot_settings import quiet_node_options
from composed_sim.ros.robot_taps import RobotTaps
from composed_sim.world.robot_models import RANGE_AND_BEARING, RobotModel

LATE_LEDS = "leds answering an earlier tick arrived after that tick closed: applied one tick late"
LATE_RAB = "rab_tx answering an earlier tick arrived after that tick closed: applied one tick late"


class CommandInbox:
    """The LEDs and rab_tx of a simulator node's robots, taken as bytes (raw) and decoded with
    numpy; late or invalid ones recorded in the node's ledger."""

    def __init__(self, node_name: str, context: Context, names: Sequence[str], models: Sequence[RobotModel],
                 devices: Sequence[frozenset], rab_payload_bytes: int, rows: np.ndarray,
                 ledger: AnswerLedger, taps: RobotTaps):
        self.node = Node(node_name + "_inbox", context=context, **quiet_node_options())
        self._models, self._rab_payload_bytes, self._rows = models, rab_payload_bytes, rows
        self._ledger, self._taps = ledger, taps
        self._led_subs = [self._subscribe(c.LEDS, name) for name in names]
        self._rab_subs = [self._subscribe(c.RAB_TX, name) if RANGE_AND_BEARING in devices[i] else None
                          for i, name in enumerate(names)]

    def _subscribe(self, topic: c.Topic, robot: str):
        return self.node.create_subscription(c.msg_type(topic), c.topic_name(robot, topic), lambda msg: None,
                                             c.QOS, event_callbacks=c.SUBSCRIPTION_EVENTS, raw=True)

    @property
    def subscriptions(self) -> list:
        return [s for s in (*self._led_subs, *self._rab_subs) if s is not None]

    def robot_subscriptions(self, i: int) -> tuple:
        """Robot i's LED and rab_tx subscriptions (None: it has no range-and-bearing)."""
        return self._led_subs[i], self._rab_subs[i]

    def take_led_commands(self) -> dict[int, np.ndarray]:
        """The latest valid colours per simulation row that sent any.

        A controller publishes ``leds`` before its ``cmd_vel``, but these are two DDS writers
        and DDS orders samples per writer only. Inside one participant (composed mode) delivery
        is synchronous, so the order holds. Across processes both samples go to the same locator
        and are received in order by one transport thread (0 late LEDs in 34,000 robot-ticks
        measured); only a lost LED sample, re-sent at the writer's next heartbeat (~3 s), could
        land after its tick closed. The sample's source timestamp tells that for sure (same
        host clock): an LED published before this tick's sensors went out answers an earlier
        tick. It is still applied (it is the latest colour) and recorded as a violation, so
        "same world and seed ⇒ same trajectories unless a violation is recorded" holds.
        """
        return self._drain(self._led_subs, c.LEDS, LATE_LEDS,
                           lambda i, msg: decoding.decode_leds(msg, self._models[i].n_leds))

    def take_rab_payloads(self) -> dict[int, np.ndarray]:
        """Like the LEDs': the latest valid payload per simulation row that sent any, to be set
        before the next step (so it is heard one tick later, as in ARGoS)."""
        return self._drain(self._rab_subs, c.RAB_TX, LATE_RAB,
                           lambda i, msg: decoding.decode_payload(msg, self._rab_payload_bytes))

    def _drain(self, subs: list, topic: c.Topic, late: str, decode: Callable) -> dict[int, np.ndarray]:
        out = {}
        for i, sub in enumerate(subs):
            if sub is None:
                continue
            inbox = inbox_of(sub)      # what the robot's nodes handed over in process (ros/in_process.py)
            if inbox is not None:
                while inbox.queue:
                    self._drained(i, topic, late, decode, *inbox.take(), out)
                if not inbox.dds_may_hold():
                    continue
            while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                self._drained(i, topic, late, decode, taken[0], taken[1]["source_timestamp"], out)
            if inbox is not None:
                inbox.emptied()
        return out

    def _drained(self, i: int, topic: c.Topic, late: str, decode: Callable, msg, published_ns: int, out: dict) -> None:
        """Robot i's message ``msg`` on an inbox topic, published at ``published_ns`` (wall)."""
        ledger = self._ledger
        if ledger.failed[i]:
            return
        self._taps.message(topic, i, msg, ledger.tick_key)
        with ledger.lock:
            if ledger.opened_ns is not None and published_ns < ledger.opened_ns:
                ledger.record(ledger.current_tick, i, late)
            try:
                out[int(self._rows[i])] = decode(i, msg)
            except ValueError as e:
                ledger.record(ledger.current_tick, i, f"{topic.name}: {e}")

    def destroy(self) -> None:
        self.node.destroy_node()
