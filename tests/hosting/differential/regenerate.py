"""Regenerate the default run's fixtures: the fixed programs (drawn with fixed seeds from the
constructs that match today, ``fixed_programs.json``) and the ground truth of those and of the
known mismatches' programs (``truth/``, one JSON file per program, named by its hash).

``python -m differential.regenerate`` (from ``tests/hosting``, with the repository's venv); it
runs rclpy itself, twice per program, and refuses to keep a program whose two runs differ.
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from differential.known import DEFAULT, FIXED, known_cases
from differential.spec import TICKS

SEEDS = ((1, 3), (2, 3))     # the default run's programs: (seed, how many), drawn from DEFAULT


def draw_fixed() -> list[dict]:
    from differential.strategies import draw_programs
    return [p for seed, count in SEEDS for p in draw_programs(count, seed, DEFAULT)]


def main() -> int:
    from differential.truth import FIXTURES, run_truth, store
    programs = draw_fixed()
    FIXED.write_text(json.dumps(programs, indent=1) + "\n")
    known = [case["program"] for case in known_cases()]
    for old in FIXTURES.glob("*.json"):
        old.unlink()
    unstable = 0
    with tempfile.TemporaryDirectory() as tmp:
        for batch in filter(None, (programs, known)):
            for record in run_truth(batch, TICKS, Path(tmp)):
                if not record["stable"]:
                    unstable += 1
                    print("not stable under rclpy:", record["notes"], json.dumps(record["program"]), file=sys.stderr)
                    continue
                store(record, FIXTURES)
    print(f"{len(programs)} fixed programs, {len(known)} known mismatches; {unstable} not stable")
    return 1 if unstable else 0


if __name__ == "__main__":
    sys.exit(main())
