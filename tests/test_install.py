"""A plain ``pip install`` of the source tree (no make): the wheel carries the kernels compiled
for a portable CPU, the first run in a fresh environment compiles nothing and prints what the
host-compiled run prints; a build that cannot compile them still gives a working, pure-Python
wheel.

Slow (a new virtual environment and a wheel build each, a few minutes): ``make reproduce-tests``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
RECORDING = ROOT / "recordings" / "golden" / "vehicle-drive.mcap"

# `navreplay run gps-ins REC --no-viz` in this process; then, on the last line, the kernels
# numba compiled, what the shipped store served and where numba's runtime library came from
_RUN = """
import json, sys
from navreplay.cli import main
try:
    main(["run", "gps-ins", sys.argv[1], "--no-viz"])
except SystemExit as e:
    assert not e.code, e.code
from navreplay.core import jit, shipped
misses = sorted(k.__name__ for k in jit.KERNELS if k._cache_misses)
print(json.dumps({"misses": misses, "stats": dict(shipped.STATS),
                  "runtime": jit.RUNTIME.get("source")}))
"""


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "NAVREPLAY_SHIPPED_KERNELS", "NAVREPLAY_BUILD_KERNELS")}
    return {**env, **extra}


def _venv(path: Path) -> Path:
    subprocess.run([sys.executable, "-m", "venv", str(path)], check=True)
    return path / "bin" / "python"


def _run(python: Path | str, cwd: Path, **env: str) -> tuple[list[str], dict]:
    cache = cwd / "numba-cache"
    cache.mkdir()
    out = subprocess.run([str(python), "-c", _RUN, str(RECORDING)], cwd=cwd, check=True,
                         capture_output=True, text=True,
                         env=_env(NUMBA_CACHE_DIR=str(cache), **env))
    lines = out.stdout.splitlines()
    return lines[:-1], json.loads(lines[-1])


def test_pip_install_ships_the_kernels_and_the_first_run_compiles_nothing(tmp_path):
    python = _venv(tmp_path / "venv")
    subprocess.run([str(python), "-m", "pip", "install", "-q", str(ROOT)], check=True,
                   env=_env(), cwd=tmp_path)
    store = next((tmp_path / "venv").rglob("navreplay/core/compiled/manifest.json"))
    assert json.loads(store.read_text())["magic"][1] == "generic"
    (tmp_path / "a").mkdir()
    printed, stats = _run(python, tmp_path / "a")
    assert stats["misses"] == [] and stats["stats"].get("loaded", 0) >= 1, stats
    assert "refused" not in stats["stats"] and stats["runtime"] == "shipped"
    (tmp_path / "b").mkdir()  # this checkout's interpreter, kernels compiled for this CPU
    host_printed, host = _run(sys.executable, tmp_path / "b", NAVREPLAY_SHIPPED_KERNELS="0",
                              PYTHONPATH=str(ROOT))
    assert "run_events" in host["misses"] and not host["stats"]
    assert host["runtime"] == "compiled"
    table = [line for line in printed if line.startswith("gps-ins")]
    assert table and table == [line for line in host_printed if line.startswith("gps-ins")]


def test_a_build_that_cannot_compile_the_kernels_gives_a_pure_wheel(tmp_path):
    """No numba in the build environment: the wheel is built without the kernels."""
    python = _venv(tmp_path / "venv")
    subprocess.run([str(python), "-m", "pip", "install", "-q", "setuptools>=77", "wheel"],
                   check=True, env=_env(), cwd=tmp_path)
    subprocess.run([str(python), "-m", "pip", "wheel", "-q", "--no-build-isolation", "--no-deps",
                    "-w", str(tmp_path / "dist"), str(ROOT)], check=True, env=_env(),
                   cwd=tmp_path)
    (wheel,) = (tmp_path / "dist").glob("navreplay-*.whl")
    assert wheel.name.endswith("-py3-none-any.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "navreplay/core/jit.py" in names
    assert not [n for n in names if "/core/compiled/" in n]
