"""The HTML report: self-contained (figures embedded, nothing fetched), the expected figures per
filter, the summary table; the command line's --export/--report/--force and lazy matplotlib."""

from __future__ import annotations

import base64
import re
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from whole_runs import run_series

from navreplay import report
from navreplay.cli import cli
from navreplay.filters.registry import load_filter
from navreplay.io import read_recording, write_recording
from navreplay.metrics import EnsembleStats, run_metrics
from navreplay.outputs import OutputError
from navreplay.replay import replay
from navreplay.sim.scenario import simulate

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    write_recording(d / "drive.mcap", simulate("vehicle-drive", {"duration": 20.0}, seed=3))
    return d / "drive.mcap"


def _images(text: str) -> list[bytes]:
    return [base64.b64decode(m) for m in
            re.findall(r'<img alt="[^"]*" src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)]


def _self_contained(text: str) -> None:
    assert not re.search(r"https?://", text)
    assert "<script" not in text and "<link" not in text and "@import" not in text
    assert re.findall(r'src="([^"]*)"', text) and all(
        s.startswith("data:image/png;base64,") for s in re.findall(r'src="([^"]*)"', text))


def test_run_report(drive, tmp_path) -> None:
    rec = read_recording(drive)
    outs, summaries = [], {}
    for name in ("ins", "gps-ins"):
        r = replay(rec, load_filter(name), {}, label=name)
        outs.append(run_series(r, rec))
        summaries[name] = run_metrics(r, rec).summary()
    path = report.write_run_report(tmp_path / "r.html", outs, summaries, title="drive")
    text = path.read_text()
    _self_contained(text)
    images = _images(text)
    # per filter: navigation errors with 3-sigma, the sensor-error states, NEES (+ NIS)
    assert len(images) == 6 and all(i.startswith(PNG_MAGIC) for i in images)
    for name in ("ins", "gps-ins"):
        assert f"<h2>{name}</h2>" in text
        assert f'alt="{name}: navigation errors (estimate minus reference) and their predicted' in text
    assert "NEES and NIS per epoch with the 95 % chi-square band" in text
    # the summary table: one row per filter, units under the names
    table = text.split("<table>")[1].split("</table>")[0]
    assert "<td>ins</td>" in table and "<td>gps-ins</td>" in table and "[m]" in table
    with pytest.raises(OutputError):
        report.write_run_report(tmp_path / "r.html", outs, summaries, title="drive")


def test_ensemble_report(drive, tmp_path) -> None:
    rec = read_recording(drive)
    r = replay(rec, load_filter("gps-ins"), {}, label="gps-ins")
    stats = EnsembleStats("gps-ins")
    for _ in range(3):
        stats.add(run_metrics(r, rec))
    ens = stats.result()
    path = report.write_ensemble_report(tmp_path / "e.html", {"gps-ins": ens},
                                        {"gps-ins": ens.summary()}, title="mc")
    text = path.read_text()
    _self_contained(text)
    assert len(_images(text)) == 2  # RMS vs sigma, consistency
    assert "RMS error over 3 runs (solid) against" in text


def test_cli_export_report_and_force(drive, tmp_path) -> None:
    def invoke(*extra):
        return CliRunner().invoke(cli, ["run", "gps-ins", str(drive), "--no-viz",
                                        "--export", str(tmp_path / "exp"), *extra])

    res = invoke("--report", str(tmp_path / "r.html"))
    assert res.exit_code == 0, res.output
    assert "Report written to" in res.output and "Exported 7 files" in res.output
    assert {p.name for p in (tmp_path / "exp").iterdir()} == {
        "gps-ins.csv", "gps-ins.tum", "reference.tum", "estimates.mcap", "manifest.json",
        "gps-ins.innovations.gps_pos.csv", "gps-ins.innovations.gps_vel.csv"}
    assert len(_images((tmp_path / "r.html").read_text())) == 3
    before = (tmp_path / "exp" / "gps-ins.csv").stat().st_mtime_ns
    res = invoke()  # refused before the replay starts, nothing touched
    assert res.exit_code == 1 and "exists" in res.stderr and "--force" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    assert (tmp_path / "exp" / "gps-ins.csv").stat().st_mtime_ns == before
    res = invoke("--report", str(tmp_path / "r.html"))
    assert res.exit_code == 1 and "r.html exists" in res.stderr
    assert invoke("--force").exit_code == 0
    assert (tmp_path / "exp" / "gps-ins.csv").stat().st_mtime_ns != before


def test_montecarlo_export_and_report(tmp_path) -> None:
    res = CliRunner().invoke(cli, ["montecarlo", "vehicle-drive", "gps-ins", "--runs", "2",
                                   "--duration", "10", "--no-viz", "--export",
                                   str(tmp_path / "exp"), "--report", str(tmp_path / "mc.html")])
    assert res.exit_code == 0, res.output
    names = {p.name for p in (tmp_path / "exp").iterdir()}
    assert {"gps-ins.ensemble.csv", "gps-ins.nis.gps_pos.csv", "manifest.json"} <= names
    assert len(_images((tmp_path / "mc.html").read_text())) == 2


def test_matplotlib_only_with_report(drive, tmp_path) -> None:
    """Start-up and a run without --report never load matplotlib."""
    code = (
        "import sys\n"
        "from click.testing import CliRunner\n"
        "from navreplay.cli import cli\n"
        f"res = CliRunner().invoke(cli, ['run', 'gps-ins', {str(drive)!r}, '--no-viz',"
        f" '--export', {str(tmp_path / 'e')!r}])\n"
        "assert res.exit_code == 0, res.output\n"
        "print('matplotlib' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(drive).parent)
    assert out.stdout.strip() == "False", out.stderr
