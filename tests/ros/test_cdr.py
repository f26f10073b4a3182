"""The serialized-bytes codecs against rclpy's own (de)serialization: the simulator and the base
class put on the wire exactly the messages of the contract, and read what any node publishes."""
import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import LaserScan, PointCloud2, PointField

from composed_sim.world.robot_models import get_model
from composed_sim.ros import cdr, contract as c, decoding
from composed_sim.ros.devices import camera, light, proximity

FOOTBOT = get_model("foot-bot")
NAMES = ["b", "bot7", "bot42", "bot123", "bot1234", "a_long_robot_name_99"]   # every CDR padding case
rng = np.random.default_rng(0)


def received(msg):
    """``msg`` as a subscriber receives it (float32 fields rounded)."""
    return deserialize_message(serialize_message(msg), type(msg))


@pytest.mark.parametrize("name", NAMES)
def test_sensor_bytes_are_the_contract_messages(name):
    stamp = c.stamp_of(int(rng.integers(0, 10**6)), 100_000_000)
    k = len(FOOTBOT.proximity.angles_rad)
    distances, readings = rng.random(k), rng.random(k)
    distances[3] = np.inf

    expected = proximity.message(FOOTBOT, name)
    proximity.fill(expected, stamp, distances, readings)
    data = proximity.encoder(FOOTBOT, name).encode(stamp.sec, stamp.nanosec, readings, distances)
    assert deserialize_message(data, LaserScan) == received(expected)

    scan = light.message(FOOTBOT, name)
    light.fill(scan, stamp, readings)
    assert deserialize_message(light.encoder(FOOTBOT, name).encode(stamp.sec, stamp.nanosec, readings),
                               LaserScan) == received(scan)

    encoder, cloud = camera.encoder(name), camera.message(name)
    for m in (0, 1, 2, 3, 9):       # the same encoder, blob counts changing tick to tick
        points = camera.points_of(rng.uniform(-3, 3, m), rng.uniform(0.1, 2, m),
                               rng.integers(0, 256, (m, 3)).astype(np.uint8))
        camera.fill(cloud, stamp, points)
        assert deserialize_message(encoder.encode(stamp.sec, stamp.nanosec, points.tobytes(), m),
                                   PointCloud2) == received(cloud)


@pytest.mark.parametrize("name", NAMES)
def test_decoding_bytes_equals_decoding_messages(name):
    """What the base class reads from bytes is what contract's decoders read from messages, for
    messages serialized by rclpy (e.g. from another publisher)."""
    stamp = c.stamp_of(77, 100_000_000)
    k = len(FOOTBOT.proximity.angles_rad)
    scan = proximity.message(FOOTBOT, name)
    proximity.fill(scan, stamp, rng.random(k), rng.random(k))
    for got, want in zip(proximity.decode_cdr(serialize_message(scan)), proximity.decode(scan)):
        assert np.array_equal(got, want)
    assert np.array_equal(light.decode_cdr(serialize_message(scan)), light.decode(scan))

    cloud = camera.message(name)
    camera.fill(cloud, stamp, camera.points_of(rng.uniform(-3, 3, 5), rng.uniform(0.1, 2, 5),
                                             rng.integers(0, 256, (5, 3)).astype(np.uint8)))
    got, want = camera.decode_cdr(serialize_message(cloud)), camera.decode(cloud)
    for field in ("angles", "distances", "colors"):
        assert np.array_equal(getattr(got, field), getattr(want, field))
    red = tuple(int(v) for v in want.colors[2])
    assert np.array_equal(got.of_color(red).angles, want.of_color(red).angles)


def test_a_cloud_with_other_fields_is_refused():
    cloud = PointCloud2()
    cloud.fields = camera.BLOB_FIELDS[:2]
    with pytest.raises(ValueError, match="not a blob cloud"):
        camera.decode_cdr(serialize_message(cloud))


def test_answers_round_trip():
    stamp = c.stamp_of(12345, 100_000_000)
    data = c.answer_encoder().encode(stamp.sec, stamp.nanosec, 0.07, -1.25)
    assert deserialize_message(data, TwistStamped) == received(c.twist_stamped(stamp, 0.07, -1.25))
    assert decoding.decode_answer_cdr(serialize_message(c.twist_stamped(stamp, 0.3, 2.0))) == \
        (c.stamp_key(stamp), 0.3, 2.0)


def test_one_decoder_follows_a_stream_whose_cloud_layout_changes():
    """A subscription's decoder parses the layout once and re-parses when the publisher changes it
    (another frame_id length, other field offsets): each cloud decodes as its message says."""
    decoder = cdr.CloudDecoder()
    reordered = [PointField(name=f.name, offset=o, datatype=f.datatype, count=1)
                 for f, o in zip(camera.BLOB_FIELDS, (4, 8, 12, 0))]       # rgb first in each point
    for name, fields, m in (("b", camera.BLOB_FIELDS, 3), ("b", camera.BLOB_FIELDS, 0), ("a_long_robot_name_99", camera.BLOB_FIELDS, 4),
                            ("a_long_robot_name_99", reordered, 2), ("b", camera.BLOB_FIELDS, 5)):
        cloud = camera.message(name)
        points = camera.points_of(rng.uniform(-3, 3, m), rng.uniform(0.1, 2, m),
                               rng.integers(0, 256, (m, 3)).astype(np.uint8))
        camera.fill(cloud, c.stamp_of(1, 100_000_000), points)
        if fields is reordered:
            cloud.fields = reordered
            data = points.view(np.uint8).reshape(m, 16)
            cloud.data = np.concatenate([data[:, 12:], data[:, :12]], axis=1).tobytes()
        got, want = camera.decode_cdr(serialize_message(cloud), decoder), camera.decode(cloud)
        assert len(got) == m
        for field in ("angles", "distances", "colors", "rgb"):
            assert np.array_equal(getattr(got, field), getattr(want, field)), (name, m, field)
