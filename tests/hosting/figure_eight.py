"""Our own figure eight as a Crazyflie trajectory (degree-7 pieces, x = sin 2πt/T, y = sin 4πt/T / 2,
fitted), flown by the firmware's tests and by the crazyswarm tool; numpy only, so the tool's process
and the ROS-free tests share it."""
from __future__ import annotations

import numpy as np

PERIOD_S, PIECES = 8.0, 4


def figure_eight() -> tuple[np.ndarray, np.ndarray]:
    """(coefficients [PIECES, 4, 8], durations [PIECES] s)."""
    durations = np.full(PIECES, PERIOD_S / PIECES)
    coefficients = np.zeros((PIECES, 4, 8))
    for i in range(PIECES):
        t = np.linspace(0.0, durations[i], 50)
        tau = i * durations[i] + t
        coefficients[i, 0] = np.polynomial.polynomial.polyfit(t, np.sin(2 * np.pi * tau / PERIOD_S), 7)
        coefficients[i, 1] = np.polynomial.polynomial.polyfit(t, 0.5 * np.sin(4 * np.pi * tau / PERIOD_S), 7)
    return coefficients, durations
