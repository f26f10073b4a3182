"""Record a run as a rosbag2 directory (MCAP storage, sim-time stamps) and read it back.

A recording is what ``ros2 bag info``, ``ros2 bag play`` and Foxglove open: ``DIR/metadata.yaml``
plus ``DIR/DIR.mcap``. Every message is logged at its sim time (tick ``k`` at ``k * tick_ns``
nanoseconds), so a bag starts at time 0, not at the wall-clock time of the run.

Topics
  /clock         rosgraph_msgs/msg/Clock          once per tick (``write_clock``)
  /swarm/state   sensor_msgs/msg/PointCloud2      once per tick, every robot in one message
                                                  (``write_swarm_state``; layout below)
  /swarm/markers visualization_msgs/msg/MarkerArray  once per tick in a run's bag: the scene
                                                  Foxglove draws (live/markers.py, live/observers.py)
  any other      whatever rclpy message is given   only topics matching the recorder's globs
                                                  (``wants``, ``write_message``)

The swarm state is one PointCloud2 per tick, one point per robot in the order of
``robot_names`` (frame ``world``): a standard type that Foxglove and RViz draw as coloured
points without any plugin, that carries poses and colours of all robots in one message (one
PoseArray would need a second message for the colours), and whose payload is one numpy
buffer, so writing it costs the same for 10 or 1280 robots apart from the copy. Fields,
``STATE_DTYPE`` (40 bytes per robot, little-endian):

  x, y, z  float64  position in m (z = 0: the simulation is planar)
  yaw      float64  heading in rad, CCW from the x axis
  rgb      uint32   0x00RRGGBB, the robot's display LED colour (``display_colors``); 0 = no LED lit
  id       uint32   the robot's index in ``robot_names``

float64 keeps the recorded poses bit-identical to the run's trajectories, so a replay
recomputes the same figures; the extra 16 bytes per robot are negligible (51 kB per tick
at 1280 robots before zstd chunk compression).

The recorder also stores, as rosbag2 ``custom_data`` (in metadata.yaml and in the MCAP's
metadata record), what a replay needs without the results directory:
``composed_sim.robot_names`` (JSON list), ``composed_sim.tick_s``, ``composed_sim.ticks``
(the ticks simulated, as summary.json counts them), ``composed_sim.world`` (the resolved world as
YAML, when given) and ``composed_sim.executor`` (what ``replay --check`` re-simulates with).

``writer.py`` writes it (``BagRecorder``, flushed so that a killed run leaves a readable bag up to
its last flush), ``reader.py`` reads it back, ``messages.py`` holds the types and the layout,
``repair.py`` finishes the bag of a killed run (``composed-sim bag repair``).
"""
from composed_sim.outputs.recording.messages import (CLOCK_TOPIC, CLOCK_TYPE, CUSTOM_PREFIX, FRAME_ID, STATE_DTYPE,
                                                     SWARM_STATE_TOPIC, UNFINISHED, RecordingError, message_definition,
                                                     pack_rgb, ros_type_name, unpack_rgb)
from composed_sim.outputs.recording.reader import Recording, read_recording, read_swarm_states
from composed_sim.outputs.recording.writer import FLUSH_EVERY_S, FLUSH_EVERY_TICKS, BagRecorder
from composed_sim.world.robot_models import display_colors

__all__ = ["BagRecorder", "CLOCK_TOPIC", "CLOCK_TYPE", "CUSTOM_PREFIX", "FLUSH_EVERY_S", "FLUSH_EVERY_TICKS",
           "FRAME_ID", "Recording", "RecordingError", "STATE_DTYPE", "SWARM_STATE_TOPIC", "UNFINISHED", "display_colors",
           "message_definition", "pack_rgb", "read_recording", "read_swarm_states", "ros_type_name", "unpack_rgb"]
