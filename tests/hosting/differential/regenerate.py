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

HERE = Path(__file__).resolve().parent
FIXED = HERE / "fixed_programs.json"
KNOWN = HERE / "known_mismatches.json"
TICKS = 16
# Programs of the default run: (seed, how many). Their constructs: ``test_differential.DEFAULT``.
SEEDS = ((1, 3), (2, 3))


def fixed_programs() -> list[dict]:
    from differential.strategies import draw_programs
    from differential.test_differential import DEFAULT
    return [p for seed, count in SEEDS for p in draw_programs(count, seed, DEFAULT)]


def main() -> int:
    from differential.truth import FIXTURES, run_truth, store
    programs = fixed_programs()
    FIXED.write_text(json.dumps(programs, indent=1) + "\n")
    known = [case["program"] for case in json.loads(KNOWN.read_text())]
    for old in FIXTURES.glob("*.json"):
        old.unlink()
    unstable = 0
    with tempfile.TemporaryDirectory() as tmp:
        for batch in (programs, known):
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
