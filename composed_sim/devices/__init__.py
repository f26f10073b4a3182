"""The devices, one module each: everything about a device is in its module (``DEVICE``, a
``common.device.Device``): its layout in a robot model, its world-file settings, its batched numpy
model over a robot group, its topics, how a simulator node publishes it and how a controller reads
it. The layers above gather them from here: the robot models and the world schema (layouts,
settings), the core (each group's ``read``), the ROS layer (the contract's topics, publishers,
readers). No module of this package imports ROS or the layers above.

A device is added by adding its module here (found by name, below) and its test
(docs/architecture.md, "Where to add").
"""
from __future__ import annotations

import importlib
import pkgutil

from composed_sim.devices.common.device import Device


# The order of the contract's topic tables (docs/contract.md); a device not listed comes after
# these, by name.
_TOPIC_ORDER = ("proximity", "light", "camera", "ground", "lidar", "range_and_bearing", "positioning", "odometry",
                "differential_steering", "tf")


def _discovered() -> tuple[Device, ...]:
    """Every module of this package (not ``common``) that declares a ``DEVICE``."""
    found = []
    listed = {name: i for i, name in enumerate(_TOPIC_ORDER)}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: (listed.get(m.name, len(listed)), m.name)):
        if not info.ispkg:
            module = importlib.import_module(f"{__name__}.{info.name}")
            if isinstance(getattr(module, "DEVICE", None), Device):
                found.append(module.DEVICE)
    return tuple(found)


DEVICES: tuple[Device, ...] = _discovered()
BY_NAME: dict[str, Device] = {d.name: d for d in DEVICES}
# The devices with a layout: a model fits them or not, and a world file switches them.
WITH_LAYOUT: tuple[str, ...] = tuple(d.name for d in DEVICES if d.layout is not None)
# The robot's devices without a layout: every model has them (the wheels are the drive itself);
# a world file switches their topics on.
ALWAYS_ON: tuple[str, ...] = tuple(d.name for d in DEVICES if d.layout is None and d.on_robot)
# The devices whose topics a world file switches on: the always-on ones and tf. Every robot
# computes their readings (cheap, vectorised), but publishing three more messages per robot and
# tick that no controller reads would cost every swarm, the paper's included; so, as ARGoS lists a
# controller's sensors, their topics exist only where the world file asks for them.
TOPIC_SWITCHED: tuple[str, ...] = tuple(d.name for d in DEVICES if d.layout is None)
# device name → read(sensing, group, readings): the devices read per robot group.
GROUP_READERS = {d.name: d.read for d in DEVICES if d.read is not None}
# device name → the GroupReadings attributes its ``read`` sets.
READINGS = {d.name: (*d.readings, *d.csr_readings) for d in DEVICES if d.read is not None}
BY_SENSOR_TOPIC: dict[str, Device] = {d.sensor_topic.name: d for d in DEVICES if d.sensor_topic is not None}
