"""An optional base class for controllers: subscribes to the robot's sensors and answers each tick.

A controller does not need it: any rclpy Node that subscribes to ``/<robot>/<sensor>`` and
answers each tick with a ``cmd_vel`` stamped like the sensors it answers works the same way.
"""
from __future__ import annotations

import functools
from typing import Callable, Optional

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.node import Node
from rclpy.parameter import Parameter

from composed_sim.world.robot_models import RobotModel, get_model
from composed_sim.core.seeding import robot_rng
from composed_sim.devices.common import cdr
from composed_sim.ros import contract as c
from composed_sim.devices import BY_SENSOR_TOPIC, DEVICES

# Parameters every hosted controller is given (a plain Node may ignore them).
PARAM_ROBOT_MODEL = "robot_model"
PARAM_RUN_SEED = "run_seed"
PARAM_SENSOR_TOPICS = "sensor_topics"          # the robot's sensor topics (its devices, per the world)
PARAM_RAB_PAYLOAD_BYTES = "rab_payload_bytes"  # its range-and-bearing payload size; 0: no such device


class Tick:
    """One tick's sensor readings for one robot, decoded into arrays (only the subscribed ones; the
    others are None). Besides ``stamp`` and ``time_s``, one attribute per reading of each device
    (its ``tick_fields``; its module in ``devices/`` says what each holds): ``proximity`` [k] in
    [0, 1] and ``proximity_distances`` [k] m from the rim; ``light`` [k]; ``blobs`` (a ``Blobs``);
    ``ground`` [s] grey levels; ``scan`` [r] LiDAR ranges (m, ±inf: REP-117); ``rab`` (a
    ``RabMessages``); ``pose`` [3] x, y, yaw in the world frame; ``odom`` [3] in the odom frame and
    ``odom_twist`` [2] (m/s, rad/s); ``wheel_speeds`` [2] and ``wheel_distances`` [2] (left, right;
    m/s and m covered in the last tick)."""

    def __init__(self, stamp: Time, time_s: float):
        self._stamp = stamp
        self.time_s = time_s

    @classmethod
    def at(cls, sec: int, nanosec: int) -> "Tick":
        """The tick stamped ``sec``, ``nanosec``; its ``stamp`` message is built when first asked
        for (most controllers read ``time_s`` or nothing, and a message costs microseconds)."""
        tick = cls.__new__(cls)
        tick._stamp, tick._sec, tick._nanosec = None, sec, nanosec
        tick.time_s = sec + nanosec * 1e-9
        return tick

    @property
    def stamp(self) -> Time:
        if self._stamp is None:
            self._stamp = Time(sec=self._sec, nanosec=self._nanosec)
        return self._stamp

    @stamp.setter
    def stamp(self, stamp: Time) -> None:
        self._stamp = stamp


_TICK_FIELDS = tuple(name for d in DEVICES for name in d.tick_fields)
# A reading the controller does not subscribe to is None: a class attribute, so that a tick sets
# only the fields its readers fill (one attribute per field and tick cost a call each).
for _name in _TICK_FIELDS:
    setattr(Tick, _name, None)


class SwarmController(Node):
    """Base for a robot controller: override ``on_tick`` and return (linear m/s, angular rad/s).

    The robot is the node's namespace (``/bot7`` → ``bot7``). ``self.model`` is its robot model,
    ``self.rng`` a generator of its own (seeded by the run seed and the robot name), and
    ``set_leds``/``set_led`` change its LEDs with the next answer.
    """

    #: sensor topics (contract names) this controller needs each tick.
    sensors: tuple[str, ...] = ("proximity", "light", "blobs")
    #: Set by a host that guards callbacks (hosting/guard/callback_guard.py): (the sensor subscriptions, in
    #: ``sensors``' order; ``_on_sensors`` as guarded). The lockstep executor then hands a tick's
    #: sensor messages to the node in one call where all of them wait in process.
    lockstep_batch: Optional[tuple[tuple, Callable[[list], None]]] = None
    #: Set by that host too: what times ``on_tick`` (``start()`` gives what ``stop(started)`` takes,
    #: hosting/guard/node_time.py); None: not counted.
    node_time = None

    def __init__(self, node_name: str = "controller", **node_kwargs):
        super().__init__(node_name, **node_kwargs)
        self.robot = self.get_namespace().strip("/")
        model_name = self.declare_parameter(PARAM_ROBOT_MODEL, "foot-bot").value
        seed = self.declare_parameter(PARAM_RUN_SEED, 0).value
        self.model: RobotModel = get_model(model_name)
        self.rng = robot_rng(seed, self.robot)
        # Empty for a model without the ring (e.g. the TurtleBot 3 has neither).
        self.proximity_angles = np.asarray(self.model.proximity.angles_rad if self.model.proximity else ())
        self.light_angles = np.asarray(self.model.light.angles_rad if self.model.light else ())
        self._leds = np.zeros((self.model.n_leds, 3), dtype=np.uint8)
        self._leds_dirty = False
        self._pending: dict[str, object] = {}
        self._pending_key = -1
        self._init_devices()
        # Each sensor is read by its device (devices/), from the serialized bytes, and answers
        # are published as bytes (cdr.py): the same messages, without building Python message objects.
        self._readers = {name: BY_SENSOR_TOPIC[name].reader(self.model) for name in self.sensors}
        self._sensor_readers = tuple(self._readers[name] for name in self.sensors)
        self._sensor_subscriptions = tuple(
            self.create_subscription(c.msg_type(c.TOPICS[name]), c.TOPICS[name].name,
                                     functools.partial(self._on_sensor, name), c.QOS, raw=True,
                                     event_callbacks=c.SUBSCRIPTION_EVENTS)
            for name in self.sensors)
        self._cmd_pub = self.create_publisher(c.msg_type(c.CMD_VEL), c.CMD_VEL.name, c.QOS,
                                              event_callbacks=c.PUBLISHER_EVENTS)
        self._answer_encoder = c.answer_encoder()
        self._led_pub = self.create_publisher(c.msg_type(c.LEDS), c.LEDS.name, c.QOS,
                                              event_callbacks=c.PUBLISHER_EVENTS)
        self._led_encoder = c.led_encoder(self.model.n_leds)

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

    def _on_sensor(self, name: str, data) -> None:
        key = cdr.stamp_ns(data)
        if key != self._pending_key:     # a new tick: whatever was left of an older one is stale
            self._pending.clear()
            self._pending_key = key
        self._pending[name] = data
        if len(self._pending) == len(self.sensors):
            msgs, self._pending = self._pending, {}
            self._answer([(self._readers[n], data) for n, data in msgs.items()])

    def sensor_batch(self) -> tuple[tuple, Callable[[list], None]]:
        """For a host that hands a tick's sensor messages in one call (``lockstep_batch``): the
        sensor subscriptions, in ``sensors``' order, and the call that takes their messages."""
        return self._sensor_subscriptions, self._on_sensors

    def _on_sensors(self, messages: list) -> None:
        """A message of every sensor, in ``sensors``' order (``lockstep_batch``): answered at once
        when they are one tick's and nothing of another tick waits, else one by one."""
        key = cdr.stamp_ns(messages[0])
        if not self._pending:
            for data in messages:
                if cdr.stamp_ns(data) != key:
                    break
            else:
                self._pending_key = key
                self._answer(zip(self._sensor_readers, messages))
                return
        for name, data in zip(self.sensors, messages):
            self._on_sensor(name, data)

    def _answer(self, readings) -> None:
        """``readings``: (a sensor's reader, its message) of each sensor of the tick."""
        sec, nanosec = divmod(self._pending_key, 1_000_000_000)
        tick = Tick.at(sec, nanosec)
        for reader, data in readings:
            reader(data, tick)
        node_time = self.node_time          # the node's own code; the rest is the host's
        started = node_time.start() if node_time is not None else None
        linear, angular = self.on_tick(tick)
        if started is not None:
            node_time.stop(started)
        if self._leds_dirty:   # before the answer, so the change lands on the same tick
            self._led_pub.publish(self._led_encoder.encode(self._leds.tobytes()))
            self._leds_dirty = False
        if self._rab_msg is not None:   # before the answer too: broadcast from the next tick on
            self._rab_pub.publish(self._rab_msg)
            self._rab_msg = None
        self._cmd_pub.publish(self._answer_encoder.encode(sec, nanosec, float(linear), float(angular)))

    # --- the robot's devices -----------------------------------------------------------------

    def _init_devices(self) -> None:
        """Check the declared sensors against the robot's topics; the range-and-bearing sender."""
        topics = self.declare_parameter(PARAM_SENSOR_TOPICS, Parameter.Type.STRING_ARRAY).value
        missing = [s for s in self.sensors if topics is not None and s not in topics]
        if missing:
            raise ValueError(f"{type(self).__name__} needs the sensor topic(s) {', '.join(missing)}, which "
                             f"{self.robot} (a {self.model.name}) does not have; its sensor topics: "
                             f"{', '.join(topics) or 'none'}. Switch the device on in the world file "
                             f"(robots[i].devices)")
        unknown = [s for s in self.sensors if s not in c.TOPICS or c.TOPICS[s].direction != "sensor"]
        if unknown:
            raise ValueError(f"{type(self).__name__}.sensors: {', '.join(map(repr, unknown))} is no sensor "
                             f"topic; known: {', '.join(t.name for t in c.SENSOR_TOPICS)}")
        self.rab_payload_bytes: int = self.declare_parameter(PARAM_RAB_PAYLOAD_BYTES, 0).value
        self._rab_pub = (self.create_publisher(c.msg_type(c.RAB_TX), c.RAB_TX.name, c.QOS, event_callbacks=c.PUBLISHER_EVENTS)
                         if self.rab_payload_bytes > 0 else None)
        self._rab_msg = None                 # the payload's message bytes, until sent
        self._payload_encoder = c.payload_encoder(self.rab_payload_bytes)
        #: [r] LiDAR ray angles in the scanner's frame (None without a LiDAR).
        self.scan_angles = self.model.lidar.angles_array() if self.model.lidar is not None else None

    def send_rab(self, data) -> None:
        """Broadcast ``data`` (bytes or uint8 values, at most rab_payload_bytes; zero-padded) with
        the next answer: neighbours in range hear it from the next tick on, until it changes."""
        if self._rab_pub is None:
            raise ValueError(f"{self.robot} has no range_and_bearing device (switch it on in the world file)")
        payload = np.frombuffer(bytes(data), dtype=np.uint8) if isinstance(data, (bytes, bytearray)) \
            else np.asarray(data).reshape(-1)
        if payload.size > self.rab_payload_bytes or (payload.size and (payload.min() < 0 or payload.max() > 255)):
            raise ValueError(f"a range-and-bearing payload is at most {self.rab_payload_bytes} bytes "
                             f"(range_and_bearing.payload_bytes), got {payload.tolist()}")
        padded = np.zeros(self.rab_payload_bytes, dtype=np.uint8)
        padded[:payload.size] = payload
        self._rab_msg = self._payload_encoder.encode(padded.tobytes())
