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
        if ca != cb:
            diffs.append(TickDiff(tick, sorted((ca - cb).elements(), key=str), sorted((cb - ca).elements(), key=str)))
    return diffs


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
