"""Scoring filter runs against the truth: navigation errors, error-state errors, RMS, CEP50, %DT,
NEES and NIS, for single runs and for Monte Carlo ensembles.

One module per concept: :mod:`~navreplay.metrics.stats` (RMS, CEP50, NEES, chi-square bounds),
:mod:`~navreplay.metrics.reference` (what a run is scored against),
:mod:`~navreplay.metrics.errors` (errors of the solution and the declared states),
:mod:`~navreplay.metrics.run` (the scores of one run, :func:`run_metrics`),
:mod:`~navreplay.metrics.summary` (its scalar summary, block by block),
:mod:`~navreplay.metrics.scoring` (a run scored as its estimates and truth arrive),
:mod:`~navreplay.metrics.ensemble` (Monte Carlo statistics) and
:mod:`~navreplay.metrics.outages` (each GNSS outage of a recording scored on its own).

All errors are estimate minus truth. Position errors are north, east, down in metres; the
attitude error is the phi angle of :func:`navreplay.geo.attitude_error`
(``C_hat = (I - [phi x]) C``); Euler-angle errors are differences of ZYX angles with the yaw
difference wrapped to [-pi, pi).

Definitions
-----------
::

    x_N = (lat_hat - lat)(R_M + h),  x_E = (lon_hat - lon)(R_N + h) cos lat,  x_D = -(h_hat - h)
    RMS over runs i = 1..N:  LatRMS = sqrt(mean_i x_N,i^2),  LongRMS = sqrt(mean_i x_E,i^2)
    CEP50  = 0.5887 (LatRMS + LongRMS)                       [m]    (eq. 29)
    DT     = integral |v_n| dt of the truth (mean over runs)   [m]
    DT CEP50 = CEP50 / DT x 100                               [%]    (eq. 30)
    NEES   = e^T P^-1 e over the scored states (e = estimation error, P its covariance)
    NIS    = nu^T S^-1 nu per measurement update
    95 % bounds of a mean over N runs of a chi-square quantity with d dof:
             chi2.ppf([0.025, 0.975], N d) / N                          (single run: N = 1)

Eqs. 29 and 30 are those of the RPM-aided INS paper (docs/methods/rpm-aided-ins.md §6).

Scoring against a reference
---------------------------
A run is scored against a :class:`Reference`: a truth-like stream (the recording's truth, or
an external reference) with whichever of ``pos``, ``v_n``, ``q_nb`` it has, plus the true
constants of ``metadata.true_errors``. What is absent is not scored: a reference with positions
only gives position errors and leaves velocity, attitude and the states that need them out.

Which states are scored, and against what, the filter declares once
(:class:`navreplay.filters.base.State`, copied into ``RunResult.states``): a ``NavError(q)``
state has ``e = (nav_hat - ref)_q - x`` (``q`` in :class:`navreplay.filters.base.Nav`), a
``TruthColumn`` state ``e = x - ref[column][index]``, a ``TrueConstant`` state ``e = x -
true_errors[key][index]``. The NEES is over the states declared with ``nees=True`` that are
scored.
"""

from navreplay.metrics.ensemble import EnsembleResult, EnsembleStats
from navreplay.metrics.errors import (
    NavErrors,
    extra_errors,
    nav_errors,
    nav_sigma,
    position_error_ned,
    reference_value,
    state_errors,
)
from navreplay.metrics.reference import Reference, truth_at
from navreplay.metrics.run import RunMetrics, row_nis, run_metrics
from navreplay.metrics.scoring import RunScorer
from navreplay.metrics.stats import (
    CEP50_FACTOR,
    cep50,
    chi2_bounds,
    chi2_bounds_per_count,
    nees,
    rms,
)
from navreplay.metrics.summary import RunSummary

__all__ = [
    "CEP50_FACTOR",
    "EnsembleResult",
    "EnsembleStats",
    "NavErrors",
    "Reference",
    "RunMetrics",
    "RunScorer",
    "RunSummary",
    "cep50",
    "chi2_bounds",
    "chi2_bounds_per_count",
    "extra_errors",
    "nav_errors",
    "nav_sigma",
    "nees",
    "position_error_ned",
    "reference_value",
    "row_nis",
    "rms",
    "run_metrics",
    "state_errors",
    "truth_at",
]
