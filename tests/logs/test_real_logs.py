"""Bags navreplay did not write (rosbags' Writer: rosbag2 folders with MCAP and sqlite3 storage),
replayed from the command line alone: conventions, frame checks, --init, --reference."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from reference_files import write_reference_csv
from rosbag_maker import LAT, LON, H, truth_table, write_bag

from navreplay.campaign.tasks import replay_filters
from navreplay.cli import cli
from navreplay.core.streams import StreamKind
from navreplay.geo import earth
from navreplay.geo.rotations import quat_to_euler, wrap_angle
from navreplay.jobs import filter_specs
from navreplay.logs.initial import initial_nav
from navreplay.logs.options import InitMethod, log_options
from navreplay.logs.prepare import read_log


def _prepared(path, options):
    """The log read whole and made ready, and its notes."""
    return read_log(path, options)


@pytest.fixture(scope="session")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bags")
    return {
        "enu": write_bag(root / "enu"),  # ENU/FLU, MCAP storage
        "ned": write_bag(root / "ned", ned=True, storage="sqlite3") / "ned.db3",  # NED/FRD
        "mislabelled": write_bag(root / "bad", ned=True, imu_frame="imu_link", duration=90.0),
        "noisy": write_bag(root / "noisy", noisy=True, seed=3),
    }


def _run(*args: str, tmp: Path, ok: bool = True) -> tuple[dict, str]:
    out = tmp / "s.json"
    res = CliRunner().invoke(cli, ["run", *args, "--no-viz", "--force", "--summary", str(out)])
    if ok:
        assert res.exit_code == 0, res.output
        return json.loads(out.read_text())["filters"], res.output
    return {}, res.output + str(res.exit_code)


def test_free_ins_matches_bag_truth_in_both_conventions(bags: dict[str, Path],
                                                         tmp_path: Path) -> None:
    """ins from --init reference over a perfect 300 s bag agrees with its Odometry to < 5 cm;
    the ENU/FLU folder and the NED/FRD .db3 of the same motion agree to < 1 mm."""
    ref = ["--reference", "/ground_truth/odom", "--init", "reference"]
    enu, _ = _run("ins", str(bags["enu"]), *ref, tmp=tmp_path)
    ned, out = _run("ins", str(bags["ned"]), *ref, tmp=tmp_path)
    for s in (enu, ned):
        assert s["ins"]["pos_rms_h"] < 0.05 and s["ins"]["pos_err_final_h"] < 0.05
        assert s["ins"]["distance"] > 2000.0
    assert abs(enu["ins"]["pos_err_final_h"] - ned["ins"]["pos_err_final_h"]) < 1e-3
    assert "NED" in out or "ned" in out


def test_mislabelled_frd_imu_never_exits_zero(bags: dict[str, Path], tmp_path: Path) -> None:
    """FRD data in a frame named imu_link: stopped before replay with the fixing option; with
    the option the run succeeds."""
    args = ["ins", str(bags["mislabelled"]), "--reference", "/ground_truth/odom",
            "--init", "reference"]
    _, out = _run(*args, tmp=tmp_path, ok=False)
    assert out.endswith("1") and "--frame imu=frd" in out and "+9.8" in out
    s, _ = _run(*args, "--frame", "imu=frd", tmp=tmp_path)
    assert s["ins"]["pos_err_final_h"] < 0.05


def test_gps_ins_align_on_noisy_bag_reaches_nees_band(bags: dict[str, Path],
                                                      tmp_path: Path) -> None:
    """gps-ins from --init align (levelling + GNSS track) is consistent: NEES and NIS means in
    band, most epochs inside the 95 % bounds."""
    s, out = _run("gps-ins", str(bags["noisy"]), "--reference", "/ground_truth/odom",
                  "--init", "align", tmp=tmp_path)
    g = s["gps-ins"]
    assert "align over the still start" in out
    assert 0.5 * 9 < g["nees_mean"] < 1.5 * 9 and g["nees_in_bounds"] > 0.6
    assert 2.0 < g["nis_mean_gps_pos"] < 4.0
    assert g["pos_rms_h"] < 2.0


def test_without_reference_summary_has_nis(bags: dict[str, Path], tmp_path: Path) -> None:
    s, out = _run("gps-ins", str(bags["noisy"]), "--init", "align", tmp=tmp_path)
    assert "nis_mean_gps_pos" in s["gps-ins"] and "pos_rms_h" not in s["gps-ins"]


def test_position_only_reference_and_no_start(bags: dict[str, Path], tmp_path: Path) -> None:
    """A NavSatFix reference scores position only; a filter without a start says what it
    needs in one line."""
    s, _ = _run("gps-ins", str(bags["noisy"]), "--reference", "/gnss/fix", "--init", "align",
                tmp=tmp_path)
    assert "pos_rms_h" in s["gps-ins"] and "vel_rms" not in s["gps-ins"]
    _, out = _run("ins", str(bags["enu"]), tmp=tmp_path, ok=False)
    assert "cannot start" in out and "--init align" in out and "Traceback" not in out


def test_info_shows_frames_and_choice(bags: dict[str, Path], tmp_path: Path) -> None:
    """One table, one row per topic: the stream it feeds, frame id, axes, rate; reference
    topics marked; the reasons below it. The same for a navreplay MCAP file."""
    res = CliRunner().invoke(cli, ["info", str(bags["enu"]), "--frame", "imu=frd"])
    assert res.exit_code == 0, res.output
    rows = {ln.split()[0]: ln.split() for ln in res.output.splitlines()
            if ln.startswith("/") and len(ln.split()) > 4}
    assert rows["/imu/data"][2:5] == ["imu", "imu_link", "FRD"] and "50.000" in rows["/imu/data"]
    assert rows["/ground_truth/odom"][2] == "(reference)"
    assert "declared frd" in res.output
    assert sum(ln.startswith("/imu/data") for ln in res.output.splitlines()) == 1
    mcap = tmp_path / "sim.mcap"
    assert CliRunner().invoke(cli, ["simulate", "stationary", "-o", str(mcap), "--duration",
                                    "5"]).exit_code == 0
    res = CliRunner().invoke(cli, ["info", str(mcap)])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert sum(ln.startswith("topic ") for ln in lines) == 1
    assert sum(ln.startswith("/imu ") for ln in lines) == 1
    assert "imu_frd" in next(ln for ln in lines if ln.startswith("/imu "))


# --------------------------------------------------------------------------------------------
# short bags for the options: references, frame checks, initialisation, times

NAV_GRADE = (0.005, 0.002, 2.5e-4, 5e-5)
"""gyro bias [deg/h], ARW [deg/sqrt(h)], accelerometer bias [m/s^2], VRW [m/s^2/sqrt(Hz)]."""
MEMS_GRADE = (10.0, 0.3, 0.02, 1e-3)
SHORT = 90.0
YAW0 = 0.4  # heading of rosbag_maker's route [rad]


@pytest.fixture(scope="session")
def short_bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("short")
    return {
        "mag": write_bag(root / "mag", mag=True, poses=True, duration=SHORT),
        "mag_flipped": write_bag(root / "mag_flipped", mag=True, mag_frame="mag_frd",
                                 duration=SHORT),
        "nav": write_bag(root / "nav", imu_grade=NAV_GRADE, duration=SHORT, seed=1),
        "mems": write_bag(root / "mems", imu_grade=MEMS_GRADE, noisy=True, mag=True,
                          mag_bias_nT=300.0, duration=SHORT, seed=2),
        "lag": write_bag(root / "lag", imu_lag=0.05, duration=SHORT),
        "zero": write_bag(root / "zero", imu_zero_stamps=True, duration=SHORT),
    }


def _ins(bag: Path, *args: str, tmp: Path) -> dict:
    return _run("ins", str(bag), "--init", "reference", *args, tmp=tmp)[0]["ins"]


def _write_tum(path: Path, tab: dict) -> Path:
    lines = ["# t x y z qx qy qz qw"]
    for t, p, q in zip(tab["t_ns"], tab["enu"], tab["q_enu_flu"], strict=True):
        lines.append(f"{t * 1e-9:.9f} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} "
                     f"{q[1]:.9f} {q[2]:.9f} {q[3]:.9f} {q[0]:.9f}")
    path.write_text("\n".join(lines) + "\n")
    return path


def _write_csv(path: Path, tab: dict) -> Path:
    return write_reference_csv(path, tab["t_ns"], tab["lla"], tab["v_n"], tab["euler"])


def test_reference_files_score_like_the_topic(short_bags: dict[str, Path],
                                              tmp_path: Path) -> None:
    """A TUM file (local ENU, FLU body) and a CSV file (geodetic, NED velocity, Euler angles)
    of the bag's truth give the Odometry topic's scores to a millimetre / 0.01 mrad; the TUM
    file has no velocity, so no velocity score."""
    tab = truth_table(SHORT)
    bag = short_bags["mag"]
    topic = _ins(bag, "--reference", "/ground_truth/odom", tmp=tmp_path)
    tum = _ins(bag, "--reference", str(_write_tum(tmp_path / "ref.tum", tab)), tmp=tmp_path)
    csv = _ins(bag, "--reference", str(_write_csv(tmp_path / "ref.csv", tab)), tmp=tmp_path)
    assert topic["distance"] > 150.0
    for s in (tum, csv):
        for k in ("pos_rms_h", "pos_err_final_h", "pos_rms_v"):
            assert abs(s[k] - topic[k]) < 1e-3, (k, s[k], topic[k])
        for k in ("att_rms_level", "att_rms_heading"):
            assert abs(s[k] - topic[k]) < 1e-5, (k, s[k], topic[k])
        assert abs(s["distance"] - topic["distance"]) < 0.5
    assert "vel_rms" not in tum and abs(csv["vel_rms"] - topic["vel_rms"]) < 1e-3


@pytest.mark.parametrize(("fault", "expect"), [
    ("columns", "line 5: 7 columns, expected 8"),
    ("order", "line 5: time"),
    ("nan", "line 5: non-finite"),
])
@pytest.mark.parametrize("kind", ["tum", "csv"])
def test_malformed_reference_file_refused_before_replay(
        short_bags: dict[str, Path], tmp_path: Path, kind: str, fault: str,
        expect: str) -> None:
    """Wrong column count, a time that goes back, a NaN: one line naming the file and line,
    before any replay (no summary is written)."""
    tab = {k: v[:10] for k, v in truth_table(SHORT).items()}
    path = (_write_tum if kind == "tum" else _write_csv)(tmp_path / f"bad.{kind}", tab)
    lines = path.read_text().splitlines()
    sep = " " if kind == "tum" else ","
    cells = lines[4].split(sep)
    if fault == "columns":
        cells = cells[:-1] if kind == "tum" else cells[:-1]
        expect = expect.replace("7", str(len(cells))).replace("8", str(len(cells) + 1))
    elif fault == "order":
        cells[0] = lines[2].split(sep)[0]
    else:
        cells[2] = "nan"
    lines[4] = sep.join(cells)
    path.write_text("\n".join(lines) + "\n")
    res = CliRunner().invoke(cli, ["run", "ins", str(short_bags["mag"]), "--init", "align",
                                   "--reference", str(path), "--no-viz", "--summary",
                                   str(tmp_path / "s.json")])
    assert res.exit_code != 0
    err = [ln for ln in res.output.splitlines() if ln.startswith("Error")]
    assert len(err) == 1 and str(path) in err[0] and expect in err[0], res.output
    assert not (tmp_path / "s.json").exists()


def test_pose_references_score_position_and_attitude(short_bags: dict[str, Path],
                                                     tmp_path: Path) -> None:
    """PoseStamped and PoseWithCovarianceStamped (ENU world, FLU body) score position and
    attitude as the Odometry does, and no velocity."""
    bag = short_bags["mag"]
    odom = _ins(bag, "--reference", "/ground_truth/odom", tmp=tmp_path)
    for topic in ("/truth/pose", "/truth/pose_cov"):
        s = _ins(bag, "--reference", topic, tmp=tmp_path)
        assert "vel_rms" not in s
        for k in ("pos_rms_h", "pos_err_final_h", "att_rms_level", "att_rms_heading"):
            assert abs(s[k] - odom[k]) < 1e-4, (topic, k)
        assert s["pos_rms_h"] < 0.01 and s["att_rms_heading"] < 1e-3


def test_local_origin_from_initial_or_gnss(short_bags: dict[str, Path], tmp_path: Path) -> None:
    """The Odometry's local ENU origin from [initial] scores like the GNSS fit (the fixes are
    exact here); an origin 10 m north moves the whole reference 10 m north."""
    bag = short_bags["mag"]
    fit, out = _run("ins", str(bag), "--init", "reference", "--reference",
                    "/ground_truth/odom", tmp=tmp_path)
    assert "a fit to" in out
    refs = []
    for north in (0.0, 10.0):
        lat = math.degrees(LAT + north / earth.radii(LAT)[0])
        cfg = tmp_path / f"o{north:g}.toml"
        cfg.write_text(f"[initial]\nlat_deg = {lat!r}\nlon_deg = {math.degrees(LON)!r}\n"
                       f"h = {H!r}\n")
        s, out = _run("ins", str(bag), "--init", "reference", "--reference",
                      "/ground_truth/odom", "--config", str(cfg), tmp=tmp_path)
        assert "from [initial] lat_deg, lon_deg, h" in out
        for k in ("pos_rms_h", "pos_err_final_h", "att_rms_heading", "vel_rms"):
            assert abs(s["ins"][k] - fit["ins"][k]) < 1e-3, k
        initial = {"lat_deg": lat, "lon_deg": math.degrees(LON), "h": H}
        ref, _ = _prepared(bag, log_options(reference="/ground_truth/odom",
                                            config={"initial": initial}))
        refs.append(ref[StreamKind.TRUTH]["pos"])
    d = earth.lla_to_ned_offset(*refs[0][0], *refs[1].T) - earth.lla_to_ned_offset(
        *refs[0][0], *refs[0].T)
    assert d[:, 0] == pytest.approx(np.full(len(d), 10.0), abs=1e-3)
    assert np.abs(d[:, 1:]).max() < 1e-3


def test_magnetometer_dip_sign(short_bags: dict[str, Path], tmp_path: Path) -> None:
    """A FLU magnetometer labelled *_frd reads the vertical field upside down: stopped with
    the fix (a declaration that must win over the frame id's name, so --force-frame); declared
    flu alone it is refused (the frame id says FRD), forced it passes. The correct one passes
    with the WMM's dip."""
    args = ["--reference", "/ground_truth/odom"]
    _, out = _run("ins", str(short_bags["mag_flipped"]), "--init", "reference", *args,
                  tmp=tmp_path, ok=False)
    assert "--frame mag=flu --force-frame" in out and "dip" in out and "Traceback" not in out
    assert out.endswith("1")
    _, out = _run("ins", str(short_bags["mag_flipped"]), "--init", "reference", "--frame",
                  "mag=flu", *args, tmp=tmp_path, ok=False)
    assert "contradicts frame id 'mag_frd'" in out
    _, out = _run("ins", str(short_bags["mag_flipped"]), "--init", "reference", "--frame",
                  "mag=flu", "--force-frame", *args, tmp=tmp_path)
    assert "magnetometer dip sign agrees" in out
    _, out = _run("ins", str(short_bags["mag"]), "--init", "reference", *args, tmp=tmp_path)
    assert "magnetometer dip sign agrees" in out


def _align(bag: Path, initial: dict | None = None, drop_mag: bool = False
           ) -> tuple[str, float, float]:
    """(method, yaw error [rad], claimed yaw sigma [rad]) of --init align."""
    rec, _ = _prepared(bag, log_options(init="align", config={"initial": initial or {}}))
    if drop_mag:
        rec.streams.pop(StreamKind.MAG)
        nav, _ = initial_nav(InitMethod.ALIGN, rec, initial or {})
    else:
        nav = rec.metadata.initial_nav
    yaw = quat_to_euler(np.asarray(nav["q_nb"]))[2]
    return nav["method"], float(wrap_angle(yaw - YAW0)), nav["sigma"]["phi"][2]


@pytest.mark.filterwarnings("ignore::navreplay.io.errors.RecordingWarning")
def test_align_heading_sources_and_their_sigmas(short_bags: dict[str, Path]) -> None:
    """Gyrocompassing on a navigation-grade IMU (heading within its claimed sigma, which is
    well under a degree); a MEMS IMU refuses it and falls back to the magnetometer (hard iron
    300 nT: error under the claimed sigma), and without a magnetometer to the GNSS track."""
    how, err, sigma = _align(short_bags["nav"], {"gyro_bias_sigma_dph": 0.01,
                                                 "accel_bias_sigma": 3e-4})
    assert how == "align (gyrocompassing)"
    assert abs(err) < sigma < math.radians(0.5)
    how, err, sigma = _align(short_bags["nav"])  # levelling sigma from the grade shown
    assert how == "align (gyrocompassing)" and abs(err) < sigma
    mems = {"accel_bias_sigma": 0.03, "gyro_bias_sigma_dph": 10.0}
    how, err, sigma = _align(short_bags["mems"], mems)
    assert how.startswith("align (magnetometer; gyrocompassing would give")
    assert math.radians(0.2) < abs(err) < sigma < math.radians(5.0)
    how, err, sigma = _align(short_bags["mems"], mems, drop_mag=True)
    assert how.startswith("align (GNSS track")
    assert abs(err) < 2 * sigma < math.radians(10.0)


def test_init_table_lands_in_the_filter(short_bags: dict[str, Path], tmp_path: Path) -> None:
    """[initial] values in degrees, metres, m/s and deg/h are the filter's first estimate;
    an incomplete table names what is missing in one line."""
    yaw = math.degrees(YAW0)  # the attitude at rest, so the first output (0.1 s on) is the start
    table = {"lat_deg": 45.001, "lon_deg": 7.002, "h": 310.0, "v_n": [0.0, 0.0, 0.0],
             "roll_deg": 0.0, "pitch_deg": 0.0, "yaw_deg": yaw, "pos_sigma": [3.0, 3.0, 5.0],
             "att_sigma_deg": 2.0, "gyro_bias_dph": [1.0, 2.0, 3.0]}
    bag = short_bags["mag"]
    rec, _ = _prepared(bag, log_options(init="table", config={"initial": table}))
    nav = rec.metadata.initial_nav
    spec = filter_specs("ins")
    res = replay_filters(rec, spec, source=str(bag))["ins"]
    assert res.t[0] <= 0.1
    assert res.nav_pos[0, :2] == pytest.approx(np.radians([45.001, 7.002]), abs=1e-9)
    assert res.nav_pos[0, 2] == pytest.approx(310.0, abs=1e-3)
    assert res.nav_v_n[0] == pytest.approx([0.0, 0.0, 0.0], abs=1e-3)
    assert np.degrees(quat_to_euler(res.nav_q_nb[0])) == pytest.approx([0.0, 0.0, yaw],
                                                                       abs=1e-3)
    assert nav["gyro_bias"] == pytest.approx(np.radians([1.0, 2.0, 3.0]) / 3600)
    assert nav["sigma"]["phi"] == pytest.approx([math.radians(2.0)] * 3)
    cfg = tmp_path / "partial.toml"
    cfg.write_text("[initial]\nlat_deg = 45.0\nlon_deg = 7.0\nh = 300.0\n")
    _, out = _run("ins", str(bag), "--init", "table", "--config", str(cfg), tmp=tmp_path,
                  ok=False)
    err = [ln for ln in out.splitlines() if ln.startswith("Error")]
    assert len(err) == 1 and "missing an attitude (roll_deg, pitch_deg, yaw_deg)" in err[0]


def test_time_header_or_log(short_bags: dict[str, Path], tmp_path: Path) -> None:
    """IMU messages logged 50 ms after their stamps: the header stamps (default) replay
    exactly, the log times lag the motion (errors of decimetres); stamps that are all zero fall
    back to the log times with a warning."""
    ref = ["--reference", "/ground_truth/odom"]
    header = _ins(short_bags["lag"], *ref, tmp=tmp_path)
    log = _ins(short_bags["lag"], *ref, "--time", "log", tmp=tmp_path)
    assert header["pos_rms_h"] < 0.01
    assert 0.1 < log["pos_rms_h"] < 0.5  # 50 ms late at up to 10 m/s
    s, out = _run("ins", str(short_bags["zero"]), "--init", "reference", *ref, tmp=tmp_path)
    assert "header stamps are zero; the log times are used" in out
    assert s["ins"]["pos_err_final_h"] < 0.01


def test_campaign_applies_log_options_per_recording(short_bags: dict[str, Path],
                                                    tmp_path: Path) -> None:
    """`run ins a b --init reference --reference TOPIC`: each recording gets its own start and
    reference (per-run scores at the millimetre level); a recording the options do not fit
    stops the campaign with one line naming it."""
    out = tmp_path / "c.json"
    bags = [str(short_bags["mag"]), str(short_bags["lag"])]
    args = ["run", "ins", *bags, "--init", "reference", "--reference", "/ground_truth/odom",
            "--no-viz", "--summary", str(out)]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    runs = json.loads(out.read_text())["runs"]
    assert [r["recording"] for r in runs] == bags
    for r in runs:
        assert r["filters"]["ins"]["pos_rms_h"] < 0.01 and r["filters"]["ins"]["distance"] > 150
    bad = str(short_bags["mag_flipped"])
    res = CliRunner().invoke(cli, [*args[:3], bad, *args[4:], "--force"])
    err = [ln for ln in res.output.splitlines() if ln.startswith("Error")]
    assert res.exit_code != 0 and len(err) == 1 and bad in err[0] and "--frame mag=flu" in err[0]


@pytest.mark.filterwarnings("ignore::navreplay.io.errors.RecordingWarning")
def test_levelling_sigma_follows_the_grade_the_gyro_shows(short_bags: dict[str, Path]) -> None:
    """Without [initial] accel_bias_sigma the levelling sigma comes from the grade the gyro
    shows at rest: navigation grade gives a few thousandths of a degree, MEMS about a degree;
    in both the roll and pitch errors lie within 3 sigma (horizontal accelerometer biases are
    not observable at rest, so the sigma must cover them)."""
    claimed = {}
    for name in ("nav", "mems"):
        rec, notes = _prepared(short_bags[name], log_options(init="align"))
        nav = rec.metadata.initial_nav
        roll, pitch, _ = quat_to_euler(np.asarray(nav["q_nb"]))
        s_level = nav["sigma"]["phi"][0]
        assert max(abs(roll), abs(pitch)) < 3 * s_level, name
        claimed[name] = math.degrees(s_level)
        assert ("navigation grade" if name == "nav" else "MEMS grade") in " ".join(notes)
    assert claimed["nav"] < 0.01 and 0.3 < claimed["mems"] < 3.0


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_bag_decoded_in_bulk_equals_rosbags_message_by_message(tmp_path, storage):
    """A rosbag2 bag's CDR messages are viewed in bulk by their fixed layouts: the same fields
    as rosbags' deserialiser gives message by message, in the bag's order, across a frame id
    that changes length halfway (two layouts) and in both storages."""
    from navreplay.io.cdr import fields_of_messages
    from navreplay.io.convert import REDUCE
    from navreplay.io.rosbag import _open, _read_topic, iter_messages
    from navreplay.io.schemas import SPECS

    bag = write_bag(tmp_path / "bag", ned=True, noisy=True, duration=20.0, storage=storage,
                    imu_frame_after=(10.0, "imu_link_frd_after_the_change"))
    for topic, kind in (("/imu/data", StreamKind.IMU), ("/gnss/fix", StreamKind.GPS)):
        with _open(bag) as b:
            bulk, times, frames = _read_topic(b, topic, kind, topic)
        pairs = list(iter_messages(bag, topic))
        assert times.tolist() == [t for t, _ in pairs]
        ref = fields_of_messages([m for _, m in pairs], SPECS[kind].message)
        assert frames == list(dict.fromkeys(ref["frame_id"].tolist()))
        np.testing.assert_array_equal(bulk["t_ns"], ref["t_ns"])
        assert set(bulk) == {"t_ns", *REDUCE[kind]}
        for name, columns in REDUCE[kind].items():
            want = ref[name] if columns is None else ref[name][:, columns]
            np.testing.assert_array_equal(bulk[name], want)
        assert len(frames) == (2 if kind is StreamKind.IMU else 1)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_an_intact_bag_read_without_rosbags_reader_gives_the_same_streams(tmp_path, storage,
                                                                           monkeypatch):
    """An intact rosbag2 folder is read from its data files directly (MCAP chunks, sqlite
    tables); the streams equal those read through rosbags' reader, across a frame id that
    changes length (declared, so the read goes on), and rosbags' reader is not opened."""
    from navreplay.io import ReadOptions, read_recording, rosbag
    from navreplay.io.errors import RecordingWarning

    bag = write_bag(tmp_path / "bag", ned=True, noisy=True, duration=20.0, storage=storage,
                    imu_frame_after=(10.0, "imu_link_frd_after_the_change"))
    opts = ReadOptions(frames={StreamKind.IMU: "frd"})
    opened: list[Path] = []
    real_open = rosbag._open
    monkeypatch.setattr(rosbag, "_open", lambda p: opened.append(p) or real_open(p))
    with pytest.warns(RecordingWarning, match="frame_id changes between messages"):
        direct = read_recording(bag, opts)
    assert opened == []
    monkeypatch.setattr(rosbag, "_bulk_data", lambda *_: None)
    with pytest.warns(RecordingWarning, match="frame_id changes between messages"):
        through_rosbags = read_recording(bag, opts)
    assert opened == [bag]
    assert set(direct.streams) == set(through_rosbags.streams) == {StreamKind.IMU,
                                                                    StreamKind.GPS}
    assert direct.t0_ns == through_rosbags.t0_ns
    for kind, s in direct.streams.items():
        r = through_rosbags.streams[kind]
        assert s.frame_id == r.frame_id
        np.testing.assert_array_equal(s.t_ns, r.t_ns)
        assert set(s.columns) == set(r.columns)
        for name in s.columns:
            np.testing.assert_array_equal(s.columns[name], r.columns[name])
