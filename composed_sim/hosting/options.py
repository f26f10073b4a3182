"""The hosts' choices and defaults, for the command line and the benchmark (imports no rclpy)."""

EXECUTORS = ("lockstep", "events", "single-threaded", "multi-threaded")
MODES = ("composed", "multi-process")
# Composed mode in one process: robots per DDS participant (hosting/participant_groups.py). Set-up
# costs about this × N; each participant costs its threads and ports: docs/speed.md has the
# measurements.
ROBOTS_PER_PARTICIPANT = 80
