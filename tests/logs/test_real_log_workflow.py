"""The ordinary workflow on logs navreplay did not write (rosbags-written bags, text files):
references with part of a solution, topics named on the command line, time windows."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from rosbag_maker import truth_table, write_bag

from navreplay.cli import cli

DRIVE = 90.0


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 90 s rosbag2 drive (60 s still, then 10 m/s with turns): tactical IMU, 1.5 m GNSS."""
    return write_bag(tmp_path_factory.mktemp("drive") / "drive", noisy=True, duration=DRIVE,
                     seed=3)


def invoke(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(cli, list(args))
    return res.exit_code, res.output



def _initial_toml(path: Path, tab: dict, k: int) -> Path:
    """A config whose [initial] table is the truth at row k of the drive's truth table."""
    lat, lon, h = (float(x) for x in tab["lla"][k])
    roll, pitch, yaw = (float(x) for x in np.degrees(tab["euler"][k]))
    path.write_text(
        f"[initial]\nlat_deg = {math.degrees(lat)!r}\nlon_deg = {math.degrees(lon)!r}\n"
        f"h = {h!r}\nv_n = {[float(v) for v in tab['v_n'][k]]!r}\nroll_deg = {roll!r}\n"
        f"pitch_deg = {pitch!r}\nyaw_deg = {yaw!r}\npos_sigma = 0.5\nvel_sigma = 0.05\n"
        "att_sigma_deg = [0.1, 0.1, 0.5]\n")
    return path

def _reference_csv(path: Path, header: str, rows: list[str]) -> Path:
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def _rows(parts: str) -> list[str]:
    tab = truth_table(DRIVE)
    out = []
    for t, p, v, e in zip(tab["t_ns"], tab["lla"], tab["v_n"], tab["euler"], strict=True):
        cols = {"t": [f"{t * 1e-9:.4f}"], "t_ns": [str(t)],
                "pos": [f"{math.degrees(p[0]):.10f}", f"{math.degrees(p[1]):.10f}",
                        f"{p[2]:.4f}"],
                "vel": [f"{x:.6f}" for x in v],
                "att": [f"{math.degrees(x):.6f}" for x in e]}
        out.append(",".join(x for part in parts.split() for x in cols[part]))
    return out


@pytest.mark.parametrize(("name", "header", "parts", "scored", "unscored", "lacks"), [
    # a header in a comment line, common names with units: position only
    ("pos", "# RTK drive\n# Time [s], Latitude, Longitude, Altitude (m)", "t pos",
     ["pos_rms_h"], ["vel_rms", "att_rms_heading"], "no velocity or attitude"),
    ("vel", "t_ns,vel_n,vel_e,vel_d", "t_ns vel", ["vel_rms"], ["pos_rms_h", "att_rms_heading"],
     "no position or attitude"),
    ("att", "time,roll,pitch,heading", "t att", ["att_rms_heading"], ["pos_rms_h", "vel_rms"],
     "no position or velocity"),
])
def test_partial_reference_everywhere(drive: Path, tmp_path: Path, name: str, header: str,
                                      parts: str, scored: list[str], unscored: list[str],
                                      lacks: str) -> None:
    """A reference with one part of a solution: the summary scores that part only, the view,
    the exports and the report are written, and what it lacks is said once."""
    ref = _reference_csv(tmp_path / f"{name}.csv", header, _rows(parts))
    code, out = invoke("run", "gps-ins", str(drive), "--reference", str(ref), "--init", "align",
                       "--export", str(tmp_path / "exp"), "--report", str(tmp_path / "r.html"),
                       "--save", str(tmp_path / "v.rrd"), "--summary", str(tmp_path / "s.json"))
    assert code == 0, out
    s = json.loads((tmp_path / "s.json").read_text())["filters"]["gps-ins"]
    for key in scored:
        assert math.isfinite(s[key]), key
    for key in unscored:
        assert key not in s
    assert out.count(f"{lacks}: not scored, not drawn") == 1
    assert (tmp_path / "v.rrd").stat().st_size > 0
    page = (tmp_path / "r.html").read_text()
    assert f"{lacks}: not scored, not drawn" in page
    manifest = json.loads((tmp_path / "exp" / "manifest.json").read_text())
    assert ("reference" in manifest) == (name == "pos")  # poses need a position
    assert manifest["origin"] is not None
    if name == "pos":  # the reference drives 200 m; the filter ends within a few metres
        assert s["distance"] > 150.0 and s["pos_err_final_h"] < 5.0


def test_reference_csv_columns_refused_in_one_line(drive: Path, tmp_path: Path) -> None:
    """Two columns for one quantity, or no usable column, name the file."""
    ref = _reference_csv(tmp_path / "dup.csv", "t,lat,latitude,lon,h", ["0,45,45,7,300"] * 2)
    code, out = invoke("run", "gps-ins", str(drive), "--reference", str(ref), "--init", "align",
                       "--no-viz")
    assert code == 1 and f"{ref}: columns 'lat' and 'latitude' both give lat_deg" in out
    ref = _reference_csv(tmp_path / "none.csv", "t,speed", ["0,1", "1,2"])
    code, out = invoke("run", "gps-ins", str(drive), "--reference", str(ref), "--init", "align",
                       "--no-viz")
    assert code == 1 and str(ref) in out and "no position, velocity or attitude" in out


@pytest.mark.parametrize("command", [
    ["run", "gps-ins", "{bag}", "--init", "align", "--no-viz"],
    ["run", "ins", "{bag}", "--reference", "/ground_truth/odom", "--init", "reference",
     "--no-frame-check", "--no-viz"],  # the named stream is not one the run reads
    ["run", "ins", "{bag}", "{bag}", "--reference", "/ground_truth/odom", "--init",
     "reference", "--no-viz"],
    ["info", "{bag}"],
])
@pytest.mark.parametrize(("named", "expect"), [
    ("imu=/imu", "topic /imu named for stream imu is not in the bag"),
    ("mag=/imu/mag", "topic /imu/mag named for stream mag is not in the bag"),
    ("gps_vel=/gnss/fix", "topic /gnss/fix has schema 'sensor_msgs/msg/NavSatFix'"),
])
def test_every_named_topic_must_exist_with_its_type(drive: Path, tmp_path: Path,
                                                    command: list[str], named: str,
                                                    expect: str) -> None:
    args = [a.replace("{bag}", str(drive)) for a in command]
    code, out = invoke(*args, "--topic", named)
    assert code == 1, out
    last = out.strip().splitlines()[-1]
    assert last.startswith("Error: ") and str(drive) in last and expect in last


def test_allan_topic_must_be_an_imu(drive: Path) -> None:
    code, out = invoke("allan", str(drive), "--topic", "/gnss/fix", "--end", "50")
    assert code == 1 and str(drive) in out and "/gnss/fix has schema" in out
    code, out = invoke("allan", str(drive), "--topic", "/imu")
    assert code == 1 and "topic /imu named for stream imu is not in the bag" in out


def test_export_rows_do_not_repeat(drive: Path, tmp_path: Path) -> None:
    """Each exported estimate time appears once."""
    code, out = invoke("run", "gps-ins", str(drive), "--init", "align", "--no-viz",
                       "--export", str(tmp_path / "exp"))
    assert code == 0, out
    stamps = np.loadtxt(tmp_path / "exp" / "gps-ins.csv", delimiter=",", skiprows=1,
                        usecols=0, dtype=np.int64)
    assert len(stamps) > 100 and np.all(np.diff(stamps) > 0)


def test_info_over_a_span(drive: Path) -> None:
    """--start/--end in seconds from the start or as a UTC time: the IMU rows counted over
    the span (50 Hz over 30 s), one line for a span the log does not have."""
    for start, end in (("30", "60"), ("2025-06-15T15:07:10Z", "1750000060")):
        code, out = invoke("info", str(drive), "--start", start, "--end", end)
        assert code == 0, out
        row = next(ln.split() for ln in out.splitlines() if ln.startswith("/imu/data"))
        assert row[5:9] == ["1501", "50.000", "30.000", "60.000"], row
    code, out = invoke("info", str(drive), "--start", "60", "--end", "30")
    assert code == 1 and "--start 60 is not before --end 30" in out
    code, out = invoke("run", "gps-ins", str(drive), "--start", "200", "--init", "align",
                       "--no-viz")
    assert code == 1 and f"{drive}: no IMU sample in t = 200.000 to end s" in out


def test_run_over_a_span_starts_there(drive: Path, tmp_path: Path) -> None:
    """--start 30 --end 85 with --init align: aligned over the still 30..62 s, exported from
    the end of the alignment to 85 s, once per time; --init table at 70 s lands on the truth."""
    code, out = invoke("run", "gps-ins", str(drive), "--start", "30", "--end", "85", "--init",
                       "align", "--no-viz", "--export", str(tmp_path / "exp"))
    assert code == 0, out
    assert "align over the still start (32.0 s)" in out and "replayed t = 30.000 to 85.000 s" in out
    t = np.loadtxt(tmp_path / "exp" / "gps-ins.csv", delimiter=",", skiprows=1, usecols=1)
    assert t[0] == pytest.approx(62.0) and t[-1] == pytest.approx(85.0)
    assert np.all(np.diff(t) > 0)
    tab = truth_table(DRIVE)
    k = int(np.searchsorted(tab["t_ns"], tab["t_ns"][0] + 70 * 10**9))
    config = _initial_toml(tmp_path / "init.toml", tab, k)
    ref = _reference_csv(tmp_path / "ref.csv", "t_ns,lat,lon,h,vn,ve,vd", _rows("t_ns pos vel"))
    code, out = invoke("run", "ins", str(drive), "--start", "70", "--end", "75", "--init",
                       "table", "--config", str(config), "--reference", str(ref),
                       "--no-viz", "--summary", str(tmp_path / "s.json"))
    assert code == 0, out
    s = json.loads((tmp_path / "s.json").read_text())["filters"]["ins"]
    assert s["duration"] == pytest.approx(5.0, abs=0.05)
    assert s["pos_err_final_h"] < 0.1 and s["vel_rms"] < 0.05


def test_allan_over_an_absolute_span(drive: Path, tmp_path: Path) -> None:
    """allan's --start/--end take UNIX seconds as run's do (the still 5..55 s of the drive;
    its IMU topic starts 0.02 s after the bag's first message)."""
    code, out = invoke("allan", str(drive), "--start", "1750000005", "--end", "55",
                       "--bootstrap", "0")
    assert code == 0, out
    assert "t = 4.98 to 55 s (50.02 s, 50 Hz, 2502 samples): still" in out


@pytest.fixture(scope="module")
def drive_ros1(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same drive as :func:`drive` in a ROS 1 bag (rosbags' rosbag1 writer)."""
    return write_bag(tmp_path_factory.mktemp("ros1") / "drive.bag", noisy=True,
                     duration=DRIVE, seed=3, ros1=True)


def test_ros1_bag_replays_like_the_ros2_bag(drive: Path, drive_ros1: Path,
                                            tmp_path: Path) -> None:
    """A ROS 1 bag of the same messages gives the ROS 2 bag's summary to the last bit (same
    conversions, same pipeline); info, --topic and --start work on it as on any log."""
    summaries = []
    for bag in (drive, drive_ros1):
        code, out = invoke("run", "gps-ins", str(bag), "--init", "align", "--reference",
                           "/ground_truth/odom", "--start", "10", "--no-viz", "--force",
                           "--summary", str(tmp_path / "s.json"))
        assert code == 0, out
        summaries.append(json.loads((tmp_path / "s.json").read_text())["filters"]["gps-ins"])
    assert summaries[0]["pos_rms_h"] < 2.0 and summaries[0]["att_rms_heading"] < 0.2
    for key in ("pos_rms_h", "vel_rms", "att_rms_heading", "nees_mean", "nis_mean_gps_pos"):
        assert summaries[1][key] == summaries[0][key], key
    code, out = invoke("info", str(drive_ros1))
    assert code == 0 and "(rosbag1, 5492 messages)" in out
    assert "/imu/data           sensor_msgs/msg/Imu        imu" in out
    code, out = invoke("run", "ins", str(drive_ros1), "--topic", "imu=/imu", "--no-viz")
    assert code == 1 and f"{drive_ros1}: topic /imu named for stream imu is not in the bag" in out
    broken = tmp_path / "cut.bag"
    broken.write_bytes(drive_ros1.read_bytes()[:5000])
    code, out = invoke("run", "ins", str(broken), "--no-viz")
    assert code == 1 and f"{broken}: not a readable ROS 1 bag" in out and "Traceback" not in out


@pytest.fixture(scope="module")
def gins_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from gins_maker import write_gins

    return write_gins(tmp_path_factory.mktemp("gins") / "drive")


def test_gins_text_log_replays_against_its_truth(gins_log: Path, tmp_path: Path) -> None:
    """A KF-GINS style folder (IMU increments, GNSS with std, an 11-column truth): info lists
    the files as topics, gps-ins aligns and scores against truth.nav to GNSS-aided accuracy;
    the IMU file alone opens the folder; a bad row and a wrong --topic are one line."""
    code, out = invoke("info", str(gins_log))
    assert code == 0, out
    rows = {ln.split()[0]: ln.split() for ln in out.splitlines() if ".txt" in ln or ".nav" in ln}
    assert rows["IMU.txt"][1:5] == ["gins/ImuIncrements", "imu", "imu_frd", "FRD"]
    assert rows["IMU.txt"][5:7] == ["9000", "100.000"] and rows["truth.nav"][2] == "(reference)"
    summaries = []
    for path in (gins_log, gins_log / "IMU.txt"):
        code, out = invoke("run", "gps-ins", str(path), "--init", "align", "--reference",
                           "truth.nav", "--no-viz", "--force", "--summary",
                           str(tmp_path / "s.json"), "--export", str(tmp_path / "exp"))
        assert code == 0, out
        summaries.append(json.loads((tmp_path / "s.json").read_text())["filters"]["gps-ins"])
    s = summaries[0]
    assert s["distance"] > 150.0 and s["pos_rms_h"] < 2.0 and s["vel_rms"] < 0.3
    assert s["att_rms_level"] < 0.05 and summaries[1]["pos_rms_h"] == s["pos_rms_h"]
    code, out = invoke("run", "gps-ins", str(gins_log), "--topic", "gps=GNSS.txt", "--no-viz")
    assert code == 1 and "topic GNSS.txt named for stream gps is not in the folder" in out
    code, out = invoke("run", "gps-ins", str(gins_log), "--topic", "gps=IMU.txt", "--no-viz")
    assert code == 1 and "topic IMU.txt has type gins/ImuIncrements; stream gps needs" in out
    bad = tmp_path / "bad"
    bad.mkdir()
    lines = (gins_log / "IMU.txt").read_text().splitlines()
    lines[100] = lines[100].replace(" ", " x", 1)
    (bad / "IMU.txt").write_text("\n".join(lines) + "\n")
    code, out = invoke("run", "ins", str(bad / "IMU.txt"), "--no-viz")
    assert code == 1 and f"{bad / 'IMU.txt'}, line 101: not a number" in out


WALK_GRADE = (10.0, 0.3, 0.02, 1e-3)
"""A MEMS IMU (gyro bias 10 deg/h: no gyrocompassing), as rosbag_maker's imu_grade."""


@pytest.fixture(scope="module")
def walks(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Handheld walks at 1 m/s after a 60 s still start, with a GNSS velocity topic (0.1 m/s)
    and 1.5 m fixes, no magnetometer: 120 s (walks 59 m) and 80 s (walks 19 m)."""
    root = tmp_path_factory.mktemp("walks")
    return {name: write_bag(root / name, noisy=True, imu_grade=WALK_GRADE, duration=duration,
                            speed=1.0, gps_vel=True, seed=0)
            for name, duration in (("walk", 120.0), ("short", 80.0))}


def test_align_on_a_slow_walk_uses_the_gnss_track(walks: dict[str, Path]) -> None:
    """Below 2 m/s the GNSS velocity gives no course: the heading comes from the track (the
    still position to the first fix 30 m away), within the sigma it states (seeds 1-8 of this
    walk, not this one: errors within 1.9 sigma, normalised RMS 1.2); a walk too short for
    the track is one line saying what was tried."""
    code, out = invoke("run", "ins", str(walks["walk"]), "--init", "align", "--topic",
                       "gps_vel=/gnss/vel", "--no-viz")
    assert code == 0, out
    line = next(ln for ln in out.splitlines() if ln.startswith("align over the still start"))
    assert "by GNSS track; gyrocompassing would give" in line
    assert "no magnetometer, no GNSS velocity over 2 m/s" in line
    yaw, sigma = (float(x) for x in re.search(
        r"yaw (-?[\d.]+) deg by .* \(1-sigma ([\d.]+) deg\)", line).groups())
    assert 1.0 < sigma < 5.0
    assert abs(yaw - math.degrees(0.4)) < 2.0 * sigma
    code, out = invoke("run", "ins", str(walks["short"]), "--init", "align", "--topic",
                       "gps_vel=/gnss/vel", "--no-viz")
    assert code == 1
    assert re.fullmatch(
        r"Error: --init align cannot find the heading \(gyrocompassing would give \d+ deg; no "
        r"magnetometer; no GNSS velocity over 2 m/s; no GNSS track of 30 m\): give yaw_deg in "
        r"\[initial\], a magnetometer topic, or use --init reference",
        out.strip().splitlines()[-1])


@pytest.mark.parametrize(("args", "error"), [
    (["--init", "align"], "Error: --init align cannot find the heading ("),
    (["--init", "table"], "Error: --init table: missing a position (lat_deg, lon_deg, h)"),
])
def test_failed_initialisation_is_one_line_on_stderr(tmp_path: Path, args: list[str],
                                                     error: str) -> None:
    """The console script on the MCAP file of a bag whose IMU stamps are zero (the reader
    warns) and whose start cannot be made: its warnings as `warning:` lines, then one error
    line; no raw `sys:1: RecordingWarning`, no traceback, nothing on stdout."""
    import subprocess
    import sys

    bag = write_bag(tmp_path / "bag", duration=30.0, imu_zero_stamps=True,
                    imu_grade=WALK_GRADE, noisy=True)
    data = next(bag.glob("*.mcap"))
    res = subprocess.run([sys.executable, "-m", "navreplay", "run", "gps-ins", str(data),
                          *args, "--no-viz"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 1 and res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert lines[-1].startswith(error) and "\n" not in lines[-1], res.stderr
    assert all(ln.startswith("warning: ") for ln in lines[:-1]), res.stderr
    assert any("header stamps are zero" in ln for ln in lines[:-1])
    assert "sys:1" not in res.stderr and "RecordingWarning" not in res.stderr


def test_initial_state_and_its_source_in_summary_text_and_report(drive: Path,
                                                                 tmp_path: Path) -> None:
    """The state the filters started from, with its source and time, is the summary's
    `initial`, one line of the text summary and a row of the report's context: [initial] at
    --start 70 (the values given, at the first IMU sample from 70 s), align over the still
    start (stamped at its end, 62 s, level within its sigma of the truth), and a method with
    [initial] values over it."""
    config = tmp_path / "init.toml"
    config.write_text("[initial]\nlat_deg = 45.001\nlon_deg = 7.002\nh = 310.0\n"
                      "v_n = [10.0, 0.5, 0.0]\nroll_deg = 1.0\npitch_deg = -2.0\nyaw_deg = 30.0\n"
                      "pos_sigma = [0.5, 0.5, 1.0]\natt_sigma_deg = [0.1, 0.1, 0.5]\n")
    code, out = invoke("run", "ins", str(drive), "--start", "70", "--end", "75", "--init",
                       "table", "--config", str(config), "--no-viz", "--summary",
                       str(tmp_path / "s.json"), "--report", str(tmp_path / "r.html"))
    assert code == 0, out
    init = json.loads((tmp_path / "s.json").read_text())["initial"]
    assert init["source"] == "[initial]" and init["t"] == pytest.approx(70.0, abs=0.021)
    assert init["t_ns"] - 1_750_000_070 * 10**9 == pytest.approx(0, abs=21_000_000)
    assert (init["lat_deg"], init["lon_deg"], init["h"]) == pytest.approx((45.001, 7.002, 310.0))
    assert init["v_n"] == pytest.approx([10.0, 0.5, 0.0])
    assert (init["roll_deg"], init["pitch_deg"], init["yaw_deg"]) == pytest.approx(
        (1.0, -2.0, 30.0), abs=1e-9)
    assert init["sigma"]["pos_ned"] == [0.5, 0.5, 1.0] and init["sigma"]["att_deg"] == [
        0.1, 0.1, 0.5]
    line = next(ln for ln in out.splitlines() if ln.startswith("initial state "))
    assert line.startswith(f"initial state from [initial] at t = {init['t']:.3f} s: "
                           "45.0010000 deg N, 7.0020000 deg E, 310.00 m; v_NED 10.00, 0.50, "
                           "0.00 m/s; roll 1.00, pitch -2.00, yaw 30.00 deg; 1-sigma 0.5, 0.5, "
                           "1 m"), line
    page = (tmp_path / "r.html").read_text()
    assert ("<td>initial state</td><td style='text-align:left'>"
            + line.removeprefix("initial state ")) in page
    tab = truth_table(DRIVE)
    code, out = invoke("run", "ins", str(drive), "--init", "align", "--no-viz", "--force",
                       "--summary", str(tmp_path / "s.json"))
    assert code == 0, out
    init = json.loads((tmp_path / "s.json").read_text())["initial"]
    assert init["source"].startswith("align (") and init["t"] == pytest.approx(62.0)
    for k, name in enumerate(("roll_deg", "pitch_deg")):
        assert abs(init[name] - math.degrees(tab["euler"][0, k])) < init["sigma"]["att_deg"][k]
    config.write_text("[initial]\nyaw_deg = 23.0\natt_sigma_deg = [0.2, 0.2, 1.0]\n"
                      "accel_bias_sigma = 0.003\n")
    code, out = invoke("run", "ins", str(drive), "--init", "align", "--config", str(config),
                       "--no-viz", "--force", "--summary", str(tmp_path / "s.json"))
    assert code == 0, out
    init = json.loads((tmp_path / "s.json").read_text())["initial"]
    assert init["source"] == "align ([initial] yaw_deg) + [initial] yaw_deg, att_sigma_deg"
    assert init["yaw_deg"] == pytest.approx(23.0) and init["sigma"]["att_deg"] == [0.2, 0.2, 1.0]


def test_initial_position_is_the_origin_at_the_start(drive: Path, tmp_path: Path) -> None:
    """--start 85 with the state at 85 s in [initial] and a local TUM reference of the whole
    drive (origin where the drive starts, 150 m back): the reference is placed so that it is
    at [initial] at the start (scored to centimetres), and the exports' frame and the view
    have their origin there (the exported trajectory starts at 0, 0, 0)."""
    tab = truth_table(DRIVE)
    k = int(np.searchsorted(tab["t_ns"], tab["t_ns"][0] + 85 * 10**9))
    assert np.hypot(*tab["enu"][k, :2]) > 100.0  # the start is far from the TUM's origin
    config = _initial_toml(tmp_path / "init.toml", tab, k)
    tum = tmp_path / "ref.tum"
    tum.write_text("".join(
        f"{t * 1e-9:.9f} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f} "
        f"{q[0]:.9f}\n" for t, p, q in zip(tab["t_ns"], tab["enu"], tab["q_enu_flu"],
                                           strict=True)))
    code, out = invoke("run", "ins", str(drive), "--start", "85", "--end", "90", "--init",
                       "table", "--config", str(config), "--reference", str(tum),
                       "--export", str(tmp_path / "exp"), "--save", str(tmp_path / "v.rrd"),
                       "--summary", str(tmp_path / "s.json"))
    assert code == 0, out
    assert ("from [initial] lat_deg, lon_deg, h, the reference's position at the start, "
            "t = 85.000 s)") in out
    s = json.loads((tmp_path / "s.json").read_text())["filters"]["ins"]
    assert s["pos_rms_h"] < 0.05 and s["att_rms_heading"] < 0.01
    origin = json.loads((tmp_path / "exp" / "manifest.json").read_text())["origin"]
    assert origin["source"] == "[initial] lat_deg, lon_deg, h (the position at the start)"
    lat, lon, h = (float(x) for x in tab["lla"][k])
    assert (origin["lat_deg"], origin["lon_deg"], origin["h_m"]) == pytest.approx(
        (math.degrees(lat), math.degrees(lon), h), abs=1e-12)
    first = np.loadtxt(tmp_path / "exp" / "ins.tum")[0]
    assert np.abs(first[1:4]).max() < 0.01  # the run starts at the origin
    from rrd import read_rrd

    body = read_rrd(tmp_path / "v.rrd")["/world/ins/body"]["Transform3D:translation"]
    assert np.abs(body.reshape(-1, 3)[0]).max() < 0.01  # the view's local NED frame alike


def test_export_rows_on_the_whole_grid_after_each_update(tmp_path: Path) -> None:
    """A 100 Hz GINS log whose 1 Hz fixes fall 5 ms after an IMU sample, replayed at
    --output-rate 100 from the end of the alignment: one row per time, none repeated (not the
    start's), a row at every IMU sample from the start (the grid keeps the sample after each
    update), and the row at the sample before a fix is the state after the fix (the filter's
    state is at that sample when it applies the fix: its position sigma drops there)."""
    from gins_maker import SOW0, write_gins

    log = write_gins(tmp_path / "log", duration=75.0, gnss_offset=0.005)
    gnss = log / "GNSS-RTK.txt"  # the log starts at the first IMU sample: the grid is on it
    gnss.write_text("".join(gnss.read_text().splitlines(keepends=True)[1:]))
    code, out = invoke("run", "gps-ins", str(log), "--init", "align", "--no-viz",
                       "--output-rate", "100", "--export", str(tmp_path / "exp"))
    assert code == 0, out
    rows = (tmp_path / "exp" / "gps-ins.csv").read_text().splitlines()
    head, rows = rows[0].split(","), rows[1:]
    assert len(set(rows)) == len(rows)
    stamps = np.array([int(r.split(",", 1)[0]) for r in rows])
    assert np.all(np.diff(stamps) > 0)
    t = np.round(stamps * 1e-6).astype(np.int64)  # ms of the GPS week
    imu = np.round(np.loadtxt(log / "IMU.txt", usecols=0) * 1e3).astype(np.int64)
    fixes = np.round(np.loadtxt(gnss, usecols=0) * 1e3).astype(np.int64)
    assert t[0] - round(SOW0 * 1e3) == 62_000  # the end of the still start
    assert np.array_equal(t, imu[imu >= t[0]])  # every IMU sample from the start, once
    fixes = fixes[(fixes > t[0] + 10) & (fixes < t[-1])]
    assert len(fixes) == 12 and np.all(fixes % 1000 == 5)
    sigma = np.array([float(r.split(",")[head.index("sigma_north [m]")]) for r in rows])
    at = np.searchsorted(t, fixes) - 1  # the sample before each fix
    assert np.all(t[at] == fixes - 5)
    # between samples the sigma grows; at the sample before a fix it drops (the update)
    assert np.all(sigma[at] < sigma[at - 1]) and np.all(sigma[at + 1] >= sigma[at])
    between = np.setdiff1d(np.arange(1, len(t) - 1), at)  # the last: after the last fix
    assert np.all(sigma[between] >= sigma[between - 1] - 1e-4)


def test_info_on_a_gins_log_names_its_files_rates_and_spans(gins_log: Path) -> None:
    """info on a GINS folder (or its IMU file) says what it read in a bag's terms: the files
    with their rows, rates and spans (the reference file's too), the time base (GPS seconds
    of the week, the files' own), and no header stamps it does not have."""
    for path in (gins_log, gins_log / "IMU.txt"):
        code, out = invoke("info", str(path))
        assert code == 0, out
        lines = out.splitlines()
        assert lines[0] == f"{path}  (GINS text log, 3 file(s) in the folder, 9992 rows)"
        assert lines[1] == "times: GPS seconds of the week, 456000.000 to 456090.000 (90.000 s)"
        assert lines[3].split()[:2] == ["file", "type"]
        rows = {ln.split()[0]: ln.split() for ln in lines if ln.split()[:1] and (
            ln.split()[0].endswith((".txt", ".nav")))}
        assert rows["GNSS-RTK.txt"][2:] == ["gps", "gnss", "-", "91", "1.000", "0.000",
                                            "90.000", "no"]
        assert rows["truth.nav"][2:] == ["(reference)", "901", "10.000", "0.000", "90.000"]
        assert ("streams (what `navreplay run` replays; times from the files' time column, "
                "GPS seconds of the week):") in lines
        assert "header" not in out and "messages" not in out
