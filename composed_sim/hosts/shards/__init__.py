"""DDS shards (``composed-sim run WORLD --external-controllers``, ``composed-sim host``): the
simulator alone (``external_controllers.py``), its controllers hosted by shards on this or other
machines (``shard_host.py``), every robot's messages on the wire; how they find each other
(``announce.py``, and the DDS discovery of ``hosts/discovery.py``) and the robot ranges a shard is
given (``robot_ranges.py``)."""
