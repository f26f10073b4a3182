"""The run-wide topic names and the fixed frame: what recordings and viewers name, no rclpy needed."""
from composed_sim.devices.common.topic import WORLD_FRAME  # noqa: F401 (the fixed frame of both)

CLOCK_TOPIC = "/clock"
# Optional global topics, for people watching or recording a run (never read by controllers).
SWARM_STATE_TOPIC = "/swarm/state"      # in a --record bag: every robot's pose and LED colour per tick
SWARM_MARKERS_TOPIC = "/swarm/markers"  # live with --markers: the swarm as one MarkerArray
