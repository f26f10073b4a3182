"""The actuators' messages → numpy arrays: the controllers' answers, LEDs (the simulator decodes
them); each device's sensor messages are decoded by its module in ``devices/``."""
from __future__ import annotations

import numpy as np
from sensor_msgs.msg import LaserScan
from std_msgs.msg import UInt8MultiArray

from composed_sim.ros import cdr


def decode_answer_cdr(data: bytes) -> tuple[int, float, float]:
    """TwistStamped cmd_vel bytes → (stamp ns, linear.x, angular.z)."""
    return (cdr.stamp_ns(data), *cdr.decode_twist(data))


def decode_unstamped_answer_cdr(data: bytes) -> tuple[float, float]:
    """Twist cmd_vel bytes → (linear.x, angular.z)."""
    return cdr.decode_unstamped_twist(data)


def decode_leds(msg: UInt8MultiArray, n_leds: int) -> np.ndarray:
    """→ [n_leds, 3] uint8; ValueError when the message does not carry n_leds colours."""
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if data.size != 3 * n_leds:
        raise ValueError(f"leds message has {data.size} bytes, expected {3 * n_leds} ({n_leds} LEDs × RGB)")
    return data.reshape(n_leds, 3)


def ring_angles(msg: LaserScan, count: int) -> np.ndarray:
    """[count] sensor angles of a ring scan."""
    return msg.angle_min + msg.angle_increment * np.arange(count)
