"""GNSS outages scored one by one (navreplay.metrics.outages): the end error, sigma and RMS of
each outage by hand, the same from a run scored whole or window by window, the ensemble's
check passing consistent errors and rejecting over-confident ones, the outage table (text and
HTML report), the view's shading, and a recording whose outage entry is malformed named in one
line."""

from __future__ import annotations

import dataclasses
import importlib
import math
from pathlib import Path

import numpy as np
import pytest
from mcap_edits import write_small_chunks

from navreplay import metrics
from navreplay.core.streams import Recording
from navreplay.io import source
from navreplay.io.errors import RecordingError
from navreplay.io.source import MemorySource
from navreplay.metrics import tables
from navreplay.metrics.outages import OutageScores, ensemble_outages
from navreplay.replay import FilterSpec, replay, replay_file
from navreplay.sim.scenario import simulate
from navreplay.viz.options import VizMode, VizOptions

run_job = importlib.import_module("navreplay.jobs.run")


def test_the_scores_of_an_outage_by_hand() -> None:
    """Errors growing 1 m/s north and 0.5 m/s down from 0 at t = 10 s, the sigma 2 m per
    axis: the outage [10, 20) ends at the estimate of 19.5 s (the one at 20 s follows the
    fix)."""
    t = np.arange(0.0, 30.0, 0.5)
    age = np.clip(t - 10.0, 0.0, None)
    err = np.stack([age, np.zeros_like(t), 0.5 * age], axis=1)
    s = OutageScores(((10.0, 20.0), (40.0, 50.0)))
    s.add(t[:25], err[:25], np.full((25, 3), 2.0))  # in two blocks
    s.add(t[25:], err[25:], np.full((35, 3), 2.0))
    first, after_the_run = s.result()
    k = (t >= 10.0) & (t < 20.0)
    assert first["t_end"] == 19.5
    assert first["err_end_h"] == pytest.approx(9.5, abs=1e-12)
    assert first["err_end_v"] == pytest.approx(4.75, abs=1e-12)
    assert first["sigma_end_h"] == pytest.approx(2.0 * math.sqrt(2.0))
    assert first["sigma_end_v"] == 2.0
    assert first["rms_h"] == pytest.approx(math.sqrt(np.mean(age[k] ** 2)))
    assert first["rms_v"] == pytest.approx(math.sqrt(np.mean((0.5 * age[k]) ** 2)))
    assert after_the_run == {"start": 40.0, "end": 50.0}  # no estimate inside: not scored


@pytest.fixture(scope="module")
def outage_drive(tmp_path_factory) -> tuple[Recording, Path]:
    """A MEMS-grade drive of 90 s with GNSS outages of 15 and 30 s, and its MCAP file."""
    rec = simulate("vehicle-drive", {"duration": 90.0, "imu_grade": "mems",
                                     "gps_outages": "20:15,50:30"}, seed=11)
    return rec, write_small_chunks(rec, tmp_path_factory.mktemp("outages") / "drive.mcap")


def test_a_run_scored_whole_or_window_by_window_gives_the_same_outages(
        outage_drive, tmp_path) -> None:
    rec, path = outage_drive
    whole = metrics.run_metrics(replay(rec, FilterSpec("gps-ins")), rec).summary()
    job = run_job.RunJob(filters=(FilterSpec("gps-ins"),), recordings=(path,),
                         viz=VizOptions(mode=VizMode.NONE), report_path=tmp_path / "r.html")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(source, "WINDOW_MESSAGES", 1000)  # several windows
        streamed = run_job.run(job)
    outages = whole["gnss_outages"]
    assert [(o["start"], o["end"]) for o in outages] == [(20.0, 35.0), (50.0, 80.0)]
    for a, b in zip(outages, streamed.summary["filters"]["gps-ins"]["gnss_outages"],
                    strict=True):
        assert a.keys() == b.keys()
        for key in a:
            assert a[key] == pytest.approx(b[key], rel=1e-9, abs=1e-12), key
    assert "GNSS outage [s]" in streamed.table and "gps-ins 50-80" in streamed.table
    html = (tmp_path / "r.html").read_text()
    assert "<h3>GNSS outages</h3>" in html and "<td>gps-ins 50-80</td>" in html
    # a MEMS IMU drifts through the outage: the longer the outage the larger the sigma at its
    # end, and the filter's sigma there is of the size of the error
    assert outages[1]["sigma_end_h"] > 1.5 * outages[0]["sigma_end_h"]
    for o in outages:
        assert o["t_end"] == pytest.approx(o["end"] - 0.1)  # the 10 Hz output before the fix
        assert 0.0 < o["err_end_h"] < 4.0 * o["sigma_end_h"]


def test_smoothed_runs_get_outage_rows_beside_the_forward_ones(outage_drive, tmp_path) -> None:
    """``run --smooth``: each outage's row of ``LABEL/rts`` follows the filter's, scored as
    the smoothed run scored whole would be; the smoother, tied to the fixes at both ends,
    makes the sigma at the outages' ends and the error inside the long one several times
    smaller (a MEMS IMU drifts metres in 30 s)."""
    from navreplay.replay import Collect

    rec, path = outage_drive
    job = run_job.RunJob(filters=(FilterSpec("gps-ins"), FilterSpec("ins")),
                         recordings=(path,), viz=VizOptions(mode=VizMode.NONE),
                         report_path=tmp_path / "r.html", smooth=True)
    done = run_job.run(job)
    names = [" ".join(ln.split()[:2]) for ln in done.table.splitlines()
             if ln.split()[1:2] and ln.split()[1] in ("20-35", "50-80")]
    assert names == ["gps-ins 20-35", "gps-ins/rts 20-35", "gps-ins 50-80",
                     "gps-ins/rts 50-80", "ins 20-35", "ins/rts 20-35", "ins 50-80",
                     "ins/rts 50-80"], done.table
    html = (tmp_path / "r.html").read_text()
    assert html.index("<td>gps-ins 20-35</td>") < html.index("<td>gps-ins/rts 20-35</td>") \
        < html.index("<td>gps-ins 50-80</td>")
    filters = done.summary["filters"]
    collect = Collect()
    replay_file(MemorySource(rec, "drive"), [FilterSpec("gps-ins")], stages=[collect],
                smooth=True, score=False)
    whole = metrics.run_metrics(collect.results()["gps-ins/rts"], rec).summary()
    for a, b in zip(whole["gnss_outages"], filters["gps-ins/rts"]["gnss_outages"],
                    strict=True):
        assert a.keys() == b.keys()
        for key in a:
            assert a[key] == pytest.approx(b[key], rel=1e-6, abs=1e-9), key
    for fwd, rts in zip(filters["gps-ins"]["gnss_outages"],
                        filters["gps-ins/rts"]["gnss_outages"], strict=True):
        assert rts["sigma_end_h"] < fwd["sigma_end_h"] / 3.0, (fwd, rts)
    # the 30 s outage (the 15 s one drifts less than the 2.5 m GNSS noise at its ends)
    fwd, rts = (filters[x]["gnss_outages"][1] for x in ("gps-ins", "gps-ins/rts"))
    assert rts["rms_h"] < fwd["rms_h"] / 5.0, (fwd, rts)


def _ensemble(scale: float, runs: int = 400, seed: int = 5) -> dict:
    """Position errors of ``runs`` runs drawn with sigma ``scale`` times the predicted one."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 100.0)
    sigma = np.stack([1.0 + 0.1 * t, 2.0 + 0.05 * t, 0.5 + 0.0 * t], axis=1)
    e = scale * sigma * rng.standard_normal((runs, *sigma.shape))
    rms = np.sqrt(np.mean(e**2, axis=0))
    return ensemble_outages(t, rms, sigma, runs, ((30.0, 60.0), (70.0, 90.0)))


def test_the_ensemble_check_passes_consistent_errors_and_rejects_over_confidence() -> None:
    ok = _ensemble(1.0)
    assert all(o["passed"] for o in ok)
    assert ok[0]["t_end"] == 59.0 and ok[0]["band"][0] < 1.0 < ok[0]["band"][1]
    assert ok[0]["ratio_end_h"] == pytest.approx(ok[0]["err_end_h"] / ok[0]["sigma_end_h"])
    assert not any(o["passed"] for o in _ensemble(1.2))  # errors 20 % above the sigma
    assert not any(o["passed"] for o in _ensemble(1 / 1.2))


def test_the_outage_table() -> None:
    run = {"start": 20.0, "end": 35.0, "t_end": 34.9, "err_end_h": 6.14, "err_end_v": -1.29,
           "sigma_end_h": 7.31, "sigma_end_v": 1.68, "rms_h": 2.94, "rms_v": 0.571}
    text = tables.format_summaries({"gps-ins": {"gnss_outages": [run, {"start": 80.0,
                                                                       "end": 90.0}]}})
    lines = text.splitlines()
    assert lines[-3].split()[:3] == ["GNSS", "outage", "[s]"]
    assert lines[-2].split() == ["gps-ins", "20-35", "6.14", "7.31", "-1.29", "1.68", "2.94",
                                 "0.571"]
    assert lines[-1].split()[-3:] == ["no", "estimate", "inside"]
    ens = _ensemble(1.0)[0]
    row = tables.outage_rows({"gps-ins": {"gnss_outages": [ens]}}).splitlines()[1]
    assert row.endswith("ok") and f"H/σ {ens['ratio_end_h']:.3g}" in row


def test_a_malformed_outage_entry_is_named_once() -> None:
    rec = simulate("vehicle-drive", {"duration": 10.0}, seed=1)
    extra = {**rec.metadata.extra, "gnss_outages": [[5.0, 2.0]]}  # ends before it starts
    bad = Recording(rec.streams, dataclasses.replace(rec.metadata, extra=extra))
    with pytest.raises(RecordingError, match=r"^bad\.mcap: metadata.extra\['gnss_outages'\]: "
                                             r"\[5\.0, 2\.0\] is not a \[start, end\] pair"):
        replay_file(MemorySource(bad, "bad.mcap"), [FilterSpec("gps-ins")])


def test_the_outages_are_shaded_in_the_view(outage_drive, tmp_path) -> None:
    """``navreplay run --save``: each outage's ±3σ band under the position errors (rows
    inside the outage only), the true track inside the outages over the trajectory and the map;
    ``navreplay montecarlo``'s position RMS plots shade them too."""
    from rrd import read_rrd, scalars

    from navreplay.jobs.montecarlo import MonteCarloJob, montecarlo
    from navreplay.viz.style import BAND_LINES

    rec, path = outage_drive
    out = tmp_path / "run.rrd"
    run_job.run(run_job.RunJob(filters=(FilterSpec("gps-ins"),), recordings=(path,),
                               viz=VizOptions(mode=VizMode.SAVE, path=out)))
    data = read_rrd(out)
    for axis in ("p_N", "p_E", "p_D"):
        error = scalars(data, f"/gps-ins/error/{axis}")  # error, +3σ, -3σ
        t_err = data[f"/gps-ins/error/{axis}"]["time"] * 1e-9
        for k, (start, end) in enumerate(((20.0, 35.0), (50.0, 80.0)), 1):
            band = scalars(data, f"/gps-ins/error/{axis}/gnss_outage/{k}")
            t = data[f"/gps-ins/error/{axis}/gnss_outage/{k}"]["time"] * 1e-9
            assert band.shape[1] == BAND_LINES and t[0] == pytest.approx(start)
            assert t[-1] == pytest.approx(end - 0.1)
            rows = np.searchsorted(t_err, t)
            np.testing.assert_allclose(band[:, -1], error[rows, 1], rtol=1e-12)
            np.testing.assert_allclose(band[:, 0], error[rows, 2], rtol=1e-12)
    assert {"/world/truth/gnss_outages", "/map/truth/gnss_outages"} <= data["static"].keys()
    assert not any("gnss_outage" in p for p in data if p.startswith("/gps-ins/error/v_"))

    mc = tmp_path / "mc.rrd"
    report = montecarlo(MonteCarloJob(
        scenario="vehicle-drive", runs=2, filters=(FilterSpec("gps-ins"),),
        values={"duration": 60.0, "imu_grade": "mems", "gps_outages": "20:15"},
        viz=VizOptions(mode=VizMode.SAVE, path=mc)))
    assert "gps-ins 20-35" in report.table and "H/σ" in report.table
    shaded = [p for p in read_rrd(mc) if p.startswith("/ensemble/") and "gnss_outage" in p]
    assert len(shaded) == 3 and all(r"position\ error" in p for p in shaded)
