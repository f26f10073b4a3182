"""Tick observers a run can attach: a rosbag2 recording and live RViz/Foxglove markers."""
from __future__ import annotations

from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from composed_sim.core.simulation import Simulation
from composed_sim.recording import BagRecorder
from composed_sim.ros.contract import stamp_of
from composed_sim.ros.markers import MARKERS_TOPIC, MARKERS_TYPE, swarm_markers_cdr


class RecordingObserver:
    """Writes /clock and the swarm state (all poses and LED colours in one message) each tick."""

    def __init__(self, recorder: BagRecorder, tick_ns: int):
        self.recorder = recorder
        self.tick_ns = tick_ns

    def on_tick(self, sim: Simulation) -> None:
        stamp_ns = sim.tick * self.tick_ns
        self.recorder.write_clock(sim.tick, stamp_ns)
        self.recorder.write_swarm_state(stamp_ns, sim.positions, sim.headings, sim.led_colors)


class MarkerObserver:
    """Publishes the whole swarm as one MarkerArray on /swarm/markers (and records it if asked)."""

    def __init__(self, node: Node, tick_ns: int, recorder: BagRecorder | None = None):
        self.publisher = node.create_publisher(MarkerArray, MARKERS_TOPIC, 10)
        self.tick_ns = tick_ns
        self.recorder = recorder if recorder is not None and recorder.wants(MARKERS_TOPIC) else None

    def on_tick(self, sim: Simulation) -> None:
        stamp_ns = sim.tick * self.tick_ns
        data = swarm_markers_cdr(sim.names, sim.positions, sim.headings, sim.led_colors,
                                 sim.model.body_radius_m, stamp_of(sim.tick, self.tick_ns),
                                 height=sim.model.body_height_m)
        self.publisher.publish(data)     # already CDR: one buffer for the whole swarm
        if self.recorder is not None:
            self.recorder.write_serialized(MARKERS_TOPIC, MARKERS_TYPE, data, stamp_ns)
