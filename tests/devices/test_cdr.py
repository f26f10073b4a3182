"""The serialized-bytes codecs against rclpy's own (de)serialization: the simulator and the base
class put on the wire exactly the messages of the contract, and read what any node publishes."""
import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState, LaserScan, PointCloud2, PointField

from composed_sim.world.robot_models import get_model
from composed_sim.devices.common import cdr, cdr_clouds
from composed_sim.ros import contract as c, decoding
from composed_sim.devices import (camera, differential_steering, ground, lidar, light, odometry, positioning,
                                  proximity, range_and_bearing)
import message_reference as ref

FOOTBOT = get_model("foot-bot")
BURGER = get_model("turtlebot3-burger")
NAMES = ["b", "bot7", "bot42", "bot123", "bot1234", "a_long_robot_name_99"]   # every CDR padding case
rng = np.random.default_rng(0)
BLOB_FIELDS = ref.point_fields(camera.BLOB_DTYPE)


def received(msg):
    """``msg`` as a subscriber receives it (float32 fields rounded)."""
    return deserialize_message(serialize_message(msg), type(msg))


@pytest.mark.parametrize("name", NAMES)
def test_sensor_bytes_are_the_contract_messages(name):
    stamp = c.stamp_of(int(rng.integers(0, 10**6)), 100_000_000)
    k = len(FOOTBOT.proximity.angles_rad)
    distances, readings = rng.random(k), rng.random(k)
    distances[3] = np.inf

    expected = ref.proximity.message(FOOTBOT.proximity, name)
    ref.proximity.fill(expected, stamp, distances, readings)
    data = proximity.encoder(FOOTBOT.proximity, name).encode(stamp.sec, stamp.nanosec, readings, distances)
    assert deserialize_message(data, LaserScan) == received(expected)

    scan = ref.light.message(FOOTBOT.light, name)
    ref.light.fill(scan, stamp, readings)
    assert deserialize_message(light.encoder(FOOTBOT.light, name).encode(stamp.sec, stamp.nanosec, readings),
                               LaserScan) == received(scan)

    ranges = rng.uniform(0.1, 3.5, BURGER.lidar.n_rays)
    ranges[[4, 9]] = np.inf, -np.inf
    scan = ref.lidar.message(BURGER.lidar, name, 0.1)
    ref.lidar.fill(scan, stamp, ranges)
    assert deserialize_message(lidar.encoder(BURGER.lidar, name, 0.1).encode_bytes(
        cdr.stamp_bytes(stamp.sec, stamp.nanosec), ranges.astype("<f4").tobytes(), b""), LaserScan) == received(scan)

    stamp_cdr = cdr.stamp_bytes(stamp.sec, stamp.nanosec)
    pose = ref.positioning.message()
    x, y, z, qz, qw = rng.uniform(-5, 5, 5)
    ref.positioning.fill(pose, stamp, x, y, qz, qw, z)
    assert deserialize_message(positioning.encoder().encode(stamp_cdr, x, y, z, qz, qw), PoseStamped) == pose

    odom = ref.odometry.message(name)
    values = rng.uniform(-5, 5, 6)
    ref.odometry.fill(odom, stamp, *values)
    assert deserialize_message(odometry.encoder(name).encode(stamp_cdr, *values), Odometry) == odom

    wheels = ref.wheels.message(name)
    angles, speeds = rng.uniform(-50, 50, 2), rng.uniform(-9, 9, 2)
    ref.wheels.fill(wheels, stamp, angles, speeds)
    assert deserialize_message(differential_steering.encoder(name).encode(stamp_cdr, *angles, *speeds),
                               JointState) == wheels

    offsets = np.array(FOOTBOT.ground.offsets_m)
    cloud = ref.ground_sensors.message(name, len(offsets))
    points = ground.points_of(offsets, rng.random(len(offsets)))
    ref.ground_sensors.fill(cloud, stamp, points)
    assert deserialize_message(ground.encoder(name).encode(stamp.sec, stamp.nanosec, points.tobytes(),
                                                                         len(points)), PointCloud2) == cloud

    encoder, cloud = range_and_bearing.encoder(name, 4), ref.rab.message(name, 4)
    for m in (0, 1, 3):           # the same encoder, message counts changing tick to tick
        points = range_and_bearing.points_of(rng.uniform(0.1, 3, m), rng.uniform(-3, 3, m), rng.uniform(-1, 1, m),
                                             rng.integers(0, 256, (m, 4)))
        ref.rab.fill(cloud, stamp, points)
        assert deserialize_message(encoder.encode(stamp.sec, stamp.nanosec, points.tobytes(), m), PointCloud2) == cloud

    encoder, cloud = camera.encoder(name), ref.blobs.message(name)
    for m in (0, 1, 2, 3, 9):       # the same encoder, blob counts changing tick to tick
        points = camera.points_of(rng.uniform(-3, 3, m), rng.uniform(0.1, 2, m),
                               rng.integers(0, 256, (m, 3)).astype(np.uint8))
        ref.blobs.fill(cloud, stamp, points)
        assert deserialize_message(encoder.encode(stamp.sec, stamp.nanosec, points.tobytes(), m),
                                   PointCloud2) == received(cloud)


@pytest.mark.parametrize("name", NAMES)
def test_decoding_bytes_equals_decoding_messages(name):
    """What the base class reads from bytes is what contract's decoders read from messages, for
    messages serialized by rclpy (e.g. from another publisher)."""
    stamp = c.stamp_of(77, 100_000_000)
    k = len(FOOTBOT.proximity.angles_rad)
    scan = ref.proximity.message(FOOTBOT.proximity, name)
    ref.proximity.fill(scan, stamp, rng.random(k), rng.random(k))
    for got, want in zip(proximity.decode(serialize_message(scan)), ref.proximity.decode(scan)):
        assert np.array_equal(got, want)
    assert np.array_equal(light.decode(serialize_message(scan)), ref.light.decode(scan))

    scan = ref.lidar.message(BURGER.lidar, name, 0.1)
    ref.lidar.fill(scan, stamp, rng.uniform(0.1, 3.5, BURGER.lidar.n_rays))
    assert np.array_equal(lidar.decode(serialize_message(scan)), ref.lidar.decode(scan))
    pose = ref.positioning.message()
    ref.positioning.fill(pose, stamp, *rng.uniform(-5, 5, 4))
    assert np.array_equal(positioning.decode(serialize_message(pose)), ref.positioning.decode(pose))
    odom = ref.odometry.message(name)
    ref.odometry.fill(odom, stamp, *rng.uniform(-5, 5, 6))
    for got, want in zip(odometry.decode(serialize_message(odom)), ref.odometry.decode(odom)):
        assert np.array_equal(got, want)
    wheels = ref.wheels.message(name)
    ref.wheels.fill(wheels, stamp, rng.uniform(-50, 50, 2), rng.uniform(-9, 9, 2))
    for got, want in zip(differential_steering.decode(serialize_message(wheels), 0.033),
                         ref.wheels.decode(wheels, 0.033)):
        assert np.array_equal(got, want)
    offsets = np.array(FOOTBOT.ground.offsets_m)
    cloud = ref.ground_sensors.message(name, len(offsets))
    ref.ground_sensors.fill(cloud, stamp, ground.points_of(offsets, rng.random(len(offsets))))
    assert np.array_equal(ground.decode(serialize_message(cloud)), ref.ground_sensors.decode(cloud))
    cloud = ref.rab.message(name, 3)
    ref.rab.fill(cloud, stamp, range_and_bearing.points_of(rng.uniform(0.1, 3, 5), rng.uniform(-3, 3, 5),
                                                                     rng.uniform(-1, 1, 5), rng.integers(0, 256, (5, 3))))
    got, want = range_and_bearing.decode(serialize_message(cloud)), ref.rab.decode(cloud)
    for field in ("ranges", "bearings", "elevations", "payloads"):
        assert np.array_equal(getattr(got, field), getattr(want, field))

    cloud = ref.blobs.message(name)
    ref.blobs.fill(cloud, stamp, camera.points_of(rng.uniform(-3, 3, 5), rng.uniform(0.1, 2, 5),
                                             rng.integers(0, 256, (5, 3)).astype(np.uint8)))
    got, want = camera.decode(serialize_message(cloud)), ref.blobs.decode(cloud)
    for field in ("angles", "distances", "colors"):
        assert np.array_equal(getattr(got, field), getattr(want, field))
    red = tuple(int(v) for v in want.colors[2])
    assert np.array_equal(got.of_color(red).angles, want.of_color(red).angles)


def test_a_cloud_with_other_fields_is_refused():
    cloud = PointCloud2()
    cloud.fields = BLOB_FIELDS[:2]
    with pytest.raises(ValueError, match="not a blob cloud"):
        camera.decode(serialize_message(cloud))


def test_answers_round_trip():
    stamp = c.stamp_of(12345, 100_000_000)
    data = c.answer_encoder().encode(stamp.sec, stamp.nanosec, 0.07, -1.25)
    assert deserialize_message(data, TwistStamped) == received(c.twist_stamped(stamp, 0.07, -1.25))
    assert decoding.decode_answer_cdr(serialize_message(c.twist_stamped(stamp, 0.3, 2.0))) == \
        (c.stamp_key(stamp), 0.3, 2.0)


@pytest.mark.parametrize("frame_id", ["", "a", "base", "bot12/base_link", "x" * 8])
def test_an_answer_is_read_whatever_its_frame_id_pads(frame_id):
    # The twist starts at the next 8-byte boundary after the frame_id: every padding is read alike.
    msg = c.twist_stamped(c.stamp_of(7, 100_000_000), -0.5, 3.25)
    msg.header.frame_id = frame_id
    msg.twist.linear.y, msg.twist.angular.x = 9.0, 8.0      # neighbours of the two read
    assert cdr.decode_twist_stamped(serialize_message(msg)) == (700_000_000, -0.5, 3.25)


def test_one_decoder_follows_a_stream_whose_cloud_layout_changes():
    """A subscription's decoder parses the layout once and re-parses when the publisher changes it
    (another frame_id length, other field offsets): each cloud decodes as its message says."""
    decoder = cdr_clouds.CloudDecoder()
    reordered = [PointField(name=f.name, offset=o, datatype=f.datatype, count=1)
                 for f, o in zip(BLOB_FIELDS, (4, 8, 12, 0))]       # rgb first in each point
    for name, fields, m in (("b", BLOB_FIELDS, 3), ("b", BLOB_FIELDS, 0), ("a_long_robot_name_99", BLOB_FIELDS, 4),
                            ("a_long_robot_name_99", reordered, 2), ("b", BLOB_FIELDS, 5)):
        cloud = ref.blobs.message(name)
        points = camera.points_of(rng.uniform(-3, 3, m), rng.uniform(0.1, 2, m),
                               rng.integers(0, 256, (m, 3)).astype(np.uint8))
        ref.blobs.fill(cloud, c.stamp_of(1, 100_000_000), points)
        if fields is reordered:
            cloud.fields = reordered
            data = points.view(np.uint8).reshape(m, 16)
            cloud.data = np.concatenate([data[:, 12:], data[:, :12]], axis=1).tobytes()
        got, want = camera.decode(serialize_message(cloud), decoder), ref.blobs.decode(cloud)
        assert len(got) == m
        for field in ("angles", "distances", "colors", "rgb"):
            assert np.array_equal(getattr(got, field), getattr(want, field)), (name, m, field)
