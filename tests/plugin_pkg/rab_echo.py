"""Test controller: stands still, broadcasts (its index, the tick) over range and bearing and keeps
what it hears, so a test can check who heard whom and when."""
from composed_sim.ros.controller import SwarmController, Tick


class RabEcho(SwarmController):
    sensors = ("rab_rx", "pose")

    def __init__(self, **node_kwargs):
        super().__init__("rab_echo", **node_kwargs)
        self.index = int(self.robot.lstrip("abcdefghijklmnopqrstuvwxyz_"))
        self.heard: dict[int, list[tuple[int, int, float, float]]] = {}   # tick → (sender, sent at, range, bearing)
        self.poses: dict[int, tuple[float, float, float]] = {}

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        k = round(tick.time_s * 10)
        self.heard[k] = sorted((int(p[0]), int(p[1]), float(r), float(b))
                               for p, r, b in zip(tick.rab.payloads, tick.rab.ranges, tick.rab.bearings))
        self.poses[k] = tuple(tick.pose)
        self.send_rab([self.index, k % 256])
        return 0.0, 0.0
