"""The differential check: a batch of programs run under rclpy (cached) and hosted in each mode,
each program's events compared tick by tick (``events.py``)."""
from __future__ import annotations

import json
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from differential.events import TickDiff, compare, describe
from differential.hosted import MODES, run_hosted
from differential.truth import truths

PARALLEL_MODES = 2        # the hosted runs of a batch at once (a 2-core machine)

# A robot that only listens: a batch of one robot still fills two worker processes.
FILLER = {"robots": 1, "nodes": [{"name": "n0", "entities": [{"kind": "scan", "name": "scan", "body": []},
                                                              {"kind": "cmd_vel", "name": "cmd_vel"}]}]}


@dataclass
class Mismatch:
    program: dict
    mode: str
    diffs: list[TickDiff]
    notes: list[str] = field(default_factory=list)

    def __str__(self) -> str:
        notes = "".join(f"\n  run: {n}" for n in self.notes)
        return (f"--workers/mode {self.mode}: {len(self.diffs)} ticks differ from rclpy, first {self.diffs[0].tick}"
                f"{notes}\n{describe(self.diffs)}\nprogram:\n{json.dumps(self.program, indent=1)}")


@dataclass
class Outcome:
    mismatches: list[Mismatch]
    unstable: list[dict]          # programs whose ground truth is not defined (two rclpy runs differ)
    compared: int

    def report(self) -> str:
        return "\n\n".join(str(m) for m in self.mismatches)


def check(programs: list[dict], ticks: int, workdir: Path, modes=tuple(MODES), recorded_only: bool = False,
          attribute: bool = False) -> Outcome:
    """``attribute``: a program that mismatches in a batch is run again alone, to tell whether the
    mismatch is its own (doubles the cost of a mismatch)."""
    records = truths(programs, ticks, workdir, recorded_only)
    batch = programs + ([FILLER] if sum(p["robots"] for p in programs) < 2 else [])
    mismatches = []
    # The modes' runs at once: each is a process of its own, mostly waiting on the others of its run.
    with ThreadPoolExecutor(max_workers=PARALLEL_MODES) as pool:
        runs = dict(zip(modes, pool.map(lambda mode: run_hosted(batch, ticks, mode, workdir / mode), modes)))
    for mode in modes:
        hosted = runs[mode]
        for i, record in enumerate(records):
            if not record["stable"]:
                continue
            diffs, notes = compare(record["events"], hosted.events.get(i, []), ticks), hosted.notes
            if diffs and attribute and len(programs) > 1:
                # Whose fault is it? The program alone says; where it matches alone, the batch's
                # differences count only if the batch's run itself did not fail (another
                # program's error would stop it too).
                alone = run_hosted([programs[i], FILLER], ticks, mode, workdir / f"{mode}_{i}")
                alone_diffs = compare(record["events"], alone.events.get(0, []), ticks)
                if alone_diffs or hosted.failed:
                    diffs, notes = alone_diffs, alone.notes
                else:
                    notes = notes + ["only beside the batch's other programs: alone it matches"]
            if diffs:
                mismatches.append(Mismatch(programs[i], mode, diffs, notes))
    unstable = [r["program"] for r in records if not r["stable"]]
    return Outcome(mismatches, unstable, len(programs) - len(unstable))
