"""Recorded estimators as rows beside the replayed filters (``run --onboard``), on logs
navreplay did not write: PX4's estimate in a ULog file written from the format's
specification, a NavSatFix topic with its covariance in a rosbags-written bag, and the master
INS of the ship scenario."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from reference_files import write_reference_csv
from rosbag_maker import write_bag
from rrd import read_rrd
from ulog_maker import EKF2_ERRORS, write_px4_log

from navreplay.cli import cli
from navreplay.core.chi2 import ppf as chi2_ppf
from navreplay.core.streams import StreamKind
from navreplay.geo.rotations import quat_to_euler
from navreplay.io import write_recording
from navreplay.sim.scenario import simulate


def invoke(*args: object) -> tuple[int, str]:
    res = CliRunner().invoke(cli, [str(a) for a in args])
    return res.exit_code, res.output


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 60 s simulated drive as a PX4 log with its truth, offset by :data:`EKF2_ERRORS`, as
    PX4's estimate; the truth as a CSV reference."""
    d = tmp_path_factory.mktemp("onboard")
    rec = simulate("vehicle-drive", {"duration": 60.0}, seed=2)
    tr = rec[StreamKind.TRUTH]
    k = slice(None, None, 5)
    write_reference_csv(d / "ref.csv", tr.t_ns[k], tr["pos"][k], tr["v_n"][k],
                        quat_to_euler(tr["q_nb"][k]))
    return {"ulg": write_px4_log(d / "flight.ulg", rec), "ref": d / "ref.csv",
            "mcap": write_recording(d / "flight.mcap", rec)}


def test_ekf2_beside_the_filter_in_one_command(flight: dict[str, Path], tmp_path: Path) -> None:
    """`run gps-ins flight.ulg --onboard ekf2`: PX4's estimate is a row of its own, scored
    against the reference with the errors it was written with (1 m north, 0.1 m/s east, 1 deg
    of yaw), its NEES from the logged variances (per axis eph/sqrt(2) = 1 m and evh/sqrt(2) =
    0.1 m/s: a NEES of exactly 2 over 6 degrees of freedom), and it is in the view, the
    exports and the report as a filter is."""
    code, out = invoke("run", "gps-ins", flight["ulg"], "--onboard", "ekf2", "--reference",
                       flight["ref"], "--init", "reference", "--save", tmp_path / "v.rrd",
                       "--export", tmp_path / "exp", "--report", tmp_path / "r.html",
                       "--summary", tmp_path / "s.json")
    assert code == 0, out
    assert "onboard ekf2: " in out and "position, velocity, attitude at 50 Hz" in out
    s = json.loads((tmp_path / "s.json").read_text())["filters"]
    assert list(s) == ["gps-ins", "ekf2"]
    ekf2 = s["ekf2"]
    assert ekf2["pos_rms_h"] == pytest.approx(EKF2_ERRORS["north"], abs=2e-3)
    assert ekf2["vel_rms"] == pytest.approx(EKF2_ERRORS["v_east"], abs=1e-4)
    assert ekf2["att_rms_heading"] == pytest.approx(math.radians(EKF2_ERRORS["yaw_deg"]),
                                                    rel=1e-3)
    assert ekf2["att_rms_level"] < 1e-4
    assert ekf2["nees_mean"] == pytest.approx(2.0, rel=1e-2)
    assert ekf2["recorded"].endswith("vehicle_local_position + vehicle_global_position + "
                                     "vehicle_attitude")
    assert s["gps-ins"]["pos_rms_h"] < 1.0
    assert {"ekf2.csv", "ekf2.tum"} <= {p.name for p in (tmp_path / "exp").iterdir()}
    header = (tmp_path / "exp" / "ekf2.csv").read_text().splitlines()[0]
    assert "lat [deg]" in header
    assert "ekf2" in (tmp_path / "r.html").read_text()
    view = read_rrd(tmp_path / "v.rrd")
    assert {"/ekf2/nav/yaw", "/ekf2/nees", "/ekf2/error/p_N", "/map/ekf2/position"} <= set(view)
    # without a filter: the recorded solution alone, scored the same
    code, out = invoke("run", flight["ulg"], "--onboard", "ekf2", "--reference", flight["ref"],
                       "--no-viz", "--summary", tmp_path / "alone.json")
    assert code == 0 and out.startswith("ekf2 over "), out
    alone = json.loads((tmp_path / "alone.json").read_text())["filters"]
    assert list(alone) == ["ekf2"] and alone["ekf2"] == ekf2


def test_onboard_alone_and_its_errors(flight: dict[str, Path], tmp_path: Path) -> None:
    """Without a reference the row is shown and exported, unscored; over --start/--end it is
    cut to the span; ekf2 on a log that is not PX4's, or a topic the log lacks, is one line
    before anything is written."""
    code, out = invoke("run", "gps-ins", flight["ulg"], "--onboard", "ekf2", "--init", "align",
                       "--no-viz", "--export", tmp_path / "whole", "--summary",
                       tmp_path / "s.json")
    assert code == 0, out
    assert "pos_rms_h" not in json.loads((tmp_path / "s.json").read_text())["filters"]["ekf2"]
    assert len((tmp_path / "whole" / "ekf2.csv").read_text().splitlines()) == 1 + 3001
    code, out = invoke("run", "gps-ins", flight["ulg"], "--onboard", "ekf2", "--init",
                       "reference", "--reference", flight["ref"], "--start", "20", "--end", "40",
                       "--no-viz", "--export", tmp_path / "e")
    assert code == 0, out
    rows = (tmp_path / "e" / "ekf2.csv").read_text().splitlines()
    t = np.array([float(r.split(",")[0]) for r in rows[1:]])
    assert t.size == 1001 and np.ptp(t) * 1e-9 == pytest.approx(20.0, abs=1e-6)  # stamp [ns]
    code, out = invoke("run", "gps-ins", flight["mcap"], "--onboard", "ekf2", "--no-viz")
    assert code == 1 and f"{flight['mcap']}: --onboard ekf2 reads PX4's estimate from a ULog " \
        "file; this log is mcap" in out
    bare = write_px4_log(tmp_path / "bare.ulg", simulate("vehicle-drive", {"duration": 20.0},
                                                         seed=2), ekf2=False)
    code, out = invoke("run", "gps-ins", bare, "--onboard", "ekf2", "--init", "align",
                       "--no-viz")
    assert code == 1 and f"{bare}: --onboard ekf2: no topic vehicle_local_position" in out
    code, out = invoke("run", "gps-ins", flight["mcap"], "--onboard", "/ins/odom", "--no-viz")
    assert code == 1 and "--onboard /ins/odom: no such topic in" in out
    (tmp_path / "other").mkdir()
    twin = tmp_path / "other" / flight["ref"].name
    twin.write_bytes(flight["ref"].read_bytes())
    code, out = invoke("run", "gps-ins", flight["ulg"], "--onboard", flight["ref"], "--onboard",
                       twin, "--no-viz")
    assert code == 1 and "two recorded solutions would be named ref.csv" in out


def test_navsatfix_topic_as_onboard_nees_in_its_band(tmp_path: Path) -> None:
    """A receiver's own fixes as the recorded solution (a rosbags-written bag, seed 5, not used
    for anything else): scored against the ground truth, the position NEES of its declared
    covariance (the noise it was drawn with) lies in the two-sided 99 % band of a mean of
    N x 3 chi-square degrees of freedom."""
    bag = write_bag(tmp_path / "bag", noisy=True, duration=120.0, seed=5)
    code, out = invoke("run", "ins", bag, "--init", "reference", "--reference",
                       "/ground_truth/odom", "--onboard", "/gnss/fix", "--no-viz",
                       "--summary", tmp_path / "s.json")
    assert code == 0, out
    fix = json.loads((tmp_path / "s.json").read_text())["filters"]["/gnss/fix"]
    n = 120  # fixes at 1 Hz
    lo, hi = chi2_ppf(0.005, 3 * n) / n, chi2_ppf(0.995, 3 * n) / n
    assert lo < fix["nees_mean"] < hi, (lo, fix["nees_mean"], hi)
    assert 0.5 < fix["pos_rms_h"] < 4.0
    assert fix.get("vel_rms") is None and fix.get("att_rms_heading") is None  # not given
    assert "onboard /gnss/fix: /gnss/fix: position at 1 Hz, variances of position (NEES)" in out


def test_master_ins_of_the_ship_beside_transfer_alignment(tmp_path: Path) -> None:
    """The ship's master INS as a row: its solution is the master's (the GINS position, the
    ship's attitude), so scored against the truth of the SDINS that transfer alignment
    estimates its errors are the lever arm and the misalignment between the two; without
    variances it has no NEES."""
    rec = simulate("ship-transfer-alignment", {"duration": 30.0}, seed=4)
    path = write_recording(tmp_path / "ship.mcap", rec)
    code, out = invoke("run", "transfer-alignment", path, "--onboard", "master_ins", "--no-viz",
                       "--summary", tmp_path / "s.json")
    assert code == 0, out
    s = json.loads((tmp_path / "s.json").read_text())["filters"]
    mins = s["master_ins"]
    assert "nees_mean" not in mins or mins["nees_mean"] is None
    tr = rec[StreamKind.TRUTH]
    from navreplay.geo.earth import lla_to_ned_offset

    d = lla_to_ned_offset(*tr["pos"].T, *tr["pos_r"].T)
    lever_h = float(np.sqrt(np.mean(d[:, 0] ** 2 + d[:, 1] ** 2)))
    assert mins["pos_rms_h"] == pytest.approx(lever_h, rel=0.05)
    assert s["transfer-alignment"]["pos_rms_h"] < 0.1 * mins["pos_rms_h"]
