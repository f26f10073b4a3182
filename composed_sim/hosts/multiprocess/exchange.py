"""Multi-process mode's tick exchange: the simulator's per-domain nodes as one, and the run-wide
topics relayed between the controller processes (hosting/run_wide/link.py)."""
from __future__ import annotations

import time
from typing import Callable, Optional

from composed_sim.hosting import (CallRelay, handover_order, NodesExchange, Rounds, routed, RUN_WIDE_ORIGIN,
                                  RunWideNodes, RunWideRelay, SimulatorLink)
from composed_sim.ros.simulator_node import AnswerTypeError, SimulatorNode
from composed_sim.world.schema import World


class RunWideLinks:
    """The run-wide topics of a multi-process run: the world's run-wide nodes, here, and a link
    into each domain whose robots use run-wide topics."""

    def __init__(self, world: World, logs=None, relays_actions: bool = True):
        self.relay = RunWideRelay(world.robot_names())
        # The run-wide nodes' calls with the robots; ``relays_actions``: see CallRelay.
        self.calls = CallRelay(world.robot_names(), relays_actions=relays_actions)
        self.nodes: Optional[RunWideNodes] = None
        self.links: dict[int, SimulatorLink] = {}      # per domain, once a robot there uses run-wide topics
        self._logs = logs

    def link(self, domain: int, context) -> SimulatorLink:
        """The link into ``domain``, in ``context`` (the simulator's there)."""
        if domain not in self.links:
            self.links[domain] = SimulatorLink(context, f"composed_sim_run_wide_d{domain}", self._logs)
        return self.links[domain]

    def batch(self, tick: int, sent: dict[int, list]) -> list:
        """The batch that opens ``tick``: the run-wide nodes' part of it, then what the robots sent
        during the tick before, in robot order (hosting/run_wide/relay.py)."""
        if self.nodes is not None:
            if self._logs is not None:
                self._logs.tick = tick
            self.nodes.start_tick(tick)
        return self.relay.take_outbox() + [m for i in sorted(sent) for m in sent[i]]

    def destroy(self) -> None:
        if self.nodes is not None:
            self.nodes.destroy()
            self.nodes = None
        for link in self.links.values():
            link.destroy()
        self.links = {}


class LinkedExchange(NodesExchange, Rounds):
    """The per-domain simulator nodes, and the run-wide relay between the controller processes:
    each tick's batch goes to every domain before the tick's sensors, and a tick closes once every
    robot that publishes run-wide messages has sent its part.

    It leads the rounds of calls between places (hosting/calls/rounds.py): place 0 is this process
    (the run-wide nodes, and the drones' services: ``_here``), then each domain whose robots use
    the link, its robots' controller processes. A robot handed calls replies once idle, with the
    calls its nodes made; the calls for the run-wide nodes among them are served here at once."""

    def __init__(self, nodes: dict[int, SimulatorNode], domains: dict[str, int], names: list[str], tick_ns: int,
                 run_wide: RunWideLinks, check: Callable[[], None], round_timeout_s: float = 1.0, drones=None):
        """``nodes``: the simulator's node in each domain; ``domains``: each robot's; ``drones``: the
        drones' endpoints beside them (hosting/drones.py), served here."""
        super().__init__(list(nodes.values()), check)
        self._drones = drones
        self._published: dict[str, int] = {}     # setpoints the drones' processes sent so far, by topic
        self._by_domain, self._domains, self._names, self._tick_ns = nodes, domains, names, tick_ns
        self._run_wide = run_wide
        self._round_timeout_s = round_timeout_s     # how long robots sent calls have to reply
        self._batch: Optional[list] = None
        self._tick = 0
        self._stamp = 0
        self._here = drones.places if drones is not None else frozenset()     # places served here
        self._round_batch: Optional[list] = None     # the tick's batch, sent with its first round
        self._waiting: dict[int, list[int]] = {}     # per domain: the robots to reply to the last round
        self._places: tuple = ((), ())

    def publish_tick(self, frame) -> None:
        run_wide = self._run_wide
        for node in self.nodes:     # the robots' clocks move with the batch below (hosting/run_wide/link.py)
            node.open_tick(frame.tick)
        if self._batch is None:               # tick 0: what the run-wide nodes publish at its start
            self._batch = run_wide.batch(frame.tick, {})
        self._tick, self._stamp = frame.tick, frame.tick * self._tick_ns
        run_wide.relay.deliver(self._batch)       # the run-wide nodes' subscriptions
        if self._batch:
            self.nodes[0].mirror_run_wide(self._batch, self._stamp)
        # With the batch, the run-wide nodes' calls of their part of the tick; what the robots
        # reply (and what that leads to) is handed over in rounds before the sensors.
        if self._drones is not None:
            self._drones.start_tick()         # other processes' calls to the drones' services
        self._round_batch = self._batch    # it goes with the first round's calls, to every domain
        self.hand_over(routed(run_wide.calls.take_outbox(), *self.places()))
        self.lead([])
        super().publish_tick(frame)

    # --- the rounds of calls between places (Rounds) ---------------------------------------------

    def places(self) -> tuple[list, range]:
        domains = list(self._run_wide.links)
        if len(self._places[1]) != len(domains) + 1:     # a domain's link is made as its robots start
            robots = [{i for i, name in enumerate(self._names) if self._domains[name] == d} - self._here
                      for d in domains]
            self._places = ([self._here, *robots], range(len(domains) + 1))
        return self._places

    def made(self) -> list:
        links = self._run_wide.links
        deadline = time.monotonic() + self._round_timeout_s
        for domain, robots in self._waiting.items():
            waiting = [i for i in robots if not self._failed(i)]
            while waiting and time.monotonic() < deadline:
                links[domain].take(self._stamp, waiting, replies=True)
                waiting = [i for i in waiting if i not in links[domain].replied]
                if waiting:
                    time.sleep(0.0002)
        self._waiting = {}
        made = [item for link in links.values() for item in link.calls]
        for link in links.values():
            link.calls = []
            if link.notes:             # what a call made (a configure's subscriptions, say)
                self._take_notes(link)
        # The run-wide nodes live here: they serve the calls for them at once, until idle.
        for_run_wide = [item for item in handover_order(made) if item.destination == RUN_WIDE_ORIGIN]
        if for_run_wide:
            self._run_wide.calls.deliver(for_run_wide)
        if self._run_wide.nodes is not None:
            self._run_wide.nodes.run_until_idle()
        if self._drones is not None:
            self._drones.run_until_idle()
        return self._run_wide.calls.take_outbox() + [item for item in made if item.destination != RUN_WIDE_ORIGIN]

    def hand_over(self, shares: dict[int, list]) -> None:
        if shares.get(0):
            self._run_wide.calls.deliver(shares[0])
        for k, (domain, link) in enumerate(self._run_wide.links.items(), 1):
            calls: dict[Optional[int], list] = {}
            for item in shares.get(k, ()):
                calls.setdefault(item.destination, []).append(item)     # None: every robot of the domain
            if self._round_batch is not None:
                link.publish(self._stamp, self._round_batch, calls)
            elif calls:
                link.publish_calls(self._stamp, calls)
            self._waiting[domain] = [i for i in calls if i is not None]
        self._round_batch = None

    # --- the tick's answers ---------------------------------------------------------------------

    def wait_for_answers(self, timeout_s: float) -> bool:
        """Every robot's answer, and the part of the tick that each robot using the link sent once
        its nodes were idle (its run-wide messages; for a robot that answers when published, the
        sign that its nodes are done with the tick: it keeps its last command); then the rounds
        of the calls those parts carried."""
        deadline = time.monotonic() + timeout_s
        while True:
            waiting = False
            for link in self._run_wide.links.values():
                pending = [i for i in link.senders if not link.done(i) and not self._failed(i)]
                link.take(self._stamp, pending)
                if link.notes:
                    self._take_notes(link)
                for i in pending:
                    if not link.done(i):
                        waiting = True
                    elif i not in link.answered:      # idle without an answer: keeps its command
                        name = self._names[i]
                        self._by_domain[self._domains[name]].settle_idle([name])
            if not waiting and any(link.calls for link in self._run_wide.links.values()):
                self.lead([])                # every part is in: the calls they carried, in rounds
                continue
            if (self.all_answered and not waiting) or time.monotonic() > deadline:
                return self.all_answered
            # The domains' nodes take their answers in threads of their own: the last one may come
            # in between the look above and this one.
            unanswered = next((n for n in self.nodes if not n.all_answered), None)
            if unanswered is not None:
                if not unanswered.wait_for_answers(min(self.POLL_S, max(0.0, deadline - time.monotonic()))):
                    self._check()
            else:
                time.sleep(0.0002)

    def _failed(self, index: int) -> bool:
        name = self._names[index]
        node = self._by_domain[self._domains[name]]
        return bool(node.failed[node.row_of(name)])

    def close_tick(self, fallback, previous, commands) -> None:
        super().close_tick(fallback, previous, commands)
        if self._drones is not None:        # before the run-wide nodes' part of the next tick
            self.drone_commands = self._drones.take(self._published, self._round_timeout_s)
        sent = {}
        for link in self._run_wide.links.values():
            # A robot failed in the tick may have sent its last part (its last log lines) as it ended.
            link.take(self._stamp, [i for i in link.senders if self._failed(i)])
            sent.update(link.collect())
        self._batch = self._run_wide.batch(self._tick + 1, sent)

    def _take_notes(self, link) -> None:
        """What robots' nodes made since they started, as their parts and replies said
        (hosting/run_wide/link.py): a first cmd_vel publisher (a lifecycle node configured) is
        subscribed to with its type, and its first answer, published before, taken now; the
        simulator's publishers of sensors that new subscriptions read wait until those are
        matched. So that the next sensors and answers go as in one process."""
        notes, link.notes = link.notes, {}
        deadline = time.monotonic() + self._round_timeout_s * 5
        for index, parts in notes.items():
            name = self._names[index]
            node = self._by_domain[self._domains[name]]
            for part in parts:
                for topic, count in part.get("published", {}).items():
                    self._published[topic] = self._published.get(topic, 0) + count
                if "answer" in part:
                    self._subscribe_later_answers(node, name, *part["answer"])
                endpoints = node.endpoints_by_topic() if part.get("reads") else {}
                for topic, count in part.get("reads", {}).items():
                    publisher = endpoints.get(topic)
                    while publisher is not None and publisher.get_subscription_count() < count \
                            and time.monotonic() < deadline:
                        time.sleep(0.001)

    def _subscribe_later_answers(self, node, name: str, type_name: str, answer) -> None:
        try:
            node.take_answers_as(name, type_name)
        except AnswerTypeError as e:
            node.mark_failed(name, f"controller failed: {e}")
            return
        if answer is not None:
            node.take_carried_answer(name, answer)
        subscription = node.answer_subscription(name)
        deadline = time.monotonic() + self._round_timeout_s * 5
        while subscription.get_publisher_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.001)

