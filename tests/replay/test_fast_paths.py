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
from navreplay.replay import replay
from navreplay.sim.scenario import simulate


@pytest.fixture(scope="module")
def drive() -> Recording:
    return simulate("vehicle-drive", {"duration": 120.0}, seed=3)


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
