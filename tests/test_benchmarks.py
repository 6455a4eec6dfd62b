"""Every benchmark still runs: ``python -m benchmarks --quick NAME`` (the same code at tiny
sizes) exits 0 and prints its ratio lines, and writes nothing into the working directory.

Slow (about a minute for all of them on two cores): run with ``make reproduce-tests``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
NAMES = sorted(p.stem for p in (ROOT / "benchmarks").glob("bench_*.py"))

_N = r"[\d,.]+(?:e[+-]\d+)?"  # a figure as the benchmarks print it (1,234 or 1.5 or 1.2e+06)

# per module: (pattern, how many lines must match it); the lines that carry the ratios
RATIO_LINES: dict[str, list[tuple[str, int]]] = {
    "bench_campaign": [
        (rf"^  .{{24}} +{_N} ms per run$", 3),
        (rf"^  repeat 1: one process +{_N} s, .+ {_N} s = {_N}x$", 2),
        (rf"^  .{{24}} speed-up median {_N}x \(range {_N}-{_N}; target >= (1\.8|1)x on an idle "
         rf"machine: (met|NOT met)\)$", 2),
    ],
    "bench_filters": [
        (rf"^strapdown\.integrate, one call \(baseline\) +{_N} +{_N} +1\.0$", 1),
        (rf"^(strapdown\.propagate|ins|gps-ins), .+ +{_N} +{_N} +{_N}$", 4),
        (rf"^(kalman|ins_error|ins_time_update)\..+ +{_N}$", 6),
    ],
    "bench_rrd_size": [
        (rf"^  (full rate \(--full-rate\)|drawn envelopes \(default\)|drawn, outputs at 100 Hz):"
         rf" +{_N} MB +{_N} MB/h  \({_N} s\)$", 3),
        (rf"^size per hour: {_N} MB/h, {_N}x smaller than full rate \(target <= 30 MB/h: "
         r"(met|NOT met)\)$", 1),
    ],
    "bench_smoothing": [
        (rf"^ +{_N}s ratios: backward / forward = {_N}, forward with --smooth / without = "
         rf"{_N}, peak with / without = {_N}; ", 1),
    ],
    "bench_io": [
        (rf"^write Imu .*: ratio {_N}x \(target >= 5x: (met|NOT met)\)$", 1),
        (rf"^read\+decode Imu .*: ratio {_N}x \(target >= 10x: (met|NOT met)\); identical "
         r"columns: True$", 1),
        (r"^file size .*; message payloads identical: True$", 1),
        (rf"^write .* at 200 Hz .*: peak RSS {_N} MiB", 1),
        (rf"^read the same file in {_N} s: peak RSS {_N} MiB", 1),
    ],
    "bench_kalman": [
        (rf"^\S.*\) +\d+ +\d+( +{_N}){{4}}$", 5),
    ],
    "bench_memory": [
        (rf"^ *{_N}[hs] +(streamed|rrd|outputs|whole) +{_N} MiB +1\.00x +{_N}$", 4),
    ],
    "bench_outputs": [
        (rf"^ +{_N} Hz +(no-viz|export|rrd) +{_N} +{_N} +{_N}$", 6),
        (rf"^(export|rrd) / no-viz wall at {_N} Hz, {_N} min: {_N}x \(target <= {_N}x: "
         rf"(met|NOT met)\); CPU {_N}x$", 4),
        (rf"^(no-viz|export|rrd) peak RSS 100 Hz / 10 Hz, {_N} min: {_N}x \(target <= 1\.2x: "
         r"(met|NOT met)\)$", 3),
    ],
    "bench_realdrive": [
        (rf"^  (numpy|bag default|bag --no-viz) +{_N} +{_N} +{_N} MB +[+-]{_N} MB$", 3),
        (rf"^bag \(drive_bag\) (default|--no-viz): {_N} s CPU = {_N}x KF-GINS's 1\.1 s "
         r"\(target <= 1\.65 s: (met|NOT met)\)$", 2),
        (rf"^bag \(drive_bag\) --no-viz: peak RSS [+-]{_N} MB over bare numpy \(target <= "
         r"\+150 MB: (met|NOT met)\)$", 1),
        (rf"^  \+ .+ +[+-]{_N} MB = +{_N} MB$", 9),
        (rf"^before reading any data: [+-]{_N} MB over numpy, of which LLVM and numba .+ "
         rf"[+-]{_N} MB$", 1),
    ],
    "bench_replay": [
        (rf"^end to end \(decode \+ gps-ins \+ summary\) +{_N} s +{_N}k IMU samples/s", 1),
        (rf"^ratios: end to end / strapdown = {_N}$", 1),
        (rf"^gps-ins replay / strapdown on the same samples = {_N} ", 1),
        (rf"^peak RSS of a process reading \+ replaying gps-ins over it: {_N} MiB", 1),
    ],
    "bench_rpm_aided_ins": [
        (rf"^(ins|rpm-aided-ins) .+( +{_N}){{6}}$", 4),
        (rf"^rpm_current end to end: {_N} IMU samples/s, (meets|MISSES) the target", 1),
        (r"^campaign: 2 simulations \+ 6 filter runs in .* checks \d+/\d+ passed$", 1),
    ],
    "bench_startup": [
        (rf"^  (first run|warm run|start-up|python) +{_N} s CPU +{_N} s wall$", 4),
        (rf"^  first run / warm run +{_N}x CPU$", 1),
    ],
    "bench_strapdown": [
        (rf"^speed-up integrate / reference +{_N} x$", 1),
        (rf"^propagate, k = 10 block +{_N} us/call", 1),
        (rf"^imu_from_truth, .* +{_N} k samples/s$", 1),
    ],
    "bench_transfer_alignment": [
        (rf"^  (engine only|free INS|transfer-alignment) .+( +{_N}){{4}}$", 5),
        (rf"^  .+ \((numba|kalman\.correct)\) +{_N} us$", 3),
        (rf"^  baseline: numpy discretize \+ predict +{_N} us$", 1),
        (r"^campaign: 3 recordings, \d+ filter runs in .* wall", 1),
    ],
    "bench_vector_matching": [
        (rf"^  (simulate|filter \(per model\)|metrics) +{_N} +{_N} +{_N}x$", 6),
        (rf"^  run, both models +{_N} +{_N} +{_N}x$", 2),
        (rf"^projected campaign .*: reference {_N} s, fast path {_N} s \({_N}x\)$", 1),
    ],
    "bench_viz": [
        (rf"^ratio \(scoring \+ logging\) / filter: +{_N} +\(target <= 1: (met|NOT met)\); "
         rf"logging / filter {_N}$", 1),
        (rf"^per-sample rr\.log, extrapolated: +{_N} s .*x the columnar sink\)$", 1),
    ],
}


def test_every_benchmark_has_its_ratio_lines() -> None:
    assert sorted(RATIO_LINES) == NAMES


@pytest.mark.parametrize("name", NAMES)
def test_quick_benchmark_runs(name: str, tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)}
    out = subprocess.run(
        [sys.executable, "-m", "benchmarks", "--quick", name],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
    )
    assert out.returncode == 0, f"{name} --quick failed:\n{out.stdout}\n{out.stderr}"
    lines = out.stdout.splitlines()
    assert lines[0] == f"== {name} (quick)"
    assert re.fullmatch(rf"== {name} done in {_N} s", lines[-2]), lines[-2]
    for pattern, count in RATIO_LINES[name]:
        matched = [line for line in lines if re.search(pattern, line)]
        assert len(matched) == count, f"{name}: {pattern!r} matched {matched}\n{out.stdout}"
    assert not list(tmp_path.iterdir()), f"{name} left files in the working directory"
