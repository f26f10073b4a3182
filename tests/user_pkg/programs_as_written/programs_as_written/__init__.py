"""Small robots' ROS 2 programs as users write them for a process of their own
(tests/hosting/test_programs_as_written.py)."""
