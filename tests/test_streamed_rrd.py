"""The .rrd of ``navreplay run`` written block by block, as the recording streams in windows,
holds the data of the .rrd written from the whole run: the same entities, the same values."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from navreplay.io import mcapread
from navreplay.io.writer import write_recording
from navreplay.replay.spec import FilterSpec
from navreplay.sim.scenario import simulate
from navreplay.viz.options import VizMode, VizOptions
from tests.test_viz import read_rrd


def _static_values(rb) -> dict[str, np.ndarray]:
    import pyarrow as pa

    out = {}
    for name in rb.schema.names:
        flat = rb.column(name)
        while pa.types.is_list(flat.type) or pa.types.is_fixed_size_list(flat.type):
            flat = flat.flatten()
        if pa.types.is_floating(flat.type):
            out[name] = flat.to_numpy(zero_copy_only=False).astype(np.float64)
    return out


def test_streamed_rrd_holds_the_whole_run(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    run = importlib.import_module("navreplay.jobs.run")
    rec = simulate("vehicle-drive", {"duration": 90.0}, seed=3)
    path = tmp_path / "drive.mcap"
    write_recording(path, rec)
    monkeypatch.setattr(mcapread, "WINDOW_MESSAGES", 1500)

    def job(rrd):
        return run.RunJob(filters=(FilterSpec("gps-ins", {}),), recordings=(path,),
                          viz=VizOptions(mode=VizMode.SAVE, path=rrd))

    streamed = run._run_streamed(job(tmp_path / "streamed.rrd"), None)
    assert streamed is not None  # block by block
    run._run_one(job(tmp_path / "whole.rrd"), None)
    a, b = read_rrd(tmp_path / "streamed.rrd"), read_rrd(tmp_path / "whole.rrd")
    assert sorted(a) == sorted(b)
    assert {"/gps-ins/error/p_N", "/gps-ins/nees", "/truth/nav/yaw",
            "/gps-ins/innovation/gps_pos/nis", "/world/gps-ins/covariance"} <= a.keys()
    for entity in b:
        if entity == "static":
            continue
        assert a[entity].keys() == b[entity].keys(), entity
        for col in b[entity]:
            np.testing.assert_allclose(a[entity][col], b[entity][col], rtol=1e-12, atol=1e-12,
                                       err_msg=f"{entity} {col}")
    sa, sb = a["static"], b["static"]
    assert sorted(sa) == sorted(sb)
    for entity in sb:
        va, vb = _static_values(sa[entity]), _static_values(sb[entity])
        assert va.keys() == vb.keys(), entity
        for col in vb:
            np.testing.assert_allclose(va[col], vb[col], rtol=1e-12, atol=1e-12,
                                       err_msg=f"{entity} {col}")
