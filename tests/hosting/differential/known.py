"""Where the hosts differ from rclpy today, as the generator found it, and what matches.

``known_mismatches.json``: one case per distinct mismatch, each a minimal program (shrunk by
``shrink.py``), the modes it fails in, and the diagnosis (the hosting code at fault and why).
``DEFAULT``: the constructs whose generated programs match rclpy in every mode today; the default
run's fixed programs (``fixed_programs.json``) are drawn from them. When a fix lands, its case's
test passes unexpectedly (strict xfail): take the mode out of the case's ``fails`` (the case
goes once no mode is left), and add the constructs it concerned to ``DEFAULT``
(then ``python -m differential.regenerate``).
"""
from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent
KNOWN = HERE / "known_mismatches.json"
FIXED = HERE / "fixed_programs.json"

DEFAULT = frozenset({"done", "async_service", "odd_periods", "pubsub", "run_wide", "two_robots", "ready",
                     "params", "apc", "make", "late_service"})


def known_cases() -> list[dict]:
    return json.loads(KNOWN.read_text()) if KNOWN.is_file() else []


def fixed_programs() -> list[dict]:
    return json.loads(FIXED.read_text())
