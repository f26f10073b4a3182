"""What the world file's models share: planar vectors and colours, and how a check that spans
several fields reports its problems (``invalid``): a ``PydanticCustomError`` of type ``"world"``
whose context carries ``problems``, ``(sub-path, message, value)`` triples relative to the model
that raised it, so the loader can point at the exact field (and its line) of each problem."""
from __future__ import annotations

import math
import re
from typing import Annotated, Any

from pydantic import Field
from pydantic_core import PydanticCustomError

Vec2 = tuple[float, float]
RGB = tuple[Annotated[int, Field(ge=0, le=255)], Annotated[int, Field(ge=0, le=255)],
            Annotated[int, Field(ge=0, le=255)]]

# Robot names become ROS namespaces (<prefix><index>), so the prefix must be a ROS name token.
ROS_TOKEN = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


def invalid(problems: list[tuple[tuple, str, Any]]) -> PydanticCustomError:
    """One validation error carrying several (sub-path, message, value) problems."""
    text = "; ".join(".".join(map(str, path)) + (": " if path else "") + message
                     for path, message, _ in problems)
    return PydanticCustomError("world", "{text}", {"text": text, "problems": problems})


def finite(x: float) -> bool:
    try:
        return math.isfinite(x)
    except OverflowError:   # an int too large for a float
        return False
