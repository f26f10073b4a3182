"""The run-wide topic names and the fixed frame: what recordings and viewers name, no rclpy needed."""

CLOCK_TOPIC = "/clock"
# Optional global topics, for people watching or recording a run (never read by controllers).
SWARM_STATE_TOPIC = "/swarm/state"      # in a --record bag: every robot's pose and LED colour per tick
SWARM_MARKERS_TOPIC = "/swarm/markers"  # live with --markers: the swarm as one MarkerArray
WORLD_FRAME = "world"                   # the fixed frame of both
