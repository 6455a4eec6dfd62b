"""Bulk CDR equals mcap-ros2-support's encoding; recordings open in mcap-ros2-support and
rosbags."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from navreplay.core.streams import Recording, StreamKind
from navreplay.io import TOPICS, read_recording, write_recording
from navreplay.io.cdr import decode_payloads, encode, layout, records_to_fields, view_records
from navreplay.io.convert import ENCODERS, aux_columns
from navreplay.io.schemas import (
    DEPTH_MSG,
    MASTER_INS_MSG,
    SPECS,
    SPEED_LOG_MSG,
    TRUTH_MSG,
)
from navreplay.io.synthetic import random_recording, random_stream


def _nested(rec: np.ndarray, spec_message) -> dict:  # type: ignore[no-untyped-def]
    """One bulk record as the nested dict mcap-ros2-support's encoder takes."""
    msg: dict = {
        "header": {
            "stamp": {"sec": int(rec["sec"]), "nanosec": int(rec["nanosec"])},
            "frame_id": rec["frame_id"].decode(),
        }
    }

    def put(path: str, value: object) -> None:
        node = msg
        *parents, last = path.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = value

    for leaf in spec_message.leaves:
        values = np.atleast_1d(rec[leaf.name]).tolist()
        if len(leaf.paths) == leaf.count:  # scalars, e.g. orientation.x .y .z .w
            for path, value in zip(leaf.paths, values, strict=True):
                put(path, value)
        else:  # one fixed-size array
            put(leaf.paths[0], values)
    seq = spec_message.sequence
    if seq is not None:
        put(seq.paths[0], rec[seq.name].tolist() if seq.name in rec.dtype.names else [])
    return msg


@pytest.mark.parametrize("kind", list(StreamKind))
@pytest.mark.parametrize("frame", ["", "x", "imu_frd", "a_rather_long_frame_name"])
def test_bulk_bytes_equal_mcap_ros2(kind: StreamKind, frame: str) -> None:
    rng = np.random.default_rng(abs(hash((kind.value, frame))) % 2**32)
    stream = random_stream(kind, rng, duration_s=3.0)
    spec = SPECS[kind]
    aux = aux_columns(stream) if kind is StreamKind.TRUTH else []
    lay = layout(spec.message, len(frame) + 1, sum(c.width for c in aux))
    records = encode(lay, stream.t_ns, frame.encode(), ENCODERS[kind](stream, aux))
    encoder = serialize_dynamic(spec.message.name, spec.message.schema_text)[spec.message.name]
    data = records.tobytes()
    for i in range(0, len(records), max(1, len(records) // 7)):
        ref = encoder(_nested(records[i], spec.message))
        assert data[i * lay.itemsize : (i + 1) * lay.itemsize] == ref, (kind, frame, i)
    # and the bulk decoder reads the same bytes back
    rows = np.frombuffer(data, dtype=np.uint8).reshape(len(records), lay.itemsize)
    fields = records_to_fields(view_records(rows, lay), spec.message)
    np.testing.assert_array_equal(fields["t_ns"], stream.t_ns)


def test_truth_without_aux_bytes_equal() -> None:
    stream = random_stream("truth", np.random.default_rng(1), duration_s=1.0, aux=False)
    spec = SPECS[StreamKind.TRUTH]
    lay = layout(spec.message, len(b"ned") + 1, 0)
    records = encode(lay, stream.t_ns, b"ned", ENCODERS[StreamKind.TRUTH](stream, []))
    encoder = serialize_dynamic(spec.message.name, spec.message.schema_text)[spec.message.name]
    assert records[:1].tobytes() == encoder(_nested(records[0], spec.message))


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Recording, Path]:
    rec = random_recording(np.random.default_rng(7), duration_s=3.0)
    path = write_recording(tmp_path_factory.mktemp("cdr") / "rec.mcap", rec)
    return rec, path


def _vec(v) -> list[float]:  # type: ignore[no-untyped-def]
    return [v.x, v.y, v.z]


def test_file_decodes_with_mcap_ros2(recorded: tuple[Recording, Path]) -> None:
    rec, path = recorded
    got: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, msg in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            assert stamp == message.log_time
            got.setdefault(channel.topic, []).append(msg)
    assert set(got) == set(TOPICS.values())
    for kind, topic in TOPICS.items():
        assert len(got[topic]) == len(rec[kind]), kind
    imu = got["/imu"]
    np.testing.assert_array_equal([_vec(m.angular_velocity) for m in imu], rec["imu"]["omega_ib_b"])
    assert imu[0].orientation_covariance[0] == -1 and imu[0].header.frame_id == "imu_frd"
    fix = got["/gps/fix"][0]
    np.testing.assert_allclose([fix.latitude, fix.longitude], np.degrees(rec["gps"]["pos"][0, :2]))
    sigma = rec["gps"]["pos_sigma"][0]
    np.testing.assert_allclose(
        np.array(fix.position_covariance).reshape(3, 3),
        np.diag([sigma[1], sigma[0], sigma[2]]) ** 2,
    )
    assert fix.position_covariance_type == 2
    vel = got["/gps/vel"][0]
    np.testing.assert_array_equal(_vec(vel.twist.twist.linear), rec["gps_vel"]["v_n"][0])
    assert vel.header.frame_id == "ned"
    mag = got["/mag"][0]
    np.testing.assert_array_equal(_vec(mag.magnetic_field), rec["mag"]["m_b"][0])
    ins = got["/master_ins"][0]
    np.testing.assert_array_equal(ins.euler, rec["master_ins"]["euler"][0])
    np.testing.assert_array_equal(
        [ins.latitude, ins.longitude, ins.height], rec["master_ins"]["pos"][0]
    )
    assert got["/speed_log"][2].rpm == rec["speed_log"]["rpm"][2]
    assert got["/depth"][1].depth == rec["depth"]["depth"][1]
    truth = got["/truth"][5]
    truth_rec = rec["truth"]
    np.testing.assert_array_equal(truth.q_nb, truth_rec["q_nb"][5])
    expected_aux = np.concatenate(
        [truth_rec[c][5].ravel() for c in ("gyro_bias", "accel_bias", "misalignment")]
        + [truth_rec["current_speed"][5:6]]
    )
    np.testing.assert_array_equal(truth.aux, expected_aux)


def test_file_opens_in_rosbags(recorded: tuple[Recording, Path]) -> None:
    rec, path = recorded
    with AnyReader([path]) as reader:
        topics = reader.topics
        assert {t: i.msgtype for t, i in topics.items()} == {
            spec.topic: spec.message.name for spec in SPECS.values()
        }
        counts: dict[str, int] = {}
        for connection, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            i = counts.get(connection.topic, 0)
            counts[connection.topic] = i + 1
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            assert stamp == timestamp
            if connection.topic == "/imu":
                np.testing.assert_array_equal(_vec(msg.linear_acceleration), rec["imu"]["f_b"][i])
            elif connection.topic == "/truth":
                np.testing.assert_array_equal(msg.v_n, rec["truth"]["v_n"][i])
                assert len(msg.aux) == 3 + 3 + 9 + 1
                assert msg.aux[-1] == rec["truth"]["current_speed"][i]
            elif connection.topic == "/master_ins":
                np.testing.assert_array_equal(msg.v_n, rec["master_ins"]["v_n"][i])
    assert counts == {TOPICS[k]: len(s) for k, s in rec.streams.items()}


def test_rosbags_typesys_from_msg_text(recorded: tuple[Recording, Path]) -> None:
    """navreplay_msgs registered from the .msg texts alone (std types from rosbags' own store)
    decode the raw payloads, and rosbags serialises them to the same bytes."""
    rec, path = recorded
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    for name, text in (
        ("navreplay_msgs/msg/MasterIns", MASTER_INS_MSG),
        ("navreplay_msgs/msg/SpeedLog", SPEED_LOG_MSG),
        ("navreplay_msgs/msg/Depth", DEPTH_MSG),
        ("navreplay_msgs/msg/Truth", TRUTH_MSG),
    ):
        types.update(get_types_from_msg(text, name))
    store.register(types)
    seen = set()
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if (
                not schema.name.startswith("navreplay_msgs/")
                and schema.name != "sensor_msgs/msg/Imu"
            ):
                continue
            msg = store.deserialize_cdr(message.data, schema.name)
            assert bytes(store.serialize_cdr(msg, schema.name)) == message.data
            seen.add(schema.name)
    assert seen == {
        "navreplay_msgs/msg/MasterIns",
        "navreplay_msgs/msg/SpeedLog",
        "navreplay_msgs/msg/Depth",
        "navreplay_msgs/msg/Truth",
        "sensor_msgs/msg/Imu",
    }
    back = read_recording(path)
    np.testing.assert_array_equal(back["truth"]["misalignment"], rec["truth"]["misalignment"])


def test_payloads_of_several_layouts_decode_in_their_order() -> None:
    """decode_payloads: two frame-id lengths (two fixed layouts) interleaved, and payloads of
    no fixed layout (big-endian) handed to the generic decoder by index; the fields come back
    in the payloads' order, equal to those of each payload decoded alone."""
    rng = np.random.default_rng(7)
    stream = random_stream(StreamKind.IMU, rng, duration_s=2.0)
    message = SPECS[StreamKind.IMU].message
    payloads: list[bytes] = []
    for frame in ("imu_frd", "a_rather_long_frame_name"):
        lay = layout(message, len(frame) + 1)
        data = encode(lay, stream.t_ns, frame.encode(), ENCODERS[StreamKind.IMU](stream, [])
                      ).tobytes()
        payloads.append(data)
    size = [len(p) // len(stream) for p in payloads]
    order = rng.permutation(2 * len(stream))  # message k of frame k // n, interleaved
    n = len(stream)
    chosen = [payloads[k // n][(k % n) * size[k // n]:(k % n + 1) * size[k // n]] for k in order]
    foreign = {3, 4, len(chosen) - 1}
    for k in foreign:  # big-endian encapsulation: no fixed layout, the generic decoder's
        chosen[k] = bytes((0, 0)) + chosen[k][2:]
    asked: list[list[int]] = []

    def generic(index: np.ndarray) -> dict[str, np.ndarray]:
        asked.append(index.tolist())
        fixed = [bytes((0, 1)) + chosen[i][2:] for i in index.tolist()]
        return decode_payloads(fixed, message, generic)

    fields = decode_payloads(chosen, message, generic)
    assert sorted(i for a in asked for i in a) == sorted(foreign)
    assert all(a == sorted(a) for a in asked)
    expected_t = stream.t_ns[order % n]
    np.testing.assert_array_equal(fields["t_ns"], expected_t)
    frames = np.where(order < n, "imu_frd", "a_rather_long_frame_name")
    assert fields["frame_id"].tolist() == frames.tolist()
    for k in (0, 1, 3, len(chosen) - 1):  # each alone (a foreign one as its little-endian twin)
        alone = decode_payloads([bytes((0, 1)) + chosen[k][2:]], message, generic)
        for name in fields:
            np.testing.assert_array_equal(fields[name][k], alone[name][0])
