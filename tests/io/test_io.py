"""Recording format: write -> read round trips, metadata, determinism, overwrite, atomicity,
validation, stream mapping, info."""

from __future__ import annotations

import io
import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer
from mcap_ros2._cdr import CdrWriter, EncapsulationKind

from navreplay.core.streams import Metadata, Recording, Stream, StreamKind
from navreplay.io import (
    TOPICS,
    ReadOptions,
    RecordingError,
    RecordingExistsError,
    RecordingWarning,
    format_info,
    read_recording,
    recording_info,
    write_recording,
)
from navreplay.io import writer as writer_module
from navreplay.io.cdr import encode, layout
from navreplay.io.convert import ENCODERS
from navreplay.io.schemas import SPECS
from navreplay.io.synthetic import T0_NS, random_recording, random_stream

RNG_SEED = 20240611


@pytest.fixture(scope="module")
def recording() -> Recording:
    return random_recording(np.random.default_rng(RNG_SEED), duration_s=10.0)


@pytest.fixture(scope="module")
def written(recording: Recording, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("io") / "rec.mcap"
    write_recording(path, recording)
    return path


def assert_same(a: Recording, b: Recording, *, gps_ulp: int = 1) -> None:
    """Streams, frames and metadata equal; NavSatFix lat/lon within ``gps_ulp`` (degrees on the
    wire), everything else bit for bit."""
    assert list(a.streams) == list(b.streams)
    assert a.metadata == b.metadata
    assert a.t0_ns == b.t0_ns
    for kind, sa in a.streams.items():
        sb = b.streams[kind]
        assert sb.kind is kind
        assert sb.frame_id == sa.frame_id, kind
        np.testing.assert_array_equal(sb.t_ns, sa.t_ns)
        assert sb.t_ns.dtype == np.int64
        assert set(sb.columns) == set(sa.columns), kind
        for name, col in sa.columns.items():
            got = sb[name]
            assert got.dtype == np.float64 and got.shape == col.shape, (kind, name)
            if kind is StreamKind.GPS and name == "pos":
                np.testing.assert_array_max_ulp(got[:, :2], col[:, :2], maxulp=gps_ulp)
                np.testing.assert_array_equal(got[:, 2], col[:, 2])
            else:
                np.testing.assert_array_equal(got, col, err_msg=f"{kind} {name}")


def test_round_trip_every_kind(recording: Recording, written: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an intact file reads without any warning
        back = read_recording(written)
    assert set(back.streams) == set(StreamKind)
    assert_same(recording, back)
    truth = back[StreamKind.TRUTH]
    assert truth["misalignment"].shape == (len(truth), 3, 3)
    assert truth["current_speed"].shape == (len(truth),)


def test_kinds_subset(recording: Recording, written: Path) -> None:
    back = read_recording(written, ReadOptions(kinds=["imu", StreamKind.DEPTH]))
    assert list(back.streams) == [StreamKind.IMU, StreamKind.DEPTH]
    np.testing.assert_array_equal(back["imu"]["f_b"], recording["imu"]["f_b"])
    assert back.t0_ns == recording.t0_ns and back.metadata == recording.metadata


def test_missing_kind_names_what_the_file_has(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    path = write_recording(tmp_path / "a.mcap", random_recording(rng, duration_s=1, kinds=["imu"]))
    with pytest.raises(RecordingError, match=r"a\.mcap.*no topic for stream\(s\) gps.*/imu"):
        read_recording(path, ReadOptions(kinds=["imu", "gps"]))


def test_gyro_free_imu_and_optional_sigmas(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    rec = random_recording(
        rng, duration_s=2, kinds=["imu", "gps", "gps_vel", "truth"], gyro=False, aux=False
    )
    del rec["gps"].columns["pos_sigma"]
    del rec["gps_vel"].columns["vel_sigma"]
    path = write_recording(tmp_path / "a.mcap", rec)
    back = read_recording(path)
    assert "omega_ib_b" not in back["imu"].columns
    assert "pos_sigma" not in back["gps"].columns and "vel_sigma" not in back["gps_vel"].columns
    assert set(back["truth"].columns) == {"pos", "v_n", "q_nb"}
    assert_same(rec, back)


def test_metadata_defaults_and_version_fill(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    rec = random_recording(rng, duration_s=1, kinds=["depth"])
    rec.metadata = Metadata()
    back = read_recording(write_recording(tmp_path / "a.mcap", rec))
    assert back.metadata.seed is None and back.metadata.params == {}
    assert back.metadata.navreplay_version  # the writer's version when none is given


def test_same_recording_gives_identical_bytes(
    recording: Recording, written: Path, tmp_path: Path
) -> None:
    again = write_recording(tmp_path / "again.mcap", recording)
    assert again.read_bytes() == written.read_bytes()
    # and re-writing what was read gives the same file (lat/lon go through degrees and back)
    back = read_recording(written)
    back["gps"].columns["pos"][:, :2] = recording["gps"]["pos"][:, :2]
    assert write_recording(tmp_path / "re.mcap", back).read_bytes() == written.read_bytes()


def test_refuses_to_overwrite_without_force(recording: Recording, tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(b"precious")
    with pytest.raises(RecordingExistsError, match=r"x\.mcap.*force=True") as info:
        write_recording(path, recording)
    assert isinstance(info.value, FileExistsError)
    assert path.read_bytes() == b"precious"
    write_recording(path, recording, force=True)
    assert path.read_bytes()[:8] == b"\x89MCAP0\r\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.mcap"]


@pytest.mark.parametrize("existing", [False, True])
def test_failure_mid_write_leaves_nothing(
    recording: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, existing: bool
) -> None:
    path = tmp_path / "x.mcap"
    if existing:
        path.write_bytes(b"precious")
    calls = {"n": 0}
    real = writer_module._encode

    def failing(topic, start, stop):  # type: ignore[no-untyped-def]
        calls["n"] += 1
        if calls["n"] == 5:
            raise OSError("disk full (simulated)")
        return real(topic, start, stop)

    monkeypatch.setattr(writer_module, "WINDOW", 500)
    monkeypatch.setattr(writer_module, "_encode", failing)
    with pytest.raises(OSError, match="simulated"):
        write_recording(path, recording, force=True)
    assert calls["n"] == 5
    if existing:
        assert path.read_bytes() == b"precious"
    else:
        assert not path.exists()
    assert [p.name for p in tmp_path.iterdir()] == (["x.mcap"] if existing else [])


def test_small_windows_give_the_same_file(
    recording: Recording, written: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(writer_module, "WINDOW", 777)
    assert write_recording(tmp_path / "w.mcap", recording).read_bytes() == written.read_bytes()


def _pieces(rec: Recording, cuts_s: list[float]) -> list[Recording]:
    """``rec`` cut at ``cuts_s`` [s after t0] into pieces on its clock."""
    edges = [None, *(rec.t0_ns + int(c * 1e9) for c in cuts_s), None]
    out = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        streams = {}
        for kind, s in rec.streams.items():
            a = 0 if lo is None else int(s.t_ns.searchsorted(lo))
            b = len(s) if hi is None else int(s.t_ns.searchsorted(hi))
            streams[kind] = s.slice(a, b)
        out.append(Recording(streams, rec.metadata, rec.t0_ns))
    return out


def test_a_recording_written_in_pieces_is_the_file_written_whole(
    recording: Recording, written: Path, tmp_path: Path
) -> None:
    first, *more = _pieces(recording, [2.5, 6.0005, 6.0006])  # the third piece is empty
    assert max(len(s) for s in more[1].streams.values()) == 0
    pieces = iter(more)  # made one at a time, as a generator would
    path = write_recording(tmp_path / "p.mcap", first, more=pieces)
    assert path.read_bytes() == written.read_bytes()


@pytest.mark.parametrize("how, match", [
    ("overlap", r"p\.mcap: piece 3 of the recording: stream imu starts at \d+ ns, not after "
                r"the previous piece's last sample"),
    ("streams", r"p\.mcap: piece 2 of the recording has the streams imu; the first piece has "),
    ("clock", r"piece 2 of the recording starts its clock at"),
])
def test_a_piece_that_does_not_continue_the_recording_writes_nothing(
    recording: Recording, tmp_path: Path, how: str, match: str
) -> None:
    first, second, third = _pieces(recording, [3.0, 6.0])
    if how == "overlap":
        third = Recording({**third.streams, StreamKind.IMU: second[StreamKind.IMU]},
                          third.metadata, third.t0_ns)
    elif how == "streams":
        second = Recording({StreamKind.IMU: second[StreamKind.IMU]}, second.metadata,
                           second.t0_ns)
    else:
        second = Recording(second.streams, second.metadata, second.t0_ns + 1)
    with pytest.raises(RecordingError, match=match):
        write_recording(tmp_path / "p.mcap", first, more=[second, third])
    assert list(tmp_path.iterdir()) == []


def _with(stream: Stream, **columns: np.ndarray) -> Recording:
    s = Stream(stream.kind, stream.t_ns.copy(), {**stream.columns, **columns}, stream.frame_id)
    return Recording({stream.kind: s}, Metadata(), T0_NS)


def test_write_refuses_bad_samples(tmp_path: Path) -> None:
    imu = random_stream("imu", np.random.default_rng(4), duration_s=1)
    f_b = imu["f_b"].copy()
    f_b[7, 1] = np.nan
    with pytest.raises(
        RecordingError, match=r"y\.mcap.*stream imu \(topic /imu\).*non-finite.*'f_b'.*t = 0\.04"
    ):
        write_recording(tmp_path / "y.mcap", _with(imu, f_b=f_b))
    assert not (tmp_path / "y.mcap").exists()
    rec = _with(imu)
    rec["imu"].t_ns[20] = rec["imu"].t_ns[19]
    with pytest.raises(RecordingError, match=r"timestamp repeats at t = 0\.1"):
        write_recording(tmp_path / "y.mcap", rec)
    rec = _with(imu)
    del rec["imu"].columns["f_b"]
    with pytest.raises(RecordingError, match=r"lacks the columns \['f_b'\]"):
        write_recording(tmp_path / "y.mcap", rec)
    rec = _with(imu, temperature=np.zeros(len(imu)))
    with pytest.raises(RecordingError, match="'temperature' has no place"):
        write_recording(tmp_path / "y.mcap", rec)
    assert list(tmp_path.iterdir()) == []


def _bad_file(path: Path, stream: Stream) -> Path:
    rec = Recording({stream.kind: stream}, Metadata(scenario="bad"), T0_NS)
    return write_recording(path, rec, validate=False)


def test_read_reports_nan_with_file_topic_and_time(tmp_path: Path) -> None:
    gps = random_stream("gps", np.random.default_rng(5), duration_s=10)
    pos = gps["pos"].copy()
    pos[3, 2] = np.inf
    path = _bad_file(tmp_path / "nan.mcap", _with(gps, pos=pos)["gps"])
    t = gps.t_ns[3]
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    msg = str(info.value)
    assert str(path) in msg and "/gps/fix" in msg and "non-finite" in msg and "'pos'" in msg
    assert f"t = {(t - T0_NS) * 1e-9:.9f} s ({t} ns)" in msg
    assert read_recording(path, ReadOptions(validate=False))["gps"]["pos"][3, 2] == np.inf


@pytest.mark.parametrize("how", ["goes backwards", "repeats"])
def test_read_reports_bad_time_with_file_topic_and_time(tmp_path: Path, how: str) -> None:
    """Header stamps that disagree with the (ordered) log times of a file from elsewhere: the
    log times are used, with a warning naming the file, topic and message; with the log times
    bad as well, the error names the file, topic and time."""
    depth = random_stream("depth", np.random.default_rng(6), duration_s=10)
    t_ns = depth.t_ns.copy()
    if how == "repeats":
        t_ns[6] = t_ns[5]
    else:
        t_ns[5], t_ns[6] = t_ns[6], t_ns[5]
    stream = Stream("depth", t_ns, depth.columns, depth.frame_id)
    path = _raw_file(tmp_path / "back.mcap", "/depth", "depth", stream, log_times=depth.t_ns)
    with pytest.warns(RecordingWarning, match="header stamps do not increase") as caught:
        rec = read_recording(path)
    msg = next(str(w.message) for w in caught if "do not increase" in str(w.message))
    assert msg.startswith(f"{path}: topic /depth (navreplay_msgs/msg/Depth): ")
    assert f"message 6, stamp {t_ns[6]} ns" in msg
    np.testing.assert_array_equal(rec["depth"].t_ns, depth.t_ns)
    path = _raw_file(tmp_path / "back_log.mcap", "/depth", "depth", stream, log_times=t_ns)
    t = t_ns[6]
    with pytest.raises(RecordingError) as info:
        read_recording(path, ReadOptions(time="log"))
    msg = str(info.value)
    assert msg.startswith(f"{path}: topic /depth (navreplay_msgs/msg/Depth): timestamp {how}")
    assert f"at t = {(t - depth.t_ns[0]) * 1e-9:.9f} s ({t} ns)" in msg


def test_gap_warning(tmp_path: Path) -> None:
    depth = random_stream("depth", np.random.default_rng(7), duration_s=20)
    keep = np.r_[0:10, 30 : len(depth)]
    stream = Stream("depth", depth.t_ns[keep], {"depth": depth["depth"][keep]}, "depth")
    path = write_recording(
        tmp_path / "gap.mcap", Recording({StreamKind.DEPTH: stream}, Metadata(), T0_NS)
    )
    with pytest.warns(
        RecordingWarning, match=r"gap\.mcap: topic /depth .*1 gap\(s\).*the longest, 10\.5"
    ):
        read_recording(path)


def _raw_file(
    path: Path,
    topic: str,
    kind: str,
    stream: Stream,
    *,
    log_times: np.ndarray | None = None,
    schema_name: str | None = None,
    fields: dict[str, np.ndarray] | None = None,
) -> Path:
    """A file written with mcap's raw Writer and navreplay's encoder (a 'foreign' file)."""
    spec = SPECS[StreamKind(kind)]
    frame = stream.frame_id.encode()
    lay = layout(spec.message, len(frame) + 1, 0)
    values = {**ENCODERS[spec.kind](stream, []), **(fields or {})}
    payload = encode(lay, stream.t_ns, frame, values).tobytes()
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(
            schema_name or spec.message.name, "ros2msg", spec.message.schema_text.encode()
        )
        cid = w.register_channel(topic, "cdr", sid)
        times = stream.t_ns if log_times is None else log_times
        for i, t in enumerate(times.tolist()):
            w.add_message(cid, t, payload[i * lay.itemsize : (i + 1) * lay.itemsize], t)
        w.finish()
    return path


def test_foreign_file_without_metadata_maps_by_schema(tmp_path: Path) -> None:
    rng = np.random.default_rng(8)
    imu = random_stream("imu", rng, duration_s=2)
    flu = Stream("imu", imu.t_ns, imu.columns, "imu_link")
    path = _raw_file(
        tmp_path / "foreign.mcap", "/vectornav/imu", "imu", flu, schema_name="sensor_msgs/Imu"
    )
    with pytest.warns(RecordingWarning, match="'imu_link' taken as FLU"):
        back = read_recording(path)
    assert back.metadata == Metadata()
    assert back.t0_ns == int(imu.t_ns[0])
    got = back["imu"]
    assert got.frame_id == "imu_link_frd"
    np.testing.assert_array_equal(got["f_b"], imu["f_b"] * [1, -1, -1])
    np.testing.assert_array_equal(got["omega_ib_b"], imu["omega_ib_b"] * [1, -1, -1])
    # an explicit topic for a kind works too
    with pytest.warns(RecordingWarning, match="FLU"):
        back = read_recording(path, ReadOptions(topics={"imu": "/vectornav/imu"}, kinds=["imu"]))
    assert len(back["imu"]) == len(imu)


def test_foreign_gps_no_fix_and_enu_velocity(tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    gps = random_stream("gps", rng, duration_s=10)
    status = np.zeros(len(gps), dtype=np.int8)
    status[[2, 5]] = -1
    path = _raw_file(tmp_path / "fix.mcap", "/fix", "gps", gps, fields={"status": status})
    with pytest.warns(RecordingWarning, match="2 fixes with status NO_FIX dropped"):
        back = read_recording(path)
    keep = status == 0
    np.testing.assert_array_equal(back["gps"].t_ns, gps.t_ns[keep])
    np.testing.assert_array_equal(back["gps"]["pos_sigma"], gps["pos_sigma"][keep])
    vel = random_stream("gps_vel", rng, duration_s=5)
    enu = Stream("gps_vel", vel.t_ns, {"v_n": vel["v_n"][:, [1, 0, 2]] * [1, 1, -1]}, "gps")
    path = _raw_file(tmp_path / "vel.mcap", "/gps/vel", "gps_vel", enu)
    with pytest.warns(RecordingWarning, match="'gps' taken as ENU"):
        back = read_recording(path)
    np.testing.assert_array_equal(back["gps_vel"]["v_n"], vel["v_n"])
    assert back["gps_vel"].frame_id == "ned"


def test_empty_streams_keep_their_columns(tmp_path: Path) -> None:
    rec = random_recording(np.random.default_rng(12), duration_s=1, kinds=["imu", "gps", "truth"])
    for kind, stream in list(rec.streams.items()):
        rec.streams[kind] = stream.slice(0, 0)
    back = read_recording(write_recording(tmp_path / "empty.mcap", rec))
    for kind, stream in rec.streams.items():
        assert len(back[kind]) == 0
        assert {k: v.shape for k, v in back[kind].columns.items()} == {
            k: v.shape for k, v in stream.columns.items()
        }


def test_canonical_topic_with_wrong_schema_is_an_error(tmp_path: Path) -> None:
    mag = random_stream("mag", np.random.default_rng(9), duration_s=2)
    path = _raw_file(tmp_path / "wrong.mcap", TOPICS[StreamKind.IMU], "mag", mag)
    with pytest.raises(
        RecordingError,
        match=r"wrong\.mcap: topic /imu has schema 'sensor_msgs/msg/MagneticField' in 'cdr' "
        r"encoding; stream imu needs sensor_msgs/msg/Imu",
    ):
        read_recording(path)


def test_other_frame_id_lengths_and_generic_fallback(tmp_path: Path) -> None:
    """Messages of one topic with two frame_id lengths: both decode (two fixed layouts), and a
    big-endian message goes through the generic decoder."""
    rng = np.random.default_rng(10)
    mag = random_stream("mag", rng, duration_s=3)
    spec = SPECS[StreamKind.MAG]
    fields = ENCODERS[StreamKind.MAG](mag, [])
    payloads = []
    for i in range(len(mag)):
        frame = b"mag_frd" if i % 2 else b"magnetometer_frd"
        lay = layout(spec.message, len(frame) + 1)
        one = {k: v[i : i + 1] for k, v in fields.items()}
        payloads.append(encode(lay, mag.t_ns[i : i + 1], frame, one).tobytes())
    buf = io.BytesIO()
    cw = CdrWriter(buf, EncapsulationKind.CDR_BE)
    sec, nsec = divmod(int(mag.t_ns[4]), 1_000_000_000)
    cw.write_int32(sec)
    cw.write_uint32(nsec)
    cw.write_string("mag_frd")
    for v in mag["m_b"][4]:
        cw.write_float64(float(v))
    for _ in range(9):
        cw.write_float64(0.0)
    payloads[4] = buf.getvalue()
    path = tmp_path / "mixed.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(spec.message.name, "ros2msg", spec.message.schema_text.encode())
        cid = w.register_channel("/mag", "cdr", sid)
        for t, p in zip(mag.t_ns.tolist(), payloads, strict=True):
            w.add_message(cid, t, p, t)
        w.finish()
    with pytest.warns(RecordingWarning, match="frame_id changes"):
        back = read_recording(path)
    np.testing.assert_array_equal(back["mag"]["m_b"], mag["m_b"])
    np.testing.assert_array_equal(back["mag"].t_ns, mag.t_ns)


def test_info(recording: Recording, written: Path) -> None:
    info = recording_info(written)
    assert info.has_metadata and info.damage is None and info.profile == "ros2"
    assert info.metadata == recording.metadata and info.t0_ns == recording.t0_ns
    by_topic = {t.topic: t for t in info.topics}
    assert set(by_topic) == set(TOPICS.values())
    imu = by_topic["/imu"]
    assert imu.kind is StreamKind.IMU and imu.schema == "sensor_msgs/msg/Imu"
    assert imu.count == len(recording["imu"])
    assert imu.start_ns == recording["imu"].t_ns[0] and imu.end_ns == recording["imu"].t_ns[-1]
    assert imu.rate_hz == pytest.approx(200.0, rel=1e-3)
    assert ("misalignment", (3, 3)) in info.truth_columns
    text = format_info(info)
    assert "synthetic" in text and "/truth" in text and "navreplay_msgs/msg/Truth" in text
    assert "200.000" in text or "199.9" in text


def test_info_of_truncated_file(written: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    data = written.read_bytes()
    cut.write_bytes(data[: len(data) * 9 // 10])
    info = recording_info(cut)
    assert info.damage and "truncated" in info.damage
    assert 0 < info.message_count
    assert "DAMAGED" in format_info(info)


def test_not_mcap_and_missing_file(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(b"hello world, not mcap")
    with pytest.raises(RecordingError, match=r"x\.mcap: not an MCAP file"):
        read_recording(tmp_path / "x.mcap")
    with pytest.raises(RecordingError, match=r"nope\.mcap: no such file"):
        read_recording(tmp_path / "nope.mcap")


def test_empty_recording(tmp_path: Path) -> None:
    rec = Recording({}, Metadata(scenario="empty"), T0_NS)
    back = read_recording(write_recording(tmp_path / "e.mcap", rec))
    assert back.streams == {} and back.metadata.scenario == "empty" and back.t0_ns == T0_NS
    assert os.path.getsize(tmp_path / "e.mcap") > 0
