"""The HTML report: self-contained (figures inline SVG, nothing fetched), opened in a headless
browser when one is installed, the expected figures per filter, the context and summary tables,
the PDF; the command line's --export/--report/--force and lazy matplotlib."""

from __future__ import annotations

import re
import shutil
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
from navreplay.io.outputs import OutputError
from navreplay.metrics import EnsembleStats, run_metrics
from navreplay.replay import replay
from navreplay.sim.scenario import simulate


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    write_recording(d / "drive.mcap", simulate("vehicle-drive", {"duration": 20.0}, seed=3))
    return d / "drive.mcap"


def _images(text: str) -> list[str]:
    """The captions of the figures (inline SVG)."""
    return re.findall(r"<figure role='img' aria-label=\"([^\"]*)\"><svg ", text)


def _self_contained(text: str) -> None:
    assert not re.search(r"https?://", text)
    assert "<script" not in text and "<link" not in text and "@import" not in text
    assert "<img" not in text and not re.search(r"(src|href)=\"(?!#)", text)


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
    # the filters overlaid and their CDFs; per filter: navigation errors with 3-sigma, the
    # sensor-error states, NEES (+ NIS), innovations (gps-ins)
    assert len(images) == 2 + 3 + 4
    assert images[0].startswith("Horizontal and vertical position, velocity and heading")
    assert images[1].startswith("Cumulative distributions")
    for name in ("ins", "gps-ins"):
        assert f"<h2>{name}</h2>" in text
        assert f"{name}: navigation errors (estimate minus reference) and their predicted" in text
    assert "gps-ins: innovations of each measurement row" in text
    assert "NEES and NIS per epoch with the 95 % chi-square band" in text
    # the headline table: a row per metric, a column per filter, the best in bold
    table = text.split("<table>")[1].split("</table>")[0]
    assert "<th>ins</th><th>gps-ins</th>" in table
    h = next(r for r in table.split("<tr>") if r.startswith("<td>horizontal position RMS [m]"))
    assert h.count("<b>") == 1 and h.index("<b>") > h.index("</td><td>", 30)
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
    assert "Report written to" in res.output and "Exported 8 files" in res.output
    assert {p.name for p in (tmp_path / "exp").iterdir()} == {
        "gps-ins.csv", "gps-ins.tum", "reference.tum", "estimates.mcap", "manifest.json",
        "estimates.foxglove-layout.json",
        "gps-ins.innovations.gps_pos.csv", "gps-ins.innovations.gps_vel.csv"}
    page = (tmp_path / "r.html").read_text()
    assert len(_images(page)) == 2 + 4
    # how it was made: the command, the scenario, its seed and initial state, the versions
    context = page.split("<table>")[1]
    assert f"<code>navreplay run gps-ins {drive}" in context
    assert "<td>seed</td><td style='text-align:left'>3</td>" in context
    assert "initial state" in context and "roll" in context and "numpy" in context
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


@pytest.fixture(scope="module")
def page(drive, tmp_path_factory) -> Path:
    rec = read_recording(drive)
    outs, summaries = [], {}
    for name in ("ins", "gps-ins"):
        r = replay(rec, load_filter(name), {}, label=name)
        outs.append(run_series(r, rec))
        summaries[name] = run_metrics(r, rec).summary()
    d = tmp_path_factory.mktemp("page")
    report.write_run_report(d / "r.pdf", outs, summaries, title="drive")
    return report.write_run_report(d / "r.html", outs, summaries, title="drive")


def test_pdf_report_has_a_page_per_figure(page) -> None:
    pdf = page.with_suffix(".pdf").read_bytes()
    assert pdf.startswith(b"%PDF-")
    pages = len(re.findall(rb"/Type\s*/Page\b", pdf))
    assert pages == 1 + 2 + 3 + 4  # the tables, then the figures of the HTML page


BROWSER = shutil.which("chromium") or shutil.which("chromium-browser")


def _browse(page: Path, tmp: Path) -> tuple[str, set[str]]:
    """The DOM Chromium builds of a page and the URLs the page requested (the net log's
    requests of the page: those with an initiator, unlike the browser's own idle ones)."""
    net = tmp / f"{page.stem}.net.json"
    out = subprocess.run(
        [BROWSER, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-background-networking", f"--user-data-dir={tmp / 'profile'}",
         f"--log-net-log={net}", "--host-resolver-rules=MAP * ~NOTFOUND",
         "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
        capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    requests = set()
    for record in re.findall(r'\{[^{}]*"url":"[^"]+"[^{}]*\}', net.read_text()):
        if '"priority"' in record and ('"initiator"' in record
                                       or '"priority":"IDLE"' not in record):
            requests.add(re.search(r'"url":"([^"]+)"', record).group(1))
    return out.stdout, {u for u in requests if not u.startswith(("file:", "data:"))}


@pytest.mark.skipif(BROWSER is None, reason="no chromium on this machine")
def test_report_renders_in_a_headless_browser_without_requests(page, tmp_path) -> None:
    """Chromium lays the page out (the DOM it dumps holds every figure as SVG) and the page
    asks for nothing from the network; a page that fetches an image is caught."""
    dom, asked = _browse(page, tmp_path)
    assert dom.count("<svg") == len(_images(page.read_text())) == 9
    assert "<h2>gps-ins</h2>" in dom
    assert not asked, asked
    control = tmp_path / "control.html"
    control.write_text("<html><body><img src='http://example.invalid/x.png'></body></html>")
    assert _browse(control, tmp_path)[1] == {"http://example.invalid/x.png"}
