"""Tick observers a run can attach: a rosbag2 recording and live RViz/Foxglove markers."""
from __future__ import annotations

from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from composed_sim.core.simulation import Simulation
from composed_sim.recording import BagRecorder
from composed_sim.ros.contract import stamp_of
from composed_sim.ros.markers import MARKERS_TOPIC, MARKERS_TYPE, swarm_markers_cdr, world_shapes


class Scene:
    """The swarm and the static world as one MarkerArray's CDR bytes (ros/markers.py), built at
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


class MarkerObserver:
    """Publishes the whole swarm as one MarkerArray on /swarm/markers."""

    def __init__(self, node: Node, scene: Scene):
        self.publisher = node.create_publisher(MarkerArray, MARKERS_TOPIC, 10)
        self.scene = scene

    def on_tick(self, sim: Simulation) -> None:
        self.publisher.publish(self.scene.cdr(sim))     # already CDR: one buffer for the whole swarm
