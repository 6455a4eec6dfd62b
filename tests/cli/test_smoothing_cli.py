"""``navreplay run --smooth``: the smoothed rows in the summary, the exports and the report, a
non-smoothable filter named once, and a smoothed export read back as ``--reference``."""

import json
import tempfile
from pathlib import Path

import pytest
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


def test_smooth_needs_one_recording(drive):
    res = invoke("run", "gps-ins", drive, drive, "--smooth", "--no-viz")
    assert res.exit_code != 0 and "--smooth needs a single recording" in res.output


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
                      "/estimates/gps_ins_rts/odom": rts.t.shape[0]}
