"""Every test runs in its own empty working directory, so a command's default outputs (``out/``)
land there and never in the checkout. Shared fixtures: ``plugin_module`` (a user's plug-in
written and made importable) and ``drive_40s`` (the recording the plug-in tests replay)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def _own_working_directory(tmp_path_factory: pytest.TempPathFactory,
                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path_factory.mktemp("cwd"))


@pytest.fixture()
def plugin_module(tmp_path, monkeypatch):
    """``plugin_module(name, source)``: write ``source`` (dedented) as the module ``name`` in
    the test's directory and make it importable, as a user's plug-in named by
    ``--filter name:Class``; returns ``name``."""

    def write(name: str, source: str) -> str:
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(source))
        monkeypatch.syspath_prepend(str(tmp_path))
        return name

    return write


@pytest.fixture(scope="session")
def drive_40s(tmp_path_factory) -> Path:
    """A 40 s vehicle drive (seed 4) written as MCAP: the recording the plug-in tests replay."""
    from navreplay.io import write_recording
    from navreplay.sim.scenario import simulate

    path = tmp_path_factory.mktemp("rec") / "drive.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 40.0}, seed=4))
    return path
