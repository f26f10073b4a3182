"""Every device module of devices/, a new one included: a robot running the device gets its
sensor topic from the simulator node, and the controller's reader of that topic gives back the
frame's readings of that robot. A new device adds its expected readings to READINGS."""
import numpy as np
import pytest
from rclpy.node import Node

from composed_sim.core.simulation import Simulation
from composed_sim.ros import contract as c
from composed_sim.ros.controller import Tick
from composed_sim.devices import BY_SENSOR_TOPIC, DEVICES
from composed_sim.ros.robot_settings import robot_devices
from composed_sim.ros.simulator_node import SimulatorNode
from composed_sim.world.robot_models import ALWAYS_ON, MODELS
from composed_sim.world.schema import World

ROBOT = 1        # the robot whose messages are checked (its group's row 1)


def blob_arrays(blobs):
    return np.stack([blobs.angles, blobs.distances]) if len(blobs) else np.zeros((2, 0))


# Per device: the Tick fields its reader fills, each with the frame's reading of ROBOT.
READINGS = {
    "proximity": lambda f, sim: {"proximity": f.groups[0].proximity[ROBOT],
                                 "proximity_distances": f.groups[0].proximity_distances[ROBOT]},
    "light": lambda f, sim: {"light": f.groups[0].light[ROBOT]},
    "camera": lambda f, sim: {"blobs": np.stack(f.groups[0].blobs.of(ROBOT)[:2])},
    "ground": lambda f, sim: {"ground": f.groups[0].ground[ROBOT]},
    "lidar": lambda f, sim: {"scan": f.groups[0].lidar[ROBOT]},
    "range_and_bearing": lambda f, sim: {"rab": f.range_and_bearing.of(ROBOT)[1]},
    "positioning": lambda f, sim: {"pose": [*f.pose.positions[ROBOT, :2], f.pose.yaws[ROBOT]]},
    "odometry": lambda f, sim: {"odom": f.odometry[ROBOT], "odom_twist": f.odometry_twist[ROBOT]},
    "differential_steering": lambda f, sim: {"wheel_speeds": f.wheels.velocities_mps[ROBOT],
                                             "wheel_distances": f.wheels.distances_m[ROBOT]},
}
AS_ARRAYS = {"blobs": blob_arrays, "rab": lambda rab: rab.ranges}


def test_every_device_with_a_sensor_topic_has_its_expected_readings():
    assert {d.name for d in DEVICES if d.reader is not None} == set(READINGS)
    assert all(BY_SENSOR_TOPIC[d.sensor_topic.name] is d for d in DEVICES if d.sensor_topic is not None)


@pytest.mark.parametrize("device", [d for d in DEVICES if d.reader is not None], ids=lambda d: d.name)
def test_a_device_topic_round_trips_from_the_frame_to_the_controllers_tick(device, ros_context):
    model = next(m for m in MODELS.values() if device.name in m.devices or device.name in ALWAYS_ON)
    world = World.model_validate({
        "name": "t", "seed": 3, "arena": {"size": [6.0, 6.0]}, "range_and_bearing": {"mode": "global"},
        "lights": [{"position": [1.0, 0.6]}],
        "floor": {"shapes": [{"type": "circle", "position": [0.2, 0.0], "radius_m": 0.3, "color": [90, 90, 90]}]},
        "robots": [{"model": model.name, "count": 3, "controller": "x", "devices": {device.name: {}},
                    "placement": {"method": "explicit", "positions": [[0.0, 0.0], [0.25, 0.05], [0.1, 0.3]]}}]})
    sim = Simulation(world)
    for i in range(sim.n):                      # lit LEDs (seen by cameras), payloads (heard)
        sim.set_led_colors(i, np.full((model.n_leds, 3), 200, dtype=np.uint8))
        sim.set_rab_payload(i, bytes([i + 1] * world.range_and_bearing.payload_bytes))
    sim.set_velocity_commands(np.full(sim.n, 0.05), np.full(sim.n, 0.3))
    sim.step()
    frame = sim.step()
    node = SimulatorNode(sim.names, sim.models, context=ros_context, tick_ns=world.tick_ns,
                         devices=robot_devices(world))
    listener = Node("listener", context=ros_context)
    try:
        topic = device.sensor_topic
        got = []
        sub = listener.create_subscription(c.msg_type(topic), c.topic_name(sim.names[ROBOT], topic), got.append,
                                           c.QOS, raw=True)
        node.publish_tick(frame)
        taken = sub.handle.take_message(sub.msg_type, sub.raw)
        assert taken is not None, f"{device.name}: nothing on {c.topic_name(sim.names[ROBOT], topic)}"
        tick = Tick(stamp=c.stamp_of(frame.tick, world.tick_ns), time_s=0.0)
        read = device.reader(model)
        if device.name == "differential_steering":     # the reader's distances are since its last message
            read(taken[0], Tick(stamp=tick.stamp, time_s=0.0))
            node.publish_tick(frame := sim.step())
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
        read(taken[0], tick)
        expected = READINGS[device.name](frame, sim)
        for field, want in expected.items():
            assert np.any(np.asarray(want) != 0), f"{device.name}: the frame has no {field} reading to compare"
            value = getattr(tick, field)
            assert value is not None, f"{device.name}'s reader left Tick.{field} empty"
            value = AS_ARRAYS.get(field, np.asarray)(value)
            np.testing.assert_allclose(value, np.asarray(want, dtype=float), rtol=1e-6, atol=1e-6,
                                       err_msg=f"{device.name}: Tick.{field}")
    finally:
        node.destroy_node()
        listener.destroy_node()
