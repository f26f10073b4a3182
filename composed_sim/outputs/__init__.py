"""What a run leaves behind: its results directory (``results.py``: summary.json, trajectories,
violations, metrics, the world), the picture and videos drawn from it (``render.py``, encoded by ``video_encoding.py``), its table
for pandas and polars (``export.py``), and the rosbag2 recording (``recording/``: written, read
back, repaired after a kill). Rendering and replaying them need no rclpy."""
