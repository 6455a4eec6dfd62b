"""Bags navreplay did not write (rosbags' Writer: rosbag2 folders with MCAP and sqlite3 storage),
replayed from the command line alone: conventions, frame checks, --init, --reference."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner
from rosbag_maker import write_bag

from navreplay.cli import cli


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


def test_info_shows_frames_and_choice(bags: dict[str, Path]) -> None:
    res = CliRunner().invoke(cli, ["info", str(bags["enu"]), "--frame", "imu=frd"])
    assert res.exit_code == 0, res.output
    assert "imu_link" in res.output and "declared frd" in res.output
    assert "/ground_truth/odom" in res.output and "50.000 Hz" in res.output
