"""ARGoS ``<sensors>`` and ``<actuators>`` → our devices (the Devices fields of a robot group).

Each ARGoS device tag maps to one of our devices, with the attributes of its implementation that
we model (noise, drop rate) converted to our units. A tag without an equivalent is reported as not
simulated, once, with its line. Which robot has which device is the entity's check
(``require_devices``): a device its model lacks is reported there.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from composed_sim.argos_import.xml_reader import XmlElement
from composed_sim.world.robot_models import get_model

if TYPE_CHECKING:
    from composed_sim.argos_import.attributes import AttributeReader

_IGNORED = {"implementation", "show_rays", "medium", "calibrated", "show_readings"}  # no effect here

# ARGoS sensor tag → (our device, {ARGoS attribute: (our field, factor)}).
SENSORS: dict[str, tuple[str, dict[str, tuple[str, float]]]] = {
    **{tag: ("proximity", {"noise_level": ("noise", 1.0)})
       for tag in ("footbot_proximity", "proximity", "epuck_proximity", "kheperaiv_proximity")},
    **{tag: ("light", {"noise_level": ("noise", 1.0)})
       for tag in ("footbot_light", "light", "epuck_light", "kheperaiv_light")},
    **{tag: ("ground", {"noise_level": ("noise", 1.0)})
       for tag in ("footbot_motor_ground", "ground", "epuck_ground", "kheperaiv_ground")},
    "colored_blob_omnidirectional_camera": ("camera", {"noise_std": ("noise_std", 1.0)}),
    # ARGoS's range-and-bearing readings are in cm: its noise_std too.
    "range_and_bearing": ("range_and_bearing", {"noise_std": ("noise_std_m", 0.01),
                                                "packet_drop_prob": ("packet_drop_probability", 1.0)}),
    "kheperaiv_lidar": ("lidar", {}),     # its noise_level is uniform, ours Gaussian: not mapped
    "positioning": ("positioning", {}),
    "differential_steering": ("differential_steering", {}),
}
# ARGoS sensor tag → the reading model of its device: each ARGoS sensor element computes its own
# readings over the robot's ring (devices/proximity.py, devices/light.py), so the generic
# ``proximity`` on an e-puck reads exp(-d), not the e-puck's calibration. ARGoS has no
# ``epuck_light``: the e-puck's light sensors are read by the generic ``light``.
SENSOR_MODELS: dict[str, str] = {
    "footbot_proximity": "foot-bot", "epuck_proximity": "e-puck", "kheperaiv_proximity": "kheperaiv",
    "proximity": "generic",
    "footbot_light": "foot-bot", "kheperaiv_light": "kheperaiv", "light": "generic", "epuck_light": "generic",
}
# ARGoS actuator tag → our device (None: every robot has it, nothing to switch).
ACTUATORS: dict[str, str | None] = {"differential_steering": None, "leds": None,
                                    "range_and_bearing": "range_and_bearing"}
# A controller's sensor topic (SwarmController.sensors) → the device that publishes it.
TOPIC_DEVICES = {"proximity": "proximity", "light": "light", "blobs": "camera", "ground": "ground",
                 "scan": "lidar", "rab_rx": "range_and_bearing", "pose": "positioning",
                 "odom": "odometry", "wheels": "differential_steering"}


def device_settings(reader: AttributeReader, sensors: tuple[XmlElement, ...],
                    actuators: tuple[XmlElement, ...], config: str) -> dict[str, dict]:
    """Our Devices fields for a controller's sensors and actuators; warns about the rest."""
    out: dict[str, dict] = {}
    for node in sensors:
        if node.tag not in SENSORS:
            reader.warn(node, node.tag, f"sensor of controller {config} is not simulated")
            continue
        device, attrs = SENSORS[node.tag]
        settings: dict[str, Any] = out.setdefault(device, {})
        if node.tag in SENSOR_MODELS:
            settings["model"] = SENSOR_MODELS[node.tag]
        for name in node.attrib:
            if name in attrs:
                field, factor = attrs[name]
                settings[field] = reader.number(node, name, low=0.0) * factor
            elif name not in _IGNORED:
                reader.warn(node, f"{node.tag}/{name}", "not simulated, ignored")
        for child in node.children:
            reader.warn(child, f"{node.tag}/{child.tag}", "not supported, ignored")
    for node in actuators:
        if node.tag not in ACTUATORS:
            reader.warn(node, node.tag, f"actuator of controller {config} is not simulated")
            continue
        device = ACTUATORS[node.tag]
        if device is not None:
            out.setdefault(device, {})
        reader.unknown(node, _IGNORED | {"noise_std", "noise_level"}, node.tag,
                       "not simulated, ignored")
    return out


def require_devices(reader: AttributeReader, entity: XmlElement, model_name: str,
                    devices: dict[str, dict], needed_topics: tuple[str, ...], plugin: str) -> dict:
    """The devices a group of ``model_name`` runs: the controller's, less those the model lacks
    (warned), plus those the plugin's sensor topics need (warned when the file does not list them)."""
    model = get_model(model_name)
    out = {}
    for device, settings in devices.items():
        if device in ("positioning", "odometry", "differential_steering") or getattr(model, device, None):
            out[device] = settings
        else:
            reader.warn(entity, entity.tag, f"the {model_name} has no {device} device: not simulated")
    for topic in needed_topics:
        device = TOPIC_DEVICES.get(topic)
        if device is None or device in out or device in model.default_devices:
            continue
        if device in ("positioning", "odometry", "differential_steering") or getattr(model, device, None):
            reader.warn(entity, entity.tag, f'the plugin "{plugin}" reads {topic}: the {device} '
                        f"device is switched on, which the controller does not list")
            out[device] = {}
    return out
