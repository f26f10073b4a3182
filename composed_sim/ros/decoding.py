"""The actuators' messages → numpy arrays: the controllers' answers, LEDs (the simulator decodes
them); each device's sensor messages are decoded by its module in ``devices/``."""
from __future__ import annotations

import numpy as np

from composed_sim.devices.common import cdr


def decode_answer_cdr(data: bytes) -> tuple[int, float, float]:
    """TwistStamped cmd_vel bytes → (stamp ns, linear.x, angular.z)."""
    return cdr.decode_twist_stamped(data)


def decode_unstamped_answer_cdr(data: bytes) -> tuple[float, float]:
    """Twist cmd_vel bytes → (linear.x, angular.z)."""
    return cdr.decode_unstamped_twist(data)


def decode_leds(data: bytes, n_leds: int) -> np.ndarray:
    """leds bytes → [n_leds, 3] uint8; ValueError when the message does not carry n_leds colours."""
    colors = cdr.decode_uint8_array(data)
    if colors.size != 3 * n_leds:
        raise ValueError(f"leds message has {colors.size} bytes, expected {3 * n_leds} ({n_leds} LEDs × RGB)")
    return colors.reshape(n_leds, 3)


def decode_payload(data: bytes, payload_bytes: int) -> np.ndarray:
    """rab_tx bytes → [B] uint8; ValueError when it does not carry exactly payload_bytes bytes."""
    payload = cdr.decode_uint8_array(data)
    if payload.size != payload_bytes:
        raise ValueError(f"rab_tx message has {payload.size} bytes, expected {payload_bytes} "
                         f"(range_and_bearing.payload_bytes of the world file)")
    return payload
