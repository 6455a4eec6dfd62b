"""The NIS of each row of a measurement (nu_i^2 / S_ii, by the row names the filter declares):
in the summary and its table, the same from a run scored whole or block by block, and it
points at the inconsistent row where the measurement's NIS cannot."""

from __future__ import annotations

import numpy as np
import pytest

from navreplay import metrics
from navreplay.filters.base import MeasurementKind
from navreplay.filters.result import InnovationSeries, RunResult
from navreplay.metrics import RunScorer, tables

T0_NS = 1_700_000_000 * 10**9


def _result(nu: np.ndarray, S: np.ndarray, rows: tuple[str, ...] | None = ("N", "E", "D"),
            t: np.ndarray | None = None) -> RunResult:
    t = np.arange(len(nu), dtype=float) if t is None else t
    nis = np.einsum("ki,ki->k", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    measurements = () if rows is None else (MeasurementKind("gps_pos", rows, "m"),)
    return RunResult(filter_name="synthetic", label="syn", recording="rec", t0_ns=T0_NS, states=(),
                     t=t, x=np.zeros((len(t), 0)), P=np.zeros((len(t), 0, 0)),
                     innovations={"gps_pos": InnovationSeries(t, nu, S, nis)},
                     measurements=measurements)


def test_row_nis_is_the_squared_innovation_over_its_variance() -> None:
    nu = np.array([[1.0, -2.0, 6.0], [0.5, 1.0, -3.0]])
    S = np.array([[[1.0, 0.5, 0.0], [0.5, 4.0, 0.0], [0.0, 0.0, 9.0]]] * 2)
    rows = metrics.row_nis(_result(nu, S), "gps_pos")
    assert list(rows) == ["N", "E", "D"]
    np.testing.assert_allclose(rows["N"], [1.0, 0.25])
    np.testing.assert_allclose(rows["E"], [1.0, 0.25])
    np.testing.assert_allclose(rows["D"], [4.0, 1.0])
    # without declarations the rows are numbered; a measurement of one row has no rows
    assert list(metrics.row_nis(_result(nu, S, rows=None), "gps_pos")) == ["0", "1", "2"]
    one = _result(nu[:, :1], S[:, :1, :1], rows=("h",))
    assert metrics.row_nis(one, "gps_pos") == {}


def test_a_mis_scaled_row_stands_out_in_the_summary() -> None:
    """East innovations twice the filter's sigma: the 3-dof NIS is high, and only the east
    row's NIS is out of its band (about 4, the others about 1)."""
    rng = np.random.default_rng(7)
    K = 3000
    S = np.tile(np.diag([1.0, 2.0, 3.0]), (K, 1, 1))
    nu = rng.normal(size=(K, 3)) * np.sqrt([1.0, 2.0, 3.0]) * [1.0, 2.0, 1.0]
    s = metrics.run_metrics(_result(nu, S), None).summary()
    lo, hi = metrics.chi2_bounds(1, K)  # of the mean of K independent samples
    assert s["nis_dof_gps_pos"] == 3 and s["nis_mean_gps_pos"] > 5.0
    assert s["nis_dof_gps_pos.E"] == 1
    assert lo < s["nis_mean_gps_pos.N"] < hi and lo < s["nis_mean_gps_pos.D"] < hi
    assert s["nis_mean_gps_pos.E"] == pytest.approx(4.0, rel=0.1)
    assert s["nis_in_bounds_gps_pos.N"] == pytest.approx(0.95, abs=0.02)
    assert s["nis_in_bounds_gps_pos.E"] < 0.8
    table = tables.format_summaries({"syn": s})
    assert "syn NIS gps_pos.E" in table and "syn NIS gps_pos " in table


def test_rows_scored_block_by_block_are_those_scored_whole() -> None:
    rng = np.random.default_rng(8)
    K = 500
    S = np.tile(np.diag([1.0, 2.0, 3.0]), (K, 1, 1))
    nu = rng.normal(size=(K, 3))
    whole = _result(nu, S)
    want = metrics.run_metrics(whole, None).summary()
    running = RunScorer("syn", T0_NS, {}, has_truth=False)
    for a in range(0, K, 77):
        b = min(a + 77, K)
        s = whole.innovations["gps_pos"]
        block = _result(nu[a:b], S[a:b], t=s.t[a:b])
        running.add(block)
    got = running.result()
    rows = {k for k in want if ".N" in k or ".E" in k or ".D" in k}
    assert len(rows) == 9 and rows <= got.keys()
    for k in rows | {"nis_mean_gps_pos"}:
        assert got[k] == pytest.approx(want[k], rel=1e-12), k


def test_rows_averaged_over_runs_in_the_ensemble_and_its_csv() -> None:
    from navreplay.export import nis_columns

    rng = np.random.default_rng(9)
    K, runs = 200, 20
    S = np.tile(np.diag([1.0, 1.0, 4.0]), (K, 1, 1))
    stats = metrics.EnsembleStats()
    for _ in range(runs):  # down row twice the filter's sigma
        nu = rng.normal(size=(K, 3)) * [1.0, 1.0, 4.0]
        stats.add(metrics.run_metrics(_result(nu, S), None))
    ens = stats.result()
    t, mean, count, dof = ens.nis_mean["gps_pos"]
    rows = ens.nis_rows_mean["gps_pos"]
    assert list(rows) == ["N", "E", "D"] and np.all(count == runs)
    np.testing.assert_allclose(rows["N"] + rows["E"] + rows["D"], mean)  # S is diagonal
    lo, hi = metrics.chi2_bounds(1, runs * K)
    assert lo < rows["N"].mean() < hi and rows["D"].mean() == pytest.approx(4.0, rel=0.05)
    s = ens.summary()
    assert s["nis_dof_gps_pos.D"] == 1 and s["nis_in_bounds_gps_pos.D"] < 0.2
    assert s["nis_in_bounds_gps_pos.E"] > 0.85
    names = [c.name for c in nis_columns(t, mean, count, dof, rows)]
    assert names[:5] == ["t", "nis_mean", "nis_lo", "nis_hi", "nis_runs"]
    assert names[5:] == ["nis_mean.N", "nis_mean.E", "nis_mean.D", "nis_row_lo", "nis_row_hi"]
