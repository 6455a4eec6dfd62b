"""Innovation exports (``L.innovations.<measurement>.csv``): they round-trip the run's
innovations and the summary's NIS, are the same bytes whether fed block by block or whole,
number the rows of undeclared measurements (a plug-in through the CLI too), and refuse to
overwrite without force."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from whole_runs import export_runs

from navreplay import export
from navreplay.filters.registry import load_filter
from navreplay.filters.result import InnovationSeries
from navreplay.io import read_recording, write_recording
from navreplay.io.outputs import OutputError
from navreplay.metrics import run_metrics
from navreplay.replay import replay
from navreplay.sim.scenario import simulate


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("innovations")
    write_recording(d / "drive.mcap", simulate("vehicle-drive", {"duration": 30.0}, seed=11))
    rec = read_recording(d / "drive.mcap")
    result = replay(rec, load_filter("gps-ins"), {}, label="gps-ins")
    return d, rec, result


def _table(path: Path) -> tuple[list[str], np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float).reshape(len(rows) - 1, len(rows[0]))


def test_round_trip_of_innovations_and_nis(run) -> None:
    d, rec, result = run
    out = d / "whole"
    export_runs(out, [result], rec)
    summary = run_metrics(result, rec).summary()
    manifest = json.loads((out / "manifest.json").read_text())["filters"]["gps-ins"]
    assert list(manifest["innovations"]) == [m.name for m in result.measurements]
    estimates, est = _table(out / "gps-ins.csv")
    for kind in result.measurements:
        s = result.innovations[kind.name]
        entry = manifest["innovations"][kind.name]
        assert entry["csv"] == f"gps-ins.innovations.{kind.name}.csv" and entry["dof"] == kind.dim
        header, table = _table(out / entry["csv"])
        assert header == [c["name"] for c in entry["columns"]] == (
            ["stamp [ns]", "t [s]"] + [f"nu.{r} [{u}]" for r, u in zip(kind.rows, kind.units)]
            + [f"sigma.{r} [{u}]" for r, u in zip(kind.rows, kind.units)] + ["nis [-]", "dof [-]"])
        col = {h.split(" ")[0]: table[:, i] for i, h in enumerate(header)}
        assert len(s.t) > 20 and table.shape[0] == len(s.t)
        # the estimates' time base: absolute stamps from the recording start
        stamps = np.array([line.split(",")[0] for line in
                           (out / entry["csv"]).read_text().splitlines()[1:]], dtype=np.int64)
        np.testing.assert_array_equal(stamps, result.t0_ns + np.rint(s.t * 1e9).astype(np.int64))
        np.testing.assert_allclose(col["t"], s.t, rtol=1e-9, atol=1e-9)
        assert np.isin(stamps, est[:, estimates.index("stamp [ns]")].astype(np.int64)).mean() > 0.9
        sd = np.sqrt(np.diagonal(s.S, axis1=1, axis2=2))
        for i, r in enumerate(kind.rows):
            np.testing.assert_allclose(col[f"nu.{r}"], s.nu[:, i], rtol=1e-8, atol=1e-12)
            np.testing.assert_allclose(col[f"sigma.{r}"], sd[:, i], rtol=1e-8)
            # per-row NIS from the file: the summary's nu_i^2 / S_ii
            row_nis = np.mean((col[f"nu.{r}"] / col[f"sigma.{r}"]) ** 2)
            assert row_nis == pytest.approx(summary[f"nis_mean_{kind.name}.{r}"], rel=1e-6)
        np.testing.assert_allclose(col["nis"], s.nis, rtol=1e-8)
        assert np.all(col["dof"] == kind.dim)
        assert col["nis"].mean() == pytest.approx(summary[f"nis_mean_{kind.name}"], rel=1e-8)
        assert summary[f"nis_dof_{kind.name}"] == kind.dim
        # and NIS = nu^T S^-1 nu of the rows written (a full S, not only its diagonal)
        nis = np.einsum("ki,ki->k", s.nu, np.linalg.solve(s.S, s.nu[..., None])[..., 0])
        np.testing.assert_allclose(col["nis"], nis, rtol=1e-7)


def _pieces(s: InnovationSeries, cuts: list[float]) -> list[InnovationSeries]:
    edges = [0, *np.searchsorted(s.t, cuts).tolist(), len(s.t)]
    return [InnovationSeries(s.t[a:b], s.nu[a:b], s.S[a:b], s.nis[a:b])
            for a, b in zip(edges[:-1], edges[1:])]


def test_block_by_block_is_the_whole_run(run) -> None:
    """Innovations fed in blocks (some empty, before and after the estimates) give the bytes
    of the whole run."""
    d, rec, result = run
    whole, streamed = d / "bytes-whole", d / "bytes-streamed"
    export_runs(whole, [result], rec)
    out = export.filter_output(result.rows(0, result.t.shape[0]), run_metrics(result, rec))
    writer = export.RunExport(streamed, ["gps-ins"], has_reference=True)
    cuts = [0.5, 0.5, 7.3, 12.0, 12.0, 29.0, 40.0]
    pieces = {name: _pieces(s, cuts) for name, s in result.innovations.items()}
    for k in range(len(cuts) + 1):
        writer.add_innovations("gps-ins", result.t0_ns,
                               {name: p[k] for name, p in pieces.items()}, result.measurements)
        if k == 3:
            writer.add_reference(rec["truth"])
            writer.add(out)
    writer.close()
    names = sorted(p.name for p in whole.iterdir())
    assert names == sorted(p.name for p in streamed.iterdir())
    assert sum(".innovations." in n for n in names) == len(result.measurements) == 2
    for name in names:
        assert (whole / name).read_bytes() == (streamed / name).read_bytes(), name


def test_undeclared_measurements_are_numbered(run) -> None:
    """A plug-in without declarations: rows 0..m-1 of unknown unit; a declared measurement
    without updates: its header."""
    d, rec, result = run
    plain = dataclasses.replace(result, label="plug-in", measurements=())
    only_pos = dataclasses.replace(result, label="declared",
                                   innovations={"gps_pos": result.innovations["gps_pos"]})
    out = d / "undeclared"
    written = export_runs(out, [plain, only_pos], rec)
    assert {p.name for p in written} >= {
        "plug-in.innovations.gps_pos.csv", "plug-in.innovations.gps_vel.csv",
        "declared.innovations.gps_pos.csv", "declared.innovations.gps_vel.csv"}
    header, table = _table(out / "plug-in.innovations.gps_vel.csv")
    assert header == ["stamp [ns]", "t [s]", "nu.0 [unknown]", "nu.1 [unknown]",
                      "nu.2 [unknown]", "sigma.0 [unknown]", "sigma.1 [unknown]",
                      "sigma.2 [unknown]", "nis [-]", "dof [-]"]
    np.testing.assert_allclose(table[:, 2:5], result.innovations["gps_vel"].nu, rtol=1e-8,
                               atol=1e-12)
    # the same numbers as the declared export of the same run, under other names
    assert (out / "plug-in.innovations.gps_pos.csv").read_text().splitlines()[1:] == (
        out / "declared.innovations.gps_pos.csv").read_text().splitlines()[1:]
    empty = (out / "declared.innovations.gps_vel.csv").read_text()
    assert empty == "stamp [ns],t [s],nu.N [m/s],nu.E [m/s],nu.D [m/s],sigma.N [m/s]," \
                    "sigma.E [m/s],sigma.D [m/s],nis [-],dof [-]\n"
    manifest = json.loads((out / "manifest.json").read_text())["filters"]
    assert manifest["plug-in"]["innovations"]["gps_vel"]["dof"] == 3
    with pytest.raises(ValueError, match="gps_pos: 2 innovation rows, 3 declared"):
        export.innovation_rows(result.measurement("gps_pos"), 2)


def test_existing_innovation_files_are_refused(run, tmp_path) -> None:
    _, rec, result = run
    out = tmp_path / "out"
    out.mkdir()
    (out / "gps-ins.innovations.gps_vel.csv").write_text("kept\n")
    with pytest.raises(OutputError, match=r"gps-ins\.innovations\.gps_vel\.csv exists"):
        export_runs(out, [result], rec)
    assert [p.name for p in out.iterdir()] == ["gps-ins.innovations.gps_vel.csv"]
    assert (out / "gps-ins.innovations.gps_vel.csv").read_text() == "kept\n"
    export_runs(out, [result], rec, force=True)
    assert (out / "gps-ins.innovations.gps_vel.csv").read_text().startswith("stamp [ns],")


PLUGIN = '''
from navreplay.filters.gps_ins import GpsInsFilter


class Silent(GpsInsFilter):
    """gps-ins declaring no measurements."""

    name = "silent"
    measurements = None
'''


def test_cli_exports_a_plug_in_without_declarations(run, tmp_path, plugin_module) -> None:
    """``navreplay run --filter module:Class --export``, streamed: the plug-in's innovations
    with numbered rows, the same updates as the declared filter's."""
    from click.testing import CliRunner

    from navreplay.cli import cli

    d, _, result = run
    plugin_module("silent_plugin", PLUGIN)
    out = tmp_path / "exp"
    res = CliRunner().invoke(cli, ["run", "gps-ins", "--filter", "silent_plugin:Silent",
                                   str(d / "drive.mcap"), "--no-viz", "--export", str(out)])
    assert res.exit_code == 0, res.output
    manifest = json.loads((out / "manifest.json").read_text())["filters"]
    assert sorted(manifest["silent"]["innovations"]) == ["gps_pos", "gps_vel"]
    for name in ("gps_pos", "gps_vel"):
        header, table = _table(out / f"silent.innovations.{name}.csv")
        assert header[2:5] == ["nu.0 [unknown]", "nu.1 [unknown]", "nu.2 [unknown]"]
        declared = (out / f"gps-ins.innovations.{name}.csv").read_text().splitlines()
        assert declared[0].startswith("stamp [ns],t [s],nu.N [m")
        assert (out / f"silent.innovations.{name}.csv").read_text().splitlines()[1:] == \
            declared[1:]
        assert len(declared) - 1 == len(result.innovations[name].t)
