"""``navreplay run`` through the one pipeline (:func:`navreplay.replay.replay_file`): a file read
in many windows and the same file read in one give the same summaries, the same exports (byte
for byte), the same .rrd and the same report numbers; the exports read back; an interrupted run
publishes nothing; a live view is logged as the saved .rrd; the reader's warnings come once per
run; a gap between two windows is the gap it is inside one; an aiding stream that pauses does
not make the replay hold the IMU samples of the pause."""

from __future__ import annotations

import csv
import dataclasses
import importlib
import json
import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap_edits import write_small_chunks as _write
from mcap_edits import zero_imu_stamps as _zero_imu_stamps
from rosbags.highlevel import AnyReader
from rrd import read_rrd

from navreplay.core.streams import Recording, Stream, StreamKind
from navreplay.io import ReadOptions, open_recording, read_recording, source
from navreplay.io.errors import RecordingError, RecordingWarning
from navreplay.logs.options import LogOptions
from navreplay.replay import FilterSpec, ReplayError
from navreplay.sim.scenario import simulate
from navreplay.viz.options import VizMode, VizOptions

run_job = importlib.import_module("navreplay.jobs.run")
FILTERS = (FilterSpec("ins", {}), FilterSpec("gps-ins", {}))
ONE = 10**9  # messages of a window: the whole file in one


@pytest.fixture(scope="module")
def drive_rec() -> Recording:
    return simulate("vehicle-drive", {"duration": 40.0}, seed=3)


@pytest.fixture(scope="module")
def drive(drive_rec, tmp_path_factory) -> Path:
    return _write(drive_rec, tmp_path_factory.mktemp("pipeline") / "drive.mcap")


def _run(path: Path, window: int, filters=FILTERS, **kw):
    """``navreplay run`` over ``path`` read in windows of ``window`` messages of a stream; the
    report and the warnings of the run."""
    job = run_job.RunJob(filters=filters, recordings=(path,), **kw)
    with pytest.MonkeyPatch.context() as mp, warnings.catch_warnings(record=True) as ws:
        mp.setattr(source, "WINDOW_MESSAGES", window)
        warnings.simplefilter("always")
        report = run_job.run(job)
    return report, [str(w.message) for w in ws if issubclass(w.category, RecordingWarning)]


def _windows(path: Path, window: int) -> int:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(source, "WINDOW_MESSAGES", window)
        return sum(1 for _ in open_recording(path, ReadOptions(kinds={StreamKind.IMU})))


def _same_summaries(a: dict, b: dict) -> None:
    """The numbers to rounding (sums run in other chunks), the settings entries exactly."""
    assert a.keys() == b.keys()
    for label in a:
        assert a[label].keys() == b[label].keys(), label
        for k, v in b[label].items():
            assert a[label][k] == (v if isinstance(v, dict | str) else
                                   pytest.approx(v, rel=1e-12, abs=1e-12)), (label, k)


@pytest.fixture(scope="module")
def both(drive, tmp_path_factory):
    """The run in windows of 1500 messages and in one window: exports, .rrd, report."""
    d = tmp_path_factory.mktemp("runs")
    from navreplay.viz import figures

    shown: list = []
    real = figures.consistency

    def capture(title, panels, color=figures.COLORS[0]):
        shown.extend(panels)
        return real(title, panels, color)

    out = {}
    for name, window in (("windows", 1500), ("one", ONE)):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(figures, "consistency", capture)
            out[name], _ = _run(drive, window, export_dir=d / name / "export",
                                report_path=d / name / "r.html",
                                viz=VizOptions(mode=VizMode.SAVE, path=d / name / "v.rrd"))
    assert _windows(drive, 1500) >= 3
    return d, out, shown


def test_windows_and_one_window_give_the_same_outputs(both) -> None:
    d, out, _ = both
    _same_summaries(out["windows"].summary["filters"], out["one"].summary["filters"])
    assert {"pos_rms_h", "nees_mean", "distance", "settings", "reference_coverage"} <= out[
        "one"].summary["filters"]["gps-ins"].keys()
    a, b = d / "windows" / "export", d / "one" / "export"
    names = sorted(p.name for p in b.iterdir())
    assert names == sorted(p.name for p in a.iterdir()) == sorted(
        ["ins.csv", "ins.tum", "gps-ins.csv", "gps-ins.tum", "reference.tum", "estimates.mcap",
         "estimates.foxglove-layout.json", "gps-ins.innovations.gps_pos.csv",
         "gps-ins.innovations.gps_vel.csv", "manifest.json"])
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert any(n.startswith("Exported 10 files") for n in out["windows"].notes)
    assert (d / "windows" / "r.html").stat().st_size > 10_000


def test_windows_and_one_window_give_the_same_rrd(both) -> None:
    d, _, _ = both
    a, b = read_rrd(d / "windows" / "v.rrd"), read_rrd(d / "one" / "v.rrd")
    assert sorted(a) == sorted(b)
    assert {"/gps-ins/error/p_N", "/gps-ins/nees", "/truth/nav/yaw",
            "/gps-ins/innovation/gps_pos/nis", "/world/gps-ins/covariance"} <= a.keys()
    for entity in b:
        if entity == "static":
            continue
        assert a[entity].keys() == b[entity].keys(), entity
        for col in b[entity]:
            np.testing.assert_allclose(a[entity][col], b[entity][col], rtol=1e-12, atol=1e-12,
                                       err_msg=f"{entity} {col}")
    assert sorted(a["static"]) == sorted(b["static"])


def test_report_numbers_are_the_summary(both) -> None:
    """The fractions inside the chi-square bands on the figures are the summary's (the
    envelopes drawn do not hold every sample)."""
    _, out, shown = both
    summary = out["windows"].summary["filters"]["gps-ins"]
    inside = {p.title: p.inside for p in shown[:len(shown) // 2]}
    assert inside["NEES (9 dof)"] == summary["nees_in_bounds"]
    assert inside["NIS gps_pos (3 dof)"] == summary["nis_in_bounds_gps_pos"]
    assert inside["NIS gps_vel (3 dof)"] == summary["nis_in_bounds_gps_vel"]


def _csv(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return {h: np.array([float(r[i]) for r in rows[1:]]) for i, h in enumerate(rows[0])}


def _tum(path: Path) -> np.ndarray:
    rows = [line.split(" ") for line in path.read_text().splitlines() if not line.startswith("#")]
    assert all(len(r) == 8 for r in rows)
    return np.array(rows, dtype=float)


def test_exports_read_back(both) -> None:
    d, _, _ = both
    out = d / "windows" / "export"
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["odometry"]["topics"] == [
        "/estimates/gps_ins/odom", "/estimates/ins/odom", "/reference/odom"]
    stamps: dict[str, list[int]] = {}
    order: list[int] = []
    with AnyReader([out / "estimates.mcap"]) as reader:
        odometry = [c for c in reader.connections if c.msgtype == "nav_msgs/msg/Odometry"]
        for conn, stamp, raw in reader.messages(connections=odometry):
            msg = reader.deserialize(raw, conn.msgtype)
            assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == stamp
            stamps.setdefault(conn.topic, []).append(stamp)
            order.append(stamp)
    assert order == sorted(order)
    for label in ("ins", "gps-ins"):
        table = _csv(out / f"{label}.csv")
        tum = _tum(out / f"{label}.tum")
        topic = manifest["filters"][label]["odometry_topic"]
        n = len(table["stamp [ns]"])
        assert n > 300 and len(tum) == n == len(stamps[topic])
        np.testing.assert_array_equal(np.array(stamps[topic]), table["stamp [ns]"].astype(np.int64))
        np.testing.assert_allclose(tum[:, 0], table["stamp [ns]"] * 1e-9, rtol=0, atol=1e-6)
        for i, axis in enumerate(("east", "north", "up")):
            np.testing.assert_allclose(tum[:, 1 + i], table[f"{axis} [m]"], atol=6e-5)
        assert np.all(np.diff(tum[:, 0]) > 0)
    ref = _tum(out / "reference.tum")
    assert len(ref) == len(stamps["/reference/odom"]) > 300
    # at the output rate (10 Hz): beside each estimate of the grid
    t_ref = np.array(stamps["/reference/odom"])
    np.testing.assert_array_equal(np.diff(t_ref), 100_000_000)
    t_est = np.array(stamps[manifest["filters"]["gps-ins"]["odometry_topic"]])
    grid = t_est[(t_est - t_ref[0]) % 100_000_000 == 0]
    assert len(grid) > 300 and np.isin(grid, t_ref).all()
    np.testing.assert_allclose(ref[0, 1:4], 0.0, atol=1e-6)  # the origin is the first sample


def test_an_interrupted_export_publishes_nothing(drive, tmp_path, monkeypatch) -> None:
    from navreplay.metrics import scoring

    out = tmp_path / "export"
    out.mkdir()
    (out / "gps-ins.csv").write_text("kept\n")
    calls = []
    real = scoring.RunScorer.add

    def failing(self, block):
        calls.append({p.name[1:p.name.index(f".{os.getpid()}@")]: p.stat().st_size
                      for p in out.glob(".*.part")})
        if len(calls) == 3:  # the files are being written: interrupt
            raise KeyboardInterrupt
        return real(self, block)

    monkeypatch.setattr(scoring.RunScorer, "add", failing)
    with pytest.raises(KeyboardInterrupt):
        # at the IMU rate: an MCAP chunk (1 MB) fills in the first windows
        _run(drive, 1500, filters=(FilterSpec("gps-ins"),), viz=VizOptions(mode=VizMode.NONE),
             export_dir=out, force=True, output_rate=100.0)
    # the files were being written as the rows came: CSV, TUM, reference TUM, MCAP
    assert len(calls) == 3 and sorted(calls[-1]) == [
        "estimates.mcap", "gps-ins.csv", "gps-ins.innovations.gps_pos.csv",
        "gps-ins.innovations.gps_vel.csv", "gps-ins.tum", "reference.tum"]
    assert all(size > 1000 for name, size in calls[-1].items()  # (small ones: buffered)
               if ".innovations." not in name), calls[-1]
    assert [p.name for p in out.iterdir()] == ["gps-ins.csv"]  # no temporaries, no new files
    assert (out / "gps-ins.csv").read_text() == "kept\n"


def test_live_view_is_logged_as_the_saved_rrd(drive, tmp_path, monkeypatch) -> None:
    import rerun as rr

    from navreplay.viz import Connect
    from navreplay.viz.sink import Sink

    live = tmp_path / "live.rrd"

    def viewer(viz_options, default, name):  # a live sink whose viewer is a file
        rec = rr.RecordingStream("navreplay", recording_id="live-test")
        rec.save(live)
        return Sink(rec, Connect("rerun+http://127.0.0.1:1/proxy"), url="test viewer")

    spec = (FilterSpec("gps-ins"),)
    saved, _ = _run(drive, 1500, filters=spec,
                    viz=VizOptions(mode=VizMode.SAVE, path=tmp_path / "saved.rrd"))
    monkeypatch.setattr(run_job, "open_output", viewer)
    report, _ = _run(drive, 1500, filters=spec, viz=VizOptions(mode=VizMode.CONNECT))
    assert "test viewer" in report.viz
    a, b = read_rrd(live), read_rrd(tmp_path / "saved.rrd")
    assert sorted(a) == sorted(b) and "/gps-ins/error/p_N" in a
    for entity in b:
        if entity != "static":
            for col in b[entity]:
                np.testing.assert_array_equal(a[entity][col], b[entity][col])


# --------------------------------------------------------------------------------------------
# the reader's warnings, once per run


GPS_INS = (FilterSpec("gps-ins"),)
NO_VIZ = VizOptions(mode=VizMode.NONE)


def test_a_warning_is_given_once_per_run_with_the_windows_it_concerns(drive, tmp_path) -> None:
    path = tmp_path / "zero.mcap"
    _zero_imu_stamps(drive, path)
    _, messages = _run(path, 150, filters=GPS_INS, viz=NO_VIZ)
    zero = [m for m in messages if "header stamps are zero" in m]
    assert len(zero) == 1, messages
    n = _windows(path, 150)
    assert n >= 10 and str(path) in zero[0] and "topic /imu" in zero[0]
    assert re.search(rf"the same in {n} of the \d+ windows of the read", zero[0]), zero[0]
    # the first window's count; the whole stream's when read in one
    _, whole = _run(path, ONE, filters=GPS_INS, viz=NO_VIZ)
    count = int(re.search(r"(\d+) header stamps are zero", zero[0]).group(1))
    total = int(re.search(r"(\d+) header stamps are zero",
                          next(m for m in whole if "header stamps" in m)).group(1))
    assert 0 < count < total == 4000


def test_stamps_that_turn_unusable_after_windows_used_them_are_refused(drive, drive_rec,
                                                                      tmp_path) -> None:
    """The windows already replayed cannot move to log times: one line naming the topic, the
    time and ``--time log``, which then replays the file on one time base."""
    t0 = int(drive_rec[StreamKind.IMU].t_ns[0])
    path = tmp_path / "turns.mcap"
    _zero_imu_stamps(drive, path, at=t0 + 30_000_000_000, latency=3_000_000)
    with pytest.raises(RecordingError) as err:
        _run(path, 150, filters=GPS_INS, viz=NO_VIZ)
    text = str(err.value)
    assert str(path) in text and "topic /imu" in text and "--time log" in text
    assert "t = 30." in text, text
    report, _ = _run(path, 150, filters=GPS_INS, viz=NO_VIZ, log=LogOptions(time="log"))
    assert report.summary["filters"]["gps-ins"]["duration"] > 39.0


# --------------------------------------------------------------------------------------------
# gaps and pauses across window boundaries


def _without(stream: Stream, t0_ns: int, lo: float, hi: float) -> Stream:
    t = (stream.t_ns - t0_ns) * 1e-9
    keep = (t <= lo) | (t > hi)
    return dataclasses.replace(stream, t_ns=stream.t_ns[keep],
                               columns={k: v[keep] for k, v in stream.columns.items()})


def _imu_window_ends(path: Path, window: int) -> list[int]:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(source, "WINDOW_MESSAGES", window)
        return [int(w[StreamKind.IMU].t_ns[-1])
                for w in open_recording(path, ReadOptions(kinds={StreamKind.IMU}))
                if StreamKind.IMU in w and len(w[StreamKind.IMU])]


def _gapped(rec: Recording, drive: Path, seconds: float, path: Path) -> tuple[Path, float]:
    """The drive with no IMU sample for ``seconds`` after the end of a window in its middle."""
    ends = _imu_window_ends(drive, 150)
    end_ns = ends[len(ends) // 2]
    lo = (end_ns - rec.t0_ns) * 1e-9 + 1e-6
    imu = _without(rec[StreamKind.IMU], rec.t0_ns, lo, lo + seconds)
    _write(Recording({**rec.streams, StreamKind.IMU: imu}, rec.metadata, rec.t0_ns), path)
    assert end_ns in _imu_window_ends(path, 150)  # the gap is between two windows
    return path, (end_ns - rec.t0_ns) * 1e-9


def test_a_gap_between_windows_is_reported_and_bridged_as_inside_one(
        drive_rec, drive, tmp_path) -> None:
    path, gap_t = _gapped(drive_rec, drive, 2.0, tmp_path / "gap.mcap")
    one, whole_lines = _run(path, ONE, filters=GPS_INS, viz=NO_VIZ)
    gap_lines = [m for m in whole_lines if "gap(s)" in m]
    assert len(gap_lines) == 1 and "topic /imu" in gap_lines[0]
    windows, lines = _run(path, 150, filters=GPS_INS, viz=NO_VIZ)
    assert [m for m in lines if "gap(s)" in m] == gap_lines  # the same line, once
    _same_summaries(windows.summary["filters"], one.summary["filters"])


def test_a_gap_between_windows_longer_than_allowed_stops_both_runs_alike(
        drive_rec, drive, tmp_path) -> None:
    path, gap_t = _gapped(drive_rec, drive, 3.0, tmp_path / "long.mcap")
    errors = []
    for window in (150, ONE):
        with pytest.raises(ReplayError) as e:
            _run(path, window, filters=GPS_INS, viz=NO_VIZ, max_imu_gap=2.5)
        errors.append(str(e.value))
    assert errors[0] == errors[1] and "--max-imu-gap" in errors[0]
    assert f"after t = {gap_t:.3f} s" in errors[0]


def test_a_paused_aiding_stream_holds_no_imu(drive_rec, tmp_path, monkeypatch) -> None:
    """No GPS fix from 10 s to 30 s: the reader says how far the paused stream is known (just
    before its next fix, read ahead in the chunk index), so the session applies the IMU
    windows of the pause instead of holding them; the run is that of one window."""
    from navreplay.replay.session import ReplaySession

    streams = dict(drive_rec.streams)
    for kind in (StreamKind.GPS, StreamKind.GPS_VEL):
        streams[kind] = _without(streams[kind], drive_rec.t0_ns, 10.0, 30.0)
    rec = Recording(streams, drive_rec.metadata, drive_rec.t0_ns)
    path = _write(rec, tmp_path / "pause.mcap")
    gps = rec[StreamKind.GPS].t_ns
    resume = int(gps[np.searchsorted(gps, rec.t0_ns + 30 * 10**9)])
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(source, "WINDOW_MESSAGES", 150)
        during = [
            w for w in open_recording(path, ReadOptions(kinds={StreamKind.IMU, StreamKind.GPS}))
            if StreamKind.IMU in w and StreamKind.GPS not in w
        ]
    assert len(during) >= 5 and all(w.known[StreamKind.GPS] == resume - 1 for w in during)
    held: list[int] = []
    real = ReplaySession.feed

    def feed(self, *a, **kw):
        out = real(self, *a, **kw)
        held.append(0 if self._pending is None else len(self._pending[0]))
        return out

    monkeypatch.setattr(ReplaySession, "feed", feed)
    windows, _ = _run(path, 150, filters=GPS_INS, viz=NO_VIZ)
    per_window = max(np.diff(_imu_window_ends(path, 150))) / 1e7  # IMU samples (100 Hz)
    assert max(held) <= per_window + 1  # not the 2000 samples of the pause
    one, _ = _run(path, ONE, filters=GPS_INS, viz=NO_VIZ)
    _same_summaries(windows.summary["filters"], one.summary["filters"])


def test_frame_check_notes_name_the_span_they_averaged(drive) -> None:
    """A run checks the frames on its first window: the note says which span it averaged (all
    of the log when it is one window)."""
    first_end = (_imu_window_ends(drive, 150)[0] - read_recording(drive).t0_ns) * 1e-9
    spans = []
    for window in (150, ONE):
        report, _ = _run(drive, window, filters=GPS_INS, viz=NO_VIZ)
        (note,) = [n for n in report.notes if "magnetometer dip sign agrees with the WMM" in n]
        found = re.search(r"averaged over t = ([\d.]+) to ([\d.]+) s\)", note)
        assert found is not None, note
        spans.append((float(found.group(1)), float(found.group(2))))
    assert spans[0][0] == spans[1][0] < 0.2
    assert spans[0][1] < first_end + 0.2 < 10.0  # the first window's magnetometer samples
    assert spans[1][1] == pytest.approx(40.0, abs=0.2)  # all of them


def test_pieces_of_a_window_give_the_estimates_of_the_whole(monkeypatch) -> None:
    """At a high output rate a window is replayed in pieces: the estimates, covariances and
    innovations are those of the window replayed at once, bit for bit."""
    from navreplay.io.source import MemorySource
    from navreplay.replay import pipeline

    rec = simulate("vehicle-drive", {"duration": 40.0}, seed=3)

    def run(pieces: int) -> dict:
        monkeypatch.setattr(pipeline, "PIECE_OUTPUTS", pieces)
        collect = pipeline.Collect()
        pipeline.replay_file(MemorySource(rec, "drive"), [FilterSpec("gps-ins")],
                             stages=[collect], output_rate=100.0, score=False)
        return collect.results()

    whole, cut = run(10**9), run(700)  # 7-second pieces, cuts between GPS fixes
    a, b = whole["gps-ins"], cut["gps-ins"]
    assert a.t.shape[0] > 3000
    for name in ("t", "x", "P", "nav_pos", "nav_v_n", "nav_q_nb"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert sorted(a.innovations) == sorted(b.innovations)
    for k, s in a.innovations.items():
        assert np.array_equal(s.nu, b.innovations[k].nu) and np.array_equal(s.t,
                                                                            b.innovations[k].t)


def test_a_stage_may_ask_for_longer_pieces() -> None:
    """A stage's ``piece_outputs`` (the view's) lengthens the pieces for every stage of the run;
    the replay's own least stays the floor for a stage that asks for less."""
    from navreplay.io.source import MemorySource
    from navreplay.replay import pipeline

    rec = simulate("vehicle-drive", {"duration": 40.0}, seed=3)

    class Counting(pipeline.Collect):
        def __init__(self, piece_outputs: int | None) -> None:
            super().__init__(whole=False)
            if piece_outputs is not None:
                self.piece_outputs = piece_outputs
            self.blocks: list[int] = []

        def rows(self, rows, metrics, truth) -> None:  # type: ignore[no-untyped-def]
            super().rows(rows, metrics, truth)
            self.blocks.append(len(rows.t))

    def blocks(*asks: int | None) -> list[list[int]]:
        stages = [Counting(a) for a in asks]
        pipeline.replay_file(MemorySource(rec, "drive"), [FilterSpec("gps-ins")],
                             stages=stages, output_rate=100.0, score=False)
        return [s.blocks for s in stages]

    (least,) = blocks(None)
    longer, plain = blocks(2500, None)
    assert longer == plain  # every stage gets the same blocks
    assert sum(least) == sum(longer) > 3000
    assert max(least) <= pipeline.PIECE_OUTPUTS + 1 < max(longer) <= 2501
    assert len(longer) < len(least)
    assert blocks(10) == [least]  # less than the floor asks for nothing
    whole = pipeline.Collect()  # the in-memory replay's: the window in one piece
    pipeline.replay_file(MemorySource(rec, "drive"), [FilterSpec("gps-ins")], stages=[whole],
                         output_rate=100.0, score=False)
    (joined,) = whole._rows.values()
    assert [len(b.t) for b in joined] == [sum(least)]
