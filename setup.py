"""Wheel build with navreplay's numba kernels compiled in (the rest of the metadata is in
pyproject.toml).

After the modules are copied into the build tree, ``python -m navreplay.jobs.warmup --ship``
compiles the kernels of every built-in filter for a portable CPU (numba's ``generic``: the
architecture's baseline) from that tree, into ``navreplay/core/compiled`` (see
:mod:`navreplay.core.shipped`); a first run after installing the wheel loads them instead of
compiling. The wheel is then tagged for this interpreter and platform, as the machine code is.

The compilation never breaks a build: if it fails (a platform numba cannot compile for, a
missing build dependency), the wheel is built without the kernels, pure Python, and numba
compiles them on first use, as before. ``NAVREPLAY_BUILD_KERNELS=0`` skips it; editable
installs skip it (``make install`` compiles for the host with ``navreplay warm-up``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from setuptools import setup
from setuptools.command.bdist_wheel import bdist_wheel
from setuptools.command.build_py import build_py

STORE = Path("navreplay", "core", "compiled")
"""Where the compiled kernels go in the package (``navreplay.core.shipped.STORE``)."""
TIMEOUT = 1800
"""Seconds the compilation may take before the wheel is built without it."""


class BuildPyWithKernels(build_py):
    """``build_py``, then the kernels compiled into the build tree."""

    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        build_lib = Path(self.build_lib).resolve()
        out = build_lib / STORE
        shutil.rmtree(out, ignore_errors=True)  # never one of an earlier build
        if os.environ.get("NAVREPLAY_BUILD_KERNELS", "1") == "0":
            return
        # the build tree first; the rest of the path is the build environment's (pip's isolated
        # build passes its packages through PYTHONPATH)
        path = os.pathsep.join(p for p in (str(build_lib), os.environ.get("PYTHONPATH")) if p)
        env = {**os.environ, "PYTHONPATH": path}
        try:
            with tempfile.TemporaryDirectory() as cwd:
                subprocess.run([sys.executable, "-m", "navreplay.jobs.warmup", "--ship", str(out)],
                               env=env, cwd=cwd, check=True, timeout=TIMEOUT)
        except (OSError, subprocess.SubprocessError) as e:
            shutil.rmtree(out, ignore_errors=True)
            print(f"navreplay: kernels not compiled into the wheel ({e}); numba compiles them "
                  "on first use", file=sys.stderr)


class BdistWheelWithKernels(bdist_wheel):
    """A wheel holding compiled kernels is tagged for this interpreter and platform."""

    def run(self) -> None:
        if not self.skip_build:
            self.run_command("build")
        build_lib = Path(self.get_finalized_command("build_py").build_lib)
        if (build_lib / STORE / "manifest.json").is_file():
            self.root_is_pure = False
        super().run()


setup(cmdclass={"build_py": BuildPyWithKernels, "bdist_wheel": BdistWheelWithKernels})
