"""A 2 s IMU gap for every built-in filter: the run stays consistent after it, or stops with one
line; never exit 0 with an inconsistent result."""

from __future__ import annotations

import json

import numpy as np
import pytest
from commands import cut_imu, invoke, one_line_error

from navreplay import metrics
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter
from navreplay.filters.registry import filters
from navreplay.filters.rpm_aided_ins import RpmAidedIns
from navreplay.filters.vector_matching import VectorMatchingFilter
from navreplay.geo.rotations import quat_to_euler
from navreplay.io import write_recording
from navreplay.replay import ReplayError, replay
from navreplay.sim.scenario import simulate

GAP = 2.0


def test_every_builtin_filter_is_covered():
    """A new built-in filter must be added to the tests of this module."""
    assert set(filters()) == {"ins", "gps-ins", "rpm-aided-ins", "transfer-alignment",
                              "vector-matching"}


UNDERWATER_SEEDS = range(1, 13)
FALSE_ALARM = 0.001  # per side


@pytest.fixture(scope="module")
def underwater():
    return [simulate("underwater-rpm", {"duration": 110.0}, seed=s) for s in UNDERWATER_SEEDS]


def _after_gap(recs, t_gap: float, gap: float, params=None):
    """Per run, the time-averaged horizontal-position NEES after the gap (one sample per run,
    docs/methods/consistency.md) and the time-averaged NIS per measurement from the gap on."""
    nees, nis = [], {}
    for rec in recs:
        m = metrics.run_metrics(replay(cut_imu(rec, t_gap, gap), RpmAidedIns, params), rec)
        after = (m.t > t_gap + gap) & (m.t <= 108.0)
        assert after.sum() > 10
        nees.append(np.mean(m.nees[after]))
        for name, (t, v, dof) in m.nis.items():
            sel = (t > t_gap) & (t <= 108.0)
            nis.setdefault(name, (dof, []))[1].append(np.mean(v[sel]))
    return np.array(nees), nis


@pytest.mark.parametrize("t_gap", [75.0, 88.0])  # inside the 60-90 s turn, and at its end
def test_rpm_aided_ins_nees_in_band_after_a_gap(underwater, t_gap):
    """The bridge holds the last turn rate through the gap; whether the turn goes on (75 s) or
    ends in the gap (88 s), the covariance covers the error after it: over 12 runs the mean
    horizontal-position NEES (2 dof) is below the top of its chi-square band (it may be
    conservative: the bridge covers motion that did not happen), and the RPM and depth NIS
    from the gap on are below the tops of theirs."""
    nees, nis = _after_gap(underwater, t_gap, GAP)
    runs = len(nees)
    assert nees.mean() < metrics.chi2_bounds(2, runs, 1.0 - 2 * FALSE_ALARM)[1], nees
    for name, (dof, v) in nis.items():
        assert np.mean(v) < metrics.chi2_bounds(dof, runs, 1.0 - 2 * FALSE_ALARM)[1], name


def test_rpm_aided_ins_without_the_bridge_covariance_would_fail(underwater):
    """Held motion without the covariance of its unknown change: the mean NEES after a longer
    gap at the end of the turn leaves the band (the test above can fail)."""
    nees, _ = _after_gap(underwater, 88.0, 5.0, {"gap_accel_sigma": 0.0, "gap_rate_sigma": 0.0})
    assert nees.mean() > metrics.chi2_bounds(2, len(nees), 1.0 - 2 * FALSE_ALARM)[1], nees


@pytest.fixture(scope="module")
def drive():
    return simulate("vehicle-drive", {"duration": 60.0}, seed=1)


def test_ins_nees_in_band_after_a_gap(drive):
    """Free inertial: after a 2 s gap at 40 s (the vehicle turning) the covariance covers the
    error, 9-dof NEES below its band's top at every output (nothing aids the filter to bring
    the bridged covariance back down: it may stay conservative); without the covariance of
    the unknown motion it would not."""
    hi = metrics.chi2_bounds(9)[1]
    for sigmas, covered in (({}, True), ({"gap_accel_sigma": 0.0, "gap_rate_sigma": 0.0}, False)):
        m = metrics.run_metrics(replay(cut_imu(drive, 40.0, GAP), InsFilter, sigmas), drive)
        assert len(m.nees_states) == 9
        after = m.t > 42.0
        assert np.all(m.nees[after] < hi) == covered, np.max(m.nees[after])


def test_gps_ins_gap_is_bridged(drive):
    """(The NEES band after the gap: tests/cli/test_robustness.py.) The bridge is used."""
    assert callable(GpsInsFilter.bridge_imu_gap)


def _attitude_error(res, rec) -> np.ndarray:
    truth = rec["truth"]
    t = (truth.t_ns - rec.t0_ns) * 1e-9
    euler = np.unwrap(np.array([quat_to_euler(q) for q in truth.columns["q_nb"]]), axis=0)
    ref = np.array([np.interp(res.t, t, euler[:, i]) for i in range(3)]).T
    return np.angle(np.exp(1j * (res.extras["euler"] - ref)))


def test_vector_matching_after_a_gap_is_as_good_as_without():
    """Gyro-free: the epochs without an accelerometer only carry the covariance and the GNSS
    velocity; after the gap the attitude error and the NIS are those of the run without a
    gap (the filter's own consistency is the published model's, not a band)."""
    rec = simulate("gimpo-accel-yaw", {}, seed=1)
    whole = replay(rec, VectorMatchingFilter)
    gap = replay(cut_imu(rec, 15.0, GAP), VectorMatchingFilter)
    sel_w, sel_g = whole.t > 18.0, gap.t > 18.0
    err_w = np.abs(_attitude_error(whole, rec)[sel_w]).max(axis=0)
    err_g = np.abs(_attitude_error(gap, rec)[sel_g]).max(axis=0)
    assert np.all(err_g <= err_w + np.radians(0.2)), np.degrees([err_g, err_w])
    nis_w = metrics.run_metrics(whole, rec).nis["vector"]
    nis_g = metrics.run_metrics(gap, rec).nis["vector"]
    assert np.mean(nis_g[1][nis_g[0] > 18.0]) < 1.1 * np.mean(nis_w[1][nis_w[0] > 18.0])
    assert gap.t[(gap.t > 15.0) & (gap.t < 17.0)].size > 0  # estimates through the gap


def test_transfer_alignment_gap_stops_in_one_line(tmp_path):
    """Transfer alignment has no honest bridge (the unmatched Q_br component is recovered from
    the SDINS attitude): a gap stops the run, naming the filter, the gap and --max-imu-gap."""
    rec = simulate("ship-transfer-alignment", {"duration": 20.0}, seed=1)
    path = tmp_path / "ship.mcap"
    write_recording(path, cut_imu(rec, 10.0, GAP))
    one_line_error(invoke("run", "transfer-alignment", path, "--no-viz"), str(path),
                   "'transfer-alignment'", "2.010 s", "t = 10.000 s", "bridge_imu_gap",
                   "--max-imu-gap")


def test_a_plugin_without_a_bridge_stops_on_a_gap(drive):
    class NoBridge(GpsInsFilter):
        bridge_imu_gap = None

    with pytest.raises(ReplayError, match="cannot bridge an IMU gap"):
        replay(cut_imu(drive, 40.0, GAP), NoBridge)
    replay(drive, NoBridge)  # without a gap it runs


# --------------------------------------------------------------------------------------------
# campaigns: --max-imu-gap and salvaged runs


@pytest.fixture(scope="module")
def gap_files(tmp_path_factory, drive):
    d = tmp_path_factory.mktemp("gaps")
    whole, cut = d / "whole.mcap", d / "cut.mcap"
    write_recording(whole, drive)
    write_recording(cut, cut_imu(drive, 40.0, 8.0))
    return whole, cut


def test_run_over_several_recordings_honours_max_imu_gap(gap_files, tmp_path):
    whole, cut = gap_files
    one_line_error(invoke("run", "gps-ins", whole, cut, "--no-viz"), str(cut), "8.010 s",
                   "t = 40.000 s", "--max-imu-gap")
    summary = tmp_path / "s.json"
    res = invoke("run", "gps-ins", whole, cut, "--no-viz", "--max-imu-gap", "9",
                 "--summary", summary)
    assert res.exit_code == 0, res.output
    rows = json.loads(summary.read_text())["runs"]
    assert [(r["salvaged"], r["coverage"]) for r in rows] == [(False, 1.0), (False, 1.0)]
    one_line_error(invoke("run", "gps-ins", whole, cut, "--no-viz", "--max-imu-gap", "-1",
                          "--summary", tmp_path / "t.json"), "--max-imu-gap")
    assert not (tmp_path / "t.json").exists()


def test_montecarlo_max_imu_gap_is_checked_before_the_work(tmp_path):
    res = invoke("montecarlo", "stationary", "ins", "--runs", "2", "--duration", "5",
                 "--no-viz", "--max-imu-gap", "nan", "--summary", tmp_path / "s.json")
    one_line_error(res, "--max-imu-gap")
    assert not (tmp_path / "s.json").exists()
    res = invoke("montecarlo", "stationary", "ins", "--runs", "2", "--duration", "5",
                 "--no-viz", "--max-imu-gap", "3", "--summary", tmp_path / "s.json")
    assert res.exit_code == 0, res.output
    rows = json.loads((tmp_path / "s.json").read_text())["runs"]
    assert [(r["salvaged"], r["coverage"]) for r in rows] == [(False, 1.0), (False, 1.0)]


def test_campaign_rows_say_which_runs_were_salvaged(gap_files, tmp_path, monkeypatch):
    from navreplay.io import writer

    monkeypatch.setattr(writer, "CHUNK_SIZE", 1 << 16)
    small = tmp_path / "small.mcap"
    write_recording(small, simulate("vehicle-drive", {"duration": 20.0}, seed=3))
    data = small.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    summary = tmp_path / "s.json"
    res = invoke("run", "gps-ins", small, cut, "--no-viz", "--summary", summary)
    assert res.exit_code == 0, res.output
    assert f"SALVAGED: {cut}" in res.output and f"SALVAGED: {small}" not in res.output
    rows = json.loads(summary.read_text())["runs"]
    assert rows[0]["salvaged"] is False and rows[0]["coverage"] == 1.0
    assert rows[1]["salvaged"] is True and 0.2 < rows[1]["coverage"] < 0.9


@pytest.mark.parametrize("option", ["--report", "--export"])
def test_montecarlo_result_outputs_are_checked_before_the_work(tmp_path, option):
    """--report and --export of montecarlo go through the same output checks as --summary:
    never onto an input (the config), never into an unwritable directory, before any run."""
    config = tmp_path / "c.toml"
    config.write_text("[filter.ins]\n")
    base = ["montecarlo", "stationary", "ins", "--runs", "1", "--duration", "5", "--no-viz",
            "--config", config]
    if option == "--report":
        one_line_error(invoke(*base, option, config, "--force"), option)  # onto the input
        assert config.read_text() == "[filter.ins]\n"
    # a directory that cannot be made (its parent is a file): refused before any run, even for
    # a user who may write anywhere
    blocker = tmp_path / "blocker"
    blocker.write_text("not a directory\n")
    res = invoke(*base, option, blocker / "out" if option == "--export" else blocker / "r.html")
    one_line_error(res, option)
    assert blocker.read_text() == "not a directory\n"
    assert not list(tmp_path.glob("**/*.part"))
