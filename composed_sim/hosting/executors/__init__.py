"""The executors that run the hosted nodes: the lockstep executor (``lockstep.py``, with what its
walk needs of each entity, ``walk_entries.py``; its tasks and callback groups, ``task_running.py``
and ``tasks.py``; its scheduler, ``scheduler.py``, and idle wait, ``idle.py``) or one of rclpy's,
made and driven by ``running.py``; and how a block's executor is driven while a tick is open
(``tick_serving.py``)."""
