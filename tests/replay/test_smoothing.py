"""The RTS smoother on the INS filters: gps-ins on vehicle-drive with 30 s and 60 s GNSS
outages (consumer IMU, differential GNSS; tests/smoothing_runs.py), at seeds not used while the
smoother was developed (those were smoothing_runs.DEV_SEEDS and 104-115): the smoothed error
during the outages, the smoothed NEES and RMS/sigma, and the smoothed sigma against the
forward one; ins and rpm-aided-ins smoothed."""

import numpy as np
import pytest
from smoothing_runs import OUTAGES, drive, horizontal, in_outage, smoothed_pair

from navreplay.io.source import MemorySource
from navreplay.metrics import consistency
from navreplay.replay.pipeline import Collect, replay_file
from navreplay.replay.spec import FilterSpec
from navreplay.sim.scenario import simulate

QUICK_SEEDS = tuple(range(5000, 5004))
SLOW_SEEDS = tuple(range(6000, 6040))
DOF = 9


def _ensemble(seeds):
    pairs = [smoothed_pair(drive(s)) for s in seeds]
    out = {}
    for o in OUTAGES:
        sq = [np.concatenate([horizontal(getattr(p, m))[in_outage(p.m_forward.t, o)] ** 2
                              for p in pairs]) for m in ("m_forward", "m_smoothed")]
        out[o] = tuple(float(np.sqrt(np.mean(s))) for s in sq)
    nees = np.array([np.mean(p.m_smoothed.nees[p.m_smoothed.t >= 10.0]) for p in pairs])
    z2 = np.concatenate([
        (p.m_smoothed.nav.pos_ned[:, :2] ** 2).sum(1)
        / (p.m_smoothed.nav_sigma["pos_ned"][:, :2] ** 2).sum(1) for p in pairs])
    return pairs, out, nees, float(np.sqrt(np.mean(z2)))


def _check(seeds, rms_band):
    pairs, outage_rms, nees, h_ratio = _ensemble(seeds)
    for o, (fwd, rts) in outage_rms.items():
        assert fwd >= 5.0 * rts, (o, fwd, rts)
    assert consistency.inside(float(nees.mean()), DOF, len(seeds)), (
        nees.mean(), consistency.mean_band(DOF, len(seeds)))
    assert rms_band[0] <= h_ratio <= rms_band[1], h_ratio
    for p in pairs:
        f, s = p.forward, p.smoothed
        np.testing.assert_array_equal(f.t, s.t)
        assert np.all(s.sigma <= f.sigma * (1.0 + 1e-9) + 1e-12)
        # the last epoch is the filter's own; earlier ones use the fixes after them
        np.testing.assert_allclose(s.nav_pos[-1], f.nav_pos[-1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(s.P[-1], f.P[-1], rtol=0, atol=1e-15)
        assert np.all(s.sigma[:-1, :2].mean(0) < 0.9 * f.sigma[:-1, :2].mean(0))
    return outage_rms, nees, h_ratio


def test_outages_and_consistency_small_ensemble():
    _check(QUICK_SEEDS, (0.6, 1.5))


@pytest.mark.slow
def test_outages_and_consistency_ensemble():
    outage_rms, nees, h_ratio = _check(SLOW_SEEDS, (0.85, 1.15))
    print("outage RMS forward / smoothed:", outage_rms, "NEES/dof", nees.mean() / DOF,
          "horizontal RMS/sigma", h_ratio)


def _pair(rec, name, **kw):
    collect = Collect()
    replay_file(MemorySource(rec, "rec"), [FilterSpec(name)], stages=[collect], smooth=True,
                score=False, **kw)
    r = collect.results()
    return r[name], r[name + "/rts"]


def test_ins_without_updates_smooths_to_itself():
    rec = simulate("vehicle-drive", {"duration": 30.0}, seed=7)
    f, s = _pair(rec, "ins", output_rate=2.0)
    np.testing.assert_allclose(s.nav_pos, f.nav_pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s.x, f.x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.P, f.P, rtol=1e-9, atol=1e-18)


def test_rpm_aided_ins_is_smoothed():
    rec = simulate("underwater-rpm", {"duration": 120.0}, seed=3)
    f, s = _pair(rec, "rpm-aided-ins", output_rate=1.0)
    assert np.all(np.isfinite(s.P)) and np.all(s.sigma <= f.sigma * (1.0 + 1e-9) + 1e-12)
    assert s.sigma[0, 2] < f.sigma[0, 2]  # depth at the start: the later updates reach back


def test_chunks_give_the_run_in_one_chunk(monkeypatch):
    rec = drive(5100, duration=60.0)
    _, one = _pair(rec, "gps-ins")
    monkeypatch.setattr("navreplay.replay.smoothing.CHUNK", 7)
    monkeypatch.setattr("navreplay.replay.smoothing.ForwardStore.__init__.__defaults__", (7,))
    _, many = _pair(rec, "gps-ins")
    np.testing.assert_allclose(many.x, one.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(many.nav_pos, one.nav_pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(many.P, one.P, rtol=1e-9, atol=1e-20)


def test_non_smoothable_filter_gets_no_smoothed_run():
    rec = simulate("vehicle-drive", {"duration": 20.0}, seed=1)
    collect = Collect()
    replay_file(MemorySource(rec, "rec"), [FilterSpec("gps-ins")], stages=[collect])
    assert set(collect.results()) == {"gps-ins"}


def test_progress_covers_the_forward_and_backward_passes_and_the_scoring(monkeypatch):
    """The bar's total is fixed from the first call; it moves through each backward pass and
    each smoothed run's scoring and reaches its end only when the last one is scored."""
    from navreplay.replay import pipeline

    events: list = []
    backward, feed = pipeline.backward, pipeline._feed_smoothed

    def spy_backward(*a, **kw):
        events.append("backward")
        out = backward(*a, **kw)
        events.append("scoring")
        return out

    def spy_feed(*a, **kw):
        feed(*a, **kw)
        events.append("scored")

    monkeypatch.setattr(pipeline, "backward", spy_backward)
    monkeypatch.setattr(pipeline, "_feed_smoothed", spy_feed)
    rec = simulate("vehicle-drive", {"duration": 60.0}, seed=9)
    replay_file(MemorySource(rec, "rec"), [FilterSpec("ins"), FilterSpec("gps-ins")],
                progress=lambda done, total: events.append((done, total)), smooth=True,
                output_rate=2.0)
    marks = [i for i, e in enumerate(events) if isinstance(e, str)]
    assert [events[i] for i in marks] == ["backward", "scoring", "scored"] * 2
    calls = [e for e in events if isinstance(e, tuple)]
    total = calls[0][1]
    assert all(t == total for _, t in calls)
    done = [d for d, _ in calls]
    assert done == sorted(done) and done[-1] == total and all(d < total for d in done[:-1])
    last = max(i for i, e in enumerate(events) if isinstance(e, tuple))
    assert marks[-2] < last < marks[-1]  # in the scoring of the last smoothed run
    # the forward passes of both filters end at 2 / (2 + 2 x (backward + scoring)) of the bar
    segments = [[e[0] for e in events[a:b] if isinstance(e, tuple)]
                for a, b in zip([0, *marks[:-1]], marks, strict=True)]
    assert segments[0][-1] == pytest.approx(
        total / (1.0 + pipeline.BACKWARD_COST + pipeline.SCORING_COST), abs=1)
    # each backward pass and each scoring moves the bar on
    moved = [seg for seg, b in zip(segments, marks, strict=True) if events[b] != "backward"]
    assert len(moved) == 4
    ends = [segments[0][-1]] + [seg[-1] for seg in moved if seg]
    assert all(seg for seg in moved) and ends == sorted(set(ends)), segments
