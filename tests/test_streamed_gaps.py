"""A file replayed in windows (``navreplay run``) against the same file read whole: each reader
warning is given once per run, a gap between two windows is the gap it is inside one (same
report, same ``--max-imu-gap`` decision, same bridge: the same bits), and an aiding stream that
pauses for longer than a window does not make the replay hold the IMU samples of the pause."""

from __future__ import annotations

import dataclasses
import importlib
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from test_streaming import assert_same_results as _assert_same

from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.io import read_recording, windows
from navreplay.io import writer as writer_module
from navreplay.io.errors import RecordingError, RecordingWarning
from navreplay.io.writer import write_recording
from navreplay.logs.options import LogOptions
from navreplay.replay import replay
from navreplay.replay.engine import ReplayError, ReplaySession
from navreplay.replay.ensemble import FilterSpec
from navreplay.replay.result import RunResult
from navreplay.replay.streaming import concat_results
from navreplay.sim.scenario import simulate
from navreplay.streams import Recording, Stream, StreamKind
from navreplay.viz.options import VizMode, VizOptions

run = importlib.import_module("navreplay.jobs.run")
CHUNK = 1 << 17  # about 2 s of the drive per chunk: many windows in a short file


@pytest.fixture(autouse=True)
def _small_windows(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(windows, "WINDOW_MESSAGES", 150)  # a window per chunk


@pytest.fixture(scope="module")
def drive() -> Recording:
    return simulate("vehicle-drive", {"duration": 60.0}, seed=5)


def _write(rec: Recording, path: Path) -> Path:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(writer_module, "CHUNK_SIZE", CHUNK)
        write_recording(path, rec)
    return path


def _without(stream: Stream, t0_ns: int, lo: float, hi: float) -> Stream:
    """The stream without its samples in (lo, hi] [s after t0]."""
    t = (stream.t_ns - t0_ns) * 1e-9
    keep = (t <= lo) | (t > hi)
    return dataclasses.replace(stream, t_ns=stream.t_ns[keep],
                               columns={k: v[keep] for k, v in stream.columns.items()})


def _imu_window_ends(path: Path) -> list[int]:
    return [int(w[StreamKind.IMU].t_ns[-1]) for w in windows.read_windows(path, {StreamKind.IMU})
            if StreamKind.IMU in w]


def _job(path: Path, **kw) -> run.RunJob:
    return run.RunJob(filters=(FilterSpec("gps-ins", {}),), recordings=(path,),
                      viz=VizOptions(mode=VizMode.NONE), **kw)


def _caught(fn, *args) -> tuple[object, list[str]]:
    with warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        out = fn(*args)
    return out, [str(w.message) for w in ws if issubclass(w.category, RecordingWarning)]


def _streamed(path: Path, held: list[int] | None = None, **kw) -> RunResult:
    """What ``navreplay run`` does with one filter, the blocks kept: windows of the file fed to
    a session (its aiding streams window by window, known as far as the reader says)."""
    ws = windows.read_windows(path, set(StreamKind))
    window = next(ws)
    head = Recording({k: s.slice(0, 0) for k, s in window.items()}, window.metadata,
                     window.t0_ns)
    session = ReplaySession(head, GpsInsFilter, {}, validate=False, **kw)
    blocks, aiding = [], dict(window)
    while True:
        following = next(ws, None)
        final = following is None
        known = {k: (windows.COMPLETE if final else t) for k, t in window.known.items()}
        blocks.append(session.feed(window.get(StreamKind.IMU), final=final, aiding=aiding,
                                   known=known))
        if held is not None:
            held.append(0 if session._pending is None else len(session._pending[0]))
        if final:
            return concat_results(blocks)
        window = aiding = following


# --------------------------------------------------------------------------------------------
# warnings once per run


def _zero_imu_stamps(src: Path, dst: Path, *, at: int | None = None, latency: int = 0) -> None:
    """A copy of ``src`` whose IMU messages have zero header stamps (a driver that never sets
    them; with ``at``: from log time ``at`` [ns] on, or before ``-at`` when negative): the stamp
    is the first 8 bytes after the CDR encapsulation header. ``latency`` [ns] is added to the
    IMU log times (a receiver's delay)."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        summary = reader.get_summary()
        w = Writer(out, chunk_size=CHUNK, compression=CompressionType.ZSTD)
        w.start()
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        schemas = {s.id: w.register_schema(s.name, s.encoding, s.data)
                   for s in summary.schemas.values()}
        channels = {c.id: w.register_channel(c.topic, c.message_encoding,
                                             schemas.get(c.schema_id, 0), c.metadata)
                    for c in summary.channels.values()}
        for _, channel, m in reader.iter_messages(log_time_order=False):
            data = m.data
            log = m.log_time
            if channel.topic == "/imu":
                if at is None or (log >= at if at >= 0 else log < -at):
                    data = data[:4] + bytes(8) + data[12:]
                log += latency
            w.add_message(channels[channel.id], log, data, m.publish_time, m.sequence)
        w.finish()


def test_a_warning_is_given_once_per_run_with_the_windows_it_concerns(drive, tmp_path) -> None:
    plain = _write(drive, tmp_path / "plain.mcap")
    path = tmp_path / "zero.mcap"
    _zero_imu_stamps(plain, path)
    assert len(_imu_window_ends(path)) >= 10
    report, messages = _caught(run._run_streamed, _job(path), None)
    assert report is not None
    zero = [m for m in messages if "header stamps are zero" in m]
    assert len(zero) == 1, messages
    n = len(_imu_window_ends(path))
    total = len(list(windows.read_windows(path, set(StreamKind))))
    assert str(path) in zero[0] and "topic /imu" in zero[0]
    assert f"the same in {n} of the {total} windows of the read" in zero[0]
    # the first window's count, as the whole reader says it for the whole stream
    _, whole = _caught(read_recording, path)
    count = int(re.search(r"(\d+) header stamps are zero", zero[0]).group(1))
    total = int(re.search(r"(\d+) header stamps are zero",
                          next(m for m in whole if "header stamps" in m)).group(1))
    assert 0 < count < total == len(drive[StreamKind.IMU])


def test_the_time_base_a_topic_starts_with_holds_for_all_its_windows(drive, tmp_path) -> None:
    """Stamps unusable in the first windows: every window takes the log times, as the whole
    reader does for the whole topic (not the stamps of the later windows)."""
    plain = _write(drive, tmp_path / "plain.mcap")
    t0 = int(drive[StreamKind.IMU].t_ns[0])
    path = tmp_path / "late.mcap"
    _zero_imu_stamps(plain, path, at=-(t0 + 5_000_000_000), latency=3_000_000)
    whole, _ = _caught(read_recording, path)
    parts, _ = _caught(lambda: [w[StreamKind.IMU].t_ns for w in windows.read_windows(
        path, {StreamKind.IMU}) if StreamKind.IMU in w])
    assert len(parts) >= 10
    np.testing.assert_array_equal(np.concatenate(parts), whole[StreamKind.IMU].t_ns)
    np.testing.assert_array_equal(whole[StreamKind.IMU].t_ns, drive[StreamKind.IMU].t_ns + 3_000_000)


def test_stamps_that_turn_unusable_after_windows_used_them_are_refused(drive, tmp_path) -> None:
    """The windows already replayed cannot move to log times: one line naming the topic, the
    time and ``--time log``, which then replays the file on one time base."""
    plain = _write(drive, tmp_path / "plain.mcap")
    t0 = int(drive[StreamKind.IMU].t_ns[0])
    path = tmp_path / "turns.mcap"
    _zero_imu_stamps(plain, path, at=t0 + 30_000_000_000, latency=3_000_000)
    with pytest.raises(RecordingError) as err:
        _caught(run._run_streamed, _job(path), None)
    text = str(err.value)
    assert str(path) in text and "topic /imu" in text and "--time log" in text
    assert "t = 30." in text, text
    report, _ = _caught(run._run_streamed, _job(path, log=LogOptions(time="log")), None)
    assert report is not None


# --------------------------------------------------------------------------------------------
# gaps across window boundaries


@pytest.fixture(scope="module")
def boundary(drive, tmp_path_factory) -> tuple[Path, int]:
    """The drive's file, and the last IMU sample of a window in its middle."""
    path = _write(drive, tmp_path_factory.mktemp("gaps") / "plain.mcap")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(windows, "WINDOW_MESSAGES", 150)
        ends = _imu_window_ends(path)
    assert len(ends) >= 10
    return path, ends[len(ends) // 2]


def _gapped(drive: Recording, end_ns: int, seconds: float, path: Path) -> Path:
    """The drive with no IMU sample for ``seconds`` after ``end_ns``: a window ends there."""
    lo = (end_ns - drive.t0_ns) * 1e-9 + 1e-6
    imu = _without(drive[StreamKind.IMU], drive.t0_ns, lo, lo + seconds)
    rec = Recording({**drive.streams, StreamKind.IMU: imu}, drive.metadata, drive.t0_ns)
    _write(rec, path)
    assert end_ns in _imu_window_ends(path)  # the gap is between two windows
    return path


def test_a_gap_between_windows_is_reported_and_bridged_as_inside_one(
        drive, boundary, tmp_path) -> None:
    path = _gapped(drive, boundary[1], 2.0, tmp_path / "gap.mcap")
    whole_rec, whole_lines = _caught(read_recording, path)
    gap_lines = [m for m in whole_lines if "gap(s)" in m]
    assert len(gap_lines) == 1 and "topic /imu" in gap_lines[0]
    # the same line, once, from the streamed run
    report, lines = _caught(run._run_streamed, _job(path), None)
    assert report is not None
    assert [m for m in lines if "gap(s)" in m] == gap_lines
    # the same bridge: the bits of the whole replay, and the run's scores
    whole = replay(whole_rec, GpsInsFilter, {}, output_rate=10.0, validate=False)
    _assert_same(_streamed(path, output_rate=10.0), whole)
    gap_t = (boundary[1] - drive.t0_ns) * 1e-9
    assert np.any((whole.t > gap_t) & (whole.t < gap_t + 2.0))  # estimates inside the gap
    got = report.summary["filters"]["gps-ins"]
    for k, v in run._run_one(_job(path), None).summary["filters"]["gps-ins"].items():
        assert got[k] == (v if isinstance(v, dict | str) else
                          pytest.approx(v, rel=1e-12, abs=1e-12)), k


def test_a_gap_between_windows_longer_than_allowed_stops_both_runs_alike(
        drive, boundary, tmp_path) -> None:
    path = _gapped(drive, boundary[1], 3.0, tmp_path / "long.mcap")
    errors = []
    for fn in (run._run_streamed, run._run_one):
        with pytest.raises(ReplayError) as e, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fn(_job(path, max_imu_gap=2.5), None)
        errors.append(str(e.value))
    assert errors[0] == errors[1] and "--max-imu-gap" in errors[0]
    assert f"after t = {(boundary[1] - drive.t0_ns) * 1e-9:.3f} s" in errors[0]


def test_the_nominal_interval_of_a_short_first_window_is_that_of_the_whole_stream(
        drive) -> None:
    """The bridge ends one nominal interval (the median of the first window's) before the
    next sample: a first window of a few samples of a regular clock gives the bits of the
    whole stream."""
    imu = _without(drive[StreamKind.IMU], drive.t0_ns, 45.0, 45.4)
    rec = Recording({**drive.streams, StreamKind.IMU: imu}, drive.metadata, drive.t0_ns)
    whole = replay(rec, GpsInsFilter, {}, output_rate=10.0)
    for first in (12, 37, 401):
        session = ReplaySession(rec, GpsInsFilter, {}, output_rate=10.0)
        blocks = [session.feed(imu.slice(0, first)),
                  session.feed(imu.slice(first, len(imu)), final=True)]
        _assert_same(concat_results(blocks), whole)


# --------------------------------------------------------------------------------------------
# an aiding stream that pauses


@pytest.fixture(scope="module")
def paused(drive, tmp_path_factory) -> tuple[Recording, Path]:
    """The drive with no GPS fix (position and velocity) from 10 s to 50 s."""
    streams = dict(drive.streams)
    for kind in (StreamKind.GPS, StreamKind.GPS_VEL):
        streams[kind] = _without(streams[kind], drive.t0_ns, 10.0, 50.0)
    rec = Recording(streams, drive.metadata, drive.t0_ns)
    return rec, _write(rec, tmp_path_factory.mktemp("pause") / "pause.mcap")


def test_the_reader_knows_a_paused_stream_up_to_its_next_sample(paused) -> None:
    rec, path = paused
    gps = rec[StreamKind.GPS].t_ns
    resume = int(gps[np.searchsorted(gps, rec.t0_ns + 50 * 10**9)])
    during = [w for w in windows.read_windows(path, {StreamKind.IMU, StreamKind.GPS})
              if StreamKind.IMU in w and StreamKind.GPS not in w]
    assert len(during) >= 10  # windows of the pause
    for w in during:
        assert w.known[StreamKind.GPS] == resume - 1


def test_a_paused_aiding_stream_holds_no_imu_and_gives_the_whole_bits(paused) -> None:
    rec, path = paused
    whole = replay(read_recording(path), GpsInsFilter, {}, output_rate=10.0, validate=False)
    held: list[int] = []
    _assert_same(_streamed(path, held, output_rate=10.0), whole)
    per_window = max(np.diff(_imu_window_ends(path))) / 1e7  # IMU samples (100 Hz)
    assert max(held) <= per_window + 1  # not the 4000 samples of the pause


# --------------------------------------------------------------------------------------------
# frame checks: they say which span they averaged


def test_frame_check_notes_name_the_span_they_averaged(drive, boundary) -> None:
    """A streamed run checks the frames on its first window, a whole run on the whole log:
    each note says which."""
    path = boundary[0]
    first_end = (_imu_window_ends(path)[0] - drive.t0_ns) * 1e-9
    spans = []
    for fn in (run._run_streamed, run._run_one):
        (note,) = [n for n in fn(_job(path), None).notes
                   if "magnetometer dip sign agrees with the WMM" in n]
        found = re.search(r"averaged over t = ([\d.]+) to ([\d.]+) s\)", note)
        assert found is not None, note
        spans.append((float(found.group(1)), float(found.group(2))))
    assert spans[0][0] == spans[1][0] < 0.2
    assert spans[0][1] < first_end + 0.2 < 10.0  # the first window's magnetometer samples
    assert spans[1][1] == pytest.approx(60.0, abs=0.2)  # all of them
