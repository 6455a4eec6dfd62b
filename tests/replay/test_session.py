"""The replay session: merge order, IMU block delivery, output ticks, checks and errors; and a
recording fed in windows (as a file is read) makes exactly the filter calls of one window holding
all of it: the same bits, window sizes notwithstanding, also across an IMU gap, with aiding
samples at window boundaries, aiding streams that start late or pause."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from same_bits import assert_same_results

from navreplay.core.streams import Metadata, Recording, Stream, StreamKind
from navreplay.filters.base import (
    TICK,
    Estimate,
    Filter,
    Innovation,
    NavSolution,
    Quantity,
    State,
)
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.filters.kalman import FilterDivergedError
from navreplay.filters.result import RunResult, concat
from navreplay.io.source import COMPLETE, MemorySource
from navreplay.replay import (
    STREAM_PRIORITY,
    FilterSpec,
    InvalidRecordingError,
    MissingStreamError,
    ReplaySession,
    plan_events,
    replay,
)
from navreplay.sim.scenario import simulate

T0 = 1_700_000_000_000_000_000
S = 1_000_000_000


def make_recording(duration_s: float = 10.0, imu_hz: float = 100.0) -> Recording:
    """IMU at 100 Hz, GPS at 1 Hz, magnetometer at 10 Hz (sharing GPS times), depth at 1 Hz
    offset, and a truth stream that must never reach the filter."""
    n = int(duration_s * imu_hz)
    imu_t = T0 + np.rint(np.arange(1, n + 1) * S / imu_hz).astype(np.int64)
    imu = Stream(StreamKind.IMU, imu_t, {
        "omega_ib_b": np.arange(3 * n, dtype=float).reshape(n, 3),
        "f_b": -np.arange(3 * n, dtype=float).reshape(n, 3),
    })
    gps_t = T0 + np.arange(1, int(duration_s)) * S
    gps = Stream(StreamKind.GPS, gps_t, {
        "pos": np.arange(3 * len(gps_t), dtype=float).reshape(-1, 3),
        "pos_sigma": np.ones((len(gps_t), 3)),
    })
    mag_t = T0 + np.arange(1, int(duration_s * 10)) * (S // 10)
    mag = Stream(StreamKind.MAG, mag_t, {"m_b": np.ones((len(mag_t), 3)) * 1e-5})
    depth_t = T0 + np.arange(1, int(duration_s)) * S + S // 2 + 3  # between IMU samples
    depth = Stream(StreamKind.DEPTH, depth_t, {"depth": np.arange(len(depth_t), dtype=float)})
    truth = Stream(StreamKind.TRUTH, imu_t.copy(), {
        "pos": np.zeros((n, 3)), "v_n": np.zeros((n, 3)), "q_nb": np.tile([1.0, 0, 0, 0], (n, 1)),
    })
    streams = {s.kind: s for s in (truth, depth, mag, imu, gps)}  # deliberately unordered
    return Recording(streams, Metadata(scenario="synthetic", seed=7), t0_ns=T0)


class Recorder(Filter):
    """Records every call; estimate is the number of IMU samples seen."""

    name = "recorder"
    requires = (StreamKind.IMU,)
    optional = (StreamKind.GPS, StreamKind.MAG, StreamKind.DEPTH, StreamKind.TRUTH)
    states = (State("n_imu", "-", Quantity.OTHER), State("n_updates", "-", Quantity.OTHER))

    def __init__(self, params, context):
        super().__init__(params, context)
        self.calls: list[tuple] = []
        self.n_imu = 0
        self.n_upd = 0
        self.t = 0.0
        Recorder.last = self

    def propagate(self, t, imu):
        assert len(t) > 0
        assert imu["omega_ib_b"].shape == (len(t), 3)
        self.calls.append(("propagate", t.copy(), imu["omega_ib_b"].copy()))
        self.n_imu += len(t)
        self.t = float(t[-1])

    def update(self, kind, t, sample):
        self.calls.append(("update", kind, t, {k: np.array(v) for k, v in sample.items()}))
        self.n_upd += 1
        self.t = t
        if kind == StreamKind.GPS:
            return [Innovation("gps_pos", t, np.array([1.0, 2.0]), np.diag([1.0, 4.0]))]
        return None

    def estimate(self):
        self.calls.append(("estimate",))
        x = np.array([self.n_imu, self.n_upd], dtype=float)
        nav = NavSolution(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]))
        return Estimate(self.t, x, np.eye(2), nav, {"k": np.array([self.t])})


def test_every_imu_sample_once_in_order_blocks_end_at_events():
    rec = make_recording()
    res = replay(rec, Recorder, output_rate=10.0)
    f = Recorder.last
    blocks = [c for c in f.calls if c[0] == "propagate"]
    imu_s = (rec["imu"].t_ns - T0) * 1e-9
    np.testing.assert_array_equal(np.concatenate([b[1] for b in blocks]), imu_s)
    np.testing.assert_array_equal(np.concatenate([b[2] for b in blocks]), rec["imu"]["omega_ib_b"])
    # the block handed over before an update ends at the last IMU sample <= the update time
    for prev, call in zip(f.calls, f.calls[1:]):
        if call[0] == "update" and prev[0] == "propagate":
            t_ev = call[2]
            assert prev[1][-1] <= t_ev + 1e-12
            later = imu_s[imu_s > prev[1][-1]]
            assert later.size == 0 or later[0] > t_ev - 1e-12
    assert res.x[-1, 0] == len(imu_s)


def test_merge_order_by_time_then_priority_and_truth_never_delivered():
    rec = make_recording()
    replay(rec, Recorder, output_rate=None)
    updates = [c for c in Recorder.last.calls if c[0] == "update"]
    kinds = [c[1] for c in updates]
    assert StreamKind.TRUTH not in kinds and StreamKind.IMU not in kinds
    assert kinds.count(StreamKind.GPS) == len(rec["gps"])
    assert kinds.count(StreamKind.MAG) == len(rec["mag"])
    assert kinds.count(StreamKind.DEPTH) == len(rec["depth"])
    times = [c[2] for c in updates]
    assert times == sorted(times)
    prio = {k: i for i, k in enumerate(STREAM_PRIORITY)}
    for a, b in zip(updates, updates[1:]):
        if a[2] == b[2]:
            assert prio[a[1]] <= prio[b[1]]
    # GPS and magnetometer share every whole second: GPS first
    at_one = [c[1] for c in updates if c[2] == 1.0]
    assert at_one == [StreamKind.GPS, StreamKind.MAG]
    # samples are the stream's rows, in order
    gps_pos = np.stack([c[3]["pos"] for c in updates if c[1] == StreamKind.GPS])
    np.testing.assert_array_equal(gps_pos, rec["gps"]["pos"])
    depth = [float(c[3]["depth"]) for c in updates if c[1] == StreamKind.DEPTH]
    assert depth == rec["depth"]["depth"].tolist()


def test_one_estimate_per_event_time_and_columns():
    rec = make_recording()
    res = replay(rec, Recorder, output_rate=None)
    n_upd = len(rec["gps"]) + len(rec["mag"]) + len(rec["depth"])
    t_ev = np.concatenate([rec["gps"].t_ns, rec["mag"].t_ns, rec["depth"].t_ns])
    times = np.unique(t_ev)
    m = len(times) + 1  # one estimate per distinct event time, + one after the trailing IMU
    assert len(times) < n_upd  # the GPS shares its times with the magnetometer
    assert len(res.t) == m
    assert np.all(np.diff(res.t) > 0)
    assert res.x.shape == (m, 2) and res.P.shape == (m, 2, 2)
    assert res.nav_q_nb.shape == (m, 4)
    assert res.extras["k"].shape == (m, 1)
    assert res.state_names == ("n_imu", "n_updates")
    assert res.recording == "synthetic#seed=7" and res.label == "recorder"
    # the update count at each estimate: every sample up to and including that time
    counts = np.searchsorted(np.sort(t_ev), times, side="right")
    np.testing.assert_array_equal(res.x[:, 1], np.r_[counts, n_upd])


def test_innovations_collected_with_nis():
    res = replay(make_recording(), Recorder, output_rate=None)
    inn = res.innovations["gps_pos"]
    assert inn.nu.shape == (9, 2) and inn.S.shape == (9, 2, 2)
    np.testing.assert_allclose(inn.nis, 1.0 + 4.0 / 4.0)
    np.testing.assert_array_equal(inn.t, np.arange(1.0, 10.0))


def test_output_ticks_only_where_no_aiding_sample():
    rec = make_recording(duration_s=10.0)
    imu_only = Recording({StreamKind.IMU: rec["imu"]}, rec.metadata, T0)
    res = replay(imu_only, Recorder, output_rate=10.0)
    np.testing.assert_allclose(res.t, np.arange(1, 101) / 10.0)
    np.testing.assert_array_equal(res.x[:, 0], np.arange(1, 101) * 10)

    gps_only = Recording({StreamKind.IMU: rec["imu"], StreamKind.GPS: rec["gps"]},
                         rec.metadata, T0)
    plan = plan_events(gps_only, output_rate=2.0)
    ticks = (plan.t_ns[plan.code == TICK] - T0) / S
    np.testing.assert_allclose(ticks, [0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5, 8.5, 9.5, 10.0])
    assert (plan.code >= 0).sum() == len(rec["gps"])


class Lazy(Recorder):
    """Returns no estimate before its first update."""

    name = "lazy"

    def estimate(self):
        return super().estimate() if self.n_upd else None


def test_no_outputs_before_initialisation():
    res = replay(make_recording(), Lazy, output_rate=10.0)
    assert res.t[0] >= 0.1  # the first aiding sample (magnetometer at 0.1 s)
    empty = Recording({StreamKind.IMU: make_recording()["imu"]}, Metadata(), T0)
    res = replay(empty, Lazy)
    assert res.t.shape == (0,) and res.x.shape == (0, 2)


class GpsOnly(Recorder):
    name = "gps-only"
    requires = (StreamKind.GPS,)
    optional = ()


def test_only_declared_streams_are_delivered():
    replay(make_recording(), GpsOnly, output_rate=None)
    kinds = {c[1] for c in Recorder.last.calls if c[0] == "update"}
    assert kinds == {StreamKind.GPS}
    assert sum(len(c[1]) for c in Recorder.last.calls if c[0] == "propagate") == 1000


class NeedsGps(Recorder):
    name = "needs-gps"
    requires = (StreamKind.IMU, StreamKind.GPS, StreamKind.SPEED_LOG)


def test_missing_stream_names_what_is_missing_and_what_exists():
    rec = make_recording()
    with pytest.raises(MissingStreamError) as e:
        replay(rec, NeedsGps, source="x.mcap")
    msg = str(e.value)
    assert "'needs-gps'" in msg and "speed_log" in msg and "x.mcap" in msg
    assert "it has: " in msg and "gps" in msg and "imu" in msg


def test_missing_column_named():
    rec = make_recording()
    del rec["imu"].columns["f_b"]
    with pytest.raises(MissingStreamError, match="imu lacks column.*f_b"):
        replay(rec, Recorder)


class AccelerometerOnly(Recorder):
    name = "accel-only"
    required_columns = {StreamKind.IMU: ("f_b",)}

    def propagate(self, t, imu):
        assert "omega_ib_b" not in imu and imu["f_b"].shape == (len(t), 3)
        self.n_imu += len(t)
        self.t = float(t[-1])


def test_required_columns_replace_the_standard_ones():
    """A gyro-free filter runs on an IMU stream without omega_ib_b, and still needs f_b."""
    rec = make_recording()
    del rec["imu"].columns["omega_ib_b"]
    with pytest.raises(MissingStreamError, match="imu lacks column.*omega_ib_b"):
        replay(rec, Recorder)
    res = replay(rec, AccelerometerOnly, output_rate=None)
    assert len(res.t) > 0 and res.x[-1, 0] == len(rec["imu"])  # every IMU sample delivered
    del rec["imu"].columns["f_b"]
    with pytest.raises(MissingStreamError, match="imu lacks column.*f_b.*'accel-only'"):
        replay(rec, AccelerometerOnly)


def test_nan_sample_named_with_stream_and_time():
    rec = make_recording()
    rec["gps"]["pos"][3, 1] = np.nan
    with pytest.raises(InvalidRecordingError,
                       match=r"stream gps: non-finite value in column 'pos' .* at t = 4\.0+ s"):
        replay(rec, Recorder)


def test_time_going_backwards_or_repeating():
    rec = make_recording()
    rec["imu"].t_ns[500] = rec["imu"].t_ns[498]
    with pytest.raises(InvalidRecordingError,
                       match=r"stream imu: timestamp goes backwards at t = 4\.99.*"
                             r"previous message is at t = 5\.0"):
        replay(rec, Recorder)
    rec = make_recording()
    rec["mag"].t_ns[5] = rec["mag"].t_ns[4]
    with pytest.raises(InvalidRecordingError, match="stream mag: timestamp repeats"):
        replay(rec, Recorder)


class Diverges(Recorder):
    name = "diverges"

    def update(self, kind, t, sample):
        if t >= 3.0:
            raise FilterDivergedError("innovation covariance S is not positive definite", t)
        return super().update(kind, t, sample)


class GoesNan(Recorder):
    name = "goes-nan"

    def estimate(self):
        est = super().estimate()
        if self.t > 2.05:
            est.x[0] = np.nan
        return est


def test_divergence_names_filter_recording_and_time():
    with pytest.raises(FilterDivergedError) as e:
        replay(make_recording(), Diverges, source="drive.mcap")
    msg = str(e.value)
    assert "'diverges'" in msg and "drive.mcap" in msg and "t = 3.000 s" in msg
    assert e.value.t == 3.0
    with pytest.raises(FilterDivergedError, match=r"'goes-nan' diverged on .* t = 2\.1"):
        replay(make_recording(), GoesNan)


def test_pacing_follows_the_recording_clock():
    rec = make_recording(duration_s=2.0)
    t = time.perf_counter()
    replay(rec, Recorder, pacing=10.0)
    elapsed = time.perf_counter() - t
    assert 0.15 < elapsed < 1.0  # 2 s of data at 10x real time


def test_observer_and_progress_called():
    seen, prog = [], []
    res = replay(make_recording(), Recorder, observer=lambda r: seen.append(len(r.t)),
                 progress=lambda d, n: prog.append((d, n)), observe_interval=0.0)
    assert seen and sum(seen) == len(res.t)  # every row once, as it came
    assert prog[-1][0] == prog[-1][1] and all(d <= n for d, n in prog)


def test_params_from_strings_are_typed():
    from navreplay.core.params import ParamError

    with pytest.raises(ParamError, match="unknown parameter"):
        replay(make_recording(), Recorder, {"gain": "2"})


# --------------------------------------------------------------------------------------------
# a recording fed in windows


@pytest.fixture(scope="module")
def drive() -> Recording:
    return simulate("vehicle-drive", {"duration": 60.0}, seed=5)


def _session(rec: Recording, cls: type, **kw) -> ReplaySession:
    """A session started on the recording's first window with no samples yet (every stream
    present, empty): the samples come in the windows fed."""
    head = next(MemorySource(Recording({k: s.slice(0, 0) for k, s in rec.streams.items()},
                                       rec.metadata, rec.t0_ns)))
    return ReplaySession(head, FilterSpec.of(cls), source="drive", **kw)


def _imu_windows(rec: Recording, cls: type, sizes: list[int], **kw) -> RunResult:
    """The aiding streams whole in the first window, the IMU in windows of ``sizes``."""
    imu = rec[StreamKind.IMU]
    session = _session(rec, cls, **kw)
    aiding = {k: s for k, s in rec.streams.items() if k is not StreamKind.IMU}
    blocks, a = [], 0
    for k, n in enumerate(sizes):
        b = len(imu) if k == len(sizes) - 1 else min(a + n, len(imu))
        blocks.append(session.feed({**aiding, StreamKind.IMU: imu.slice(a, b)},
                                   final=k == len(sizes) - 1))
        aiding, a = {}, b
    return concat(blocks)


def _time_windows(rec: Recording, cls: type, ends_ns: list[int], **kw) -> RunResult:
    """Every stream fed in the windows (previous end, end] of time, each aiding kind known up
    to its last sample so far (complete once all of it is fed), as a file's reader hands
    them."""
    session = _session(rec, cls, **kw)
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
        blocks.append(session.feed(part, final=final, known=known))
        lo = hi
    joined = concat(blocks, consume=True)  # each block let go of as it is copied
    assert blocks == []
    return joined


def _ends(rec: Recording, seconds: list[float]) -> list[int]:
    return [rec.t0_ns + round(s * 1e9) for s in seconds] + [rec.t0_ns + 10**12]


def _without(rec: Recording, kind: StreamKind, lo: float, hi: float) -> Recording:
    """The recording without the samples of ``kind`` in (lo, hi] [s after t0]."""
    s = rec[kind]
    t = (s.t_ns - rec.t0_ns) * 1e-9
    keep = (t <= lo) | (t > hi)
    cut = dataclasses.replace(s, t_ns=s.t_ns[keep],
                              columns={k: v[keep] for k, v in s.columns.items()})
    return Recording({**rec.streams, kind: cut}, rec.metadata, rec.t0_ns)


@pytest.mark.parametrize("filter_cls", [GpsInsFilter, InsFilter])
def test_imu_windows_give_the_bits_of_one_window(drive: Recording, filter_cls: type) -> None:
    whole = replay(drive, filter_cls, {}, output_rate=10.0)
    rng = np.random.default_rng(1)
    sizes = [int(s) for s in rng.integers(1, 700, size=40)]  # windows of 1 to 699 samples
    assert_same_results(_imu_windows(drive, filter_cls, sizes, output_rate=10.0), whole)


@pytest.mark.parametrize("filter_cls", [GpsInsFilter, InsFilter])
def test_time_windows_give_the_bits_of_one_window(drive: Recording, filter_cls: type) -> None:
    whole = replay(drive, filter_cls, {}, output_rate=10.0)
    rng = np.random.default_rng(2)
    cuts = np.cumsum(rng.uniform(0.003, 4.0, size=60))  # 3 ms to 4 s windows, odd boundaries
    got = _time_windows(drive, filter_cls, _ends(drive, list(cuts[cuts < 59.0])),
                        output_rate=10.0)
    assert_same_results(got, whole)
    if filter_cls is GpsInsFilter:  # GPS updates were applied
        assert sum(len(s.t) for s in got.innovations.values()) > 50


def test_windows_across_an_imu_gap(drive: Recording) -> None:
    rec = _without(drive, StreamKind.IMU, 20.0, 20.45)  # bridged, with fixes and ticks inside
    whole = replay(rec, GpsInsFilter, {}, output_rate=20.0)
    t = (rec[StreamKind.IMU].t_ns - rec.t0_ns) * 1e-9
    cut = int(np.searchsorted(t, 20.0))  # a window ends at the last sample before the gap
    sizes = [cut - 7, 7, 150, 3, 10_000]
    assert_same_results(_imu_windows(rec, GpsInsFilter, sizes, output_rate=20.0), whole)


def test_the_nominal_interval_of_a_short_first_window_is_that_of_the_whole_stream(
        drive: Recording) -> None:
    """The bridge ends one nominal interval (the median of the first window's) before the
    next sample: a first window of a few samples of a regular clock gives the same bits."""
    rec = _without(drive, StreamKind.IMU, 45.0, 45.4)
    whole = replay(rec, GpsInsFilter, {}, output_rate=10.0)
    for first in (12, 37, 401):
        assert_same_results(_imu_windows(rec, GpsInsFilter, [first, 10**6], output_rate=10.0),
                            whole)


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
    ends = sorted({int(imu.t_ns[j1]), int(imu.t_ns[j1]) + 1, int(t_gps[k2]),
                   int(imu.t_ns[j2]) - 2, int(imu.t_ns[j2]), rec.t0_ns + 10**12})
    assert_same_results(_time_windows(rec, GpsInsFilter, ends, output_rate=10.0), whole)


def test_an_aiding_stream_that_starts_late(drive: Recording) -> None:
    rec = _without(drive, StreamKind.GPS, -1.0, 25.0)
    whole = replay(rec, GpsInsFilter, {}, output_rate=10.0)
    got = _time_windows(rec, GpsInsFilter, _ends(rec, [3.0, 7.5, 24.999, 25.0, 40.0, 55.5]),
                        output_rate=10.0)
    assert_same_results(got, whole)


def test_a_window_without_samples_applies_nothing(drive: Recording) -> None:
    imu = drive[StreamKind.IMU]
    session = _session(drive, GpsInsFilter)
    aiding = {k: s for k, s in drive.streams.items() if k is not StreamKind.IMU}
    first = session.feed({**aiding, StreamKind.IMU: imu.slice(0, 500)})
    assert first.t.size and first.t[-1] <= (imu.t_ns[499] - drive.t0_ns) * 1e-9
    assert session.feed({StreamKind.IMU: imu.slice(500, 500)}).t.size == 0
    rest = session.feed({StreamKind.IMU: imu.slice(500, len(imu))}, final=True)
    assert rest.t[0] > first.t[-1]
