"""Gap warnings: an interval far longer than a topic's median is reported once, naming the
topic and time, except where the recording declares a GNSS outage
(``metadata.extra["gnss_outages"]``) that explains it."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from mcap_edits import write_small_chunks

from navreplay.core.outages import OUTAGES_KEY
from navreplay.core.streams import Recording, StreamKind
from navreplay.io import ReadOptions, open_recording, source
from navreplay.io.checks import declared_outages, gap_steps
from navreplay.io.errors import RecordingWarning
from navreplay.logs.describe import describe_log
from navreplay.logs.options import LogOptions
from navreplay.sim.scenario import simulate

S = 1_000_000_000


def test_gap_steps_excuse_only_what_a_declared_outage_explains() -> None:
    t = np.array([0, 1, 2, 3, 9, 10, 11, 20, 21], dtype=np.int64) * S  # 1 s median
    assert gap_steps(t, 1.0 * S).tolist() == [3, 6]  # 3 -> 9 and 11 -> 20
    declared = np.array([[4, 8]]) * S  # samples 3 and 9 lie within 5 s of it
    assert gap_steps(t, 1.0 * S, declared=declared).tolist() == [6]
    wide = np.array([[4, 8], [12, 19]]) * S
    assert gap_steps(t, 1.0 * S, declared=wide).size == 0
    late = np.array([[10.5, 13]]) * S  # the 11 -> 20 gap ends 7 s after this outage ends
    assert gap_steps(t, 1.0 * S, declared=late).tolist() == [3, 6]


def test_only_gnss_streams_have_declared_outages() -> None:
    extra = {OUTAGES_KEY: [[20, 35]]}
    t0 = 7 * S
    assert declared_outages(StreamKind.GPS, extra, t0).tolist() == [[27 * S, 42 * S]]
    assert declared_outages(StreamKind.GPS_VEL, extra, t0).tolist() == [[27 * S, 42 * S]]
    assert declared_outages(StreamKind.IMU, extra, t0).size == 0
    assert declared_outages(StreamKind.GPS, {OUTAGES_KEY: [[3, 1]]}, t0).size == 0  # malformed


@pytest.fixture(scope="module")
def outage_drive() -> Recording:
    return simulate("vehicle-drive", {"duration": 60.0, "gps_outages": "20:15"}, seed=3)


def _gap_lines(path, window: int) -> list[str]:
    with warnings.catch_warnings(record=True) as caught, pytest.MonkeyPatch.context() as mp:
        warnings.simplefilter("always")
        mp.setattr(source, "WINDOW_MESSAGES", window)
        for _ in open_recording(path, ReadOptions()):
            pass
    return [str(w.message) for w in caught
            if issubclass(w.category, RecordingWarning) and "gap(s)" in str(w.message)]


@pytest.mark.parametrize("window", [100_000, 150])
def test_a_declared_outage_is_not_a_gap_but_an_undeclared_one_is(outage_drive, tmp_path,
                                                                  window) -> None:
    gps = outage_drive[StreamKind.GPS]
    t = (gps.t_ns - outage_drive.t0_ns) * 1e-9
    assert not np.any((t >= 20.0) & (t < 35.0)) and np.any(t < 20.0) and np.any(t > 35.0)
    path = tmp_path / "declared.mcap"
    write_small_chunks(outage_drive, path)
    assert _gap_lines(path, window) == []
    # the same samples, the outage declared elsewhere: both GNSS topics warn, naming the time
    moved = dataclasses.replace(outage_drive.metadata,
                                extra={**outage_drive.metadata.extra, OUTAGES_KEY: [[40, 50]]})
    path = tmp_path / "undeclared.mcap"
    write_small_chunks(Recording(outage_drive.streams, moved, outage_drive.t0_ns), path)
    lines = _gap_lines(path, window)
    assert len(lines) == 2, lines
    assert any("topic /gps/fix" in m for m in lines) and any("topic /gps/vel" in m for m in lines)
    assert all("16 s, starts at t = 19." in m for m in lines), lines


def test_info_does_not_call_a_declared_outage_a_gap(outage_drive, tmp_path) -> None:
    path = tmp_path / "declared.mcap"
    write_small_chunks(outage_drive, path)
    text = describe_log(path, LogOptions()).text
    gnss = [line for line in text.splitlines() if line.startswith(("/gps/fix", "/gps/vel"))]
    assert len(gnss) == 2 and all(line.rstrip().endswith("no") for line in gnss), text
    assert "gap(s)" not in text
