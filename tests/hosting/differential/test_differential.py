"""Generated robots' programs behave hosted, in every mode, as in processes of their own under
rclpy (``ground_truth.py`` says how the ground truth is run and what rclpy defines; ``events.py``
how runs are compared; ``known.py`` the differences that are explained, each with its reason).

- default run: the fixed programs (``fixed_programs.json``, drawn with fixed seeds from every
  construct) in every mode, against their rclpy runs recorded in ``truth/`` (no rclpy process is
  started: ``python -m differential.regenerate`` records them; a program whose text changed has no
  recorded truth, and the test says so);
- ``slow``: 200 distinct generated programs (25 batches of 8, each batch one run per mode), their rclpy
  runs made once and kept (``truth.py``). Every mismatch must be a known one; the ones found are
  appended to ``$DIFFERENTIAL_REPORT`` (JSON lines) when it is set, to count them.
"""
from __future__ import annotations

import functools
import json
import os

import pytest

from differential.check import check
from differential.known import explained, fixed_programs
from differential.spec import TICKS
from differential.strategies import ALL, draw_programs

BATCHES, PER_BATCH = 25, 8
SEED = 1000


def unexplained(outcome, batch: list[dict], label: str) -> list:
    report = os.environ.get("DIFFERENTIAL_REPORT")
    if report:
        with open(report, "a") as f:
            for m in outcome.mismatches:
                f.write(json.dumps({"batch": label, "mode": m.mode, "known": explained(m.program, m.mode, batch), "program": m.program,
                                    "first_tick": m.diffs[0].tick}) + "\n")
    return [m for m in outcome.mismatches if not explained(m.program, m.mode, batch)]


def test_the_fixed_programs_behave_in_every_mode_as_in_processes_of_their_own(tmp_path):
    programs = fixed_programs()
    outcome = check(programs, TICKS, tmp_path, recorded_only=True)
    assert outcome.unstable == []
    left = unexplained(outcome, programs, "fixed")
    assert not left, "\n\n".join(map(str, left))


@functools.lru_cache(maxsize=1)
def generated() -> list[dict]:
    """The slow run's programs: distinct, drawn with one seed (hypothesis draws its simplest
    programs first for every seed, so batches of seeds of their own would share them)."""
    return draw_programs(BATCHES * PER_BATCH, SEED, ALL)


@pytest.mark.slow
@pytest.mark.parametrize("batch", range(BATCHES))
def test_generated_programs_behave_in_every_mode_as_in_processes_of_their_own(batch, tmp_path):
    programs = generated()[batch * PER_BATCH:(batch + 1) * PER_BATCH]
    outcome = check(programs, TICKS, tmp_path)
    # A program whose two rclpy runs differ has no one behaviour to compare with (rclpy's own
    # threads, on a loaded machine); most of a batch so means the rig itself is broken.
    assert len(outcome.unstable) <= len(programs) // 2, \
        f"{len(outcome.unstable)} of {len(programs)} programs run differently twice under rclpy"
    left = unexplained(outcome, programs, str(batch))
    assert not left, "\n\n".join(map(str, left))
