"""The devices on the ROS side, one module each: topics, publishing, decoding (device.py says how).
Their readings come from the module of the same name in ``core/devices/`` (or, for the devices
every robot has, from ``core/odometry.py`` and ``core/range_and_bearing.py``).

To add a device: docs/architecture.md, "Where to add".
"""
from composed_sim.ros.devices import (camera, differential_steering, ground, lidar, light, odometry, positioning,
                                      proximity, range_and_bearing, tf)
from composed_sim.ros.devices.device import Device

# In the contract's topic order.
DEVICES: tuple[Device, ...] = tuple(m.DEVICE for m in (
    proximity, light, camera, ground, lidar, range_and_bearing, positioning, odometry, differential_steering, tf))
BY_SENSOR_TOPIC: dict[str, Device] = {d.sensor_topic.name: d for d in DEVICES if d.sensor_topic is not None}
