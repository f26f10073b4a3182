"""One process's drone commands of the tick (core/drone_commands.py), as its endpoints and its
``crazyflie_server`` take them; the host takes them all at the tick's close."""
from __future__ import annotations

import itertools
import threading
import time

from composed_sim.core.drone_commands import DroneCommand


class DroneOutbox:
    def __init__(self):
        self._commands: list[DroneCommand] = []
        self._lock = threading.Lock()      # a multi-threaded executor serves calls on its threads
        self._sequence = itertools.count()

    def post(self, robot: int, kind: str, args: tuple, stamp_ns: int = 0) -> None:
        """A command for ``robot`` (or ALL) that arrived at ``stamp_ns`` (0: now, wall clock)."""
        with self._lock:
            self._commands.append(DroneCommand(robot, stamp_ns or time.time_ns(), next(self._sequence), kind, args))

    def take(self) -> list[DroneCommand]:
        with self._lock:
            taken, self._commands = self._commands, []
        return taken
