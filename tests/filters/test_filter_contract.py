"""Any filter is scored and checked the same way: declared states travel with the result, and
the engine validates every filter's output (built-in or plug-in) with one-line errors."""

import json

import pytest
from click.testing import CliRunner

from navreplay.cli import cli

PLUGINS = '''
import numpy as np

from navreplay.filters.base import Estimate, Innovation
from navreplay.filters.gps_ins import GpsInsFilter


class MyGpsIns(GpsInsFilter):
    """A copy of gps-ins under another name, not in the registry."""

    name = "my-gps-ins"


class NegativeVariance(GpsInsFilter):
    name = "negative-variance"

    def estimate(self):
        est = super().estimate()
        if est is None or est.t < 20.0:
            return est
        P = est.P.copy()
        P[4, 4] = -abs(P[4, 4]) - 1.0
        return Estimate(est.t, est.x, P, est.nav, est.extras)


class ShortState(GpsInsFilter):
    name = "short-state"

    def estimate(self):
        est = super().estimate()
        if est is None or est.t < 20.0:
            return est
        return Estimate(est.t, est.x[:-1], est.P[:-1, :-1], est.nav, est.extras)


class NanInnovation(GpsInsFilter):
    name = "nan-innovation"

    def update(self, kind, t, sample):
        out = super().update(kind, t, sample)
        if out and t >= 20.0:
            out = [Innovation(i.name, i.t, np.full_like(i.nu, np.nan), i.S) for i in out]
        return out


class Raises(GpsInsFilter):
    name = "raises"

    def update(self, kind, t, sample):
        if t >= 20.0:
            raise RuntimeError("lookup table exhausted")
        return super().update(kind, t, sample)


class RejectsItsStart(GpsInsFilter):
    name = "rejects-its-start"

    def __init__(self, params, context):
        raise ValueError("needs a surveyed antenna position")
'''


@pytest.fixture()
def drive(drive_40s):
    return drive_40s


@pytest.fixture()
def plugins(plugin_module):
    return plugin_module("contract_plugins", PLUGINS)


def test_a_copy_of_gps_ins_is_scored_like_the_built_in(plugins, drive, tmp_path):
    runner = CliRunner()
    a, b = tmp_path / "builtin.json", tmp_path / "copy.json"
    res = runner.invoke(cli, ["run", "gps-ins", str(drive), "--no-viz", "--summary", str(a)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["run", "--filter", f"{plugins}:MyGpsIns", str(drive), "--no-viz",
                              "--summary", str(b)])
    assert res.exit_code == 0, res.output
    builtin = json.loads(a.read_text())["filters"]["gps-ins"]
    copy = json.loads(b.read_text())["filters"]["my-gps-ins"]
    assert copy == builtin  # every key, the NEES included
    assert builtin["nees_dof"] == 9 and 0.0 < builtin["nees_mean"] < 100.0
    assert "nis_mean_gps_pos" in builtin


@pytest.mark.parametrize(("cls", "what"), [
    ("NegativeVariance", "negative variance"),
    ("ShortState", "declares 33 states"),
    ("NanInnovation", "innovation 'gps_pos': nu is not finite"),
    ("Raises", "RuntimeError: lookup table exhausted"),
])
def test_a_broken_plugin_stops_with_one_line(plugins, drive, cls, what):
    res = CliRunner().invoke(cli, ["run", "--filter", f"{plugins}:{cls}", str(drive),
                                   "--no-viz"])
    assert res.exit_code != 0
    assert "Traceback" not in res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("Error:")]
    assert len(errors) == 1, res.output
    line = errors[0]
    assert what in line and str(drive.name) in line and "at t = " in line
    t = float(line.split("at t = ")[1].split(" s")[0])
    assert 20.0 <= t <= 21.0


def test_debug_shows_the_traceback(plugins, drive):
    res = CliRunner().invoke(cli, ["--debug", "run", "--filter", f"{plugins}:Raises",
                                   str(drive), "--no-viz"])
    assert res.exit_code != 0
    assert isinstance(res.exception, Exception)
    assert isinstance(res.exception.__cause__, RuntimeError)


def test_the_summary_and_the_rrd_carry_the_same_navigation_errors(drive, tmp_path):
    import numpy as np
    from rrd import read_rrd

    rrd, summary = tmp_path / "v.rrd", tmp_path / "s.json"
    res = CliRunner().invoke(cli, ["run", "gps-ins", str(drive), "--save", str(rrd),
                                   "--full-rate", "--summary", str(summary)])
    assert res.exit_code == 0, res.output
    s = json.loads(summary.read_text())["filters"]["gps-ins"]
    data = read_rrd(rrd)

    def error(name):
        cols = data[f"/gps-ins/error/{name}"]
        (key,) = [k for k in cols if k not in ("time", "timestamp")]
        return cols[key][:, 0]

    p_n, p_e, p_d = error("p_N"), error("p_E"), error("p_D")  # m
    assert np.sqrt(np.mean(p_d**2)) == pytest.approx(s["pos_rms_v"], rel=1e-6)
    assert np.hypot(p_n, p_e)[-1] == pytest.approx(s["pos_err_final_h"], rel=1e-6)
    assert np.sqrt(np.mean(p_n**2 + p_e**2)) == pytest.approx(s["pos_rms_h"], rel=1e-6)


@pytest.mark.parametrize(("how", "what"), [
    ("plugin", "filter 'rejects-its-start' cannot start on {rec}: ValueError: needs a surveyed "
               "antenna position"),
    ("no-initial-nav", "filter 'ins' cannot start on {rec}: InitialNavError: no initial "
                       "solution"),
])
def test_a_filter_that_cannot_start_stops_with_one_line(plugins, drive, tmp_path, how, what):
    from navreplay.io import read_recording, write_recording

    if how == "plugin":
        args, rec = ["--filter", f"{plugins}:RejectsItsStart", str(drive)], drive
    else:  # a built-in whose recording lacks the initial solution
        rec = tmp_path / "no_init.mcap"
        r = read_recording(drive)
        r.metadata.initial_nav = {}
        write_recording(rec, r)
        args = ["ins", str(rec)]
    res = CliRunner().invoke(cli, ["run", *args, "--no-viz"])
    assert res.exit_code != 0
    assert "Traceback" not in res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1, res.output
    assert what.format(rec=rec) in errors[0], errors[0]
    res = CliRunner().invoke(cli, ["--debug", "run", *args, "--no-viz"])
    assert isinstance(res.exception, ValueError)  # FilterInitError, the filter's error its cause
    assert isinstance(res.exception.__cause__, ValueError)
