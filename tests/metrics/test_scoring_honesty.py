"""No wrong answer with exit 0: a reference that covers part of a run says so, and filter outputs
that are not finite, overflow or leave the earth stop the run (never skipped with a numpy
warning); a plug-in that exits or interrupts itself is a filter error."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from commands import one_line_error

from navreplay.cli import cli
from navreplay.core.streams import StreamKind
from navreplay.filters.base import OUTPUT_LIMIT, output_problem
from navreplay.io import read_recording
from navreplay.logs.reference import (
    COVERAGE_WARNING,
    CoverageCount,
    coverage_warning,
    reference_coverage,
)


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


# --------------------------------------------------------------------------------------------
# coverage of the reference


def test_coverage_counts_the_outputs_the_reference_spans():
    t = np.arange(600) * 0.1  # 10 Hz outputs over 60 s
    # 1 Hz reference over 0.03..6.03 s, scored within 0.5 s of its ends: outputs 0.0 .. 6.5 s
    t_ref = np.arange(7.0) + 0.03
    assert reference_coverage(t, t_ref) == 66 / 600
    assert reference_coverage(t, np.arange(61.0)) == 1.0
    # from 30.25 s: outputs 29.8 .. 59.9 s
    assert reference_coverage(t, np.arange(30.0, 70.0) + 0.25) == 302 / 600
    assert reference_coverage(np.zeros(0), t_ref) == 1.0
    assert reference_coverage(t, np.zeros(0)) == 0.0


def test_coverage_fed_in_windows_equals_the_whole():
    rng = np.random.default_rng(5)
    t = np.sort(rng.uniform(0.0, 100.0, 2000))
    t_ref = np.sort(rng.uniform(10.0, 80.0, 700))
    count = CoverageCount()
    for a in range(0, 100, 7):  # windows of 7 s: outputs first, then the reference
        count.outputs(t[(t >= a) & (t < a + 7)])
        count.reference(t_ref[(t_ref >= a) & (t_ref < a + 7)])
    assert count.total == 2000
    assert count.fraction() == reference_coverage(t, t_ref)


def test_coverage_warning_text():
    assert coverage_warning("gps-ins", COVERAGE_WARNING) is None
    text = coverage_warning("gps-ins", 0.1, "reference r.csv")
    assert "reference r.csv covers 10.0 % of the outputs of gps-ins" in text


def _truth_csv(recording_path, out, t_end: float | None = None) -> None:
    rec = read_recording(recording_path)
    truth = rec[StreamKind.TRUTH]
    t = (truth.t_ns - rec.t0_ns) * 1e-9
    keep = (np.arange(len(t)) % 10 == 0) & (t <= (t_end if t_end is not None else np.inf))
    rows = ["t_ns,lat_deg,lon_deg,h"] + [
        f"{tn},{np.degrees(p[0]):.10f},{np.degrees(p[1]):.10f},{p[2]:.4f}"
        for tn, p in zip(truth.t_ns[keep], truth["pos"][keep], strict=True)]
    out.write_text("\n".join(rows) + "\n")


def test_a_reference_covering_part_of_the_run_warns_and_says_so(drive_40s, tmp_path):
    """The truth as a CSV reference: over the whole run the scores are the run's own; cut to
    its first 6 s, the run warns and the summary gives the coverage (the 6 s of a 40 s run,
    each output scored within half a reference interval of its end)."""
    whole, part = tmp_path / "whole.csv", tmp_path / "part.csv"
    _truth_csv(drive_40s, whole)
    _truth_csv(drive_40s, part, 6.0)
    out = {}
    for name, ref in (("whole", whole), ("part", part)):
        s = tmp_path / f"{name}.json"
        res = invoke("run", "gps-ins", drive_40s, "--reference", ref, "--no-viz", "--summary", s)
        assert res.exit_code == 0, res.output
        out[name] = (json.loads(s.read_text())["filters"]["gps-ins"], res.stderr)
    assert out["whole"][0]["reference_coverage"] == 1.0 and "covers" not in out["whole"][1]
    cov = out["part"][0]["reference_coverage"]
    assert 6.0 / 40.0 < cov < 6.2 / 40.0, cov
    assert f"reference {part} covers {100 * cov:.1f} % of the outputs of gps-ins" in \
        out["part"][1]
    # and a recording's own truth covers the run (the streamed path)
    s = tmp_path / "own.json"
    res = invoke("run", "gps-ins", drive_40s, "--no-viz", "--summary", s)
    assert res.exit_code == 0 and "covers" not in res.stderr, res.output
    assert json.loads(s.read_text())["filters"]["gps-ins"]["reference_coverage"] == 1.0


# --------------------------------------------------------------------------------------------
# outputs that are no estimates

PLUGINS = '''
import os
import signal
import sys

import numpy as np

from navreplay.filters.base import Estimate, Innovation, NavSolution
from navreplay.filters.gps_ins import GpsInsFilter


class _Late(GpsInsFilter):
    def estimate(self):
        est = super().estimate()
        if est is None or est.t < 20.0:
            return est
        return self.spoil(est)


class HugeHeight(_Late):
    name = "huge-height"

    def spoil(self, est):
        pos = est.nav.pos.copy()
        pos[2] = 1e300
        return Estimate(est.t, est.x, est.P, NavSolution(pos, est.nav.v_n, est.nav.q_nb),
                        est.extras)


class BeyondThePole(_Late):
    name = "beyond-the-pole"

    def spoil(self, est):
        pos = est.nav.pos.copy()
        pos[0] = 2.0
        return Estimate(est.t, est.x, est.P, NavSolution(pos, est.nav.v_n, est.nav.q_nb),
                        est.extras)


class HugeState(_Late):
    name = "huge-state"

    def spoil(self, est):
        x = est.x.copy()
        x[-1] = -1e300
        return Estimate(est.t, x, est.P, est.nav, est.extras)


class HugeInnovation(GpsInsFilter):
    name = "huge-innovation"

    def update(self, kind, t, sample):
        out = super().update(kind, t, sample)
        if out and t >= 20.0:
            out = [Innovation(i.name, i.t, np.full_like(i.nu, 1e300), i.S) for i in out]
        return out


class Exits(GpsInsFilter):
    name = "exits"

    def update(self, kind, t, sample):
        if t >= 20.0:
            sys.exit(0)
        return super().update(kind, t, sample)


class Interrupts(GpsInsFilter):
    name = "interrupts"

    def update(self, kind, t, sample):
        if t >= 20.0:
            raise KeyboardInterrupt
        return super().update(kind, t, sample)


class Closes(GpsInsFilter):
    name = "closes"

    def update(self, kind, t, sample):
        if t >= 20.0:
            raise GeneratorExit
        return super().update(kind, t, sample)
'''


@pytest.fixture()
def plugins(plugin_module):
    return plugin_module("honesty_plugins", PLUGINS)


@pytest.mark.parametrize(("cls", "what"), [
    ("HugeHeight", "overflowing (1e+300, beyond 1e+100) position estimate"),
    ("BeyondThePole", "impossible (latitude 2 rad, beyond a pole) position estimate"),
    ("HugeState", "overflowing (1e+300, beyond 1e+100) state estimate"),
    ("HugeInnovation", "innovation 'gps_pos': nu is overflowing"),
    ("Exits", "SystemExit"),
    ("Interrupts", "KeyboardInterrupt"),
    ("Closes", "GeneratorExit"),
])
def test_outputs_that_are_no_estimates_stop_the_run(plugins, drive_40s, tmp_path, cls, what):
    summary = tmp_path / "s.json"
    res = invoke("run", "--filter", f"{plugins}:{cls}", drive_40s, "--no-viz",
                 "--summary", summary)
    err = one_line_error(res, what, drive_40s.name, "at t = 2")
    assert "RuntimeWarning" not in res.output and "overflow" not in res.stderr.replace(
        "overflowing", "")
    assert not summary.exists(), err


def test_output_problem():
    ok = np.array([[0.7, 2.0, 100.0], [-1.5707963267, 3.0, -400.0]])
    assert not output_problem("pos", ok)[0].any()
    bad, why = output_problem("pos", np.array([[0.1, 0, 0], [1.6, 0, 0], [np.nan, 0, 0]]))
    assert bad.tolist() == [False, True, True] and "latitude 1.6" in why
    bad, why = output_problem("x", np.array([[OUTPUT_LIMIT], [-2 * OUTPUT_LIMIT]]))
    assert bad.tolist() == [False, True] and why.startswith("overflowing")
    bad, why = output_problem("P", np.full((2, 3, 3), np.inf))
    assert bad.all() and why == "non-finite"
