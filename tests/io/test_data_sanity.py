"""Data sanity before any replay: IMU samples beyond the sensor's range, frame ids that change or
contradict a declaration, references read in the wrong axes, and configuration values of the
wrong type or range each stop the command with one line (naming file, topic and time)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner
from commands import one_line_error
from rosbag_maker import write_bag

from navreplay.cli import cli
from navreplay.core.params import ParamError
from navreplay.core.streams import Recording, Stream, StreamKind
from navreplay.io import write_recording
from navreplay.io.checks import ImuRange
from navreplay.logs.options import imu_range
from navreplay.sim.scenario import simulate


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def drive() -> Recording:
    return simulate("vehicle-drive", {"duration": 20.0}, seed=3)


@pytest.fixture(scope="module")
def drive_file(drive, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("drive") / "drive.mcap"
    write_recording(path, drive)
    return path


def _with_imu_sample(rec: Recording, row: int, column: str, value: float) -> Recording:
    imu = rec[StreamKind.IMU]
    cols = {k: v.copy() for k, v in imu.columns.items()}
    cols[column][row, 0] = value
    streams = dict(rec.streams)
    streams[StreamKind.IMU] = Stream(imu.kind, imu.t_ns, cols, imu.frame_id)
    return Recording(streams, rec.metadata, rec.t0_ns)


# --------------------------------------------------------------------------------------------
# the IMU's range


def test_one_gyro_sample_beyond_any_imu_stops_the_run(drive, tmp_path):
    """1e12 rad/s once (the issue's 3,645 km): one line naming the file, topic and time, on
    both paths that read a recording (streamed, and whole with a reference)."""
    path = tmp_path / "spike.mcap"
    write_recording(path, _with_imu_sample(drive, 1000, "omega_ib_b", 1e12), validate=False)
    t = (int(drive[StreamKind.IMU].t_ns[1000]) - drive.t0_ns) * 1e-9
    for extra in ((), ("--reference", "/truth")):
        err = one_line_error(invoke("run", "gps-ins", path, "--no-viz", *extra), str(path),
                             "topic /imu", f"t = {t:.9f} s", "omega_ib_b",
                             "beyond the IMU's range", "--imu-range")
        assert "gyro 20000 deg/s" in err
    # a fast but possible rate (15,000 deg/s) passes the default, not a 2000 deg/s datasheet
    path2 = tmp_path / "fast.mcap"
    write_recording(path2, _with_imu_sample(drive, 1000, "omega_ib_b", math.radians(15000.0)))
    res = invoke("run", "ins", path2, "--no-viz")
    assert res.exit_code == 0, res.output
    one_line_error(invoke("run", "ins", path2, "--no-viz", "--imu-range", "gyro=2000"),
                   "beyond the IMU's range", "gyro 2000 deg/s")
    cfg = tmp_path / "range.toml"
    cfg.write_text("[imu_range]\ngyro = 2000\naccel = 16\n")
    one_line_error(invoke("run", "ins", path2, "--no-viz", "--config", cfg),
                   "gyro 2000 deg/s, accel 16 g")


def test_a_gyro_spike_in_a_bag(tmp_path):
    bag = write_bag(tmp_path / "bag", duration=20.0, gyro_spike=(12.0, 1e12))
    one_line_error(invoke("run", "ins", bag, "--no-viz", "--init", "align"), str(bag),
                   "topic /imu/data", "t = 1", "beyond the IMU's range")


@pytest.mark.parametrize("text, fragment", [
    ("gyro=-1", "positive number of deg/s"), ("gyro=abc", "positive number"),
    ("accel=inf", "positive number of g"), ("foo=1", "unknown key(s) foo"),
    ("gyro", "expected KIND=VALUE"),
])
def test_imu_range_values_are_checked(drive_file, text, fragment):
    one_line_error(invoke("run", "ins", drive_file, "--no-viz", "--imu-range", text),
                   "--imu-range", fragment)


def test_imu_range_api():
    r = imu_range("gyro=2000,accel=16")
    assert r.gyro == pytest.approx(math.radians(2000.0), abs=1e-12)
    assert r.accel == pytest.approx(16 * 9.80665, abs=1e-12)
    assert imu_range() == ImuRange()
    assert imu_range("gyro=300", {"gyro": 2000, "accel": 4}).gyro == pytest.approx(
        math.radians(300.0), abs=1e-12)  # the option wins over the table
    for bad in ({"gyro": True}, {"accel": "16g"}, {"gyro": [1]}):
        with pytest.raises(ParamError):
            imu_range(table=bad)


# --------------------------------------------------------------------------------------------
# frame ids


@pytest.fixture(scope="module")
def switching_bag(tmp_path_factory) -> Path:
    """An FRD IMU whose frame id turns from imu_frd into imu_link after 10 s."""
    return write_bag(tmp_path_factory.mktemp("switch") / "bag", ned=True, duration=20.0,
                     imu_frame_after=(10.0, "imu_link"))


def test_a_frame_id_that_changes_is_an_error_unless_declared(switching_bag):
    err = one_line_error(invoke("run", "ins", switching_bag, "--no-viz", "--init", "align"),
                         str(switching_bag), "topic /imu/data", "frame_id changes",
                         "--frame imu=frd|flu")
    assert "'imu_frd', 'imu_link'" in err
    # declared: the data are read as declared (an FRD IMU: the frame check agrees)
    res = invoke("run", "ins", switching_bag, "--no-viz", "--init", "align", "--frame",
                 "imu=frd")
    assert res.exit_code == 0, res.output
    # declared FLU contradicts the imu_frd messages: refused, unless forced (then the
    # gravity check catches the data)
    one_line_error(invoke("run", "ins", switching_bag, "--no-viz", "--init", "align",
                          "--frame", "imu=flu"), "contradicts frame id 'imu_frd'")
    one_line_error(invoke("run", "ins", switching_bag, "--no-viz", "--init", "align",
                          "--frame", "imu=flu", "--force-frame"), "+g on a z-down axis")
    # info says so too, and fails
    res = invoke("info", switching_bag)
    assert res.exit_code == 1 and "frame_id changes" in res.output


def test_a_declared_frame_contradicting_the_frame_id_is_an_error(drive_file):
    """navreplay's GNSS velocity topic is named NED: declaring it ENU (the issue's 215 m with
    exit 0) is refused; --force-frame reads it as declared."""
    one_line_error(invoke("run", "gps-ins", drive_file, "--no-viz", "--frame", "gps_vel=enu"),
                   str(drive_file), "--frame gps_vel=enu contradicts frame id",
                   "--force-frame")
    one_line_error(invoke("run", "gps-ins", drive_file, "--no-viz", "--frame", "imu=flu"),
                   "--frame imu=flu contradicts frame id 'imu_frd'")
    res = invoke("run", "gps-ins", drive_file, "--no-viz", "--frame", "gps_vel=enu",
                 "--force-frame", "--summary", "s.json")
    assert res.exit_code == 0, res.output
    assert json.loads(Path("s.json").read_text())["filters"]["gps-ins"]["pos_rms_h"] > 3.0


@pytest.fixture(scope="module")
def moving_bag(tmp_path_factory) -> Path:
    return write_bag(tmp_path_factory.mktemp("moving") / "bag", duration=100.0)


def test_a_reference_read_in_the_wrong_axes_is_caught_by_the_gnss_fit(moving_bag, tmp_path):
    """An ENU Odometry (frame id 'odom', which names no axes) declared NED: its positions fit
    the GNSS fixes only read as ENU; the run stops and says so, unless forced."""
    args = ("run", "ins", moving_bag, "--no-viz", "--init", "reference", "--reference",
            "/ground_truth/odom")
    res = invoke(*args, "--summary", tmp_path / "ok.json")
    assert res.exit_code == 0, res.output
    assert "m RMS apart" in res.output
    err = one_line_error(invoke(*args, "--frame", "reference=ned"), "/ground_truth/odom",
                         "read as NED (declared ned)", "read as ENU by",
                         "use --frame reference=enu")
    rms = float(err.split("GNSS fixes by ")[1].split(" m")[0])
    rms_enu = float(err.split("read as ENU by ")[1].split(" m")[0])
    assert rms > 50.0 and rms_enu < 1.0, err
    res = invoke(*args, "--frame", "reference=ned", "--force-frame")
    assert res.exit_code == 0, res.output


def test_a_reference_frame_id_naming_its_axes_wins_over_a_contradiction(tmp_path):
    bag = write_bag(tmp_path / "bag", duration=70.0, world_frame="odom_enu")
    one_line_error(invoke("run", "ins", bag, "--no-viz", "--init", "reference", "--reference",
                          "/ground_truth/odom", "--frame", "reference=ned"),
                   "--frame reference=ned contradicts frame id 'odom_enu'")


# --------------------------------------------------------------------------------------------
# configuration values


@pytest.mark.parametrize("table, fragment", [
    ("[initial]\nlat_deg = 1000\nlon_deg = 7\n", "lat_deg = 1000: out of range"),
    ("[initial]\nlat_deg = true\nlon_deg = 7\n", "lat_deg = True: expected finite numbers"),
    ("[initial]\nv_n = [1.0, 2.0]\n", "v_n = [1.0, 2.0]: expected 3 value(s)"),
    ("[initial]\npos_sigma = 0.0\n", "pos_sigma = 0.0: out of range (0 < value"),
    ("[initial]\natt_sigma_deg = [1, -1, 1]\n", "att_sigma_deg"),
    ("[initial]\nyaw_deg = \"north\"\n", "yaw_deg = 'north': expected finite numbers"),
    ("[initial]\nh = [1.0]\n", "h = [1.0]: expected 1 value(s)"),
    ("[topics]\nimu = 42\n", "[topics] imu = 42: expected a topic as a string"),
    ("[topics]\nimu = \"\"\n", "[topics] imu = ''"),
    ("[frames]\nimu = true\n", "[frames] imu = True: expected axes as a string"),
    ("[imu_range]\ngyro = true\n", "--imu-range gyro=True"),
    ("[filter.gps-ins]\ngps_pos_sigma_scale = true\n", "gps_pos_sigma_scale: expected a number"),
    ("[filter.gps-ins]\nuse_gps_vel = 1\n", "use_gps_vel: 1 is not a boolean"),
])
def test_configuration_values_are_type_and_range_checked(drive_file, tmp_path, table,
                                                         fragment):
    cfg = tmp_path / "c.toml"
    cfg.write_text(table)
    one_line_error(invoke("run", "gps-ins", drive_file, "--no-viz", "--config", cfg), fragment)


def test_named_topics_must_exist_on_navreplay_recordings_too(drive_file):
    """The streamed path and info refuse a topic named for a stream that the file lacks."""
    for extra in ((), ("--reference", "/truth")):
        one_line_error(invoke("run", "gps-ins", drive_file, "--no-viz", "--topic",
                              "imu=/nonexistent", *extra),
                       "topic /nonexistent named for stream imu is not in the file")
    res = invoke("info", drive_file, "--topic", "imu=/nonexistent")
    assert res.exit_code == 1 and "/nonexistent" in res.stderr
