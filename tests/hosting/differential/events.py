"""What a run of a batch leaves: each program's events by tick, and how two runs are compared.

An event is ``(tick, who, activation, seq, kind, *payload)``. Compared per tick as a multiset:
within an activation the events keep their order through ``seq``, and an activation's id says
what started it (a timer's n-th firing, a scan's tick, a request's value), so one callback's
events are compared as an exact sequence while the order between callbacks, which rclpy does not
define, is not compared. What happens before tick 0 (construction, ``autostart``, the first
calls) is compared with tick 0: in both runs it comes before tick 0's sensors.
"""
from __future__ import annotations

import json
import re
from collections import Counter
from dataclasses import dataclass, field

EVENT = re.compile(r"\bEV (p\d+) (\S+) (\[.*\])\s*$")
FAILED = "failed"


@dataclass
class RunResult:
    label: str                                   # "rclpy", or the hosted mode
    events: dict[int, list[tuple]] = field(default_factory=dict)    # program → events
    notes: list[str] = field(default_factory=list)                  # exit status, errors, stalls
    failed: bool = False                         # the run itself ended in error: a program may be its cause

    def add(self, program: int, event: tuple) -> None:
        self.events.setdefault(program, []).append(event)

    def add_line(self, line: str, tick: int) -> bool:
        """An ``EV`` line logged at ``tick``; False if the line is none."""
        m = EVENT.search(line)
        if m is None:
            return False
        self.add(int(m.group(1)[1:]), (tick, m.group(2), *json.loads(m.group(3))))
        return True

    def fail(self, program: int, who: str, tick: int, what: str) -> None:
        """A place stopped: a process died, the host failed a robot."""
        self.add(program, (tick, who, "-", 0, FAILED, what))


def by_tick(events: list[tuple], ticks: int) -> dict[int, Counter]:
    out: dict[int, Counter] = {}
    for tick, *rest in events:
        if tick >= ticks:
            continue
        out.setdefault(max(tick, 0), Counter())[_frozen(rest)] += 1
    return out


def _frozen(value):
    return tuple(_frozen(v) for v in value) if isinstance(value, (list, tuple)) else value


@dataclass
class TickDiff:
    tick: int
    only_truth: list[tuple]
    only_hosted: list[tuple]


def compare(truth: list[tuple], hosted: list[tuple], ticks: int) -> list[TickDiff]:
    """The ticks whose events differ, in order."""
    a, b = by_tick(truth, ticks), by_tick(hosted, ticks)
    diffs = []
    for tick in sorted(set(a) | set(b)):
        ca, cb = a.get(tick, Counter()), b.get(tick, Counter())
        only_truth, only_hosted = ca - cb, cb - ca
        for event in [e for e in only_hosted if not only_truth and _feedback_raced_by_result(e, ca)]:
            del only_hosted[event]
        if only_truth or only_hosted:
            diffs.append(TickDiff(tick, sorted(only_truth.elements(), key=str),
                                  sorted(only_hosted.elements(), key=str)))
    return diffs


def _feedback_raced_by_result(event: tuple, truth: Counter) -> bool:
    """A goal's feedback that rclpy's client may drop: the last ones its server sent right before
    the result. Its client takes one feedback per wake-up, and the result (taken with one of them,
    or before) removes the goal's feedback callback, so how many of the last feedbacks it hears
    depends on its threads' timing; hosted, the client hears every one. So where rclpy heard the
    goal's first m feedbacks and its result in this tick, the hosted run's feedback m + 1, … is not
    a difference."""
    who, activation, _, kind, *_ = event
    if kind != "feedback" or ".fb" not in activation:
        return False
    goal, number = activation.rsplit(".fb", 1)
    heard = {int(e[1].rsplit(".fb", 1)[1]) for e in truth
             if e[0] == who and e[2] == 0 and e[3] == "feedback" and e[1].rsplit(".fb", 1)[0] == goal}
    result = any(e[0] == who and e[3] == "result" and (e[1] == goal.rsplit("/", 1)[0] or e[1] == f"{goal}.result")
                 for e in truth)
    return result and int(number) > max(heard, default=0) and heard == set(range(1, len(heard) + 1))


def describe(diffs: list[TickDiff], limit: int = 6, per_tick: int = 8) -> str:
    lines = []
    for d in diffs[:limit]:
        lines.append(f"  tick {d.tick}:")
        lines += [f"    rclpy only:  {e}" for e in d.only_truth[:per_tick]]
        lines += [f"    hosted only: {e}" for e in d.only_hosted[:per_tick]]
        more = len(d.only_truth) + len(d.only_hosted) - 2 * per_tick
        if more > 0:
            lines.append(f"    … {more} more")
    if len(diffs) > limit:
        lines.append(f"  … {len(diffs) - limit} more ticks differ (first: {diffs[0].tick}, last: {diffs[-1].tick})")
    return "\n".join(lines)
