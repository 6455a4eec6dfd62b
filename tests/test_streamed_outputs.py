"""``navreplay run --export DIR --report r.html`` and the live views on a file stream with the
replay: the exports are written block by block and are the very files of the whole run
(byte for byte), they read back (rosbags, a plain TUM parse, the CSV), an interrupted run
publishes nothing, the report's figures keep bounded envelopes of the series and quote the
summary's numbers, and a live view is logged block by block like the .rrd."""

from __future__ import annotations

import csv
import dataclasses
import importlib
import json
import os
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from navreplay.envelope import Envelope
from navreplay.io import mcapread
from navreplay.io.writer import write_recording
from navreplay.logs import prepare
from navreplay.replay.spec import FilterSpec
from navreplay.sim.scenario import simulate
from navreplay.viz.options import VizMode, VizOptions

run = importlib.import_module("navreplay.jobs.run")
FILTERS = (FilterSpec("ins", {}), FilterSpec("gps-ins", {}))


@pytest.fixture(scope="module")
def drive(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("streamed-outputs") / "drive.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 40.0}, seed=3))
    return path


def _job(path: Path, out: Path, **kw) -> run.RunJob:
    return run.RunJob(filters=FILTERS, recordings=(path,), viz=VizOptions(mode=VizMode.NONE),
                      export_dir=out / "export", report_path=out / "r.html", **kw)


@pytest.fixture(scope="module")
def both(drive, tmp_path_factory):
    """The same run streamed (small windows) and replayed whole."""
    d = tmp_path_factory.mktemp("runs")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(mcapread, "WINDOW_MESSAGES", 1500)
        read = []
        real = prepare.open_recording

        def counted(*a, **kw):
            return _counted(real(*a, **kw), read.append)

        mp.setattr(prepare, "open_recording", counted)
        from navreplay import figures

        shown = []
        real_figure = figures.consistency

        def capture(title, panels, color=figures.COLORS[0]):
            shown.extend(panels)
            return real_figure(title, panels, color)

        mp.setattr(figures, "consistency", capture)
        streamed = run._run_streamed(_job(drive, d / "streamed"), None)
    assert streamed is not None and len(read) >= 3
    # (the report is left out here: its envelopes do not depend on the blocks, tested below)
    whole = run._run_one(dataclasses.replace(_job(drive, d / "whole"), report_path=None), None)
    return d, streamed, whole, shown


def test_streamed_exports_are_the_files_of_the_whole_run(both) -> None:
    d, streamed, whole, _ = both
    a, b = d / "streamed" / "export", d / "whole" / "export"
    names = sorted(p.name for p in b.iterdir())
    assert names == sorted(p.name for p in a.iterdir()) == sorted(
        ["ins.csv", "ins.tum", "gps-ins.csv", "gps-ins.tum", "reference.tum", "estimates.mcap",
         "gps-ins.innovations.gps_pos.csv", "gps-ins.innovations.gps_vel.csv", "manifest.json"])
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (d / "streamed" / "r.html").stat().st_size > 10_000
    assert streamed.summary["filters"].keys() == whole.summary["filters"].keys()
    assert any(n.startswith("Exported 9 files") for n in streamed.notes)


def _csv(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return {h: np.array([float(r[i]) for r in rows[1:]]) for i, h in enumerate(rows[0])}


def _tum(path: Path) -> np.ndarray:
    rows = [line.split(" ") for line in path.read_text().splitlines() if not line.startswith("#")]
    assert all(len(r) == 8 for r in rows)
    return np.array(rows, dtype=float)


def test_streamed_exports_read_back(both, drive) -> None:
    d, *_ = both
    out = d / "streamed" / "export"
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["odometry"]["topics"] == [
        "/estimates/gps_ins/odom", "/estimates/ins/odom", "/reference/odom"]
    stamps: dict[str, list[int]] = {}
    order: list[int] = []
    with AnyReader([out / "estimates.mcap"]) as reader:
        for conn, stamp, raw in reader.messages():
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
    assert len(ref) == len(stamps["/reference/odom"]) > 3000
    np.testing.assert_allclose(ref[0, 1:4], 0.0, atol=1e-6)  # the origin is the first sample


def test_report_numbers_are_the_summary(both) -> None:
    """The fractions inside the chi-square bands on the figures are the summary's (the
    envelopes drawn do not hold every sample)."""
    _, streamed, _, shown = both
    summary = streamed.summary["filters"]["gps-ins"]
    inside = {p.title: p.inside for p in shown}
    assert inside["NEES (9 dof)"] == summary["nees_in_bounds"]
    assert inside["NIS gps_pos (3 dof)"] == summary["nis_in_bounds_gps_pos"]
    assert inside["NIS gps_vel (3 dof)"] == summary["nis_in_bounds_gps_vel"]


def test_an_interrupted_export_publishes_nothing(drive, tmp_path, monkeypatch) -> None:
    from navreplay.replay import streaming

    out = tmp_path / "export"
    out.mkdir()
    (out / "gps-ins.csv").write_text("kept\n")
    calls = []
    real = streaming.RunningSummary.add

    def failing(self, block):
        calls.append({p.name[1:p.name.index(f".{os.getpid()}@")]: p.stat().st_size
                      for p in out.glob(".*.part")})
        if len(calls) == 3:  # the files are being written: interrupt
            raise KeyboardInterrupt
        return real(self, block)

    monkeypatch.setattr(mcapread, "WINDOW_MESSAGES", 1500)
    monkeypatch.setattr(streaming.RunningSummary, "add", failing)
    job = run.RunJob(filters=(FilterSpec("gps-ins", {}),), recordings=(drive,),
                     viz=VizOptions(mode=VizMode.NONE), export_dir=out, force=True)
    with pytest.raises(KeyboardInterrupt):
        run._run_streamed(job, None)
    # the files were being written as the rows came: CSV, TUM, reference TUM, MCAP
    assert len(calls) == 3 and sorted(calls[-1]) == [
        "estimates.mcap", "gps-ins.csv", "gps-ins.innovations.gps_pos.csv",
        "gps-ins.innovations.gps_vel.csv", "gps-ins.tum", "reference.tum"]
    assert all(size > 1000 for name, size in calls[-1].items()  # (small ones: buffered)
               if ".innovations." not in name), calls[-1]
    assert [p.name for p in out.iterdir()] == ["gps-ins.csv"]  # no temporaries, no new files
    assert (out / "gps-ins.csv").read_text() == "kept\n"


def test_live_view_is_logged_block_by_block(drive, tmp_path, monkeypatch) -> None:
    import rerun as rr

    from navreplay.viz import Connect
    from navreplay.viz.sink import Sink
    from tests.test_viz import read_rrd

    live = tmp_path / "live.rrd"

    def viewer(viz_options, default, name):  # a live sink whose viewer is a file
        rec = rr.RecordingStream("navreplay", recording_id="live-test")
        rec.save(live)
        return Sink(rec, Connect("rerun+http://127.0.0.1:1/proxy"), url="test viewer")

    monkeypatch.setattr(mcapread, "WINDOW_MESSAGES", 1500)
    spec = (FilterSpec("gps-ins", {}),)
    saved = run._run_streamed(run.RunJob(filters=spec, recordings=(drive,), viz=VizOptions(
        mode=VizMode.SAVE, path=tmp_path / "saved.rrd")), None)
    monkeypatch.setattr(run, "open_output", viewer)
    report = run._run_streamed(run.RunJob(filters=spec, recordings=(drive,),
                                          viz=VizOptions(mode=VizMode.CONNECT)), None)
    assert saved is not None and report is not None and "test viewer" in report.viz
    a, b = read_rrd(live), read_rrd(tmp_path / "saved.rrd")
    assert sorted(a) == sorted(b) and "/gps-ins/error/p_N" in a
    for entity in b:
        if entity != "static":
            for col in b[entity]:
                np.testing.assert_array_equal(a[entity][col], b[entity][col])


# --------------------------------------------------------------------------------------------
# envelopes


def test_envelope_keeps_every_extreme_in_bounded_memory() -> None:
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 86_400.0, 0.1)  # a day at 10 Hz
    v = np.cumsum(rng.normal(size=t.size))
    v[123_456] = np.nan
    whole = Envelope(bins=500)
    whole.add(t, v)
    split = Envelope(bins=500)
    cuts = np.sort(rng.choice(t.size, size=300, replace=False))
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, t.size], strict=True):
        split.add(t[a:b], v[a:b])
    tw, vw = whole.points()
    ts, vs = split.points()
    np.testing.assert_array_equal(tw, ts)
    np.testing.assert_array_equal(vw, vs)
    assert 1000 <= len(tw) <= 2000 and whole.count == t.size - 1
    assert np.all(np.diff(tw) > 0)
    # per bin of the final width: its minimum and maximum, at the time they occurred
    ok = np.isfinite(v)
    idx = np.floor(t[ok] / whole.width).astype(int)
    lo = np.full(idx.max() + 1, np.inf)
    hi = np.full(idx.max() + 1, -np.inf)
    np.minimum.at(lo, idx, v[ok])
    np.maximum.at(hi, idx, v[ok])
    assert set(vw) == set(lo) | set(hi)
    at = dict(zip(t[ok], v[ok], strict=True))
    assert all(at[ti] == vi for ti, vi in zip(tw, vw, strict=True))


def test_envelope_of_a_short_series_is_the_series() -> None:
    t = np.arange(0.0, 100.0, 0.1)
    v = np.sin(t)
    e = Envelope()
    e.add(t[:400], v[:400])
    e.add(t[400:], v[400:])
    got_t, got_v = e.points()
    np.testing.assert_array_equal(got_t, t)
    np.testing.assert_array_equal(got_v, v)


def _counted(source, seen):
    """The source, each window it hands out passed to ``seen`` first."""
    windows = source._windows

    def counting():
        for w in windows():
            seen(w)
            yield w

    source._windows = counting
    return source
