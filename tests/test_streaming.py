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


def assert_same_results(a: RunResult, b: RunResult) -> None:
    """Two replays of the same recording gave the same bits (estimates and innovations)."""
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
    assert_same_results(_windows(drive, filter_cls, {}, sizes, output_rate=10.0), whole)


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
    assert_same_results(_windows(rec, GpsInsFilter, {}, sizes, output_rate=20.0), whole)


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
    for k, v in whole.items():  # the numbers to rounding, the settings entries exactly
        assert got[k] == (v if isinstance(v, dict | str) else
                          pytest.approx(v, rel=1e-12, abs=1e-12)), k


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


# --------------------------------------------------------------------------------------------
# aiding streams in windows too (one pass over the file)


def _head(rec: Recording) -> Recording:
    """The recording with every stream emptied (its columns kept): what a session starts on
    when the samples come window by window."""
    return Recording({k: s.slice(0, 0) for k, s in rec.streams.items()}, rec.metadata,
                     rec.t0_ns)


def _time_windows(rec: Recording, cls: type, ends_ns: list[int], **kw) -> RunResult:
    """Every stream fed in the windows (previous end, end] of time, each aiding kind known up
    to its last sample so far (complete once all of it is fed), as read_windows hands them."""
    from navreplay.io.windows import COMPLETE

    session = ReplaySession(_head(rec), cls, {}, **kw)
    blocks, lo = [], None
    for k, hi in enumerate(ends_ns):
        final = k == len(ends_ns) - 1
        part, known = {}, {}
        for kind, s in rec.streams.items():
            a = 0 if lo is None else int(np.searchsorted(s.t_ns, lo, side="right"))
            b = len(s) if final else int(np.searchsorted(s.t_ns, hi, side="right"))
            part[kind] = s.slice(a, b)
            known[kind] = (COMPLETE if b == len(s) else
                           int(s.t_ns[b - 1]) if b else -COMPLETE)
        imu = part.pop(StreamKind.IMU)
        blocks.append(session.feed(imu, final=final, aiding=part, known=known))
        lo = hi
    return concat_results(blocks)


def _ends(rec: Recording, seconds: list[float]) -> list[int]:
    return [rec.t0_ns + round(s * 1e9) for s in seconds] + [rec.t0_ns + 10**12]


@pytest.mark.parametrize("filter_cls", [GpsInsFilter, InsFilter])
def test_aiding_in_windows_gives_the_bits_of_the_whole_replay(drive: Recording,
                                                             filter_cls: type) -> None:
    whole = replay(drive, filter_cls, {}, output_rate=10.0)
    rng = np.random.default_rng(2)
    cuts = np.cumsum(rng.uniform(0.003, 4.0, size=60))  # 3 ms to 4 s windows, odd boundaries
    got = _time_windows(drive, filter_cls, _ends(drive, list(cuts[cuts < 59.0])),
                        output_rate=10.0)
    assert_same_results(got, whole)
    if filter_cls is GpsInsFilter:  # GPS updates were applied
        assert sum(len(s.t) for s in got.innovations.values()) > 50


def test_a_window_boundary_between_an_imu_sample_and_a_gps_fix(drive: Recording) -> None:
    """Fixes 1 ns after and 1 ns before an IMU sample that ends a window: the fix after it
    waits for the next window, the IMU samples after the one before it wait too."""
    imu, gps = drive[StreamKind.IMU], drive[StreamKind.GPS]
    t_gps = gps.t_ns.copy()
    k1, k2 = 10, 20
    j1 = int(np.searchsorted(imu.t_ns, t_gps[k1]))
    j2 = int(np.searchsorted(imu.t_ns, t_gps[k2]))
    t_gps[k1] = imu.t_ns[j1] + 1
    t_gps[k2] = imu.t_ns[j2] - 1
    moved = dataclasses.replace(gps, t_ns=t_gps)
    rec = Recording({**drive.streams, StreamKind.GPS: moved}, drive.metadata, drive.t0_ns)
    whole = replay(rec, GpsInsFilter, {}, output_rate=10.0)
    ends = [int(imu.t_ns[j1]), int(imu.t_ns[j1]) + 1, int(t_gps[k2]),
            int(imu.t_ns[j2]) - 2, int(imu.t_ns[j2]), rec.t0_ns + 10**12]
    ends = sorted(set(ends))
    got = _time_windows(rec, GpsInsFilter, ends, output_rate=10.0)
    assert_same_results(got, whole)


def test_an_aiding_stream_that_starts_late(drive: Recording) -> None:
    gps = drive[StreamKind.GPS]
    late = gps.slice(int(np.searchsorted(gps.t_ns, drive.t0_ns + 25 * 10**9)), len(gps))
    rec = Recording({**drive.streams, StreamKind.GPS: late}, drive.metadata, drive.t0_ns)
    whole = replay(rec, GpsInsFilter, {}, output_rate=10.0)
    got = _time_windows(rec, GpsInsFilter, _ends(rec, [3.0, 7.5, 24.999, 25.0, 40.0, 55.5]),
                        output_rate=10.0)
    assert_same_results(got, whole)
