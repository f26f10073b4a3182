"""What the lockstep records when a robot's controller breaks the rules of a tick."""
from __future__ import annotations

from dataclasses import dataclass

FAILED = "controller failed: "    # how the one violation that fails a robot begins


@dataclass
class Violation:
    tick: int
    robot: str
    reason: str
