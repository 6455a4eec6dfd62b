"""A replay fed its IMU in windows (what ``navreplay run`` does on files) makes exactly the
filter calls of a replay of the whole recording: the same bits, window sizes notwithstanding,
also across an IMU gap and with aiding samples after the last IMU sample."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.replay import replay
from navreplay.replay.engine import ReplaySession
from navreplay.replay.result import RunResult
from navreplay.replay.streaming import concat_results
from navreplay.sim.scenario import simulate
from navreplay.streams import Recording, StreamKind


@pytest.fixture(scope="module")
def drive() -> Recording:
    return simulate("vehicle-drive", {"duration": 60.0}, seed=5)


def _windows(rec: Recording, cls: type, params: dict, sizes: list[int], **kw) -> RunResult:
    imu = rec[StreamKind.IMU]
    session = ReplaySession(rec, cls, params, **kw)
    blocks, a = [], 0
    for k, n in enumerate(sizes):
        b = len(imu) if k == len(sizes) - 1 else min(a + n, len(imu))
        blocks.append(session.feed(imu.slice(a, b), final=k == len(sizes) - 1))
        a = b
    return concat_results(blocks)


def _assert_same(a: RunResult, b: RunResult) -> None:
    assert a.t.shape == b.t.shape and a.t.shape[0] > 100
    for name in ("t", "x", "P", "nav_pos", "nav_v_n", "nav_q_nb"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.innovations.keys() == b.innovations.keys()
    for k in a.innovations:
        np.testing.assert_array_equal(a.innovations[k].t, b.innovations[k].t, err_msg=k)
        np.testing.assert_array_equal(a.innovations[k].nu, b.innovations[k].nu, err_msg=k)


@pytest.mark.parametrize("filter_cls", [GpsInsFilter, InsFilter])
def test_windows_give_the_bits_of_the_whole_replay(drive: Recording, filter_cls: type) -> None:
    whole = replay(drive, filter_cls, {}, output_rate=10.0)
    rng = np.random.default_rng(1)
    sizes = [int(s) for s in rng.integers(1, 700, size=40)]  # windows of 1 to 699 samples
    _assert_same(_windows(drive, filter_cls, {}, sizes, output_rate=10.0), whole)


def test_windows_across_an_imu_gap(drive: Recording) -> None:
    imu = drive[StreamKind.IMU]
    t = (imu.t_ns - imu.t_ns[0]) * 1e-9
    keep = (t < 20.0) | (t > 20.45)  # a bridged gap with GPS samples and ticks inside
    gapped = dataclasses.replace(imu, t_ns=imu.t_ns[keep],
                                 columns={k: v[keep] for k, v in imu.columns.items()})
    rec = Recording({**drive.streams, StreamKind.IMU: gapped}, drive.metadata, drive.t0_ns)
    whole = replay(rec, GpsInsFilter, {}, output_rate=20.0)
    cut = int(np.searchsorted(t[keep], 20.0))  # a window ends at the last sample before it
    sizes = [cut - 7, 7, 150, 3, 10_000]
    _assert_same(_windows(rec, GpsInsFilter, {}, sizes, output_rate=20.0), whole)


def test_a_window_without_samples_applies_nothing(drive: Recording) -> None:
    imu = drive[StreamKind.IMU]
    session = ReplaySession(drive, GpsInsFilter, {})
    first = session.feed(imu.slice(0, 500))
    assert first.t.size and first.t[-1] <= (imu.t_ns[499] - drive.t0_ns) * 1e-9
    assert session.feed(imu.slice(500, 500)).t.size == 0
    rest = session.feed(imu.slice(500, len(imu)), final=True)
    assert rest.t[0] > first.t[-1]


def test_run_on_a_file_streams_and_scores_as_the_whole_run(
    drive: Recording, tmp_path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    import importlib

    from navreplay.io import windows
    from navreplay.io.writer import write_recording
    from navreplay.replay.ensemble import FilterSpec
    from navreplay.viz.options import VizMode, VizOptions

    run = importlib.import_module("navreplay.jobs.run")
    path = tmp_path / "drive.mcap"
    write_recording(path, drive)
    job = run.RunJob(filters=(FilterSpec("gps-ins", {}),), recordings=(path,),
                     viz=VizOptions(mode=VizMode.NONE))
    read = []
    real = windows.read_windows

    def counted(*a, **kw):
        for w in real(*a, **kw):
            read.append(len(w[StreamKind.IMU]) if StreamKind.IMU in w else 0)
            yield w

    monkeypatch.setattr(windows, "WINDOW_MESSAGES", 700)
    monkeypatch.setattr(windows, "read_windows", counted)
    streamed = run._run_streamed(job, None)
    assert streamed is not None and len(read) >= 3 and max(read) < 2500  # chunk by chunk
    whole = run._run_one(job, None).summary["filters"]["gps-ins"]
    got = streamed.summary["filters"]["gps-ins"]
    assert got.keys() == whole.keys() and {"pos_rms_h", "nees_mean", "distance"} <= got.keys()
    for k, v in whole.items():
        assert got[k] == pytest.approx(v, rel=1e-12, abs=1e-12), k


def test_paced_replay_reads_the_whole_file(drive: Recording, tmp_path) -> None:
    """Live views and exports stream (tests/test_streamed_outputs.py); a paced replay does not."""
    import importlib

    from navreplay.io.writer import write_recording
    from navreplay.replay.ensemble import FilterSpec
    from navreplay.viz.options import VizMode, VizOptions

    run = importlib.import_module("navreplay.jobs.run")
    path = tmp_path / "drive.mcap"
    write_recording(path, drive)
    job = run.RunJob(filters=(FilterSpec("gps-ins", {}),), recordings=(path,),
                     viz=VizOptions(mode=VizMode.NONE), pacing=100.0)
    assert run._run_streamed(job, None) is None
