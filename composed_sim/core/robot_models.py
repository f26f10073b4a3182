"""Robot models as data: dimensions, drive limits and device layouts.

One place for every robot fact. Numbers for the foot-bot come from the ARGoS 3
sources (``plugins/robots/foot-bot``); see ``shared/reference/argos-models.md``.
Units are SI (REP-103): metres, radians, kilograms; x forward, y left, angles CCW.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def _ring_angles(first_deg: float, step_deg: float, count: int) -> tuple[float, ...]:
    return tuple(math.radians(first_deg + step_deg * i) for i in range(count))


@dataclass(frozen=True)
class ProximityRing:
    """IR rays cast radially outward from the body rim."""
    angles_rad: tuple[float, ...]   # [k] CCW from the front
    range_m: float                   # ray length measured from the rim
    elevation_m: float               # height of the rays: lower bodies are not seen


@dataclass(frozen=True)
class LightRing:
    angles_rad: tuple[float, ...]   # [k] CCW from the front


@dataclass(frozen=True)
class BlobCamera:
    """Omnidirectional coloured-blob camera looking down a mirror above the body."""
    height_m: float
    aperture_rad: float   # the square window's half-side is height * tan(aperture)


@dataclass(frozen=True)
class RobotModel:
    name: str
    body_radius_m: float
    body_height_m: float
    mass_kg: float
    wheel_separation_m: float      # distance between the two wheels (ARGoS "interwheel distance")
    wheel_radius_m: float
    max_wheel_speed_mps: float     # used to clamp commands; ARGoS's actuator has none, its examples use 0.10
    max_force_n: float             # pivot joint cap: how hard the drive can push
    max_torque_nm: float           # gear joint cap
    friction: float
    proximity: ProximityRing
    light: LightRing
    camera: BlobCamera
    # [n_leds, 3] body-frame (x, y, z) positions; ring LEDs first, beacon last.
    led_positions_m: tuple[tuple[float, float, float], ...] = field(default=())

    @property
    def n_leds(self) -> int:
        return len(self.led_positions_m)

    def led_positions_array(self) -> np.ndarray:
        """[n_leds, 3] body-frame LED positions."""
        return np.asarray(self.led_positions_m, dtype=float).reshape(-1, 3)


# --- foot-bot (ARGoS 3, plugins/robots/foot-bot/simulator) ---------------------------
_FOOTBOT_RING_LEDS = tuple(
    (0.090 * math.cos(math.radians(15.0 + 30.0 * i)),
     0.090 * math.sin(math.radians(15.0 + 30.0 * i)),
     0.085)
    for i in range(12)
)
FOOTBOT_BEACON_LED_INDEX = 12

FOOTBOT = RobotModel(
    name="foot-bot",
    body_radius_m=0.085036758,          # footbot_entity.cpp BODY_RADIUS
    body_height_m=0.146899733,          # BODY_HEIGHT
    mass_kg=1.6,                        # dynamics2d_footbot_model.cpp
    wheel_separation_m=0.14,            # INTERWHEEL_DISTANCE
    wheel_radius_m=0.029112741,         # WHEEL_RADIUS
    max_wheel_speed_mps=0.10,           # argos3-examples flocking: max_speed 10 cm/s
    max_force_n=15.0,                   # dynamics2d differential steering control: max force
    max_torque_nm=150.0,                # ... and max torque
    friction=0.7,
    proximity=ProximityRing(angles_rad=_ring_angles(7.5, 15.0, 24), range_m=0.10,
                            elevation_m=0.06),           # footbot_entity.cpp: proximity sensors at 6 cm
    light=LightRing(angles_rad=_ring_angles(7.5, 15.0, 24)),
    camera=BlobCamera(height_m=0.288699733, aperture_rad=math.radians(70.0)),
    led_positions_m=_FOOTBOT_RING_LEDS + ((0.0, 0.0, 0.1742),),
)

MODELS: dict[str, RobotModel] = {FOOTBOT.name: FOOTBOT}


def get_model(name: str) -> RobotModel:
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown robot model {name!r}; known: {', '.join(sorted(MODELS))}") from None


def display_colors(led_colors: np.ndarray) -> np.ndarray:
    """The one colour that stands for each robot's LEDs → [n, 3] uint8.

    led_colors: [n, L, 3] (ring LEDs first, beacon last, as in the topic contract) or
    already [n, 3]. The beacon (the last LED) when it is lit, else the first lit ring LED,
    else black (no LED lit).
    """
    c = np.asarray(led_colors)
    c = c if c.dtype == np.uint8 else c.astype(np.uint8)
    if c.ndim == 2 and c.shape[1] == 3:
        return c
    if c.ndim != 3 or c.shape[2] != 3 or c.shape[1] == 0:
        raise ValueError(f"led_colors must be [n, L, 3] or [n, 3], got shape {c.shape}")
    lit = (c[..., 0] | c[..., 1] | c[..., 2]) != 0               # [n, L]; faster than any(axis=2)
    ring_first = np.argmax(lit[:, :-1], axis=1) if c.shape[1] > 1 else np.zeros(len(c), int)
    # With nothing lit argmax gives LED 0, which is then black: the right answer.
    first = np.where(lit[:, -1], c.shape[1] - 1, ring_first)      # [n]
    return c[np.arange(len(c)), first]
