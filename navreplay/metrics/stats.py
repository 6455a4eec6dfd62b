"""Statistics of errors and of chi-square quantities: RMS, CEP50, NEES, chi-square bounds.

Examples
--------
>>> import numpy as np
>>> round(chi2_bounds(3)[1], 3), [round(b, 3) for b in chi2_bounds(2, runs=50)]
(9.348, [1.484, 2.591])
>>> round(float(cep50(np.array([3.0, -4.0]), np.array([0.0, 0.0]))), 3)
2.081
"""

from __future__ import annotations

import numpy as np

from navreplay.core import chi2

CEP50_FACTOR = 0.5887
"""CEP50 = CEP50_FACTOR (LatRMS + LongRMS) (circular approximation for similar axes)."""


def chi2_bounds(dof: int, runs: int = 1, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided bounds of the mean over ``runs`` of a chi-square variable with ``dof`` dof.

    Parameters
    ----------
    dof : int
        Degrees of freedom of one sample (state or measurement dimension).
    runs : int
        Number of independent samples averaged (Monte Carlo runs, or epochs of a white
        sequence).
    probability : float
        Probability inside the bounds.

    Returns
    -------
    lo, hi : float
        ``chi2.ppf([(1 - p)/2, (1 + p)/2], runs dof) / runs``.
    """
    if dof < 1 or runs < 1:
        raise ValueError(f"dof and runs must be >= 1, got {dof}, {runs}")
    a = 0.5 * (1.0 - probability)
    k = runs * dof
    return chi2.ppf(a, k) / runs, chi2.ppf(1.0 - a, k) / runs


def rms(a: np.ndarray, axis: int | tuple[int, ...] | None = 0) -> np.ndarray:
    """Root mean square along ``axis`` (NaNs ignored)."""
    return np.sqrt(np.nanmean(np.square(a), axis=axis))


def cep50(north: np.ndarray, east: np.ndarray, axis: int = 0) -> np.ndarray:
    """CEP50 [m] of north and east errors [m] over runs (along ``axis``).

    ``0.5887 (LatRMS + LongRMS)`` with the RMS taken over the runs.
    """
    return CEP50_FACTOR * (rms(north, axis) + rms(east, axis))


def nees(e: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``e^T P^-1 e`` per epoch.

    Solved on the correlation form of P (robust to states of very different units); an epoch
    whose P is singular (a zero variance, or perfectly correlated states) gives NaN.

    Parameters
    ----------
    e : ndarray, shape (M, k)
        Estimation errors.
    P : ndarray, shape (M, k, k)
        Their covariances.

    Returns
    -------
    ndarray, shape (M,)
    """
    e = np.asarray(e, dtype=float)
    P = np.asarray(P, dtype=float)
    out = np.full(e.shape[0], np.nan)
    if e.shape[1] == 0:
        return out
    d = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
    ok = np.all(d > 0.0, axis=1) & np.all(np.isfinite(e), axis=1)
    if not ok.any():
        return out
    s = d[ok]
    en = e[ok] / s
    C = P[ok] / s[:, :, None] / s[:, None, :]
    try:
        L = np.linalg.cholesky(C)
        w = _forward(L, en)
        out[ok] = np.einsum("ki,ki->k", w, w)
    except np.linalg.LinAlgError:
        vals = np.empty(en.shape[0])
        for i in range(en.shape[0]):
            try:
                L = np.linalg.cholesky(C[i])
                w = np.linalg.solve(L, en[i])
                vals[i] = w @ w
            except np.linalg.LinAlgError:
                vals[i] = np.nan
        out[ok] = vals
    return out


def _forward(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``L^-1 b`` of lower-triangular ``L`` (M, k, k) and ``b`` (M, k) by forward substitution,
    a component at a time for all M (a general solve would factorise L again)."""
    w = np.empty_like(b)
    for i in range(b.shape[1]):
        w[:, i] = (b[:, i] - np.einsum("kj,kj->k", L[:, i, :i], w[:, :i])) / L[:, i, i]
    return w


def chi2_bounds_per_count(
    dof: int, count: np.ndarray, probability: float = 0.95
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`chi2_bounds` elementwise for means over ``count`` runs (NaN where the count is 0).

    Parameters
    ----------
    dof : int
    count : ndarray of int, shape (M,)
        Runs averaged at each index.
    probability : float

    Returns
    -------
    lo, hi : ndarray, shape (M,)
    """
    lo = np.full(count.shape, np.nan)
    hi = np.full(count.shape, np.nan)
    for c in np.unique(count[count > 0]):
        lo[count == c], hi[count == c] = chi2_bounds(dof, int(c), probability)
    return lo, hi
