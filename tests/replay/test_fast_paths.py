"""The compiled fast paths of ``Filter.run_events`` (``ins``: runs of output ticks in one call
of the time update; ``gps-ins``: runs of events in one call) give the bits of the default, the
events one by one through ``propagate``, ``update`` and ``estimate``, with and without IMU
gaps; a subclass that changes what a kernel assumes gets the default; an event that fails
inside a compiled run is undone and applied by the default, which names it."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from same_bits import assert_same_results

from navreplay.core.streams import Recording, StreamKind
from navreplay.filters.base import Filter
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.replay import replay, session
from navreplay.sim.scenario import simulate


@pytest.fixture(scope="module")
def drive() -> Recording:
    return simulate("vehicle-drive", {"duration": 120.0}, seed=3)


@pytest.fixture(scope="module")
def banked() -> Recording:
    """Coordinated turns at 40 m/s, a time-correlated GNSS error and a GNSS outage: every
    state of the full models moves."""
    return simulate("vehicle-drive", {"duration": 120.0, "turn_mode": "coordinated",
                                      "cruise_speed": 40.0, "gps_pos_gm_sigma": 1.5,
                                      "gps_pos_gm_tau": 60.0, "gps_outages": "50:20"}, seed=4)


def _one_by_one(monkeypatch: pytest.MonkeyPatch, *args: Any, **kw: Any) -> Any:
    """The replay with every filter on the default of ``Filter.run_events``."""
    with monkeypatch.context() as m:
        for cls in (InsFilter, GpsInsFilter):
            m.setattr(cls, "run_events", Filter.run_events)
        return replay(*args, **kw)


@pytest.mark.parametrize("filter_cls, params", [
    (GpsInsFilter, {"estimate_lever_arm": True}),
    (GpsInsFilter, {"use_gps_vel": False}),
    (GpsInsFilter, {}),
    (InsFilter, {}),
])
def test_compiled_runs_are_bitwise_the_events_one_by_one(
    drive: Recording, monkeypatch: pytest.MonkeyPatch, filter_cls: type, params: dict,
) -> None:
    fast = replay(drive, filter_cls, params, output_rate=20.0)
    slow = _one_by_one(monkeypatch, drive, filter_cls, params, output_rate=20.0)
    assert_same_results(fast, slow)
    if filter_cls is GpsInsFilter:
        assert ("gps_vel" in fast.innovations) is params.get("use_gps_vel", True)


FULL_INS = {"gyro_roll_pitch_states": True, "accel_motion_states": True,
            "accel_load_states": True}


@pytest.mark.parametrize("filter_cls, params", [
    (GpsInsFilter, {"estimate_lever_arm": True}),
    (GpsInsFilter, {"use_gps_vel": False, "gps_pos_gm_tau": 200.0}),
    (InsFilter, FULL_INS),
])
def test_the_full_models_are_bitwise_the_events_one_by_one(
    banked: Recording, monkeypatch: pytest.MonkeyPatch, filter_cls: type, params: dict,
) -> None:
    """The gyro and accelerometer scale-factor and misalignment columns, the GNSS
    Gauss-Markov states (from the recording's specification) and a GNSS outage: the compiled
    runs of ticks and of events give the bits of the events one by one."""
    fast = replay(banked, filter_cls, params, output_rate=20.0)
    slow = _one_by_one(monkeypatch, banked, filter_cls, params, output_rate=20.0)
    assert_same_results(fast, slow)
    names = fast.state_names
    assert {"s_g_x", "m_g_zy", "s_a_z"} <= set(names)
    assert ("gm_N" in names) is (filter_cls is GpsInsFilter)
    if filter_cls is GpsInsFilter:  # (a free INS feeds nothing back)
        moved = np.ptp(fast.x, axis=0) > 0.0
        assert moved[[names.index(n) for n in ("s_g_x", "m_g_zy", "s_a_z", "gm_N")]].all()


def test_compiled_runs_around_an_imu_gap(drive: Recording,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    imu = drive[StreamKind.IMU]
    t = (imu.t_ns - imu.t_ns[0]) * 1e-9
    keep = (t < 50.0) | (t > 50.35)  # a 0.35 s gap: bridged, with ticks and fixes inside it
    gapped = dataclasses.replace(imu, t_ns=imu.t_ns[keep],
                                 columns={k: v[keep] for k, v in imu.columns.items()})
    rec = Recording({**drive.streams, StreamKind.IMU: gapped}, drive.metadata)
    for cls in (GpsInsFilter, InsFilter):
        assert_same_results(replay(rec, cls), _one_by_one(monkeypatch, rec, cls))


def test_a_subclass_that_changes_estimate_gets_the_default() -> None:
    calls = []

    class Changed(InsFilter):
        name = "changed"

        def estimate(self) -> Any:
            calls.append(self.t)
            return super().estimate()

    rec = simulate("vehicle-drive", {"duration": 10.0}, seed=3)
    result = replay(rec, Changed, output_rate=10.0)
    assert len(calls) == len(result.t) > 90  # every estimate through the subclass


def test_a_failing_event_in_a_run_is_named_by_the_default(drive: Recording) -> None:
    from navreplay.filters.kalman import FilterDivergedError

    gps = drive[StreamKind.GPS]
    pos = gps.columns["pos"].copy()
    pos[40, 0] = np.nan  # a fix the kernel refuses: the engine applies it one by one
    bad = dataclasses.replace(gps, columns={**gps.columns, "pos": pos})
    rec = Recording({**drive.streams, StreamKind.GPS: bad}, drive.metadata)
    t_bad = (int(gps.t_ns[40]) - rec.t0_ns) * 1e-9
    with pytest.raises(FilterDivergedError, match=rf"at t = {t_bad:.3f} s: .*z has non-finite"):
        replay(rec, GpsInsFilter, validate=False)


def test_live_views_see_compiled_runs_as_they_come(drive: Recording) -> None:
    seen: list[int] = []
    result = replay(drive, GpsInsFilter, output_rate=20.0, observe_interval=0.0,
                    observer=lambda rows: seen.append(len(rows.t)))
    assert len(seen) >= 3 and sum(seen) == len(result.t)
    assert seen[0] < len(result.t)  # not only the end: runs of at most 1024 events


def test_a_subclass_keeps_the_decay_of_the_markov_states(
        banked: Recording, monkeypatch: pytest.MonkeyPatch) -> None:
    """A ``gps-ins`` subclass that changes ``update`` runs its ticks through the time update's
    kernel only where no state is a first-order Markov process: the GNSS Gauss-Markov
    estimates decay from tick to tick as one by one (runs of at most 8 events, as a replay
    that reports its progress cuts them: runs of ticks alone between the fixes)."""

    class Changed(GpsInsFilter):
        name = "changed-gps-ins"

        def update(self, *args: Any, **kw: Any) -> Any:
            return super().update(*args, **kw)

    monkeypatch.setattr(session, "CHECK_EVERY", 8)
    kw = {"output_rate": 20.0, "progress": lambda done, total: None}
    params = {"gps_pos_gm_tau": 200.0}
    fast = replay(banked, Changed, params, **kw)
    assert_same_results(fast, _one_by_one(monkeypatch, banked, Changed, params, **kw))
    gm = fast.x[:, fast.state_names.index("gm_N")]
    assert np.count_nonzero(np.diff(gm)) > 0.9 * (len(gm) - 1)  # not held between fixes


def _smoothed(rec: Recording, **kw: Any) -> dict[str, Any]:
    from navreplay.io.source import MemorySource
    from navreplay.replay.pipeline import Collect, replay_file
    from navreplay.replay.spec import FilterSpec

    collect = Collect()
    replay_file(MemorySource(rec, "rec"), [FilterSpec("gps-ins")], stages=[collect],
                smooth=True, score=False, **kw)
    return collect.results()


@pytest.mark.parametrize("output_rate", [1.0, 20.0])
def test_smoothed_compiled_runs_are_bitwise_the_events_one_by_one(
        banked: Recording, monkeypatch: pytest.MonkeyPatch, output_rate: float) -> None:
    """With a smoother, the compiled runs of ``gps-ins`` keep the transition, the covariance
    before the updates and the corrections of every output as the events one by one do: the
    forward and the smoothed runs have the same bits (full models, Gauss-Markov GNSS states,
    an outage; runs cut short by the progress bar and by the check interval)."""
    monkeypatch.setattr(session, "CHECK_EVERY", 64)
    kw = {"output_rate": output_rate, "progress": lambda done, total: None}
    calls: list[int] = []
    compiled = GpsInsFilter.run_events

    def spy(self: GpsInsFilter, run: Any) -> int:
        calls.append(len(run))
        return compiled(self, run)

    monkeypatch.setattr(GpsInsFilter, "run_events", spy)
    fast = _smoothed(banked, **kw)
    assert sum(calls) > 100  # the events went through the compiled runs
    monkeypatch.setattr(GpsInsFilter, "run_events", Filter.run_events)
    slow = _smoothed(banked, **kw)
    assert_same_results(fast["gps-ins"], slow["gps-ins"])
    for name in ("t", "x", "P", "nav_pos", "nav_v_n", "nav_q_nb"):
        np.testing.assert_array_equal(getattr(fast["gps-ins/rts"], name),
                                      getattr(slow["gps-ins/rts"], name), err_msg=name)
