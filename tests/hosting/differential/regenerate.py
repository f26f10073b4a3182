"""Regenerate the default run's fixtures: the fixed programs (drawn with fixed seeds from every
construct, ``fixed_programs.json``) and their ground truth (``truth/``, one JSON file per program,
named by the hash of its text, so that a program and its recorded run cannot disagree).

``python -m differential.regenerate`` (from ``tests/hosting``, with the repository's venv); it
runs rclpy itself, twice per program, and refuses to keep a program whose two runs differ.
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from differential.known import FIXED
from differential.spec import TICKS

SEEDS = ((1, 3), (2, 3))     # the default run's programs: (seed, how many)


def draw_fixed() -> list[dict]:
    from differential.strategies import ALL, draw_programs
    return [p for seed, count in SEEDS for p in draw_programs(count, seed, ALL)]


def main() -> int:
    from differential.truth import FIXTURES, run_truth, store
    programs = draw_fixed()
    FIXED.write_text(json.dumps(programs, indent=1) + "\n")
    for old in FIXTURES.glob("*.json"):
        old.unlink()
    unstable = 0
    with tempfile.TemporaryDirectory() as tmp:
        for record in run_truth(programs, TICKS, Path(tmp)):
            if not record["stable"]:
                unstable += 1
                print("not stable under rclpy:", record["notes"], json.dumps(record["program"]), file=sys.stderr)
                continue
            store(record, FIXTURES)
    print(f"{len(programs)} fixed programs; {unstable} not stable")
    return 1 if unstable else 0


if __name__ == "__main__":
    sys.exit(main())
