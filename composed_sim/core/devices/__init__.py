"""The devices with a layout, one module each: how a group's readings are made (``read``), over
all robots at once, and the batched numpy model behind it. ``Simulation.sense`` calls each
running device's ``read`` per robot group. A device's messages: its module in ``ros/devices/``.

To add a device: docs/architecture.md, "Where to add".
"""
from composed_sim.core.devices import camera, ground, lidar, light, proximity
from composed_sim.world.robot_models import CAMERA, GROUND, LIDAR, LIGHT, PROXIMITY

# device name → read(sensing, group, readings): the devices read per robot group. (Range and
# bearing is a medium between all robots, core/range_and_bearing.py, read once per step.)
GROUP_READERS = {PROXIMITY: proximity.read, LIGHT: light.read, CAMERA: camera.read, GROUND: ground.read,
                 LIDAR: lidar.read}
