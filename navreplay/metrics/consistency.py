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

Correlated epochs count as what they are worth (docs/methods/consistency.md §7): the time
average of a series whose squared autocorrelation sums to an integrated time ``tau`` (in
epochs) is worth ``n / tau`` independent samples (:func:`integrated_time`,
:func:`effective_samples`). That gives a per-run test of the time-averaged NEES
(:func:`time_average_check`) and, per axis, the ratio RMS/sigma of the normalised errors
``e_i / sigma_i`` with an interval and a check over an ensemble (:func:`scale_check`, the lag
products pooled over runs by :class:`LagProducts`).

Examples
--------
>>> lo, hi = mean_band(2, 100)
>>> round(lo, 2), round(hi, 2)
(1.41, 2.72)
>>> round(rejection_probability(2, 900, 1 / 1.09), 2)
0.97
>>> c = scale_check(1.6**2, 60.0, false_alarm=0.05)
>>> round(c.ratio, 2), c.passed, [round(v, 2) for v in c.band]
(1.6, False, [0.82, 1.18])
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from navreplay.core import chi2

CHECK_FALSE_ALARM = 1e-3
"""False-alarm probability of one consistency check of the slow reproduction tests: with the
k checks of the suite the family-wise probability that a consistent filter fails any of them is
at most k times this (Bonferroni)."""
SIGMA_ERROR = 0.09
"""The mis-scaling of a covariance the checks must detect: 9 % in sigma, either way."""


def mean_band(dof: int, samples: float, false_alarm: float = CHECK_FALSE_ALARM
              ) -> tuple[float, float]:
    """Two-sided band of the mean of ``samples`` independent chi-square(``dof``) draws that a
    consistent filter leaves with probability ``false_alarm`` (``samples`` may be an effective,
    non-integer count)."""
    if dof < 1 or not samples > 0.0:
        raise ValueError(f"dof must be >= 1 and samples > 0, got {dof}, {samples}")
    k = samples * dof
    return (chi2.ppf(0.5 * false_alarm, k) / samples,
            chi2.ppf(1.0 - 0.5 * false_alarm, k) / samples)


def inside(mean: float, dof: int, samples: float, false_alarm: float = CHECK_FALSE_ALARM
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
    from scipy import special  # only here: metrics imports this module, and scipy is slow to load

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


# --------------------------------------------------------------------------------------------
# correlated epochs

SOKAL_WINDOW = 5.0
"""Sokal's automatic window: the autocorrelation is summed up to the first lag W with
W >= SOKAL_WINDOW * tau(W)."""


def autocovariance(x: np.ndarray, centre: bool = True) -> np.ndarray:
    """Sums of lagged products ``sum_t x[t] x[t + l]`` for l = 0 .. n-1, by FFT.

    Parameters
    ----------
    x : ndarray, shape (n,) or (n, k)
        NaN rows are taken as zero (and should be excluded from the counts by the caller).
    centre : bool
        Remove the mean first.

    Returns
    -------
    ndarray, shape (n,) or (n, k)
    """
    x = np.asarray(x, dtype=float)
    x = np.where(np.isfinite(x), x, 0.0)
    if centre:
        x = x - x.mean(axis=0)
    n = x.shape[0]
    size = 1 << max(0, (2 * n - 1).bit_length())
    f = np.fft.rfft(x, size, axis=0)
    return np.fft.irfft(f * np.conj(f), size, axis=0)[:n]


def integrated_time(rho: np.ndarray, window: float = SOKAL_WINDOW) -> float:
    """Integrated time ``1 + 2 sum_{l>=1} rho(l)`` of an autocorrelation [epochs], summed up to
    Sokal's window.

    For the time average of a squared Gaussian series (z^2, or a NEES), pass the squared
    autocorrelation of z (``rho_z(l)^2``), or the autocorrelation of the squared series.

    Examples
    --------
    >>> round(float(integrated_time(0.5 ** np.arange(200))), 3)  # AR(1): (1 + a) / (1 - a)
    3.0
    """
    rho = np.asarray(rho, dtype=float)
    tau = 1.0
    for lag in range(1, rho.shape[0]):
        tau += 2.0 * rho[lag]
        if lag >= window * tau:
            break
    return float(max(tau, 1.0))


def effective_samples(n: int | np.ndarray, tau: float) -> float | np.ndarray:
    """Independent samples a time average of ``n`` epochs is worth: ``n / tau``, at least one
    and at most ``n`` (a run whose curve never decorrelates is one sample)."""
    return np.clip(np.asarray(n, dtype=float) / tau, np.minimum(1.0, n), n)


@dataclasses.dataclass(frozen=True)
class MeanCheck:
    """A time-averaged chi-square statistic (NEES) against its band.

    Attributes
    ----------
    mean : float
    dof : int
    samples : float
        Effective independent samples of the average.
    band : tuple of float
        Its band at the false-alarm probability of the check.
    passed : bool
    """

    mean: float
    dof: int
    samples: float
    band: tuple[float, float]
    passed: bool


def time_average_check(nees: np.ndarray, tau: float, dof: int,
                       false_alarm: float = CHECK_FALSE_ALARM) -> MeanCheck:
    """The per-run test of a NEES series: its time average against the band of ``n / tau``
    independent samples.

    ``tau`` is the integrated time of the NEES [epochs]; for the runs of an ensemble,
    :meth:`LagProducts.time_of_mean` of the normalised errors of the NEES states pooled over
    the runs (one run's own autocorrelation is too noisy: a run that drifts away from zero looks
    more correlated than it is, and the test loses its power).

    Parameters
    ----------
    nees : ndarray, shape (n,)
        NEES at each epoch (NaN epochs are left out).
    tau : float
    dof : int
    false_alarm : float
    """
    v = np.asarray(nees, dtype=float)
    ok = np.isfinite(v)
    if not ok.any():
        raise ValueError("no finite NEES")
    return mean_check(float(v[ok].mean()), dof, float(effective_samples(int(ok.sum()), tau)),
                      false_alarm)


def mean_check(mean: float, dof: int, samples: float, false_alarm: float = CHECK_FALSE_ALARM
               ) -> MeanCheck:
    """A mean of ``samples`` (effective) chi-square(``dof``) draws against its band."""
    band = mean_band(dof, samples, false_alarm)
    return MeanCheck(mean, dof, samples, band, bool(band[0] <= mean <= band[1]))


@dataclasses.dataclass(frozen=True)
class ScaleCheck:
    """RMS/sigma of one axis's normalised errors ``z = e / sigma`` with its interval and check.

    Attributes
    ----------
    ratio : float
        ``sqrt(mean z^2)``: 1 for a consistent filter, 1.6 when the errors are 1.6 times the
        predicted sigma.
    interval : tuple of float
        ``confidence`` interval of the true ratio s (``samples mean / s^2`` is
        chi-square(``samples``)).
    samples : float
        Effective independent samples of the mean.
    band : tuple of float
        The ratio a consistent filter stays within (probability ``1 - false_alarm``).
    passed : bool
    """

    ratio: float
    interval: tuple[float, float]
    samples: float
    band: tuple[float, float]
    passed: bool


def scale_check(mean_square: float, samples: float, false_alarm: float = CHECK_FALSE_ALARM,
                confidence: float = 0.95) -> ScaleCheck:
    """The ratio RMS/sigma of ``samples`` effective samples of ``z^2`` (mean ``mean_square``):
    interval, band and check."""
    lo, hi = mean_band(1, samples, false_alarm)
    a = 0.5 * (1.0 - confidence)
    k = samples
    interval = (math.sqrt(mean_square * k / chi2.ppf(1.0 - a, k)),
                math.sqrt(mean_square * k / chi2.ppf(a, k)))
    ratio = math.sqrt(mean_square)
    return ScaleCheck(ratio, interval, samples, (math.sqrt(lo), math.sqrt(hi)),
                      bool(lo <= mean_square <= hi))


class LagProducts:
    """Lag products of normalised errors pooled over runs, per axis, for the integrated time
    of ``z^2`` (by the Gaussian identity ``rho_{z^2}(l) = rho_z(l)^2``).

    ``rho_z`` is estimated about zero (the mean of z is zero for a consistent filter), from
    the sums ``sum_r sum_t z_r(t) z_r(t + l)`` over every run r, divided by their counts.
    """

    def __init__(self) -> None:
        self.sums: np.ndarray | None = None
        self.counts: np.ndarray | None = None

    def add(self, z: np.ndarray) -> None:
        """One run's normalised errors, shape (n, k) (NaN where unscored)."""
        z = np.asarray(z, dtype=float)
        ok = np.isfinite(z).astype(float)
        sums = autocovariance(z, centre=False)
        counts = autocovariance(ok, centre=False)
        if self.sums is None:
            self.sums, self.counts = sums, counts
            return
        assert self.counts is not None  # created with the sums
        n = max(self.sums.shape[0], sums.shape[0])
        pad = [(0, n - self.sums.shape[0]), (0, 0)]
        self.sums, self.counts = np.pad(self.sums, pad), np.pad(self.counts, pad)
        self.sums[: sums.shape[0]] += sums
        self.counts[: counts.shape[0]] += counts

    def _rho2(self) -> np.ndarray:
        """Squared autocorrelation of each axis, shape (L, k)."""
        if self.sums is None or self.counts is None:
            return np.zeros((0, 0))
        with np.errstate(invalid="ignore", divide="ignore"):
            c = self.sums / self.counts
            rho = c / c[0]
        return np.where((self.counts > 0.5) & np.isfinite(rho), rho, 0.0) ** 2

    def times(self) -> np.ndarray:
        """Integrated time of each axis's ``z^2`` [epochs], shape (k,)."""
        rho2 = self._rho2()
        return np.array([integrated_time(rho2[:, j]) for j in range(rho2.shape[1])])

    def time_of_mean(self, columns: np.ndarray | None = None) -> float:
        """Integrated time of the sum of the axes' ``z^2`` (a NEES over ``columns``, default
        all): ``1 + 2 sum_l mean_i rho_i(l)^2``, leaving out the axes' cross-correlation
        [epochs]. Scaling the errors leaves it unchanged."""
        rho2 = self._rho2()
        if columns is not None:
            rho2 = rho2[:, columns]
        return integrated_time(rho2.mean(axis=1)) if rho2.size else 1.0


@dataclasses.dataclass(frozen=True)
class EnsembleConsistency:
    """The consistency of an ensemble beyond its NEES curve (:class:`ConsistencyStats`).

    Attributes
    ----------
    names : tuple of str
        The scored states (axes).
    nees_names : tuple of str
        Those in the NEES.
    scale : dict[str, ScaleCheck]
        Per axis, RMS/sigma of the normalised errors over every run and epoch, its interval and
        check; the samples are each run's epochs over the axis's integrated time (pooled over
        the runs), at least one per run.
    z2_mean : ndarray, shape (M, k)
        Mean over runs of ``z^2`` at each epoch (NaN where no run has one).
    z2_count : ndarray, shape (M, k)
        Runs averaged at each epoch.
    nees : MeanCheck or None
        The time-averaged NEES over every run and epoch, with the samples of the per-run tests
        added up.
    nees_runs_failed : int
        Runs whose own time-averaged NEES test fails (a consistent filter fails
        ``false_alarm`` of them).
    runs : int
    false_alarm : float
        Of every check.
    """

    names: tuple[str, ...]
    nees_names: tuple[str, ...]
    scale: dict[str, ScaleCheck]
    z2_mean: np.ndarray
    z2_count: np.ndarray
    nees: MeanCheck | None
    nees_runs_failed: int
    runs: int
    false_alarm: float

    def summary(self) -> dict[str, object]:
        """Nested entries of an ensemble summary (JSON-friendly)."""
        out: dict[str, object] = {"rms_over_sigma": {
            name: {"ratio": c.ratio, "interval_95": list(c.interval), "samples": c.samples,
                   "band": list(c.band), "passed": c.passed, "nees": name in self.nees_names}
            for name, c in self.scale.items()}}
        if self.nees is not None:
            out["nees_time_averaged"] = {
                "mean": self.nees.mean, "dof": self.nees.dof, "samples": self.nees.samples,
                "band": list(self.nees.band), "passed": self.nees.passed,
                "runs_failed": self.nees_runs_failed, "runs": self.runs}
        out["consistency_false_alarm"] = self.false_alarm
        return out


class ConsistencyStats:
    """Accumulates, run by run, what :class:`EnsembleConsistency` reports: the normalised
    errors' squares and lag products per axis, and each run's time-averaged NEES test."""

    def __init__(self, false_alarm: float = CHECK_FALSE_ALARM) -> None:
        self.false_alarm = false_alarm
        self.lags = LagProducts()
        self.sum_sq: np.ndarray | None = None
        self.run_counts: list[np.ndarray] = []
        self.z2_sum: np.ndarray | None = None
        self.z2_n: np.ndarray | None = None
        self.nees_runs: list[tuple[float, int]] = []  # per run: mean NEES, epochs
        self.in_nees = np.zeros(0, dtype=int)

    def add(self, error: np.ndarray, variance: np.ndarray, nees: np.ndarray,
            in_nees: np.ndarray) -> None:
        """One run: its state errors and predicted variances, shape (M, k), its NEES (M,) and
        the columns of the states in the NEES (``in_nees``, int array)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            z = np.where(variance > 0.0, error / np.sqrt(variance), np.nan)
        ok = np.isfinite(z)
        z2 = np.where(ok, z * z, 0.0)
        self.lags.add(z)
        self.run_counts.append(ok.sum(axis=0))
        if self.sum_sq is None:
            self.sum_sq = np.zeros(z.shape[1])
            self.z2_sum, self.z2_n = np.zeros(z.shape), np.zeros(z.shape, dtype=np.int64)
        assert self.z2_sum is not None and self.z2_n is not None  # created with sum_sq
        self.sum_sq += z2.sum(axis=0)
        m = z.shape[0]
        if m > self.z2_sum.shape[0]:
            grow = ((0, m - self.z2_sum.shape[0]), (0, 0))
            self.z2_sum, self.z2_n = np.pad(self.z2_sum, grow), np.pad(self.z2_n, grow)
        self.z2_sum[:m] += z2
        self.z2_n[:m] += ok
        finite = np.isfinite(nees)
        if len(in_nees) and finite.any():
            self.in_nees = np.asarray(in_nees, dtype=int)
            self.nees_runs.append((float(np.mean(nees[finite])), int(finite.sum())))

    def result(self, names: tuple[str, ...], nees_names: tuple[str, ...] = ()
               ) -> EnsembleConsistency:
        """The statistics of the runs added so far; ``names`` of the k axes, ``nees_names``
        those in the NEES."""
        runs = len(self.run_counts)
        scale: dict[str, ScaleCheck] = {}
        if self.sum_sq is not None:
            taus = self.lags.times()
            counts = np.array(self.run_counts)
            total = counts.sum(axis=0)
            for j, name in enumerate(names):
                if total[j] == 0:
                    continue
                samples = float(np.sum(effective_samples(counts[:, j][counts[:, j] > 0],
                                                         taus[j])))
                scale[name] = scale_check(self.sum_sq[j] / total[j], samples, self.false_alarm)
        with np.errstate(invalid="ignore", divide="ignore"):
            z2_mean = (self.z2_sum / self.z2_n if self.z2_sum is not None
                       else np.zeros((0, len(names))))
        nees, failed = None, 0
        if self.nees_runs:
            dof = len(self.in_nees)
            tau = self.lags.time_of_mean(self.in_nees)
            means = np.array([m for m, _ in self.nees_runs])
            epochs = np.array([n for _, n in self.nees_runs])
            run_samples = np.broadcast_to(effective_samples(epochs, tau), epochs.shape)
            failed = sum(not mean_check(float(m), dof, float(k), self.false_alarm).passed
                         for m, k in zip(means, run_samples, strict=True))
            nees = mean_check(float(np.sum(means * epochs) / np.sum(epochs)), dof,
                              float(np.sum(run_samples)), self.false_alarm)
        return EnsembleConsistency(
            names=names, nees_names=tuple(nees_names), scale=scale, z2_mean=z2_mean,
            z2_count=self.z2_n if self.z2_n is not None else np.zeros((0, len(names)), int),
            nees=nees, nees_runs_failed=failed, runs=runs,
            false_alarm=self.false_alarm)
