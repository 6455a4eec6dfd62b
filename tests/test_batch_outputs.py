"""Runs of output ticks handed to a filter at once (``propagate_outputs``) and runs of events
handed to ``gps-ins`` at once (``replay_events``) give the same bits as the same events one by
one, with and without IMU gaps, and only to filters whose hook belongs with their
``propagate``, ``update`` and ``estimate``; an event that fails inside a run is undone and
applied one by one, which names it."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from test_streaming import assert_same_results as _assert_same

from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.replay import engine, replay
from navreplay.sim.scenario import simulate
from navreplay.streams import Recording, StreamKind


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
    with monkeypatch.context() as m:
        m.setattr(engine, "_batch_hook", lambda filt: None)
        m.setattr(engine, "_events_hook", lambda filt: None)
        return replay(*args, **kw)


@pytest.mark.parametrize("filter_cls, params", [
    (GpsInsFilter, {"estimate_lever_arm": True}),
    (GpsInsFilter, {}),
    (InsFilter, {}),
])
def test_batched_ticks_are_bitwise_the_events_one_by_one(
    drive: Recording, monkeypatch: pytest.MonkeyPatch, filter_cls: type, params: dict,
) -> None:
    assert engine._batch_hook(filter_cls.__new__(filter_cls)) is not None
    fast = replay(drive, filter_cls, params, output_rate=20.0)
    slow = _one_by_one(monkeypatch, drive, filter_cls, params, output_rate=20.0)
    _assert_same(fast, slow)


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
    _assert_same(fast, slow)
    names = fast.state_names
    assert {"s_g_x", "m_g_zy", "s_a_z"} <= set(names)
    assert ("gm_N" in names) is (filter_cls is GpsInsFilter)
    if filter_cls is GpsInsFilter:  # (a free INS feeds nothing back)
        moved = np.ptp(fast.x, axis=0) > 0.0
        assert moved[[names.index(n) for n in ("s_g_x", "m_g_zy", "s_a_z", "gm_N")]].all()


def test_batched_ticks_around_an_imu_gap(drive: Recording,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    imu = drive[StreamKind.IMU]
    t = (imu.t_ns - imu.t_ns[0]) * 1e-9
    keep = (t < 50.0) | (t > 50.35)  # a 0.35 s gap: bridged, with ticks inside it
    gapped = dataclasses.replace(imu, t_ns=imu.t_ns[keep],
                                 columns={k: v[keep] for k, v in imu.columns.items()})
    rec = Recording({**drive.streams, StreamKind.IMU: gapped}, drive.metadata)
    _assert_same(replay(rec, GpsInsFilter), _one_by_one(monkeypatch, rec, GpsInsFilter))


def test_no_batch_for_a_subclass_that_changes_estimate() -> None:
    class Changed(InsFilter):
        name = "changed"

        def estimate(self) -> Any:
            return super().estimate()

    assert engine._batch_hook(Changed.__new__(Changed)) is None
    assert engine._batch_hook(InsFilter.__new__(InsFilter)) is not None


@pytest.mark.parametrize("params", [{}, {"estimate_lever_arm": True, "use_gps_vel": False}])
def test_event_runs_are_bitwise_the_events_one_by_one(
    drive: Recording, monkeypatch: pytest.MonkeyPatch, params: dict,
) -> None:
    assert engine._events_hook(GpsInsFilter.__new__(GpsInsFilter)) is not None
    assert engine._events_hook(InsFilter.__new__(InsFilter)) is None  # no update of its own
    fast = replay(drive, GpsInsFilter, params)
    slow = _one_by_one(monkeypatch, drive, GpsInsFilter, params)
    _assert_same(fast, slow)
    assert ("gps_vel" in fast.innovations) is not ("use_gps_vel" in params)


def test_a_failing_event_in_a_run_is_named_by_the_one_by_one_path(drive: Recording) -> None:
    from navreplay.filters.kalman import FilterDivergedError

    gps = drive[StreamKind.GPS]
    pos = gps.columns["pos"].copy()
    pos[40, 0] = np.nan  # a fix the kernel refuses: the engine replays it one by one
    bad = dataclasses.replace(gps, columns={**gps.columns, "pos": pos})
    rec = Recording({**drive.streams, StreamKind.GPS: bad}, drive.metadata)
    t_bad = (int(gps.t_ns[40]) - rec.t0_ns) * 1e-9
    with pytest.raises(FilterDivergedError, match=rf"at t = {t_bad:.3f} s: .*z has non-finite"):
        replay(rec, GpsInsFilter, validate=False)


def test_live_views_see_event_runs_as_they_come(drive: Recording) -> None:
    seen: list[int] = []
    result = replay(drive, GpsInsFilter, output_rate=20.0, observe_interval=0.0,
                    observer=lambda rows: seen.append(len(rows.t)))
    assert len(seen) >= 3 and seen == sorted(seen) and seen[-1] == len(result.t)
    assert seen[0] < len(result.t)  # not only the end: runs of at most 1024 events
