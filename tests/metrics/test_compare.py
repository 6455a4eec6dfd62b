"""Comparing filters: the error magnitudes, their distributions in bounded memory, the table of
headline metrics, and ``navreplay compare`` over saved summaries."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from commands import invoke, one_line_error

from navreplay.metrics.compare import (
    Quantiles,
    compared_errors,
    format_comparison,
    headline_rows,
    labelled,
    markdown_comparison,
)


def test_quantiles_match_the_sorted_samples_within_a_bin():
    rng = np.random.default_rng(7)
    x = np.abs(rng.standard_cauchy(100_000))  # eight decades of values
    q = Quantiles()
    for part in np.array_split(x, 13):  # block by block, as a run arrives
        q.add(part)
    q.add(np.array([np.nan, np.inf]))  # ignored
    p = np.array([0.01, 0.1, 0.5, 0.9, 0.99, 0.999])
    ratio = 10 ** (14 / 1400)  # one bin
    np.testing.assert_array_less(np.abs(np.log(q.quantile(p) / np.quantile(x, p))),
                                 np.log(ratio) + 1e-12)
    assert q.n == x.size
    assert math.isclose(q.rms(), float(np.sqrt(np.mean(x**2))), rel_tol=1e-12)
    v, f = q.cdf(200)
    assert v.shape == f.shape == (200,) and f[-1] == 1.0 and np.all(np.diff(v) >= 0)
    assert np.isnan(Quantiles().quantile(0.5))


def test_compared_errors_are_the_summary_magnitudes():
    pos = np.array([[3.0, 4.0, -2.0]])
    v = np.array([[1.0, 2.0, 2.0]])
    phi = np.array([[0.1, 0.2, -0.03]])
    m = compared_errors(pos, v, phi)
    assert m["pos_h"][0] == 5.0 and m["pos_v"][0] == 2.0 and m["vel"][0] == 3.0
    assert m["heading"][0] == pytest.approx(0.03)


SUMMARIES = {
    "ins": {"pos_rms_h": 812.0, "att_rms_heading": 0.02, "nees_mean": 30.0, "nees_dof": 15,
            "nees_in_bounds": 0.4},
    "gps-ins": {"pos_rms_h": 0.9, "att_rms_heading": 0.004, "nees_mean": 16.0, "nees_dof": 15,
                "nees_in_bounds": 0.95},
}


def test_headline_rows_in_display_units_with_the_best_of_each():
    rows = {name: (values, pick) for name, values, pick in headline_rows(SUMMARIES)}
    assert rows["horizontal position RMS [m]"] == ([812.0, 0.9], 1)
    assert rows["heading RMS [mrad]"][0] == pytest.approx([20.0, 4.0])
    assert rows["NEES mean / dof"] == (pytest.approx([2.0, 16 / 15]), 1)  # nearest 1 wins
    assert rows["NEES in 95 % bounds [%]"] == (pytest.approx([40.0, 95.0]), 1)
    assert "velocity RMS [m/s]" not in rows  # in no summary


def test_text_and_markdown_tables():
    text = format_comparison(SUMMARIES)
    lines = text.splitlines()
    assert lines[0].split() == ["metric", "ins", "gps-ins"]
    assert lines[1].split()[-2:] == ["0.9", "*"]
    md = markdown_comparison(SUMMARIES)
    assert "| horizontal position RMS [m] | 812 | **0.9** |" in md
    assert "(no headline metrics" in format_comparison({"a": {"duration": 1.0}})


def test_labels_prefixed_by_their_source_only_when_repeated():
    a = {"ins": {}, "gps-ins": {}}
    assert list(labelled([("day1", a)])) == ["ins", "gps-ins"]
    assert list(labelled([("day1", a), ("day2", {"gps-ins": {}})])) == [
        "day1/ins", "day1/gps-ins", "day2/gps-ins"]


def test_compare_command_reads_two_summaries(tmp_path):
    run = {"recording": "a.mcap", "filters": {"gps-ins": SUMMARIES["gps-ins"]}}
    ens = {"ensemble": {"gps-ins": {**SUMMARIES["gps-ins"], "pos_rms_h": 1.4}},
           "runs": []}
    (tmp_path / "a.json").write_text(json.dumps(run))
    (tmp_path / "b.json").write_text(json.dumps(ens))
    res = invoke("compare", tmp_path / "a.json", tmp_path / "b.json",
                 "--report", tmp_path / "c.html", "--save", tmp_path / "c.rrd")
    assert res.exit_code == 0, res.output
    row = next(line for line in res.output.splitlines() if line.startswith("horizontal"))
    assert row.split()[-3:] == ["0.9", "*", "1.4"]
    assert "a/gps-ins" in res.output and "b/gps-ins" in res.output
    page = (tmp_path / "c.html").read_text()
    assert "<svg" in page and "<b>0.9</b>" in page
    from rrd import read_rrd

    data = read_rrd(tmp_path / "c.rrd")
    assert "/compare/summary" in data["static"]
    # bad input: one line naming the file
    (tmp_path / "bad.json").write_text("{\"x\": 1}")
    res = invoke("compare", tmp_path / "bad.json")
    one_line_error(res, "bad.json", "not a navreplay summary")
