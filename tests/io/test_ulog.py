"""PX4 ULog files, written by a test from the format's specification (tests/ulog_maker.py) with
a simulated recording's samples: read back as the recording's streams, replayed as the MCAP
file they came from, and their damage and wrong topics in one line."""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from reference_files import write_reference_csv
from ulog_maker import write_px4_log

from navreplay.cli import cli
from navreplay.core.streams import StreamKind
from navreplay.geo.rotations import quat_to_euler
from navreplay.io import ReadOptions, RecordingError, write_recording
from navreplay.io.errors import SalvagedWarning
from navreplay.io.files import file_kind, read_streams
from navreplay.sensors.specs import SensorSpecs, specs_toml
from navreplay.sim.scenario import simulate


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 60 s simulated drive (tactical IMU, GNSS, magnetometer) as MCAP and as PX4 logs, its
    truth as a CSV reference and its sensor specifications as a configuration."""
    d = tmp_path_factory.mktemp("ulog")
    rec = simulate("vehicle-drive", {"duration": 60.0}, seed=1)
    tr = rec[StreamKind.TRUTH]
    k = slice(None, None, 10)
    write_reference_csv(d / "ref.csv", tr.t_ns[k], tr["pos"][k], tr["v_n"][k],
                        quat_to_euler(tr["q_nb"][k]), t0_ns=rec.t0_ns)
    (d / "sensors.toml").write_text(specs_toml(SensorSpecs.from_metadata(rec.metadata.sensors)))
    return {"mcap": write_recording(d / "drive.mcap", rec),
            "ulg": write_px4_log(d / "drive.ulg", rec),
            "imu": write_px4_log(d / "imu.ulg", rec, imu="vehicle_imu", utc=False),
            "ref": d / "ref.csv", "config": d / "sensors.toml", "dir": d}


def invoke(*args: object) -> tuple[int, str]:
    res = CliRunner().invoke(cli, [str(a) for a in args])
    return res.exit_code, res.output


def test_streams_read_back_as_the_recording(flight: dict[str, Path]) -> None:
    """Every stream as PX4 logged it: float32 rates and forces, positions in 1e-7 deg and mm,
    gauss; the times UTC from the receiver (those of the MCAP file), or the autopilot's clock
    without it; vehicle_imu's increments give the same rates; v1.15's sensor_gps layout the
    same fixes as v1.14's vehicle_gps_position."""
    assert file_kind(flight["ulg"]).name == "ulog"
    mcap, _ = read_streams(flight["mcap"])
    ulog, sources = read_streams(flight["ulg"])
    assert sources[StreamKind.IMU].topic == "sensor_combined"
    assert sources[StreamKind.GPS].topic == "vehicle_gps_position"
    assert sources[StreamKind.GPS].picked_from == ("sensor_gps",)
    assert sources[StreamKind.MAG].convention.value == "frd"
    for kind in (StreamKind.IMU, StreamKind.GPS, StreamKind.GPS_VEL, StreamKind.MAG):
        np.testing.assert_array_equal(ulog[kind].t_ns, mcap[kind].t_ns)
    a, b = ulog[StreamKind.IMU], mcap[StreamKind.IMU]
    np.testing.assert_allclose(a["omega_ib_b"], b["omega_ib_b"], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(a["f_b"], b["f_b"], rtol=1e-6, atol=1e-6)
    g, g0 = ulog[StreamKind.GPS], mcap[StreamKind.GPS]
    np.testing.assert_allclose(g["pos"][:, :2], g0["pos"][:, :2], rtol=0, atol=1e-9)  # 6 mm
    np.testing.assert_allclose(g["pos"][:, 2], g0["pos"][:, 2], rtol=0, atol=5e-4)
    np.testing.assert_allclose(g["pos_sigma"], g0["pos_sigma"], rtol=1e-6)
    v, v0 = ulog[StreamKind.GPS_VEL], mcap[StreamKind.GPS_VEL]
    np.testing.assert_allclose(v["v_n"], v0["v_n"], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(v["vel_sigma"], v0["vel_sigma"], rtol=1e-6)
    np.testing.assert_allclose(ulog[StreamKind.MAG]["m_b"], mcap[StreamKind.MAG]["m_b"],
                               rtol=1e-6, atol=1e-12)
    assert ulog.metadata.extra["clock"].startswith("UTC")
    other, src = read_streams(flight["imu"])
    assert src[StreamKind.IMU].topic == "vehicle_imu" and "since boot" in \
        other.metadata.extra["clock"]
    np.testing.assert_array_equal(other[StreamKind.IMU].t_ns - other.t0_ns,
                                  b.t_ns - mcap.t0_ns)
    np.testing.assert_allclose(other[StreamKind.IMU]["omega_ib_b"], b["omega_ib_b"],
                               rtol=1e-5, atol=1e-8)
    np.testing.assert_allclose(other[StreamKind.IMU]["f_b"], b["f_b"], rtol=1e-5, atol=1e-5)
    v15, src = read_streams(flight["ulg"], ReadOptions(kinds=["gps"],
                                                       topics={"gps": "sensor_gps/0"}))
    assert src[StreamKind.GPS].topic == "sensor_gps"  # instance 0 is the topic's name
    np.testing.assert_allclose(v15[StreamKind.GPS]["pos"], g0["pos"], rtol=0, atol=1e-9)


def test_gps_ins_on_the_log_scores_as_on_the_mcap(flight: dict[str, Path],
                                                  tmp_path: Path) -> None:
    """The same filter, reference, start and sensor specifications over the MCAP file and
    the PX4 log of its samples: the same scores (within what float32 samples change)."""
    summaries = {}
    for kind in ("mcap", "ulg"):
        code, out = invoke("run", "gps-ins", flight[kind], "--reference", flight["ref"],
                           "--init", "reference", "--config", flight["config"], "--no-viz",
                           "--summary", tmp_path / f"{kind}.json")
        assert code == 0, out
        summaries[kind] = json.loads((tmp_path / f"{kind}.json").read_text())["filters"][
            "gps-ins"]
    a, b = summaries["mcap"], summaries["ulg"]
    assert a["pos_rms_h"] < 1.0 and a["att_rms_heading"] < 0.005
    for key in ("pos_rms_h", "pos_rms_v", "vel_rms", "att_rms_level", "att_rms_heading",
                "nees_mean"):
        assert b[key] == pytest.approx(a[key], rel=0.01, abs=1e-4), key


def test_info_topic_and_span_on_a_log(flight: dict[str, Path]) -> None:
    """info lists the uORB topics and what each feeds; --topic names a topic by name and
    instance, and one absent or of another type is one line naming the log; --start/--end
    cut it."""
    code, out = invoke("info", flight["ulg"])
    assert code == 0, out
    rows = {ln.split()[0]: ln.split() for ln in out.splitlines() if ln.startswith(("sensor",
                                                                                 "vehicle"))}
    assert rows["sensor_combined"][2:5] == ["imu", "imu_frd", "FRD"]
    assert rows["sensor_combined"][5:7] == ["6000", "100.000"]
    assert rows["vehicle_gps_position"][2] == "gps,gps_vel"
    assert rows["vehicle_attitude"][2:4] == ["(onboard", "ekf2)"]
    code, out = invoke("info", flight["ulg"], "--start", "10", "--end", "20")
    assert code == 0 and rows["sensor_combined"][0] in out
    assert any(ln.startswith("sensor_combined") and " 1001 " in ln for ln in out.splitlines())
    code, out = invoke("run", "ins", flight["ulg"], "--topic", "imu=vehicle_imu/1", "--no-viz")
    assert code == 1 and f"{flight['ulg']}: topic vehicle_imu/1 named for stream imu is not " \
        "in the log" in out
    code, out = invoke("run", "ins", flight["ulg"], "--topic", "imu=vehicle_attitude",
                       "--no-viz")
    assert code == 1 and "topic vehicle_attitude has type vehicle_attitude; stream imu needs " \
        "sensor_combined or vehicle_imu" in out


def test_allan_reads_a_log(flight: dict[str, Path], tmp_path: Path) -> None:
    """allan takes a PX4 log's IMU like any recording's, over --start/--end."""
    code, out = invoke("allan", flight["ulg"], "--end", "10", "--bootstrap", "0",
                       "-o", tmp_path / "imu.toml")
    assert code == 0, out
    assert "[sensors.imu]" in (tmp_path / "imu.toml").read_text()
    assert "sensor_combined" in out


def test_a_cut_log_is_salvaged_and_garbage_refused(flight: dict[str, Path],
                                                   tmp_path: Path) -> None:
    """A log cut inside a message gives the messages before the cut, with one warning naming
    the file, the byte and the time of the last message; a file that is ULog by its magic
    only is one line."""
    data = flight["ulg"].read_bytes()
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(data[: len(data) * 2 // 3 + 5])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec, _ = read_streams(cut, ReadOptions(kinds=["imu"]))
    salvaged = [str(w.message) for w in caught if issubclass(w.category, SalvagedWarning)]
    assert len(salvaged) == 1 and salvaged[0].startswith(f"{cut}: file is cut short inside a "
                                                         "message at byte")
    assert "the last at" in salvaged[0]
    t = (rec[StreamKind.IMU].t_ns[-1] - rec.t0_ns) * 1e-9
    assert 30.0 < t < 50.0
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(data[:16] + b"\xff" * 40)
    with pytest.raises(RecordingError, match=f"{bad}: "):
        read_streams(bad)
    code, out = invoke("run", "ins", cut, "--no-viz")
    assert "SALVAGED" in out or "salvaged" in out, out


def test_without_pyulog_one_line_names_the_extra(flight: dict[str, Path],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pyulog", None)
    code, out = invoke("info", flight["ulg"])
    assert code == 1 and "pip install 'navreplay[ulog]'" in out
    assert len([ln for ln in out.splitlines() if ln.startswith("Error")]) == 1
