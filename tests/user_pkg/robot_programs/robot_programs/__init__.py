"""Robots' ROS 2 programs as users write them for a process of their own (tests/hosting/test_robot_programs.py)."""
