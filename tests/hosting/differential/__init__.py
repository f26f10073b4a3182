"""Differential tests of generated ROS 2 programs: each program hosted by composed_sim in every
mode, and in processes of its own under rclpy (the ground truth), compared tick by tick."""
