"""Distributed runs: the simulator alone (``external.py``), its controllers hosted by shards on
this or other machines (``shard.py``); how they find each other (``announce.py``, ``discovery.py``)
and the robot ranges a shard is given (``robot_ranges.py``)."""
