"""Firefly synchronisation over range and bearing (pulse-coupled oscillators, Mirollo-Strogatz).

Each robot stands still and runs a phase from 0 to 1 over ``period_ticks`` ticks. When the phase
reaches 1 it flashes: its LEDs light for that tick and its range-and-bearing payload says "flash"
(byte 0 = 1). A robot hearing a neighbour's flash (one tick later, ARGoS order) advances its
phase by ``coupling`` · phase: robots close to flashing are pulled over the threshold, and the
swarm converges to one common flash. The initial phase is drawn from the robot's own generator.
"""
from __future__ import annotations

import numpy as np

from composed_sim.plugins import ArgosPort
from composed_sim.ros.controller import SwarmController, Tick

FLASH = (255, 255, 0)
OFF = (0, 0, 0)


def advance(phase: float, step: float, heard_flash: bool, coupling: float) -> tuple[float, bool]:
    """One tick of the oscillator → (new phase, flashes now)."""
    phase += step
    if heard_flash:
        phase += coupling * phase
    if phase >= 1.0:
        return 0.0, True
    return phase, False


class FireflyController(SwarmController):
    """Flash the LEDs in step with the neighbours heard over range and bearing."""

    sensors = ("rab_rx",)
    # ARGoS footbot_synchronization (the same oscillators; ARGoS sees flashes with the camera,
    # this port hears them over range and bearing). Its <params> are empty.
    argos = ArgosPort("footbot_synchronization_controller")

    def __init__(self, **node_kwargs):
        super().__init__("firefly", **node_kwargs)
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("period_ticks", 20), ("coupling", 0.2))}
        if p["period_ticks"] < 2:
            raise ValueError(f"parameter period_ticks must be >= 2, got {p['period_ticks']}")
        self.step = 1.0 / p["period_ticks"]
        self.coupling = float(p["coupling"])
        self.phase = float(self.rng.uniform(0.0, 1.0))
        self._flashing = False

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        heard = bool(len(tick.rab)) and bool(np.any(tick.rab.payloads[:, 0] == 1))
        self.phase, flash = advance(self.phase, self.step, heard, self.coupling)
        if flash != self._flashing:     # LEDs and payload are kept until changed: send changes only
            self.set_leds(FLASH if flash else OFF)
            self.send_rab([1 if flash else 0])
            self._flashing = flash
        return 0.0, 0.0
