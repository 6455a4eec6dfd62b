"""Chi-square quantiles computed without scipy agree with scipy.stats to 1e-11 relative,
from 1 to 18000 degrees of freedom and deep into both tails."""

from __future__ import annotations

import pytest
from scipy.stats import chi2 as scipy_chi2

from navreplay.core import chi2
from navreplay.metrics import chi2_bounds


@pytest.mark.parametrize("k", [1, 2, 3, 6, 9, 18, 100, 900, 18000])
def test_quantiles_match_scipy(k: int) -> None:
    for p in (1e-6, 0.025, 0.5, 0.975, 1 - 1e-6):
        assert chi2.ppf(p, k) == pytest.approx(scipy_chi2.ppf(p, k), rel=1e-11)


def test_incomplete_gamma_inverts_the_quantile() -> None:
    for k in (1, 4, 50):
        assert chi2.gammainc(0.5 * k, 0.5 * chi2.ppf(0.3, k)) == pytest.approx(0.3, abs=1e-13)


def test_bounds_of_a_mean_over_runs() -> None:
    lo, hi = chi2_bounds(3, 50, 0.95)
    assert (lo, hi) == pytest.approx(tuple(scipy_chi2.ppf([0.025, 0.975], 150) / 50), rel=1e-11)
    with pytest.raises(ValueError):
        chi2.ppf(1.0, 3)
