"""Allan deviation of a still IMU and the noise terms fitted to it.

The overlapping Allan deviation (ADEV) of each axis is computed with ``allantools``; the noise
terms of the simulator's IMU model (:class:`~navreplay.sensors.imu.ImuModel`) are fitted to it,
one triad (gyro or accelerometer) at a time. Each term has its own slope on the log-log plot
(IEEE Std 952 and Std 1554 read them off these asymptotes)::

    term                               Allan variance AVAR(tau)                 ADEV slope
    white noise N  (ARW, VRW)          N^2 / tau                                -1/2
    Gauss-Markov bias (sigma, T)       (2 sigma^2 T / tau) [1 - T/(2 tau)        hump
                                        (3 - 4 exp(-tau/T) + exp(-2 tau/T))]
    random walk K  (RRW, accel RW)     K^2 tau / 3                              +1/2

* The white-noise density N is the -1/2 line read at tau = 1 s; the random-walk density K is
  the +1/2 line read at tau = 3 s.
* The bias instability is modelled as the simulator and the filters model it, a first-order
  Gauss-Markov process of steady-state sigma and correlation time T. Its ADEV is a hump whose
  maximum, ``GM_PEAK_ADEV`` = 0.6174 sigma, lies at tau = ``GM_PEAK_X`` T = 1.893 T; fitting the
  hump gives sigma and T directly. The IEEE "bias instability" B of a flicker floor
  (ADEV floor = ``FLICKER_FLOOR`` B = 0.6643 B) is reported beside it for comparison with
  datasheets, read at the flat part of the fitted curve (without white noise, a Gauss-Markov
  hump read as a floor would give B = 0.929 sigma; with it, the floor lies before the hump
  and B is smaller).

Fit
    The three terms are fitted together to the mean Allan variance of the three axes (a triad
    has one value per term in the specification; the axes are also fitted one by one for the
    table) over tau from ``FIT_MIN_TAU`` (and ten samples) to half the record: non-negative
    least squares on the Allan variance, each point weighted by the inverse of its standard
    error ``AVAR sqrt(2 / edf)``; T by a search over a log grid. The weights come from the
    model, not from the noisy estimate (iteratively reweighted, which removes the low bias of
    weighting by the estimate), and edf is Greenhall's equivalent number of degrees of freedom
    of the overlapping estimator for the noise type of the fitted model's local slope.

What the record supports
    A Gauss-Markov term is reported when its hump peaks inside [10 tau_min, tau_max / 2] and
    rises at its peak at least ``DETECTION_Z`` standard errors above the other terms; a random
    walk when it does so at the longest tau. A term the record cannot resolve is left out with
    a note saying why (and, for the random walk, the upper bound the curve allows). A record
    whose clusters do not span a decade of tau is refused (:class:`AllanError`).

Uncertainty
    The ADEV of each tau has a chi-square confidence interval with Greenhall's edf
    (:attr:`AllanCurve.lo`, :attr:`AllanCurve.hi`, 68.3 %). The fitted terms get theirs from a
    parametric bootstrap: ``bootstrap`` synthetic records of the fitted model, as long as the
    measured one (sampled at up to ``BOOTSTRAP_MAX_SAMPLES`` intervals), go through the same
    fit; the 16th and 84th percentiles of each term are its interval. This includes what the
    per-tau intervals cannot: neighbouring taus share data, and sigma trades against T.

Examples
--------
White noise of density 0.01 (unit sqrt(s)) at 100 Hz for 20 min:

>>> import numpy as np
>>> rng = np.random.default_rng(1)
>>> y = rng.standard_normal((120_000, 3)) * 0.01 / np.sqrt(0.01)
>>> a = analyse_triad(y, 100.0, bootstrap=0)
>>> round(a.fit.white, 4), sorted(str(t) for t in a.fit.terms)
(0.01, ['white'])
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import minimize_scalar, nnls

from navreplay.sensors.noise import gauss_markov, random_walk

GM_PEAK_X = 1.8926178
"""tau / T at the maximum of a first-order Gauss-Markov process's ADEV."""
GM_PEAK_ADEV = 0.6173643
"""The maximum of a first-order Gauss-Markov process's ADEV over its steady-state sigma."""
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
"""ADEV floor of flicker noise over the IEEE bias instability B (0.6643)."""
FIT_MIN_TAU = 0.1
"""Shortest cluster time fitted [s] (and at least ten samples): an IMU's anti-alias filter
colours the noise at the shortest taus."""
DETECTION_Z = 2.0
"""Standard errors of the Allan variance by which a Gauss-Markov hump or a random walk must
rise above the other terms to be reported."""
FLOOR_SLOPE = -0.25
"""Steepest log-log slope of the fitted ADEV still read as a floor when it has no minimum."""
CONFIDENCE = 0.6826894921370859
"""Probability of the confidence intervals (1 sigma)."""
BOOTSTRAP_MAX_SAMPLES = 60_000
"""Longest synthetic record of the bootstrap [samples]; longer records are simulated at a
coarser interval (a multiple of the sampling interval)."""
TAUS_PER_DECADE = 10


class AllanError(ValueError):
    """A segment the Allan analysis refuses (too short, not still); one line."""


class Term(enum.StrEnum):
    """The noise terms of the fit."""

    WHITE = "white"
    GAUSS_MARKOV = "gauss_markov"
    RANDOM_WALK = "random_walk"


def gm_avar(tau: np.ndarray, sigma: float, T: float) -> np.ndarray:
    """Allan variance of a first-order Gauss-Markov process.

    Parameters
    ----------
    tau : ndarray
        Cluster times [s].
    sigma : float
        Steady-state 1-sigma [unit].
    T : float
        Correlation time [s].

    Returns
    -------
    ndarray
        [unit^2].

    Examples
    --------
    >>> x = float(np.sqrt(gm_avar(np.array([GM_PEAK_X * 50.0]), 1.0, 50.0))[0])
    >>> round(x, 4)
    0.6174
    """
    x = np.asarray(tau, dtype=float) / T
    # 3 - 4 e^-x + e^-2x = (1 - e^-x)(3 - e^-x), written with expm1 for small x
    e = -np.expm1(-x)
    return 2.0 * sigma**2 / x * (1.0 - e * (2.0 + e) / (2.0 * x))


@dataclasses.dataclass(frozen=True)
class AllanCurve:
    """Overlapping Allan deviation of one axis (or the mean of a triad's variances).

    Attributes
    ----------
    tau : ndarray, shape (K,)
        Cluster times [s].
    adev : ndarray, shape (K,)
        [unit].
    edf : ndarray, shape (K,)
        Equivalent degrees of freedom (Greenhall, noise type of the fitted model).
    lo, hi : ndarray, shape (K,)
        Chi-square confidence interval of ``adev`` (``CONFIDENCE``).
    """

    tau: np.ndarray
    adev: np.ndarray
    edf: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


@dataclasses.dataclass(frozen=True)
class NoiseFit:
    """The noise terms fitted to an Allan variance curve (SI units of the samples).

    Attributes
    ----------
    white : float
        White-noise density N [unit sqrt(s)] (ARW in rad/sqrt(s), VRW in m/s/sqrt(s)).
    gm_sigma : float
        Gauss-Markov steady-state sigma [unit]; 0 when not reported.
    gm_tau : float
        Gauss-Markov correlation time T [s]; NaN when not reported.
    walk : float
        Random-walk density K [unit/sqrt(s)]; 0 when not reported.
    terms : frozenset of Term
        The terms the record supports (reported).
    floor : float
        The flat part of the fitted ADEV [unit] (its first minimum, or its flattest point when
        flatter than ``FLOOR_SLOPE``; NaN when the curve falls at -1/2 throughout), at
        ``floor_tau`` [s]: the IEEE bias instability is ``floor / FLICKER_FLOOR``.
    floor_tau : float
    walk_bound : float
        When the random walk is not reported: the largest K the curve allows (the +1/2 line
        through the upper 95 % bound of the ADEV at the longest tau) [unit/sqrt(s)]; else NaN.
    notes : tuple of str
        Why a term is not reported.
    """

    white: float
    gm_sigma: float
    gm_tau: float
    walk: float
    terms: frozenset[Term]
    floor: float
    floor_tau: float
    walk_bound: float = math.nan
    notes: tuple[str, ...] = ()

    @property
    def bias_instability(self) -> float:
        """IEEE bias instability of the floor, ``floor / FLICKER_FLOOR`` [unit]."""
        return self.floor / FLICKER_FLOOR

    def avar(self, tau: np.ndarray) -> np.ndarray:
        """The fitted model's Allan variance [unit^2] at ``tau`` [s]."""
        tau = np.asarray(tau, dtype=float)
        out = self.white**2 / tau + self.walk**2 * tau / 3.0
        if Term.GAUSS_MARKOV in self.terms:
            out = out + gm_avar(tau, self.gm_sigma, self.gm_tau)
        return out

    def values(self) -> dict[str, float]:
        """The fitted parameters by name (``white``, ``gm_sigma``, ``gm_tau``, ``walk``)."""
        return {"white": self.white, "gm_sigma": self.gm_sigma, "gm_tau": self.gm_tau,
                "walk": self.walk}


@dataclasses.dataclass(frozen=True)
class TriadAnalysis:
    """Allan analysis of one triad (three gyro or three accelerometer axes).

    Attributes
    ----------
    rate : float
        Sample rate [Hz].
    samples : int
        Samples per axis.
    axes : tuple of AllanCurve
        Per axis x, y, z.
    axis_fits : tuple of NoiseFit
        Per axis.
    curve : AllanCurve
        The triad: square root of the mean of the three Allan variances, edf summed.
    fit : NoiseFit
        Fitted to ``curve``: the triad's values.
    intervals : dict[str, tuple[float, float]]
        Bootstrap interval (``CONFIDENCE``) of each parameter of ``fit.values()`` that is
        reported; empty without bootstrap.
    bootstrap : int
        Number of bootstrap records.
    """

    rate: float
    samples: int
    axes: tuple[AllanCurve, AllanCurve, AllanCurve]
    axis_fits: tuple[NoiseFit, NoiseFit, NoiseFit]
    curve: AllanCurve
    fit: NoiseFit
    intervals: dict[str, tuple[float, float]]
    bootstrap: int

    @property
    def duration(self) -> float:
        """Length of the record [s]."""
        return self.samples / self.rate


# --------------------------------------------------------------------------------------------
# Allan variance and its confidence


def cluster_sizes(samples: int, per_decade: int = TAUS_PER_DECADE) -> np.ndarray:
    """Cluster sizes m (samples), log-spaced from 1 to half the record.

    >>> cluster_sizes(1001, 5).tolist()
    [1, 2, 3, 4, 7, 11, 18, 28, 46, 74, 119, 192, 310, 500]
    """
    top = (samples - 1) // 2
    if top < 1:
        return np.zeros(0, dtype=np.int64)
    count = int(math.floor(math.log10(top) * per_decade)) + 1
    return np.unique(np.round(np.logspace(0.0, math.log10(top), count)).astype(np.int64))


def overlapping_avar(y: np.ndarray, rate: float, m: np.ndarray) -> np.ndarray:
    """Overlapping Allan variance of rate samples ``y`` (N,) at cluster sizes ``m`` (K,).

    ``allantools.oadev`` with ``data_type="freq"``: each sample is the mean over its interval,
    as an IMU's increments are.

    Returns
    -------
    ndarray, shape (K,)
        [unit^2].
    """
    allantools = _allantools()
    taus, adev, _, _ = allantools.oadev(np.ascontiguousarray(y, dtype=float), rate=rate,
                                         data_type="freq", taus=m / rate)
    got = np.round(np.asarray(taus) * rate).astype(np.int64)
    if not np.array_equal(got, m):  # allantools drops taus it cannot compute
        raise AllanError(f"the Allan variance has no value at cluster sizes "
                         f"{sorted(set(m.tolist()) - set(got.tolist()))[:3]}")
    return np.asarray(adev, dtype=float) ** 2


def _allantools():  # noqa: ANN202 - the module
    """allantools, the optional extra ``allan`` (imported only for this analysis)."""
    try:
        import allantools
    except ImportError:
        raise ImportError("the Allan analysis needs allantools: pip install "
                          "'navreplay[allan]'") from None
    return allantools


@functools.lru_cache(maxsize=4096)
def _edf(alpha: int, m: int, samples: int) -> float:
    return float(_allantools().edf_greenhall(alpha=alpha, d=2, m=m, N=samples + 1,
                                          overlapping=True))


def greenhall_edf(m: np.ndarray, samples: int, slope: np.ndarray) -> np.ndarray:
    """Greenhall's edf of the overlapping ADEV at cluster sizes ``m`` for the noise type of
    the local log-log slope of the Allan variance (-1 white FM, 0 flicker FM, +1 random-walk
    FM, rounded).

    Parameters
    ----------
    m : ndarray of int, shape (K,)
    samples : int
        Rate samples of the record.
    slope : ndarray, shape (K,)
        d ln AVAR / d ln tau.
    """
    alpha = np.clip(np.round(-1.0 - np.asarray(slope)), -2, 0).astype(int)
    return np.array([_edf(int(a), int(k), int(samples)) for a, k in zip(alpha, m, strict=True)])


def chi2_interval(adev: np.ndarray, edf: np.ndarray, p: float = CONFIDENCE
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided chi-square interval of an ADEV estimate with ``edf`` degrees of freedom."""
    from scipy.stats import chi2

    q = (1.0 - p) / 2.0
    lo = adev * np.sqrt(edf / chi2.ppf(1.0 - q, edf))
    hi = adev * np.sqrt(edf / chi2.ppf(q, edf))
    return lo, hi


# --------------------------------------------------------------------------------------------
# the fit


@dataclasses.dataclass(frozen=True)
class _Range:
    """The taus a fit uses and the Gauss-Markov peaks it can resolve."""

    keep: np.ndarray  # bool mask over the curve's taus
    peak_min: float
    peak_max: float


def _fit_range(tau: np.ndarray, rate: float) -> _Range:
    tau_min = max(FIT_MIN_TAU, 10.0 / rate)
    keep = tau >= tau_min * (1.0 - 1e-9)
    if keep.sum() < 3 or tau[keep][-1] < 10.0 * tau[keep][0]:
        longest = tau[-1] if len(tau) else 0.0
        raise AllanError(
            f"too short for an Allan analysis: its clusters reach {longest:.3g} s; a fit needs "
            f"them to span a decade from {tau_min:.3g} s (a record of at least "
            f"{20.0 * tau_min:.3g} s; minutes for the white noise, hours for a bias "
            "instability)")
    t = tau[keep]
    return _Range(keep, 10.0 * t[0], t[-1] / 2.0)


def _design(tau: np.ndarray, terms: Sequence[Term], T: float) -> np.ndarray:
    cols = []
    for term in terms:
        if term is Term.WHITE:
            cols.append(1.0 / tau)
        elif term is Term.GAUSS_MARKOV:
            cols.append(gm_avar(tau, 1.0, T))
        else:
            cols.append(tau / 3.0)
    return np.column_stack(cols)


def _solve(tau: np.ndarray, avar: np.ndarray, se: np.ndarray, terms: Sequence[Term],
           grid: np.ndarray) -> tuple[dict[Term, float], float]:
    """Non-negative weighted least squares; T by search over ``grid`` when a GM is fitted.
    Returns the coefficients (N^2, sigma^2, K^2) by term and T (NaN without GM)."""
    b = avar / se
    if Term.GAUSS_MARKOV not in terms:
        c, _ = nnls(_design(tau, terms, 1.0) / se[:, None], b)
        return dict(zip(terms, c, strict=True)), math.nan
    def cost(T: float) -> tuple[float, np.ndarray]:
        c, r = nnls(_design(tau, terms, T) / se[:, None], b)
        return r, c

    costs = [cost(float(T))[0] for T in grid]
    k = int(np.argmin(costs))
    # refine T between the grid's neighbours of the best point
    lo, hi = math.log(grid[max(k - 1, 0)]), math.log(grid[min(k + 1, len(grid) - 1)])
    best = minimize_scalar(lambda u: cost(math.exp(u))[0], bounds=(lo, hi), method="bounded",
                           options={"xatol": 1e-3})
    T = math.exp(best.x) if best.fun <= costs[k] else float(grid[k])
    return dict(zip(terms, cost(T)[1], strict=True)), T


def _model(coef: dict[Term, float], T: float, tau: np.ndarray) -> np.ndarray:
    out = coef.get(Term.WHITE, 0.0) / tau + coef.get(Term.RANDOM_WALK, 0.0) * tau / 3.0
    if coef.get(Term.GAUSS_MARKOV, 0.0) > 0.0:
        out = out + gm_avar(tau, math.sqrt(coef[Term.GAUSS_MARKOV]), T)
    return out


def _edf_of_model(tau: np.ndarray, m: np.ndarray, samples: int, axes: int,
                  model: np.ndarray) -> np.ndarray:
    slope = np.gradient(np.log(model), np.log(tau)) if len(tau) > 1 else np.array([-1.0])
    return axes * greenhall_edf(m, samples, slope)


def fit_noise(tau: np.ndarray, avar: np.ndarray, rate: float, samples: int, axes: int = 1,
              iterations: int = 3) -> tuple[NoiseFit, np.ndarray]:
    """Fit white noise, a Gauss-Markov bias and a random walk to an Allan variance curve.

    Parameters
    ----------
    tau : ndarray, shape (K,)
        Cluster times [s] (multiples of 1 / rate), from :func:`cluster_sizes`.
    avar : ndarray, shape (K,)
        Allan variance [unit^2]; for a triad, the mean of its axes.
    rate : float
        Sample rate [Hz].
    samples : int
        Samples per axis.
    axes : int
        Independent axes averaged into ``avar`` (their edf add up).
    iterations : int
        Reweighting passes.

    Returns
    -------
    fit : NoiseFit
    edf : ndarray, shape (K,)
        Greenhall's edf of each tau for the fitted model's noise types.

    Raises
    ------
    AllanError
        The curve does not span a decade of fitted taus.
    """
    rng_ = _fit_range(tau, rate)
    m_all = np.round(tau * rate).astype(np.int64)
    t, a, m = tau[rng_.keep], avar[rng_.keep], m_all[rng_.keep]
    grid = np.logspace(math.log10(t[0] / GM_PEAK_X), math.log10(10.0 * t[-1]), 160)
    all_terms = (Term.WHITE, Term.GAUSS_MARKOV, Term.RANDOM_WALK)

    # start: weights from the estimate itself and the white-noise edf
    se = a * np.sqrt(2.0 / (axes * np.maximum(samples / m - 1.0, 1.0)))
    coef, T = _solve(t, a, se, all_terms, grid)
    model = _model(coef, T, t)
    edf = _edf_of_model(t, m, samples, axes, model)
    coef, T = _solve(t, a, model * np.sqrt(2.0 / edf), all_terms, grid)

    # which terms the record supports
    model = _model(coef, T, t)
    edf = _edf_of_model(t, m, samples, axes, model)
    se = model * np.sqrt(2.0 / edf)
    notes: list[str] = []
    gm_ok = _gm_supported(coef, T, t, se, rng_, notes)
    terms = [Term.WHITE, Term.GAUSS_MARKOV] if gm_ok else [Term.WHITE]
    coef, T = _solve(t, a, se, [*terms, Term.RANDOM_WALK], grid)
    if _rises(coef.get(Term.RANDOM_WALK, 0.0) * t / 3.0, se) >= DETECTION_Z:
        terms.append(Term.RANDOM_WALK)

    for _ in range(iterations):
        coef, T = _solve(t, a, se, terms, grid)
        model = _model(coef, T, t)
        edf = _edf_of_model(t, m, samples, axes, model)
        se = model * np.sqrt(2.0 / edf)
    if Term.GAUSS_MARKOV in terms and not _gm_supported(coef, T, t, se, rng_, notes):
        terms.remove(Term.GAUSS_MARKOV)
        coef, T = _solve(t, a, se, terms, grid)

    walk_bound = math.nan
    if Term.RANDOM_WALK not in terms:
        hi95 = chi2_interval(np.sqrt(a[-1:]), edf[-1:], 0.95)[1][0]
        walk_bound = math.sqrt(3.0 * hi95**2 / t[-1])
        notes.append(f"random walk: not detected (nowhere up to tau = {t[-1]:.4g} s does it "
                     f"rise {DETECTION_Z:g} standard errors)")
    elif Term.GAUSS_MARKOV not in terms:
        notes.append(f"random walk: may also be a bias instability with a correlation time "
                     f"beyond {rng_.peak_max / GM_PEAK_X:.4g} s, which a record this long "
                     "cannot tell from it")
    fit = NoiseFit(
        white=math.sqrt(coef.get(Term.WHITE, 0.0)),
        gm_sigma=math.sqrt(coef.get(Term.GAUSS_MARKOV, 0.0)) if Term.GAUSS_MARKOV in terms
        else 0.0,
        gm_tau=T if Term.GAUSS_MARKOV in terms else math.nan,
        walk=math.sqrt(coef.get(Term.RANDOM_WALK, 0.0)),
        terms=frozenset(terms), floor=math.nan, floor_tau=math.nan,
        walk_bound=walk_bound, notes=tuple(dict.fromkeys(notes)),
    )
    floor, floor_tau = _floor(fit, t)
    fit = dataclasses.replace(fit, floor=floor, floor_tau=floor_tau)
    edf_all = _edf_of_model(tau, m_all, samples, axes, np.maximum(fit.avar(tau), 1e-300))
    return fit, edf_all


def _floor(fit: NoiseFit, t: np.ndarray) -> tuple[float, float]:
    """The flat part of the fitted curve: its first local minimum, or else its flattest point
    if the slope there is above ``FLOOR_SLOPE``; NaN when the curve has no flat part."""
    tau = np.logspace(math.log10(t[0]), math.log10(t[-1]), 400)
    adev = np.sqrt(fit.avar(tau))
    slope = np.gradient(np.log(adev), np.log(tau))
    rising = np.flatnonzero((slope[:-1] < 0.0) & (slope[1:] >= 0.0))
    k = int(rising[0]) if rising.size else int(np.argmax(slope))
    if not rising.size and slope[k] < FLOOR_SLOPE:
        return math.nan, math.nan
    return float(adev[k]), float(tau[k])


def _gm_supported(coef: dict[Term, float], T: float, t: np.ndarray, se: np.ndarray,
                  rng_: _Range, notes: list[str]) -> bool:
    """Whether a fitted Gauss-Markov hump lies in the resolvable range and is detected; a
    note says why not."""
    sigma2 = coef.get(Term.GAUSS_MARKOV, 0.0)
    z = _rises(gm_avar(t, math.sqrt(sigma2), T), se) if sigma2 > 0.0 else 0.0
    if z < DETECTION_Z:
        notes.append(f"bias instability: not detected (no Gauss-Markov hump rises "
                     f"{DETECTION_Z:g} standard errors above the other terms)")
        return False
    peak = GM_PEAK_X * T
    if peak > rng_.peak_max:
        notes.append(
            f"bias instability: not resolved: the curve still rises at tau = {t[-1]:.4g} s "
            f"(a record this long resolves correlation times up to "
            f"{rng_.peak_max / GM_PEAK_X:.4g} s; a slower bias shows as a random walk)")
        return False
    if peak < rng_.peak_min:
        notes.append(f"bias instability: its hump lies below tau = {rng_.peak_min:.3g} s, "
                     "where the fit cannot tell it from white noise")
        return False
    return True


def _rises(term: np.ndarray, se: np.ndarray) -> float:
    """By how many standard errors of the Allan variance a term rises above the others, at
    the tau where it rises most."""
    return float(np.max(term / se))


# --------------------------------------------------------------------------------------------
# one triad


def triad_curves(samples: np.ndarray, rate: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cluster times and the Allan variance of each axis.

    Parameters
    ----------
    samples : ndarray, shape (N, 3)
    rate : float
        [Hz].

    Returns
    -------
    tau : ndarray, shape (K,)
    avar : ndarray, shape (3, K)
    m : ndarray of int, shape (K,)
    """
    m = cluster_sizes(samples.shape[0])
    avar = np.stack([overlapping_avar(samples[:, i], rate, m) for i in range(3)])
    return m / rate, avar, m


def analyse_triad(samples: np.ndarray, rate: float, *, bootstrap: int = 40,
                  rng: np.random.Generator | None = None) -> TriadAnalysis:
    """Allan deviation of a still triad and the noise terms fitted to it.

    Parameters
    ----------
    samples : ndarray, shape (N, 3)
        Rate samples (interval means) of the three axes [unit], uniformly spaced.
    rate : float
        Sample rate [Hz].
    bootstrap : int
        Synthetic records for the parameter intervals (0: none).
    rng : numpy.random.Generator, optional
        Source of the bootstrap records (seed 0 when omitted: the analysis is a pure function
        of its inputs).

    Returns
    -------
    TriadAnalysis

    Raises
    ------
    AllanError
        The record is too short for any fit.
    """
    samples = np.asarray(samples, dtype=float)
    if samples.ndim != 2 or samples.shape[1] != 3:
        raise ValueError(f"samples must have shape (N, 3), got {samples.shape}")
    n = samples.shape[0]
    tau, avar, _ = triad_curves(samples, rate)
    fit, edf = fit_noise(tau, avar.mean(axis=0), rate, n, axes=3)
    curve = _curve(tau, avar.mean(axis=0), edf)
    axis_fits, axes = [], []
    for i in range(3):
        f_i, edf_i = fit_noise(tau, avar[i], rate, n, axes=1)
        axis_fits.append(f_i)
        axes.append(_curve(tau, avar[i], edf_i))
    intervals = {}
    if bootstrap > 0:
        intervals = _bootstrap(fit, rate, n, bootstrap,
                               rng if rng is not None else np.random.default_rng(0))
    return TriadAnalysis(rate=rate, samples=n, axes=(axes[0], axes[1], axes[2]),
                         axis_fits=(axis_fits[0], axis_fits[1], axis_fits[2]),
                         curve=curve, fit=fit, intervals=intervals, bootstrap=bootstrap)


def _curve(tau: np.ndarray, avar: np.ndarray, edf: np.ndarray) -> AllanCurve:
    adev = np.sqrt(avar)
    lo, hi = chi2_interval(adev, edf)
    return AllanCurve(tau=tau, adev=adev, edf=edf, lo=lo, hi=hi)


def simulate_terms(fit: NoiseFit, n: int, dt: float, rng: np.random.Generator) -> np.ndarray:
    """A synthetic triad record of the fitted terms: ``n`` interval means at ``dt`` [s].

    Returns
    -------
    ndarray, shape (n, 3)
    """
    out = rng.standard_normal((n, 3)) * (fit.white / math.sqrt(dt))
    if Term.GAUSS_MARKOV in fit.terms:
        out += gauss_markov(n, dt, fit.gm_sigma, fit.gm_tau, rng)
    if Term.RANDOM_WALK in fit.terms:
        out += random_walk(n, dt, fit.walk, rng)
    return out


def _bootstrap(fit: NoiseFit, rate: float, n: int, count: int, rng: np.random.Generator
               ) -> dict[str, tuple[float, float]]:
    """Percentile intervals of the fitted parameters over synthetic records of the fit."""
    step = max(1, math.ceil(n / BOOTSTRAP_MAX_SAMPLES))
    rate_b, n_b = rate / step, n // step
    draws: list[dict[str, float]] = []
    for _ in range(count):
        y = simulate_terms(fit, n_b, 1.0 / rate_b, rng)
        tau, avar, _ = triad_curves(y, rate_b)
        try:
            f, _ = fit_noise(tau, avar.mean(axis=0), rate_b, n_b, axes=3)
        except AllanError:
            continue
        draws.append(f.values())
    q = ((1.0 - CONFIDENCE) / 2.0 * 100.0, (1.0 + CONFIDENCE) / 2.0 * 100.0)
    out = {}
    for key, value in fit.values().items():
        if not (value > 0.0):  # not reported
            continue
        got = np.array([d[key] for d in draws])
        got = np.where(np.isnan(got), np.inf if key == "gm_tau" else 0.0, got)
        lo, hi = np.percentile(got, q, method="inverted_cdf")
        out[key] = (float(lo), float(hi))
    return out


# --------------------------------------------------------------------------------------------
# is the segment still?

STILL_BLOCK = 1.0
"""Block over which the still checks average [s] (at least ten samples)."""
STILL_GRAVITY = 0.05
"""Largest relative difference of the mean specific force's norm from standard gravity."""
STILL_ACCEL = 0.05
"""Largest change of a block's mean specific force from the start's, per axis, beyond
five times its white noise [m/s^2] (a tilt of 0.3 deg)."""
STILL_RATE = math.radians(0.05)
"""Largest change of a block's mean angular rate from the start's, per axis, beyond
five times its white noise [rad/s] (0.05 deg/s, 180 deg/h)."""
STILL_MEAN_RATE = math.radians(1.0)
"""Largest mean angular rate beyond the earth rate [rad/s]: a larger one is a turning
platform, not a gyro bias (1 deg/s)."""
EARTH_RATE = 7.292115e-5
"""[rad/s]."""
G0 = 9.80665


def motion(f_b: np.ndarray, omega_ib_b: np.ndarray | None, rate: float
           ) -> tuple[float, str] | None:
    """Where a segment is not still, or None when it is.

    Parameters
    ----------
    f_b : ndarray, shape (N, 3)
        Specific force [m/s^2].
    omega_ib_b : ndarray, shape (N, 3) or None
        Angular rate [rad/s].
    rate : float
        [Hz].

    Returns
    -------
    (t, what) or None
        Time of the first offending block from the segment start [s] and a description.
    """
    per = max(10, int(round(STILL_BLOCK * rate)))
    blocks = f_b.shape[0] // per
    f_mean = f_b.mean(axis=0)
    g = float(np.linalg.norm(f_mean))
    if abs(g - G0) > STILL_GRAVITY * G0:
        return 0.0, (f"the specific force averages {g:.3f} m/s^2, not gravity ({G0:.2f} "
                     f"+- {STILL_GRAVITY:.0%}): not a still accelerometer in m/s^2")
    checks = [(f_b, STILL_ACCEL, "specific force", "m/s^2", 1.0)]
    if omega_ib_b is not None:
        checks.append((omega_ib_b, STILL_RATE, "angular rate", "deg/s", math.degrees(1.0)))
    for x, limit, what, unit, scale in checks if blocks >= 2 else ():
        means = x[: blocks * per].reshape(blocks, per, 3).mean(axis=1)
        # white noise of a block mean from the sample-to-sample differences (motion is slow)
        noise = np.std(np.diff(x[: blocks * per], axis=0), axis=0) / math.sqrt(2.0 * per)
        # changes from the start (the median of the first blocks: a bump in one is seen)
        dev = np.abs(means - np.median(means[:5], axis=0))
        bad = np.flatnonzero((dev > limit + 5.0 * noise).any(axis=1))
        if bad.size:
            k = int(bad[0])
            return k * per / rate, (
                f"the {what} of the {STILL_BLOCK:g}-s block changes by "
                f"{dev[k].max() * scale:.3g} {unit} from the segment's start (limit "
                f"{limit * scale:.3g} {unit} + 5 sigma of its noise): the IMU moves")
    if omega_ib_b is not None:
        w = float(np.linalg.norm(omega_ib_b.mean(axis=0)))
        if w > EARTH_RATE + STILL_MEAN_RATE:
            return 0.0, (f"the angular rate averages {math.degrees(w):.3f} deg/s, more than "
                         f"the earth rate and a gyro bias ({math.degrees(STILL_MEAN_RATE):g} "
                         "deg/s): a turning platform")
    return None
