"""An optional base class for controllers: subscribes to the robot's sensors and answers each tick.

A controller does not need it: any rclpy Node that subscribes to ``/<robot>/<sensor>`` and
answers each tick with a ``cmd_vel`` stamped like the sensors it answers works the same way.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.node import Node

from composed_sim.core.robot_models import RobotModel, get_model
from composed_sim.core.seeding import robot_rng
from composed_sim.ros import cdr, contract as c

# Parameters every hosted controller is given (a plain Node may ignore them).
PARAM_ROBOT_MODEL = "robot_model"
PARAM_RUN_SEED = "run_seed"


@dataclass
class Tick:
    """One tick's sensor readings for one robot, decoded into arrays (only the subscribed ones)."""
    stamp: Time
    time_s: float
    proximity: Optional[np.ndarray] = None            # [k] readings in [0, 1]
    proximity_distances: Optional[np.ndarray] = None  # [k] m from the rim, inf = nothing
    light: Optional[np.ndarray] = None                # [k] readings in [0, 1]
    blobs: Optional[c.Blobs] = None


class SwarmController(Node):
    """Base for a robot controller: override ``on_tick`` and return (linear m/s, angular rad/s).

    The robot is the node's namespace (``/bot7`` → ``bot7``). ``self.model`` is its robot model,
    ``self.rng`` a generator of its own (seeded by the run seed and the robot name), and
    ``set_leds``/``set_led`` change its LEDs with the next answer.
    """

    #: sensor topics (contract names) this controller needs each tick.
    sensors: tuple[str, ...] = ("proximity", "light", "blobs")

    def __init__(self, node_name: str = "controller", **node_kwargs):
        super().__init__(node_name, **node_kwargs)
        self.robot = self.get_namespace().strip("/")
        model_name = self.declare_parameter(PARAM_ROBOT_MODEL, "foot-bot").value
        seed = self.declare_parameter(PARAM_RUN_SEED, 0).value
        self.model: RobotModel = get_model(model_name)
        self.rng = robot_rng(seed, self.robot)
        self.proximity_angles = np.asarray(self.model.proximity.angles_rad)
        self.light_angles = np.asarray(self.model.light.angles_rad)
        self._leds = np.zeros((self.model.n_leds, 3), dtype=np.uint8)
        self._leds_dirty = False
        self._pending: dict[str, bytes] = {}
        self._pending_key = -1
        # Sensors are taken and answers published as serialized bytes, decoded straight into
        # arrays (cdr.py): the same messages, without building Python message objects.
        for name in self.sensors:
            topic = c.TOPICS[name]
            self.create_subscription(topic.msg_type, topic.name,
                                     lambda data, name=name: self._on_sensor(name, data), c.QOS, raw=True)
        self._cmd_pub = self.create_publisher(c.CMD_VEL.msg_type, c.CMD_VEL.name, c.QOS)
        self._answer_encoder = c.answer_encoder()
        self._led_pub = self.create_publisher(c.LEDS.msg_type, c.LEDS.name, c.QOS)

    # --- for subclasses ---------------------------------------------------------------------

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        raise NotImplementedError

    def set_led(self, index: int, rgb) -> None:
        self._leds[index] = rgb
        self._leds_dirty = True

    def set_leds(self, rgb) -> None:
        self._leds[:] = rgb
        self._leds_dirty = True

    # --- the tick exchange ------------------------------------------------------------------

    def _on_sensor(self, name: str, data: bytes) -> None:
        key = cdr.stamp_ns(data)
        if key != self._pending_key:     # a new tick: whatever was left of an older one is stale
            self._pending.clear()
            self._pending_key = key
        self._pending[name] = data
        if len(self._pending) == len(self.sensors):
            self._answer()

    def _answer(self) -> None:
        msgs, self._pending = self._pending, {}
        sec, nanosec = divmod(self._pending_key, 1_000_000_000)
        tick = Tick(stamp=Time(sec=sec, nanosec=nanosec), time_s=sec + nanosec * 1e-9)
        if "proximity" in msgs:
            tick.proximity_distances, tick.proximity = c.decode_proximity_cdr(msgs["proximity"])
        if "light" in msgs:
            tick.light = c.decode_light_cdr(msgs["light"])
        if "blobs" in msgs:
            tick.blobs = c.decode_blobs_cdr(msgs["blobs"])
        linear, angular = self.on_tick(tick)
        if self._leds_dirty:   # before the answer, so the change lands on the same tick
            self._led_pub.publish(c.led_message(self._leds))
            self._leds_dirty = False
        self._cmd_pub.publish(self._answer_encoder.encode(sec, nanosec, float(linear), float(angular)))
