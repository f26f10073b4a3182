"""What a run leaves behind: its results directory (``results.py``: summary.json, trajectories,
violations, metrics, the world), the picture and videos drawn from it (``render.py``), its table
for pandas and polars (``export.py``), and the rosbag2 recording (``recording.py``) with the
repair of one whose run was killed (``bag_repair.py``). Rendering and replaying them need no rclpy."""
