"""The executors that run the hosted nodes: the lockstep executor (``lockstep.py``, with its
scheduler, tasks and idle wait) or one of rclpy's, made and driven by ``running.py``; and how a
block's executor is driven while a tick is open (``tick_serving.py``)."""
