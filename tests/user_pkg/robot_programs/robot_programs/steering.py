"""The one decision every program here makes, so that runs of different programs compare bit for bit."""


def closeness(scan) -> float:
    """How close the nearest obstacle is, from a proximity ring's scan (0: none, 1: touching)."""
    return max(scan.intensities) if len(scan.intensities) else 0.0


def steer(close: float, speed: float = 0.05) -> tuple[float, float]:
    """Drive on, slower as something comes close, and turn away once it is close."""
    return speed * (1.0 - close), (1.0 if close > 0.3 else 0.0)
