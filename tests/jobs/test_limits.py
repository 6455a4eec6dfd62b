"""Limits: `simulate` refuses recordings that would not fit on disk or in memory (estimated from
a short probe, before any work) and stops within a second of SIGTERM or Ctrl-C, wherever its
workers are; its refusals name `--force`, not the Python argument."""

from __future__ import annotations

import importlib
import signal
import subprocess
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from commands import NAVREPLAY, one_line_error, parts

from navreplay.cli import cli
from navreplay.jobs import SimulateJob

simulate_job = importlib.import_module("navreplay.jobs.simulate")  # the module, not the function


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_a_duration_that_cannot_fit_is_refused_at_once(tmp_path):
    t0 = time.monotonic()
    err = one_line_error(invoke("simulate", "vehicle-drive", "-o", tmp_path / "x.mcap",
                                "--duration", "1e12"),
                         "simulate vehicle-drive: the recordings would take about",
                         "GiB on disk", "free", "60 s probe")
    assert time.monotonic() - t0 < 30.0, "refused before any work"
    assert "e+07 GiB" in err  # about 20 kB per second of a drive: 2e7 GiB for 1e12 s
    assert list(tmp_path.iterdir()) == []


def test_the_estimate_scales_a_probe(tmp_path):
    """The probe's file and peak memory per second, times the duration and the runs (disk)
    or the runs at once (memory); recordings no longer than the probe are not estimated."""
    job = SimulateJob("vehicle-drive", tmp_path / "a.mcap", {"duration": 600.0}, runs=3,
                      workers=2)
    est = simulate_job.estimate_size(job)
    one = simulate_job.estimate_size(SimulateJob("vehicle-drive", tmp_path / "b.mcap",
                                                 {"duration": 600.0}))
    assert est.disk_bytes == pytest.approx(3 * one.disk_bytes, rel=1e-9)
    assert est.memory_bytes == pytest.approx(2 * one.memory_bytes, rel=0.05)
    # a 20 s drive's file (about 0.4 MB) per 20 s, within a factor of 2
    assert 0.5 < one.disk_bytes / (30 * 415_600) < 2.0, one.disk_bytes
    assert simulate_job.estimate_size(SimulateJob("vehicle-drive", tmp_path / "c.mcap",
                                                  {"duration": 30.0})) is None


def test_memory_that_is_not_there_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(simulate_job, "available_memory", lambda: 50 << 20)  # 50 MiB
    one_line_error(invoke("simulate", "vehicle-drive", "-o", tmp_path / "x.mcap",
                          "--duration", "3600"),
                   "would need about", "of memory and 0.0488 GiB is available")
    assert invoke("simulate", "vehicle-drive", "-o", tmp_path / "y.mcap",
                  "--duration", "30").exit_code == 0


def test_an_existing_file_names_the_option(tmp_path):
    target = tmp_path / "x.mcap"
    target.write_bytes(b"mine")
    err = one_line_error(invoke("simulate", "stationary", "-o", target, "--duration", "5"),
                         "--force")
    assert "force=True" not in err


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_simulate_stops_within_a_second(tmp_path, sig, code):
    """A two-hour drive: the signal comes while a worker is deep in the simulation (numpy and
    compiled kernels over 720,000 samples, which do not look at signals for up to seconds);
    the command still ends within a second, with one line, and leaves nothing behind."""
    target = tmp_path / "long.mcap"
    target.write_bytes(b"keep")
    latencies = []
    for delay in (0.5, 2.0):  # after the worker starts: the drive takes seconds on any machine
        proc = subprocess.Popen(NAVREPLAY + ["simulate", "vehicle-drive", "-o", str(target),
                                             "--duration", "7200", "--force"], cwd=tmp_path,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            started = time.monotonic() + 60.0
            while _processes_of(target) < 2 and proc.poll() is None \
                    and time.monotonic() < started:
                time.sleep(0.05)
            time.sleep(delay)
            assert proc.poll() is None, proc.communicate()
            t0 = time.monotonic()
            proc.send_signal(sig)
            _, err = proc.communicate(timeout=30)
            latencies.append(time.monotonic() - t0)
        finally:
            proc.kill()
        assert proc.returncode == code, err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert max(latencies) < 1.5, latencies  # a second, and scheduling on a busy machine
    assert parts(tmp_path) == [] and target.read_bytes() == b"keep"
    deadline = time.monotonic() + 3.0  # workers end on their parent's death, when scheduled
    while _children_alive(target) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _children_alive(target), "the workers are gone"


def _processes_of(target: Path) -> int:
    """The processes of this test's command: the command and its forked workers, whose command
    lines name its target (other runs of the suite may simulate a file of the same name
    meanwhile, in another folder)."""
    count = 0
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes()
            except OSError:
                continue
            count += str(target).encode() in cmd and b"simulate" in cmd
    return count


def _children_alive(target: Path) -> bool:
    """Any worker left of this test's command."""
    return _processes_of(target) > 0
