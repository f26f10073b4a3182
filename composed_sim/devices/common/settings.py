"""What every device's world-file settings are built from: strict pydantic models (unknown fields
rejected, no NaN or infinity) and the switch that a device's presence in a world file means.

The world schema (``world/schema.py``) builds its sections on ``Strict`` too, and gathers every
device's settings class into a group's ``devices``.
"""
from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

PositiveFloat = Annotated[float, Field(gt=0)]
NonNegativeFloat = Annotated[float, Field(ge=0)]
Probability = Annotated[float, Field(ge=0, le=1)]


class Strict(BaseModel):
    # NaN or infinity in a position or a size would only surface later as a physics blow-up.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class DeviceSwitch(Strict):
    """Present in the world file: the device runs (unless enabled: false)."""
    enabled: bool = True
