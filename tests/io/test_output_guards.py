"""No input is ever a target, outputs never clash, two commands never write the same file, and a
full disk publishes nothing: through the command line, before any work."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from commands import NAVREPLAY, one_line_error, parts, wait_for
from rosbag_maker import write_bag

from navreplay.cli import cli
from navreplay.io import outputs, write_recording
from navreplay.sim.scenario import simulate


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def drive(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("drive") / "drive.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 20.0}, seed=3))
    return path


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    return write_bag(tmp_path_factory.mktemp("bag") / "bag", duration=20.0)


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


# --------------------------------------------------------------------------------------------
# inputs


def test_nothing_is_written_into_a_bag_folder_even_with_force(bag, tmp_path):
    before = _snapshot(bag)
    data = next(p for p in bag.iterdir() if p.suffix == ".mcap")
    for args in (("--summary", bag / "metadata.yaml"), ("--save", data),
                 ("--report", bag / "new.html"), ("--export", bag / "exports"),
                 ("--save", bag)):
        viz = () if args[0] == "--save" else ("--no-viz",)
        for force in ((), ("--force",)):
            one_line_error(invoke("run", "gps-ins", bag, *viz, *args, *force), args[0],
                           str(bag))
    # the bag named by its metadata.yaml or data file protects its folder too
    one_line_error(invoke("run", "gps-ins", bag / "metadata.yaml", "--no-viz",
                          "--summary", data, "--force"), "--summary", "input")
    one_line_error(invoke("run", "gps-ins", data, "--no-viz", "--summary",
                          bag / "s.json"), "--summary", "inside", "input folder")
    assert _snapshot(bag) == before


def test_an_export_never_writes_over_an_input_in_its_directory(drive, tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    rec = d / "estimates.mcap"  # the name of the export's Odometry file
    rec.write_bytes(drive.read_bytes())
    cfg = d / "gps-ins.toml"  # gps-ins.* are the filter's export files
    cfg.write_text("[filter.gps-ins]\ngps_pos_sigma_scale = 2.0\n")
    ref = d / "reference.tum"
    ref.write_text("# t x y z qx qy qz qw\n")
    for args in ((rec,), (drive, "--config", cfg), (drive, "--reference", ref)):
        for force in ((), ("--force",)):
            one_line_error(invoke("run", "gps-ins", *args, "--no-viz", "--export", d, *force),
                           f"--export {d}", "would write over", "input")
    assert rec.read_bytes() == drive.read_bytes() and "sigma_scale" in cfg.read_text()
    # a campaign's export directory the same way
    one_line_error(invoke("montecarlo", "vehicle-drive", "gps-ins", "--runs", "1", "--no-viz",
                          "--config", cfg, "--export", d), "would write over")


def test_outputs_of_one_command_never_clash(drive, tmp_path):
    x = tmp_path / "x"
    cases = [("--summary", x / "manifest.json"), ("--save", x / "estimates.mcap"),
             ("--report", x / "gps-ins.csv"), ("--summary", x / "gps-ins.innovations.gps.csv"),
             ("--report", x / "reference.tum")]
    for option, path in cases:
        err = one_line_error(invoke("run", "gps-ins", drive, "--export", x, option, path,
                                    *(("--no-viz",) if option != "--save" else ())),
                             f"{option} {path}", f"inside --export {x}")
        assert "choose another" in err
    one_line_error(invoke("montecarlo", "stationary", "ins", "--runs", "1", "--duration", "5",
                          "--no-viz", "--export", x, "--report", x / "ins.ensemble.csv"),
                   "inside --export")
    # any other name inside the export directory too (it is the export's own folder)
    one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--export", x, "--summary",
                          x / "sub" / "summary.json"), "inside --export")
    assert not x.exists()  # refused before any work
    # beside the export directory is fine, and so is the default view beside an input under out/
    res = invoke("run", "gps-ins", drive, "--no-viz", "--export", x, "--summary",
                 tmp_path / "summary.json", "--report", tmp_path / "report.html")
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "summary.json").read_text())["filters"]["gps-ins"]
    out = Path("out")
    out.mkdir()
    (out / "drive.mcap").write_bytes(drive.read_bytes())
    assert invoke("run", "gps-ins", out / "drive.mcap").exit_code == 0
    assert (out / "drive.rrd").is_file()


def test_check_outputs_api(tmp_path):
    folder = tmp_path / "bag"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("x")
    with pytest.raises(outputs.OutputError, match="inside .* input folder"):
        outputs.check_outputs([outputs.Output(folder / "deep" / "s.json", "--summary")],
                              [folder], force=True)
    export = outputs.Output(tmp_path / "e", "--export", directory=True, writes=("a.*",))
    assert export.receives(tmp_path / "e" / "a.csv")
    assert not export.receives(tmp_path / "e" / "b.csv")
    assert not export.receives(tmp_path / "e" / "sub" / "a.csv")
    for name in ("a.json", "b.json", "sub/c.json"):
        with pytest.raises(outputs.OutputError, match="inside --export"):
            outputs.check_outputs([export, outputs.Output(tmp_path / "e" / name, "--summary")])
    outputs.check_outputs([export, outputs.Output(tmp_path / "b.json", "--summary")])
    # the default view's folder holds only the files it writes
    view = outputs.Output(tmp_path / "out", "--save (default)", explicit=False, directory=True,
                          writes=("*.rrd",))
    outputs.check_outputs([view, outputs.Output(tmp_path / "out" / "s.json", "--summary")])


# --------------------------------------------------------------------------------------------
# concurrent commands


def _spawn(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(NAVREPLAY + args, cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def test_two_commands_never_write_the_same_outputs(drive, tmp_path):
    """A paced run holds its outputs; a second command naming any of them stops at once,
    naming the first one's PID, and leaves the first one's work alone."""
    summary, export, view = tmp_path / "s.json", tmp_path / "e", tmp_path / "v.rrd"
    first = _spawn(["run", "gps-ins", str(drive), "--rate", "2", "--force", "--summary",
                    str(summary), "--export", str(export), "--save", str(view)], tmp_path)
    try:
        assert wait_for(lambda: parts(tmp_path), 60), "the first run did not start"
        for args in (("--no-viz", "--summary", summary), ("--no-viz", "--export", export),
                     ("--save", view)):
            t0 = time.monotonic()
            one_line_error(invoke("run", "gps-ins", drive, "--force", *args),
                           f"{args[-2]} {args[-1]}", "another navreplay command",
                           f"PID {first.pid}")
            assert time.monotonic() - t0 < 5.0
        sim = _spawn(["simulate", "stationary", "-o", str(summary), "--duration", "5",
                      "--force"], tmp_path)  # another process, another command
        _, err = sim.communicate(timeout=120)
        assert sim.returncode == 1 and f"PID {first.pid}" in err, err
        out, err = first.communicate(timeout=120)
    finally:
        first.kill()
    assert first.returncode == 0, err
    assert json.loads(summary.read_text())["filters"]["gps-ins"]
    assert (export / "manifest.json").is_file() and view.stat().st_size > 0
    assert not list(tmp_path.glob(".*.lock")), "locks are removed at the end"
    # the lock of a process killed outright does not block
    second = _spawn(["run", "gps-ins", str(drive), "--rate", "2", "--force", "--no-viz",
                     "--summary", str(summary)], tmp_path)
    try:
        assert wait_for(lambda: outputs.lock_path(summary).exists(), 60)
        second.send_signal(signal.SIGKILL)
        second.communicate(timeout=30)
    finally:
        second.kill()
    res = invoke("run", "gps-ins", drive, "--no-viz", "--summary", summary, "--force")
    assert res.exit_code == 0, res.output


def test_a_forked_worker_never_removes_its_parents_locks(tmp_path):
    target = outputs.Output(tmp_path / "s.json", "--summary")
    outputs.lock_outputs([target])
    try:
        pid = os.fork()
        if pid == 0:  # the child: what a pool worker does when it stops
            outputs.remove_temporaries()
            os._exit(0)
        os.waitpid(pid, 0)
        assert outputs.lock_path(target.path).exists()
        with pytest.raises(outputs.OutputError, match="another navreplay command"):
            _lock_in_child(target)
    finally:
        outputs.release_locks()
    assert not outputs.lock_path(target.path).exists()


def _lock_in_child(target: outputs.Output) -> None:
    """Try the lock from another process (a lock is per process); raise what it raised."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(r)
        try:
            outputs.lock_outputs([target])
            os.write(w, b"")
        except outputs.OutputError as e:
            os.write(w, str(e).encode())
        os._exit(0)
    os.close(w)
    message = os.read(r, 4096).decode()
    os.close(r)
    os.waitpid(pid, 0)
    if message:
        raise outputs.OutputError(message)


# --------------------------------------------------------------------------------------------
# a full disk


@contextlib.contextmanager
def small_disk(path: Path, size: str = "300k"):
    """A small tmpfs at ``path`` (needs the right to mount; else the test is skipped)."""
    path.mkdir()
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                         capture_output=True)
    if res.returncode:
        pytest.skip("cannot mount a small tmpfs here")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="tmpfs")
def test_a_full_disk_publishes_nothing_and_says_so_in_one_line(drive, tmp_path):
    with small_disk(tmp_path / "small") as disk:
        fill = disk / "fill"
        for args, what, full in (
                (("--save", disk / "v.rrd"), f"{disk / 'v.rrd'}: the Rerun view is incomplete",
                 False),
                (("--no-viz", "--export", disk / "e"), f"--export {disk / 'e'}: ", False),
                (("--no-viz", "--report", disk / "r.html"), "r.html: No space", True),
                (("--no-viz", "--summary", disk / "s.json"), "s.json: No space", True)):
            if full and not fill.exists():
                _fill(fill)
            res = subprocess.run(NAVREPLAY + ["run", "gps-ins", str(drive), *map(str, args)],
                                 capture_output=True, text=True, cwd=tmp_path, timeout=300)
            assert res.returncode == 1, res.stderr
            lines = res.stderr.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("Error: ") and what in lines[0], lines
            assert "No space left on device" in lines[0] or "disk is full" in lines[0]
            left = [p for p in disk.rglob("*") if p.is_file() and p != fill]
            assert left == [], left  # nothing published, no temporary left


def _fill(path: Path) -> None:
    """Write ``path`` until the disk is full."""
    with contextlib.suppress(OSError), path.open("wb", buffering=0) as f:
        while True:
            f.write(b"\0" * 1024)


def _file_size_limit(limit: int):
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes past the limit fail: EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_FSIZE")
def test_a_view_cut_short_is_never_published(drive, tmp_path):
    """Rerun writes the .rrd in a thread of its own and reports a failed write only in its
    log: the file is checked for its footer before it is renamed onto the target."""
    target = tmp_path / "v.rrd"
    target.write_bytes(b"the user's view")
    res = subprocess.run(NAVREPLAY + ["run", "gps-ins", str(drive), "--save", str(target),
                                      "--force"], capture_output=True, text=True, cwd=tmp_path,
                         preexec_fn=_file_size_limit(200_000), timeout=300)
    assert res.returncode == 1, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "the Rerun view is incomplete" in lines[0], lines
    assert target.read_bytes() == b"the user's view" and parts(tmp_path) == []


def test_disk_errors_are_one_line_wherever_they_happen(drive, tmp_path, monkeypatch):
    from navreplay import export

    def full(*args, **kw):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(export.RunExport, "add", full)
    one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--export", tmp_path / "e"),
                   f"--export {tmp_path / 'e'}", "No space left on device")
    assert not (tmp_path / "e" / "manifest.json").exists() and parts(tmp_path / "e") == []
    monkeypatch.undo()
    import importlib

    # a write with no file name at all
    monkeypatch.setattr(importlib.import_module("navreplay.jobs.run"), "write_json", full)
    one_line_error(invoke("run", "gps-ins", drive, "--no-viz", "--summary", tmp_path / "s"),
                   "No space left on device; nothing was written")


def test_rrd_footer_check(tmp_path):
    import numpy as np
    import rerun as rr

    from navreplay.viz.targets import rrd_problem

    path = tmp_path / "a.rrd"
    rec = rr.RecordingStream("navreplay-test", recording_id="footer")
    rec.save(path)
    rec.send_columns("/s", indexes=[rr.TimeColumn("t", duration=np.arange(100.0))],
                     columns=rr.Scalars.columns(scalars=np.arange(100.0)))
    rec.flush()
    rec.disconnect()
    assert rrd_problem(path) is None
    data = path.read_bytes()
    for cut in (len(data) - 1, len(data) // 2, 10):
        path.write_bytes(data[:cut])
        assert rrd_problem(path).startswith("incomplete")
    path.write_bytes(data[:-40] + data[-32:])  # a footer whose manifest does not end there
    assert "does not match" in rrd_problem(path)
