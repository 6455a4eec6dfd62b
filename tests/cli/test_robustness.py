"""Never lose a file, never a wrong answer with exit 0: output guards, signals and temporaries,
IMU gaps, strict configs, damaged recordings and exit codes, through the command line."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from commands import NAVREPLAY, cut_imu, invoke, one_line_error, parts, wait_for
from mcap.reader import SeekingReader
from mcap.stream_reader import StreamReader
from mcap_edits import uncompressed_copy

from navreplay import metrics
from navreplay.core.streams import Recording, StreamKind
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.io import outputs, read_recording, write_recording
from navreplay.replay import replay
from navreplay.sim.scenario import simulate


@pytest.fixture(scope="module")
def drive(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("drive") / "drive.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 20.0}, seed=3))
    return path


@pytest.fixture
def in_tmp(tmp_path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    return tmp_path


# --------------------------------------------------------------------------------------------
# 1. outputs


def test_summary_onto_the_recording_is_refused_even_with_force(drive, in_tmp):
    before = drive.read_bytes()
    for extra in ((), ("--force",)):
        one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--summary", drive, *extra),
                       "--summary", "is an input of this command")
    link = in_tmp / "link.mcap"
    os.link(drive, link)  # another name of the same file
    one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--save", link, "--force"),
                   "--save", "input")
    assert drive.read_bytes() == before


def test_existing_outputs_need_force(drive, in_tmp):
    Path("s.json").write_text("mine")
    Path("v.rrd").write_text("mine too")
    one_line_error(invoke("run", "gps-ins", drive, "--save", "v.rrd"), "--save v.rrd exists",
                   "--force")
    one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--summary", "s.json"),
                   "--summary s.json exists")
    assert Path("s.json").read_text() == "mine" and Path("v.rrd").read_text() == "mine too"
    res = invoke("run", "gps-ins", drive, "--no-viz", "--summary", "s.json", "--force")
    assert res.exit_code == 0, res.output
    assert json.loads(Path("s.json").read_text())["salvaged"] is False
    one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--summary", "s.json",
                          "--save", "s.json", "--force"), "the same file")


def test_unwritable_targets_fail_before_the_work(drive, in_tmp):
    Path("plain").write_text("x")
    one_line_error(invoke("run", "gps-ins", drive, "--save", "plain/v.rrd"), "--save",
                   "is not a directory")
    one_line_error(invoke("montecarlo", "vehicle-drive", "gps-ins", "--runs", "2",
                          "--duration", "20", "--no-viz", "--summary", "plain/s.json"),
                   "--summary")
    one_line_error(invoke("simulate", "stationary", "-o", "plain/s.mcap", "--duration", "5"),
                   "-o plain/s.mcap", "is not a directory")
    if os.geteuid() != 0:  # root may write anywhere
        ro = in_tmp / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        one_line_error(invoke("run", "gps-ins", drive, "--save", ro / "v.rrd"), "not writable")


def test_output_rate_must_be_positive_and_finite(drive):
    for bad in ("-1", "nan", "inf", "0"):
        one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--output-rate", bad),
                       "--output-rate")


def test_check_outputs_api_for_other_options(tmp_path):
    """The guard is general: any option name, files and directories."""
    target = tmp_path / "report.html"
    target.write_text("x")
    with pytest.raises(outputs.OutputError, match="--report .* exists"):
        outputs.check_outputs([outputs.Output(target, "--report")])
    outputs.check_outputs([outputs.Output(target, "--report")], force=True)
    outputs.check_outputs([outputs.Output(tmp_path / "new" / "deeper" / "e.csv", "--export")])
    with pytest.raises(outputs.OutputError, match="is a directory"):
        outputs.check_outputs([outputs.Output(tmp_path, "--export")], force=True)


# --------------------------------------------------------------------------------------------
# 2. signals and temporaries


def _spawn(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(NAVREPLAY + args, cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130),
                                       (signal.SIGHUP, 129)])
def test_signal_during_run_save_removes_the_temporary(drive, tmp_path, sig, code):
    target = tmp_path / "view.rrd"
    target.write_bytes(b"the user's view")
    proc = _spawn(["run", "gps-ins", str(drive), "--save", str(target), "--force",
                   "--rate", "1"], tmp_path)  # paced: runs for 20 s
    try:
        assert wait_for(lambda: parts(tmp_path), 30), "no temporary appeared"
        time.sleep(0.3)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == code, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert parts(tmp_path) == []
    assert target.read_bytes() == b"the user's view"


def test_sigterm_during_simulate_and_stale_temporaries_of_kill_9(tmp_path):
    target = tmp_path / "long.mcap"
    target.write_bytes(b"keep")
    args = ["simulate", "vehicle-drive", "-o", str(target), "--duration", "3600", "--force"]
    proc = _spawn(args, tmp_path)
    try:
        assert wait_for(lambda: parts(tmp_path), 120), "no temporary appeared"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 143 and "terminated by SIGTERM" in err, err
    assert parts(tmp_path) == [] and target.read_bytes() == b"keep"

    # kill -9 of the command and its worker (the process group, as a killed session would)
    proc = subprocess.Popen(NAVREPLAY + args, cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        assert wait_for(lambda: parts(tmp_path), 120)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=30)
    finally:
        proc.kill()
    left = parts(tmp_path)
    assert len(left) == 1  # kill -9 cannot clean up
    assert wait_for(lambda: not outputs._alive(outputs._pid_of(left[0])), 10)
    res = invoke("simulate", "stationary", "-o", tmp_path / "next.mcap", "--duration", "5")
    assert res.exit_code == 0, res.output
    assert "temporary file of an interrupted run" in res.stderr
    assert parts(tmp_path) == [] and target.read_bytes() == b"keep"


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rpartition(")")[2].split()[1]) == pid:
                out.append(int(d.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_montecarlo_workers_die_with_their_parent(tmp_path):
    proc = _spawn(["montecarlo", "vehicle-drive", "gps-ins", "--runs", "8", "--workers", "2",
                   "--duration", "600", "--no-viz"], tmp_path)
    try:
        assert wait_for(lambda: len(_children(proc.pid)) >= 2, 60), "no workers"
        workers = _children(proc.pid)
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=30)
        assert wait_for(lambda: not any(_alive(w) for w in workers), 10), workers
    finally:
        proc.kill()


def test_temporary_names_carry_the_pid_and_host(tmp_path):
    tmp = outputs.temporary_path(tmp_path / "x.json")
    assert tmp.name.startswith(f".x.json.{os.getpid()}@") and tmp.name.endswith(".part")
    tmp.write_text("partial")
    assert outputs.stale_temporaries(tmp_path) == []  # ours, alive
    assert outputs.remove_temporaries() == [tmp] and not tmp.exists()


def test_only_this_machines_dead_temporaries_are_stale(tmp_path):
    """On a shared file system another machine's PID says nothing here: its temporary is
    kept; this machine's (and an older name without a host) of a dead process are stale."""
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    pid = dead.pid
    host = tmp.name.split("@")[1].split(".")[0] if (
        tmp := outputs.temporary_path(tmp_path / "y.json")) else ""
    outputs.release(tmp)
    mine = tmp_path / f".a.json.{pid}@{host}.0123abcd.part"
    older = tmp_path / f".b.json.{pid}.0123abcd.part"
    other = tmp_path / f".c.json.{pid}@another-host.0123abcd.part"
    for p in (mine, older, other):
        p.write_text("partial")
    assert outputs.stale_temporaries(tmp_path) == sorted([mine, older])


# --------------------------------------------------------------------------------------------
# 3. IMU gaps


@pytest.fixture(scope="module")
def gap_drive() -> Recording:
    return simulate("vehicle-drive", {"duration": 90.0}, seed=1)


@pytest.mark.parametrize("length", [2.0, 5.0])
def test_gps_ins_nees_back_in_its_band_after_a_gap(gap_drive, length):
    """The vehicle turns during the gap at t = 40 s; the bridged covariance covers the error,
    so 10-30 s after the gap the NEES (9 dof) is inside its 95 % band on average and the
    position error is small again."""
    res = replay(cut_imu(gap_drive, 40.0, length), GpsInsFilter)
    m = metrics.run_metrics(res, gap_drive)
    assert len(m.nees_states) == 9
    lo, hi = metrics.chi2_bounds(9)
    after = (m.t > 50.0 + length) & (m.t <= 70.0 + length)
    nees = m.nees[after]
    assert lo < np.mean(nees) < hi, np.mean(nees)
    assert np.mean((nees > lo) & (nees < hi)) > 0.8
    assert np.all(np.isfinite(m.nees))


def test_a_bridge_without_the_unknown_motion_would_be_inconsistent(gap_drive):
    """A bridge that dead-reckons without covering the unknown motion leaves the NEES of the
    same 2 s gap far outside its band: the test above can fail."""
    res = replay(cut_imu(gap_drive, 40.0, 2.0), GpsInsFilter,
                 {"gap_accel_sigma": 0.0, "gap_rate_sigma": 0.0})
    m = metrics.run_metrics(res, gap_drive)
    after = (m.t > 52.0) & (m.t <= 72.0)
    assert np.mean(m.nees[after]) > metrics.chi2_bounds(9)[1]


def test_long_gap_stops_in_one_line_unless_allowed(gap_drive, tmp_path):
    path = tmp_path / "gap.mcap"
    write_recording(path, cut_imu(gap_drive, 40.0, 10.0))
    one_line_error(invoke("run", "gps-ins", path, "--no-viz"), str(path), "imu",
                   "t = 40.000 s", "--max-imu-gap")
    res = invoke("run", "gps-ins", path, "--no-viz", "--max-imu-gap", "12")
    assert res.exit_code == 0, res.output
    one_line_error(invoke("run", "gps-ins", path, "--no-viz", "--max-imu-gap", "nan"),
                   "--max-imu-gap")


@pytest.mark.parametrize("n", [0, 2])
def test_imu_too_short_is_an_error(gap_drive, tmp_path, n):
    rec = gap_drive
    imu = rec[StreamKind.IMU]
    streams = dict(rec.streams)
    streams[StreamKind.IMU] = imu.slice(0, n)
    path = tmp_path / f"imu{n}.mcap"
    write_recording(path, Recording(streams, rec.metadata, rec.t0_ns))
    err = one_line_error(invoke("run", "gps-ins", path, "--no-viz"))
    assert "imu" in err


# --------------------------------------------------------------------------------------------
# 4. configuration


@pytest.mark.parametrize("text, line, fragment", [
    ("[filtr.gps-ins]\ngps_pos_sigma_scale = 2\n", 1, "unknown table [filtr]"),
    ("# a comment\n[filter.gps-ins]\ngps_pos_sigma_scale = 2\n[filter.gps-inz]\nx = 1\n", 4,
     "[filter.gps-inz]: no such filter"),
    ("\ngps_pos_sigma_scale = 2\n[filter.gps-ins]\n", 2, "outside any table"),
])
def test_config_mistakes_name_the_line(drive, tmp_path, text, line, fragment):
    cfg = tmp_path / "c.toml"
    cfg.write_text(text)
    one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--config", cfg),
                   f"{cfg}:{line}:", fragment)


def test_config_tables_per_command(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[scenario]\nduration = 5.0\n[filter.gps-ins]\ngps_pos_sigma_scale = 2\n")
    one_line_error(invoke("simulate", "stationary", "-o", tmp_path / "s.mcap", "--config", cfg),
                   "unknown table [filter]")
    cfg.write_text("[scenario]\nduration = 5.0\n")
    assert invoke("simulate", "stationary", "-o", tmp_path / "s.mcap",
                  "--config", cfg).exit_code == 0


# --------------------------------------------------------------------------------------------
# 5. recordings


def test_metadata_record_precedes_the_messages(drive):
    with drive.open("rb") as f:
        kinds = [type(r).__name__ for r in StreamReader(f, emit_chunks=True).records]
    assert kinds[:3] == ["Header", "Metadata", "Chunk"]


def test_recordings_are_byte_identical_for_a_seed(tmp_path):
    rec = simulate("stationary", {"duration": 5.0}, seed=4)
    write_recording(tmp_path / "a.mcap", rec)
    write_recording(tmp_path / "b.mcap", simulate("stationary", {"duration": 5.0}, seed=4))
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def test_truncated_recording_keeps_its_metadata_and_says_salvaged(drive, tmp_path, monkeypatch):
    from navreplay.io import writer

    monkeypatch.setattr(writer, "CHUNK_SIZE", 1 << 16)
    small = tmp_path / "small.mcap"
    write_recording(small, simulate("vehicle-drive", {"duration": 20.0}, seed=3))
    data = small.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    res = invoke("info", cut)
    assert res.exit_code == 1 and "DAMAGED" in res.output and "scenario: vehicle-drive" in \
        res.output
    res = invoke("run", "gps-ins", cut, "--no-viz", "--summary", tmp_path / "s.json")
    assert res.exit_code == 0, res.output
    assert "SALVAGED" in res.output
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["salvaged"] is True and 0.2 < summary["coverage"] < 0.9


def test_info_garbage_and_inconsistent_indexes(drive, tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"\x89MCAP0\r\n" + b"123456789")  # 17 bytes, MCAP magic
    one_line_error(invoke("info", junk), "DAMAGED", "0 messages")
    junk.write_bytes(os.urandom(17))
    one_line_error(invoke("info", junk), "not an MCAP file")
    # a message index time that disagrees with the summary (an uncompressed file without CRCs
    # cannot tell otherwise): DAMAGED, exit 1
    plain = tmp_path / "plain.mcap"
    uncompressed_copy(drive, plain)
    data = bytearray(plain.read_bytes())
    with plain.open("rb") as f:
        summary = SeekingReader(f).get_summary()
    offset = next(iter(summary.chunk_indexes[0].message_index_offsets.values()))
    data[offset + 1 + 8 + 2 + 4 + 5] ^= 0x10  # the first entry's log time, by about 4e3 s
    plain.write_bytes(bytes(data))
    res = invoke("info", plain)
    assert res.exit_code == 1 and "DAMAGED" in res.output and "summary" in res.output


# --------------------------------------------------------------------------------------------
# 6. exit codes


class _Check:
    def __init__(self, passed: bool) -> None:
        self.passed = passed


class _Report:
    checks = [_Check(True), _Check(False)]
    passed = False

    def format(self) -> str:
        return "a reproduction"


class _Rep:
    summary = "fake"
    quick_runs = 1

    def run(self, **kw):
        return _Report()


def test_reproduce_and_demo_fail_on_a_missed_band(monkeypatch, in_tmp):
    import navreplay.reproduce as registry
    from navreplay import jobs

    monkeypatch.setattr(registry, "get", lambda name: _Rep())
    one_line_error(invoke("reproduce", "x"), "1 acceptance check(s) failed")
    assert invoke("reproduce", "x", "--no-strict").exit_code == 0
    monkeypatch.setattr(jobs, "demo", lambda job, progress: jobs.DemoReport(["d"], None,
                                                                            failed_checks=2))
    one_line_error(invoke("demo", "--no-view"), "2 acceptance check(s) failed")
    assert invoke("demo", "--no-view", "--no-strict").exit_code == 0


def test_help_documents_exit_codes():
    text = invoke("--help").output
    for code in ("130", "143", "usage error", "--no-strict", "DAMAGED"):
        assert code in text


# --------------------------------------------------------------------------------------------
# 7. what used to end in a traceback


@pytest.fixture(scope="module")
def odd_bags(tmp_path_factory) -> dict[str, Path]:
    from rosbag_maker import write_bag

    root = tmp_path_factory.mktemp("odd")
    return {"no_imu": write_bag(root / "no_imu", duration=20.0, imu=False),
            "text": write_bag(root / "text", duration=20.0, text_topic="/status")}


def test_a_bag_without_imu_and_init_reference(odd_bags):
    one_line_error(invoke("run", "ins", odd_bags["no_imu"], "--no-viz", "--init", "reference",
                          "--reference", "/ground_truth/odom"),
                   "--init reference", "no IMU samples", "--topic imu=")


def test_a_reference_topic_of_another_type(odd_bags, drive):
    one_line_error(invoke("run", "ins", odd_bags["text"], "--no-viz", "--init", "reference",
                          "--reference", "/status"),
                   "reference /status: type std_msgs/msg/String cannot be a reference",
                   "nav_msgs/msg/Odometry")
    one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--reference", "/imu"),
                   "type sensor_msgs/msg/Imu cannot be a reference")


def test_output_rate_has_an_upper_bound(drive):
    for bad in ("1e9", "1000.5"):
        one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--output-rate", bad),
                       "--output-rate must be positive and at most 1000 Hz")
    assert invoke("run", "ins", drive, "--no-viz", "--output-rate", "1000").exit_code == 0


def test_a_position_only_reference_is_viewed_exported_and_reported(drive, tmp_path):
    """A reference with positions only: the default view, the exports and the report are
    written (its missing attitude is NaN, never made up), and the position is scored."""
    rec = read_recording(drive)
    truth = rec[StreamKind.TRUTH]
    rows = ["t_ns,lat_deg,lon_deg,h"] + [
        f"{t},{np.degrees(p[0]):.10f},{np.degrees(p[1]):.10f},{p[2]:.4f}"
        for t, p in zip(truth.t_ns[::10], truth["pos"][::10], strict=True)]
    ref = tmp_path / "pos.csv"
    ref.write_text("\n".join(rows) + "\n")
    out = tmp_path / "out"
    res = invoke("run", "gps-ins", drive, "--reference", ref, "--save", out / "v.rrd",
                 "--export", out / "e", "--report", out / "r.html", "--summary", out / "s.json")
    assert res.exit_code == 0, res.output
    assert res.stderr == "", res.stderr
    assert (out / "v.rrd").stat().st_size > 0 and (out / "r.html").stat().st_size > 0
    lines = [ln.split() for ln in (out / "e" / "reference.tum").read_text().splitlines()
             if not ln.startswith("#")]
    assert len(lines) == len(rows) - 1 and all(ln[4:] == ["nan"] * 4 for ln in lines)
    s = json.loads((out / "s.json").read_text())["filters"]["gps-ins"]
    assert s["pos_rms_h"] < 5.0 and "att_rms_heading" not in s


def test_info_exit_status_agrees_with_what_it_prints(drive, tmp_path):
    """A CRC mismatch (an uncompressed file with chunk CRCs, one bit flipped in a chunk) is
    printed and is an error: exit 1."""
    plain = tmp_path / "crc.mcap"
    uncompressed_copy(drive, plain, crcs=True)
    data = bytearray(plain.read_bytes())
    data[len(data) // 2] ^= 0x10
    plain.write_bytes(bytes(data))
    res = invoke("info", plain)
    assert res.exit_code == 1 and "CRC mismatch" in res.output
    one_line_error(res, "CRC mismatch")


def test_no_raw_warning_lines_after_an_error(tmp_path):
    """An error while a file is read in windows: the reader's warnings come as `warning:`
    lines before the error, never as `sys:1: RecordingWarning` at exit."""
    from rosbag_maker import write_bag

    bag = write_bag(tmp_path / "bag", duration=20.0)
    data = next(bag.glob("*.mcap"))  # the bag's MCAP file alone: no start for gps-ins
    res = subprocess.run(NAVREPLAY + ["run", "gps-ins", str(data), "--no-viz"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert "sys:1" not in res.stderr and "RecordingWarning" not in res.stderr, res.stderr
    assert lines[-1].startswith("Error: ") and all(ln.startswith("warning: ")
                                                   for ln in lines[:-1]), lines
