"""``navreplay run --smooth`` and ``navreplay montecarlo --smooth``: the smoothed rows in the
summary, the tables, the exports, the view and the report, a non-smoothable filter named once, a
smoothed export read back as ``--reference``, the forward passes stored in the temporary
directory and removed, the same ensemble on Dask."""

import json
import tempfile
from pathlib import Path

import distributed
import pytest
import rerun as rr
from click.testing import CliRunner
from mcap.reader import make_reader

from navreplay.cli import cli
from navreplay.export import RunExport, filter_output
from navreplay.io import read_recording, write_recording
from navreplay.io.source import MemorySource
from navreplay.replay.pipeline import Collect, replay_file
from navreplay.replay.spec import FilterSpec
from navreplay.sim.scenario import simulate


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    path = tmp_path_factory.mktemp("smooth") / "drive.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 60.0, "imu_grade": "consumer"},
                                   seed=21))
    return path


def test_run_smooth_exports_and_round_trips_as_reference(drive, tmp_path):
    ex, summary = tmp_path / "ex", tmp_path / "s.json"
    res = invoke("run", "gps-ins", drive, "--smooth", "--no-viz", "--export", ex,
                 "--summary", summary, "--report", tmp_path / "r.html")
    assert res.exit_code == 0, res.output
    filters = json.loads(summary.read_text())["filters"]
    assert list(filters) == ["gps-ins", "gps-ins/rts"]
    fwd, rts = filters["gps-ins"], filters["gps-ins/rts"]
    assert rts["pos_rms_h"] < fwd["pos_rms_h"]
    assert rts["pos_err_final_h"] == pytest.approx(fwd["pos_err_final_h"], rel=1e-9)
    for name in ("gps-ins_rts.csv", "gps-ins_rts.tum"):
        assert (ex / name).is_file(), name
    assert not list(ex.glob("gps-ins_rts.innovations.*"))  # a smoother makes no updates
    manifest = (ex / "manifest.json").read_text()
    assert "gps-ins/rts" in manifest
    assert "gps-ins/rts" in (tmp_path / "r.html").read_text()
    # the smoothed run as the reference of the forward one: its errors are the differences
    for ref in ("gps-ins_rts.csv", "gps-ins_rts.tum"):
        s2 = tmp_path / f"{ref}.json"
        res = invoke("run", "gps-ins", drive, "--no-viz", "--reference", ex / ref,
                     "--summary", s2)
        assert res.exit_code == 0, res.output
        against = json.loads(s2.read_text())["filters"]["gps-ins"]
        # the last epoch of the smoothed run is the filter's own (a TUM file's local frame
        # is placed by a fit of its origin to the GNSS fixes: centimetres)
        limit = 1e-3 if ref.endswith(".csv") else 0.2
        assert against["pos_err_final_h"] < limit, (ref, against["pos_err_final_h"])
        assert 0.0 < against["pos_rms_h"] < fwd["pos_rms_h"] + rts["pos_rms_h"]


def test_non_smoothable_filter_is_named_once(drive, tmp_path):
    res = invoke("run", "gps-ins,vector-matching", drive, "--smooth", "--no-viz",
                 "-p", "vector-matching.earth_field_n=2e-5,0,4e-5")
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if "not smoothed" in ln]
    assert lines == ["vector-matching: not smoothed (vector-matching does not declare "
                     "navreplay.filters.smoothable.Smoothable)"], res.output
    assert "gps-ins/rts" in res.output and "vector-matching/rts" not in res.output


MC = ("montecarlo", "vehicle-drive", "gps-ins,vector-matching", "--runs", "2", "--seed", "31",
      "-p", "scenario.duration=40", "-p", "scenario.imu_grade=consumer",
      "-p", "scenario.gps_outages=15:15", "-p", "vector-matching.earth_field_n=2e-5,0,4e-5",
      "--smooth")


@pytest.fixture
def scratch(tmp_path, monkeypatch):
    """The temporary directory of the runs, and the directories the forward passes went to."""
    root = tmp_path / "scratch"
    root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(root))
    used = []
    from navreplay.replay import smoothing

    init = smoothing.ForwardStore.__init__

    def spy(self, directory, *args, **kw):
        used.append(Path(directory))
        init(self, directory, *args, **kw)

    monkeypatch.setattr(smoothing.ForwardStore, "__init__", spy)
    return root, used


def test_montecarlo_smooth_gives_smoothed_ensembles_beside_forward(tmp_path, scratch):
    ex, summary, rrd = tmp_path / "ex", tmp_path / "mc.json", tmp_path / "mc.rrd"
    res = invoke(*MC, "--summary", summary, "--export", ex, "--report", tmp_path / "r.html",
                 "--save", rrd)
    assert res.exit_code == 0, res.output
    data = json.loads(summary.read_text())
    ens = data["ensemble"]
    assert list(ens) == ["gps-ins", "gps-ins/rts", "vector-matching"]
    fwd, rts = ens["gps-ins"], ens["gps-ins/rts"]
    assert fwd["runs"] == rts["runs"] == 2
    assert rts["pos_rms_h"] < fwd["pos_rms_h"]
    # the last epoch is the filter's own
    assert rts["cep50_final"] == pytest.approx(fwd["cep50_final"], rel=1e-9)
    assert rts["nees_dof"] == fwd["nees_dof"] == 9
    assert "nees_time_averaged" in rts and rts["rms_over_sigma"]
    (o_f,), (o_s,) = fwd["gnss_outages"], rts["gnss_outages"]
    assert (o_s["start"], o_s["end"]) == (o_f["start"], o_f["end"]) == (15.0, 30.0)
    assert o_s["rms_h"] < 0.5 * o_f["rms_h"] and o_s["sigma_end_h"] < o_f["sigma_end_h"]
    for run in data["runs"]:
        assert list(run["filters"]) == ["gps-ins", "gps-ins/rts", "vector-matching"]
    # the text: the tables, the outage rows side by side, the filter that is not smoothed
    out = res.output
    assert "gps-ins/rts NEES" in out
    rows = [ln.split()[0:2] for ln in out.splitlines() if ln.endswith(("ok", "INCONSISTENT"))
            and "15-30" in ln]
    assert [r[0] for r in rows] == ["gps-ins", "gps-ins/rts"], out
    assert [ln for ln in out.splitlines() if "not smoothed" in ln] == [
        "vector-matching: not smoothed (vector-matching does not declare "
        "navreplay.filters.smoothable.Smoothable)"]
    # the exports, the report and the view
    assert (ex / "gps-ins_rts.ensemble.csv").is_file()
    assert "gps-ins/rts" in json.loads((ex / "manifest.json").read_text())["filters"]
    assert "gps-ins/rts" in (tmp_path / "r.html").read_text()
    paths = {c.entity_path for c in rr.chunk.RrdReader(rrd).stream().collect().stream()
             .to_chunks()}
    assert any(p.startswith("/ensemble/gps-ins\\/rts") for p in paths), paths
    # each run's forward pass went to the temporary directory, and nothing is left there
    root, used = scratch
    assert len(used) == 2 and all(root in d.parents for d in used)
    assert not list(root.iterdir())


def test_montecarlo_smooth_on_dask_equals_one_process(tmp_path, scratch):
    one, dask = tmp_path / "one.json", tmp_path / "dask.json"
    res = invoke(*MC, "--no-viz", "--summary", one)
    assert res.exit_code == 0, res.output
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  protocol="tcp://", dashboard_address=None) as cluster:
        address = cluster.scheduler_address.replace("tcp://", "dask://")
        res = invoke(*MC, "--no-viz", "--summary", dask, "--executor", address)
    assert res.exit_code == 0, res.output
    a, b = json.loads(one.read_text()), json.loads(dask.read_text())
    assert "gps-ins/rts" in b["ensemble"]
    assert a["ensemble"] == b["ensemble"]
    assert [r["filters"] for r in a["runs"]] == [r["filters"] for r in b["runs"]]
    root, used = scratch
    assert len(used) == 4 and not list(root.glob("navreplay-rts-*"))  # (Dask keeps its own)


def test_run_smooth_over_several_recordings(drive, tmp_path):
    summary = tmp_path / "s.json"
    res = invoke("run", "gps-ins", drive, drive, "--smooth", "--no-viz", "--summary", summary)
    assert res.exit_code == 0, res.output
    data = json.loads(summary.read_text())
    assert list(data["ensemble"]) == ["gps-ins", "gps-ins/rts"]
    assert "gps-ins/rts @ drive.mcap (run 2)" in res.output


def test_exports_do_not_wait_for_the_smoothed_run(drive):
    """The smoothed rows come after the last window: the exports write the forward rows as
    they come (nothing held for the smoothed label), and the Odometry MCAP gets every row of
    both."""
    rec = read_recording(drive)
    collect = Collect()
    replay_file(MemorySource(rec, "d"), [FilterSpec("gps-ins")], stages=[collect], smooth=True,
                score=False)
    res = collect.results()
    fwd, rts = res["gps-ins"], res["gps-ins/rts"]
    with tempfile.TemporaryDirectory() as tmp:
        ex = RunExport(Path(tmp), ["gps-ins", "gps-ins/rts"], has_reference=False,
                       late={"gps-ins/rts": "gps-ins"})
        half = fwd.t.shape[0] // 2
        ex.add(filter_output(fwd.rows(0, half)))
        assert not ex._held  # started on the forward rows alone
        ex.add(filter_output(fwd.rows(half, fwd.t.shape[0])))
        ex.add(filter_output(rts.rows(0, rts.t.shape[0])))
        ex.close()
        with open(Path(tmp) / "estimates.mcap", "rb") as f:
            counts = {}
            for _, channel, _ in make_reader(f).iter_messages():
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts == {"/estimates/gps_ins/odom": fwd.t.shape[0],
                      "/estimates/gps_ins_rts/odom": rts.t.shape[0],
                      "/estimates/gps_ins/fix": fwd.t.shape[0],
                      "/estimates/gps_ins_rts/fix": rts.t.shape[0],
                      "/tf": fwd.t.shape[0] + rts.t.shape[0]}


def test_the_progress_bar_takes_a_total_that_grows(monkeypatch):
    """Without the recording's length the bar counts events, whose total grows as each
    filter's become known: the bar follows it instead of ending early."""
    from navreplay.cli import options

    monkeypatch.setattr(options, "stderr_is_tty", lambda: True)
    with options.Progress("replay") as bar:
        bar(120, 174)
        bar(302, 437)
        assert bar.bar.length == 437 and bar.bar.pct == pytest.approx(302 / 437)
        bar(437, 437)
        assert bar.bar.pct == 1.0
