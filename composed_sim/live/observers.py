"""Tick observers a run can attach: a rosbag2 recording and live RViz/Foxglove markers."""
from __future__ import annotations

from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from composed_sim.core.simulation import Simulation
from composed_sim.outputs.recording import BagRecorder
from composed_sim.ros.contract import stamp_of
from composed_sim.live.markers import MARKERS_TOPIC, MARKERS_TYPE, swarm_markers_cdr, world_shapes


class Scene:
    """The swarm and the static world as one MarkerArray's CDR bytes (live/markers.py), built at
    most once per tick however many observers (live markers, recording, Foxglove) ask for it."""

    def __init__(self, sim: Simulation, tick_ns: int):
        self.tick_ns = tick_ns
        self.shapes = world_shapes(sim.world)
        self._tick, self._data = -1, b""

    def cdr(self, sim: Simulation) -> bytes:
        if sim.tick != self._tick:
            self._data = swarm_markers_cdr(sim.names, sim.positions, sim.headings, sim.led_colors,
                                           sim.radii, stamp_of(sim.tick, self.tick_ns), height=sim.heights,
                                           shapes=self.shapes)
            self._tick = sim.tick
        return self._data


class RecordingObserver:
    """Writes /clock, the swarm state (all poses and LED colours in one message) and the scene
    (/swarm/markers, so that Foxglove shows a bag as it shows a live run) each tick."""

    def __init__(self, recorder: BagRecorder, scene: Scene):
        self.recorder = recorder
        self.scene = scene
        self.tick_ns = scene.tick_ns

    def on_tick(self, sim: Simulation) -> None:
        stamp_ns = sim.tick * self.tick_ns
        self.recorder.write_clock(sim.tick, stamp_ns)
        self.recorder.write_swarm_state(stamp_ns, sim.positions, sim.headings, sim.led_colors)
        self.recorder.write_serialized(MARKERS_TOPIC, MARKERS_TYPE, self.scene.cdr(sim), stamp_ns, always=True)


class RosoutObserver:
    """Writes the hosted nodes' log lines (``NodeLogs.rosout``, hosting/guard/node_logs.py) to /rosout as
    ``rcl_interfaces/msg/Log``, stamped with sim time, as a ROS node's /rosout carries them."""

    TOPIC, TYPE = "/rosout", "rcl_interfaces/msg/Log"

    def __init__(self, recorder: BagRecorder, logs):
        from rosbags.typesys import Stores, get_typestore
        self.recorder, self.logs = recorder, logs
        self._store = get_typestore(Stores.ROS2_JAZZY)
        self._Log = self._store.types[self.TYPE]
        self._Time = self._store.types["builtin_interfaces/msg/Time"]

    def on_tick(self, sim: Simulation) -> None:
        records, self.logs.rosout = self.logs.rosout, []
        for ns, level, name, text, file, function, line in records:
            msg = self._Log(stamp=self._Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), level=level,
                            name=name, msg=text, file=file, function=function, line=line)
            self.recorder.write_serialized(self.TOPIC, self.TYPE, self._store.serialize_cdr(msg, self.TYPE), ns,
                                           always=True)


class MarkerObserver:
    """Publishes the whole swarm as one MarkerArray on /swarm/markers."""

    def __init__(self, node: Node, scene: Scene):
        self.publisher = node.create_publisher(MarkerArray, MARKERS_TOPIC, 10)
        self.scene = scene

    def on_tick(self, sim: Simulation) -> None:
        self.publisher.publish(self.scene.cdr(sim))     # already CDR: one buffer for the whole swarm
