"""A recording as a source of windows: ``open_recording`` decides a file's kind once and opens it
once; the windows of an intact MCAP file hold, joined, the streams of the file read in one; a
damaged file, a rosbag2 bag and a recording in memory are one window; a topic keeps the time
base its first window chose."""

from __future__ import annotations

import builtins
import dataclasses
import warnings

import numpy as np
import pytest
from mcap_edits import write_small_chunks as _write
from mcap_edits import zero_imu_stamps as _zero_imu_stamps

from navreplay.core.streams import StreamKind
from navreplay.io import ReadOptions, files, mcapread, open_recording, read_recording, rosbag
from navreplay.io import source as source_module
from navreplay.io.errors import RecordingError
from navreplay.io.source import COMPLETE, MemorySource
from navreplay.sim.scenario import simulate


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    rec = simulate("vehicle-drive", {"duration": 40.0}, seed=3)
    return rec, _write(rec, tmp_path_factory.mktemp("source") / "drive.mcap")


def _windows(path, window: int, **kw) -> list:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(source_module, "WINDOW_MESSAGES", window)
        with open_recording(path, ReadOptions(**kw)) as source:
            return list(source)


def test_windows_joined_are_the_file_read_in_one(drive) -> None:
    rec, path = drive
    windows = _windows(path, 150)
    assert len(windows) >= 10 and windows[-1].final and not windows[0].final
    assert set(windows[0]) == set(rec.streams)  # the first window holds every stream read
    whole = read_recording(path)
    for kind, stream in whole.streams.items():
        parts = [w[kind] for w in windows if kind in w]
        np.testing.assert_array_equal(np.concatenate([p.t_ns for p in parts]), stream.t_ns)
        for name, col in stream.columns.items():
            np.testing.assert_array_equal(np.concatenate([p[name] for p in parts]), col)
    # each stream is known up to its last sample so far, complete at the end
    for w in windows[:-1]:
        for kind, t in w.known.items():
            assert t == COMPLETE or kind not in w or t >= int(w[kind].t_ns[-1])
    assert set(windows[-1].known.values()) == {COMPLETE}
    assert all(w.t0_ns == whole.t0_ns and w.metadata == whole.metadata for w in windows)


def test_the_file_is_opened_once_and_its_kind_decided_once(drive, monkeypatch) -> None:
    _, path = drive
    opened, asked = [], []
    real_open = builtins.open

    def counting_open(file, *a, **kw):
        if str(file) == str(path):
            opened.append(file)
        return real_open(file, *a, **kw)

    monkeypatch.setattr(mcapread, "open", counting_open, raising=False)
    monkeypatch.setattr(files, "FILE_KINDS", tuple(
        dataclasses.replace(k, accepts=_counting(k.accepts, asked, k.name))
        for k in files.FILE_KINDS))
    windows = _windows(path, 150)
    assert len(windows) >= 10 and len(opened) == 1
    assert asked == ["rosbag1", "gins", "ulog", "rosbag2", "mcap"]  # each asked once, in order


def _counting(fn, seen: list, name: str):
    def accepts(p):
        seen.append(name)
        return fn(p)

    return accepts


def test_a_damaged_file_is_one_window(drive, tmp_path) -> None:
    _, path = drive
    cut = tmp_path / "cut.mcap"
    data = path.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    with warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        source = open_recording(cut)
        windows = list(source)
        source.close()
    assert len(windows) == 1 and windows[0].final
    assert source.salvaged and 0.3 < source.coverage() < 0.7
    assert any("salvaged" in str(w.message) for w in ws)


def test_a_recording_in_memory_is_one_window(drive) -> None:
    rec, _ = drive
    source = MemorySource(rec)
    (window,) = list(source)
    assert window.final and window.recording().streams == rec.streams
    assert source.name == "vehicle-drive#seed=3" and source.coverage() == 1.0


def test_kinds_of_files(tmp_path) -> None:
    (tmp_path / "bag").mkdir()
    assert files.file_kind(tmp_path / "bag").name == "rosbag2"
    assert files.file_kind(tmp_path / "x.db3").name == "rosbag2"
    assert files.file_kind(tmp_path / "x.mcap").name == "mcap"
    assert rosbag.accepts(tmp_path / "bag" / "metadata.yaml")
    with pytest.raises(RecordingError, match="no such file"):
        open_recording(tmp_path / "missing.mcap")


def test_the_time_base_a_topic_starts_with_holds_for_all_its_windows(drive, tmp_path) -> None:
    """Stamps unusable in the first windows: every window takes the log times, as a read in
    one window does for the whole topic (not the stamps of the later windows)."""
    rec, plain = drive
    t0 = int(rec[StreamKind.IMU].t_ns[0])
    path = tmp_path / "late.mcap"
    _zero_imu_stamps(plain, path, at=-(t0 + 5_000_000_000), latency=3_000_000)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = read_recording(path)
        parts = [w[StreamKind.IMU].t_ns for w in _windows(path, 150, kinds={StreamKind.IMU})
                 if StreamKind.IMU in w]
    assert len(parts) >= 10
    np.testing.assert_array_equal(np.concatenate(parts), whole[StreamKind.IMU].t_ns)
    np.testing.assert_array_equal(whole[StreamKind.IMU].t_ns, rec[StreamKind.IMU].t_ns + 3_000_000)


def test_a_log_opened_to_draw_reads_longer_windows(drive) -> None:
    """``open_log(window=...)`` sets the messages per window (a run that draws the view asks
    for :data:`navreplay.viz.options.DRAWN_WINDOW_MESSAGES`); without it the reader's own."""
    from navreplay.logs.prepare import open_log
    from navreplay.viz.options import DRAWN_WINDOW_MESSAGES, VizMode, VizOptions

    _, path = drive
    assert DRAWN_WINDOW_MESSAGES > source_module.WINDOW_MESSAGES
    assert VizOptions().draws and not VizOptions(mode=VizMode.NONE).draws

    def imu_lengths(**kw) -> list[int]:
        with open_log(path, **kw) as source:
            return [len(w[StreamKind.IMU]) for w in source if StreamKind.IMU in w]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(source_module, "WINDOW_MESSAGES", 500)
        short = imu_lengths()
        long = imu_lengths(window=2000)
    assert sum(short) == sum(long) == 4000  # 40 s of 100 Hz
    # a window closes at the end of the chunk in which a stream reaches its count
    assert max(short) < 1000 and len(short) >= 6
    assert max(long) >= 2000 and len(long) <= 2
