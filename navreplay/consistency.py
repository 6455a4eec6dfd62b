"""Chi-square consistency checks with a stated false-alarm probability and power.

The statistics of docs/methods/consistency.md. A consistent filter's NEES (or NIS) at one epoch
is chi-square with ``dof`` degrees of freedom; the mean of ``samples`` independent draws is
``chi2(samples dof) / samples``. A check accepts when that mean lies in its two-sided band of
probability ``1 - false_alarm``.

What counts as a sample is the whole point: the NIS of a consistent filter is white, so every
update of every run is a sample; the NEES of a run is correlated in time (for the
rpm-aided-ins position it is flat: the position error is the current error times the time
elapsed), so a run's time-averaged NEES counts as ONE sample, and epochs add nothing. Counting
a correlated curve's epochs as samples gives a band far too tight; counting runs is exact for a
flat curve and conservative (a smaller false alarm) for one that decorrelates.

Examples
--------
>>> lo, hi = mean_band(2, 100)
>>> round(lo, 2), round(hi, 2)
(1.41, 2.72)
>>> round(rejection_probability(2, 900, 1 / 1.09), 2)
0.97
"""

from __future__ import annotations

from scipy import special

from navreplay.metrics import chi2_bounds

CHECK_FALSE_ALARM = 1e-3
"""False-alarm probability of one consistency check of the slow reproduction tests: with the
k checks of the suite the family-wise probability that a consistent filter fails any of them is
at most k times this (Bonferroni)."""
SIGMA_ERROR = 0.09
"""The mis-scaling of a covariance the checks must detect: 9 % in sigma, either way."""


def mean_band(dof: int, samples: int, false_alarm: float = CHECK_FALSE_ALARM
              ) -> tuple[float, float]:
    """Two-sided band of the mean of ``samples`` independent chi-square(``dof``) draws that a
    consistent filter leaves with probability ``false_alarm``."""
    return chi2_bounds(dof, samples, 1.0 - false_alarm)


def inside(mean: float, dof: int, samples: int, false_alarm: float = CHECK_FALSE_ALARM
           ) -> bool:
    """The check: ``mean`` (of ``samples`` independent NEES or NIS draws) inside its band."""
    lo, hi = mean_band(dof, samples, false_alarm)
    return bool(lo <= mean <= hi)


def rejection_probability(dof: int, samples: int, sigma_scale: float,
                          false_alarm: float = CHECK_FALSE_ALARM) -> float:
    """Probability that the check rejects a filter whose errors are ``sigma_scale`` times its
    predicted sigma (> 1 over-confident, < 1 under-confident).

    The mean NEES is then ``sigma_scale^2 chi2(samples dof) / samples``; at ``sigma_scale = 1``
    this is ``false_alarm``.
    """
    if not sigma_scale > 0.0:
        raise ValueError(f"sigma_scale must be > 0, got {sigma_scale!r}")
    lo, hi = mean_band(dof, samples, false_alarm)
    k = 0.5 * samples * dof
    s2 = sigma_scale * sigma_scale
    return float(special.gammainc(k, 0.5 * samples * lo / s2)
                 + special.gammaincc(k, 0.5 * samples * hi / s2))


def samples_needed(dof: int, sigma_error: float = SIGMA_ERROR, power: float = 0.9,
                   false_alarm: float = CHECK_FALSE_ALARM) -> int:
    """Fewest samples with which the check rejects a covariance mis-scaled by
    ``1 +- sigma_error`` in sigma (both directions) with probability >= ``power``."""
    def ok(n: int) -> bool:
        return min(rejection_probability(dof, n, 1.0 + sigma_error, false_alarm),
                   rejection_probability(dof, n, 1.0 / (1.0 + sigma_error), false_alarm)
                   ) >= power
    hi = 1
    while not ok(hi):
        hi *= 2
        if hi > 1 << 24:
            raise ValueError("no sample count up to 2^24 reaches that power")
    lo = hi // 2
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if ok(mid) else (mid, hi)
    return hi
