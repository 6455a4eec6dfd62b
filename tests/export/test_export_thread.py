"""``--export`` written by its own thread: the same bytes as written by the caller however the
blocks come, and a failure there surfaces in the caller with nothing published."""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest

from navreplay import export
from navreplay.export import run as export_run
from navreplay.filters.registry import load_filter
from navreplay.io import read_recording, write_recording
from navreplay.metrics import run_metrics
from navreplay.replay import replay
from navreplay.sim.scenario import simulate


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("thread")
    write_recording(d / "drive.mcap", simulate("vehicle-drive", {"duration": 30.0}, seed=12))
    rec = read_recording(d / "drive.mcap")
    result = replay(rec, load_filter("gps-ins"), {}, label="gps-ins", output_rate=100.0)
    return d, rec, result


def _feed(out_dir: Path, rec, result, *, background: bool, cuts: int = 9) -> list[Path]:
    """The run fed as a pipeline feeds it: truth windows, then each window's estimates."""
    truth = rec["truth"]
    writer = export.RunExport(out_dir, ["gps-ins"], has_reference=True, t0_ns=result.t0_ns,
                              reference_rate=100.0, background=background)
    t_edges = np.linspace(result.t[0], result.t[-1] + 1.0, cuts + 1)
    try:
        for a, b in zip(t_edges[:-1], t_edges[1:], strict=True):
            i = np.searchsorted(truth.t_ns, result.t0_ns + np.array([a, b]) * 1e9)
            writer.add_reference(truth.slice(int(i[0]), int(i[1])))
            j = np.searchsorted(result.t, [a, b])
            rows = result.rows(int(j[0]), int(j[1]))
            writer.add(export.filter_output(rows, run_metrics(rows, rec)))
    except BaseException:
        writer.abort()
        raise
    return writer.close()


def test_the_thread_writes_the_callers_bytes(run) -> None:
    d, rec, result = run
    mine, theirs = d / "in-thread", d / "in-caller"
    written = _feed(mine, rec, result, background=True)
    _feed(theirs, rec, result, background=False)
    names = sorted(p.name for p in written)
    assert names == sorted(p.name for p in theirs.iterdir())
    assert {"gps-ins.csv", "gps-ins.tum", "reference.tum", "estimates.mcap"} <= set(names)
    for name in names:
        assert (mine / name).read_bytes() == (theirs / name).read_bytes(), name


def test_a_failure_in_the_thread_publishes_nothing(run, monkeypatch) -> None:
    """A full disk met while the thread writes the third block of poses: raised by a later
    call or by close, every temporary removed, no target made."""
    d, rec, result = run
    blocks = export_run.tum_blocks
    calls = []

    def full(poses):
        calls.append(1)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        return blocks(poses)

    monkeypatch.setattr(export_run, "tum_blocks", full)
    out = d / "full-disk"
    with pytest.raises(OSError, match="No space left"):
        _feed(out, rec, result, background=True)
    assert list(out.iterdir()) == []
