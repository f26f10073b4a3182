"""Generated robots' programs behave hosted, in every mode, as in processes of their own under
rclpy (``ground_truth.py`` says how the ground truth is run and what rclpy defines; ``events.py``
how runs are compared).

- default run: the fixed programs (``fixed_programs.json``, drawn from the constructs that match
  today, ``known.DEFAULT``; their rclpy runs are committed in ``truth/``) in every mode; each known
  mismatch (``known_mismatches.json``) as a strict xfail in the first mode it fails in, the others
  behind ``slow``;
- ``slow``: 200 generated programs (25 batches of 8, each batch one run per mode) from
  ``known.DEFAULT``, which must match, and 200 from every construct, which must match once the
  known mismatches are fixed (a strict xfail until then). A mismatch is shrunk
  (``DIFFERENTIAL_SHRINK_S`` seconds, 300 by default) and reported with its program.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from differential.check import check
from differential.known import DEFAULT, fixed_programs, known_cases
from differential.spec import TICKS
from differential.strategies import ALL, programs

BATCHES, PER_BATCH = 25, 8


def test_the_fixed_programs_behave_in_every_mode_as_in_processes_of_their_own(tmp_path):
    outcome = check(fixed_programs(), TICKS, tmp_path)
    assert outcome.unstable == [], "the committed ground truth is missing: python -m differential.regenerate"
    assert not outcome.mismatches, outcome.report()


def known_params():
    for case in known_cases():
        for i, mode in enumerate(case["fails"]):
            marks = [pytest.mark.xfail(strict=True, reason=case["title"])] + ([pytest.mark.slow] if i else [])
            yield pytest.param(case, mode, marks=marks, id=f"{case['id']}-{mode}")


@pytest.mark.parametrize("case, mode", list(known_params()))
def test_a_known_mismatch_behaves_as_in_processes_of_its_own(case, mode, tmp_path):
    outcome = check([case["program"]], TICKS, tmp_path, modes=(mode,))
    assert outcome.unstable == []
    assert not outcome.mismatches, f"{case['title']}\n{outcome.report()}"


def check_generated(batch: list[dict]) -> None:
    import json
    from differential.shrink import minimize
    with tempfile.TemporaryDirectory() as tmp:
        outcome = check(batch, TICKS, Path(tmp))
        assert len(outcome.unstable) <= 1, f"{len(outcome.unstable)} programs of {len(batch)} run differently under rclpy twice"
        if outcome.mismatches:
            first = outcome.mismatches[0]
            budget = float(os.environ.get("DIFFERENTIAL_SHRINK_S", "300"))
            small = minimize(first.program, first.mode, TICKS, Path(tmp) / "shrink", budget_s=budget) if budget else None
            pytest.fail(f"{len(outcome.mismatches)} mismatches; the first, shrunk:\n"
                        f"{json.dumps(small, indent=1) if small else '(not shrunk)'}\n\n{outcome.report()}")


GENERATED = settings(max_examples=BATCHES, derandomize=True, database=None, deadline=None,
                     phases=[Phase.explicit, Phase.generate], suppress_health_check=list(HealthCheck))


@pytest.mark.slow
@GENERATED
@given(st.lists(programs(DEFAULT), min_size=PER_BATCH, max_size=PER_BATCH))
def test_generated_programs_of_the_matching_constructs_behave_in_every_mode_as_in_their_own_processes(batch):
    check_generated(batch)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the known mismatches (known_mismatches.json) are not fixed yet")
@GENERATED
@given(st.lists(programs(ALL), min_size=PER_BATCH, max_size=PER_BATCH))
def test_generated_programs_behave_in_every_mode_as_in_processes_of_their_own(batch):
    check_generated(batch)

