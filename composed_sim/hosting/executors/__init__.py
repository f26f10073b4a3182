"""The executors that run the hosted nodes: the lockstep executor (``lockstep.py``) or one of
rclpy's, made and driven by ``running.py``."""
