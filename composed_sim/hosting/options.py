"""How a process hosts its nodes: the choices and their defaults, for the command line and the
benchmark too (imports no rclpy)."""

EXECUTORS = ("lockstep", "events", "single-threaded", "multi-threaded")
DEFAULT_EXECUTOR = EXECUTORS[0]
# Composed mode in one process: robots per DDS participant (hosting/participant_groups.py). Set-up
# costs about this × N; each participant costs its threads and ports: docs/speed.md has the
# measurements.
ROBOTS_PER_PARTICIPANT = 80
