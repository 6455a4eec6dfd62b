"""Kalman filter math shared by every filter: discretisation, prediction, correction, checks.

Everything here is a pure function of arrays. State vectors have shape (n,), covariances
(n, n), measurement matrices (m, n); column vectors (n, 1) are rejected.

Models
------
Continuous error dynamics and their discrete form over a step dt::

    dx/dt = F x + G w,        E[w w^T] = Qc delta(t - s)                       (1)
    x_k+1 = Phi x_k + w_k,    E[w_k w_k^T] = Qd                                 (2)
    Phi   = I + F dt + (F dt)^2 / 2              (second-order series)          (3)
    Qd    = G Qc G^T dt                          (rectangular rule)             (4)
    Qd    = Phi B12,  [[B11, B12], [0, B22]] = expm([[-F, G Qc G^T], [0, F^T]] dt)
                                                 (Van Loan, exact for constant F) (5)

First-order Markov (Gauss-Markov) states, ``x_i' = -x_i / tau_i + w_i`` with ``E[w_i^2] = q_i``
(``q_i = 2 sigma_i^2 / tau_i`` for a stationary sigma) and no other state in their rows or
columns of F, have the exact transition and noise::

    Phi_ii = a_i = exp(-dt / tau_i),   Qd_ii = q_i tau_i (1 - a_i^2) / 2 = sigma_i^2 (1 - a_i^2)
                                                                                 (5a)

Prediction and correction (Joseph form, valid for any gain, hence for frozen states)::

    x^- = Phi x,   P^- = Phi P Phi^T + Qd                                        (6)
    nu  = z - H x                                 innovation                     (7)
    S   = H P H^T + R = L L^T                     Cholesky factor, no inverse    (8)
    K^T = L^-T L^-1 H P                           two triangular solves          (9)
    K[frozen, :] = 0                              frozen states keep x, P block  (10)
    x+  = x + K nu                                                               (11)
    P+  = (I - K H) P (I - K H)^T + K R K^T       Joseph form                    (12)
    NIS = nu^T S^-1 nu = |L^-1 nu|^2,  L^-1 nu is the normalised innovation      (13)

Checks
------
Inputs are checked for shape, finiteness, symmetry and positive semi-definiteness; a
failure raises (:class:`FilterDivergedError` for a covariance that lost its meaning, naming the
time when the caller passes it), never repairs. The checks work on the correlation form
``D^-1/2 P D^-1/2`` (D = diag P), so a relative tolerance means the same for states of very
different units (radians of latitude next to metres per second). States with zero variance
(inert or frozen states) are allowed: P must be PSD, not PD. Outputs of (6) and (12) are
symmetrised to remove rounding-level asymmetry of the matrix products, then checked.

Stacks of filters
-----------------
:func:`predict_batch` and :func:`correct_batch` apply (6) and (7)-(13) to many independent
filters at once (leading axes, e.g. the runs of a Monte Carlo campaign), vectorised across the
stack; their checks are lighter (finiteness, and positive definiteness through the Cholesky
factors of S and of the corrected P).

Examples
--------
Scalar random constant, measured once with unit noise:

>>> import numpy as np
>>> c = correct(np.zeros(1), np.eye(1), np.array([2.0]), np.eye(1), np.eye(1))
>>> c.x, c.P, round(c.nis, 12)
(array([1.]), array([[0.5]]), 2.0)
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navreplay.core.jit import kernel
from navreplay.core.lti import discrete_noise, discretize, van_loan  # noqa: F401  (part of this API)
from navreplay.filters.base import Innovation

DEFAULT_RTOL = 1e-9
"""Default relative tolerance of the symmetry and PSD checks (on the correlation form)."""


class FilterDivergedError(RuntimeError):
    """A covariance that is not symmetric positive semi-definite (or not finite).

    Attributes
    ----------
    t : float | None
        Filter time [s] of the failure, when known.
    """

    def __init__(self, message: str, t: float | None = None) -> None:
        self.t = t
        super().__init__(message if t is None else f"t = {t:.6f} s: {message}")


class Measurement(NamedTuple):
    """A linearised measurement, the shape every measurement model returns.

    ``z ~ H x + v``, ``v ~ N(0, R)``. For an error-state filter after feedback (x = 0), z is
    the innovation itself (e.g. INS minus GPS). Apply it with ``correct(x, P, *measurement)``.

    Attributes
    ----------
    z : ndarray, shape (m,)
        Measurement or residual.
    H : ndarray, shape (m, n)
        Measurement matrix.
    R : ndarray, shape (m,) or (m, m)
        Noise covariance (a diagonal as a vector).
    """

    z: np.ndarray
    H: np.ndarray
    R: np.ndarray


class Correction(NamedTuple):
    """Result of :func:`correct`.

    Attributes
    ----------
    x : ndarray, shape (n,)
        Corrected state.
    P : ndarray, shape (n, n)
        Corrected covariance.
    nis : float
        Normalised innovation squared ``nu^T S^-1 nu``; chi-square with m dof when consistent.
    nu : ndarray, shape (m,)
        Innovation ``z - H x``.
    S : ndarray, shape (m, m)
        Innovation covariance ``H P H^T + R``.
    nu_normalised : ndarray, shape (m,)
        ``L^-1 nu`` with ``S = L L^T``: unit-covariance white noise when consistent.
    """

    x: np.ndarray
    P: np.ndarray
    nis: float
    nu: np.ndarray
    S: np.ndarray
    nu_normalised: np.ndarray

    def innovation(self, name: str, t: float, rows: slice = slice(None)) -> Innovation:
        """The record a filter returns from ``update``: innovation and its covariance (of
        the rows ``rows`` of a stacked measurement)."""
        return Innovation(name, t, self.nu[rows], self.S[rows, rows])


# --------------------------------------------------------------------------------------------
# checks


@kernel
def _covariance_ok(P: np.ndarray, rtol: float) -> bool:
    """Fast path of :func:`check_covariance`: True when all its checks pass."""
    n = P.shape[0]
    if rtol < 0.0:  # no asymmetry is within a negative tolerance
        return n == 0
    s = np.empty(n)
    for i in range(n):
        d = P[i, i]
        if not (np.isfinite(d) and d >= 0.0):
            return False
        s[i] = np.sqrt(d) if d > 0.0 else 1.0
    # Cholesky of the correlation form plus rtol I column by column, checking symmetry on
    # the way (the diagonal and an entry equal to its mirror need no second division)
    L = np.empty((n, n))  # (only its lower triangle, written before it is read)
    for j in range(n):
        sj = s[j]
        c = P[j, j] / (sj * sj)
        if not np.isfinite(c):
            return False
        c += rtol
        for k in range(j):
            c -= L[j, k] * L[j, k]
        if c <= 0.0:
            return False
        ljj = np.sqrt(c)
        L[j, j] = ljj
        for i in range(j + 1, n):
            d = s[i] * sj
            c = P[i, j] / d
            if not np.isfinite(c) or (P[j, i] != P[i, j] and abs(c - P[j, i] / d) > rtol):
                return False
            for k in range(j):
                c -= L[i, k] * L[j, k]
            L[i, j] = c / ljj
    return True


def check_covariance(
    P: np.ndarray,
    *,
    name: str = "P",
    t: float | None = None,
    rtol: float = DEFAULT_RTOL,
) -> None:
    """Raise unless P is a finite, symmetric, positive semi-definite square matrix.

    Parameters
    ----------
    P : ndarray, shape (n, n)
        Covariance to check.
    name : str
        Name used in the message (``"P"``, ``"R"``, ``"S"``, ...).
    t : float, optional
        Filter time [s], reported in the error.
    rtol : float
        Tolerance on the correlation form ``D^-1/2 P D^-1/2`` (D = diag P; zero diagonal
        entries are scaled by 1): asymmetry above ``rtol`` or an eigenvalue below ``-rtol``
        fails.

    Raises
    ------
    ValueError
        P is not a square 2-D array.
    FilterDivergedError
        P has non-finite entries, a negative variance, or is not symmetric / PSD.
    """
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {P.shape}")
    if P.dtype == np.float64 and _covariance_ok(P, rtol):
        return
    # slow path: find what is wrong and say so
    if not np.all(np.isfinite(P)):
        raise FilterDivergedError(f"{name} has non-finite entries", t)
    d = np.diagonal(P)
    if np.any(d < 0.0):
        i = int(np.argmin(d))
        raise FilterDivergedError(f"{name}[{i},{i}] = {d[i]:.3e} is a negative variance", t)
    s = np.sqrt(d)
    s[s == 0.0] = 1.0
    C = P / s[:, None] / s[None, :]
    asym = np.abs(C - C.T)
    if asym.max(initial=0.0) > rtol:
        i, j = (int(v) for v in np.unravel_index(int(np.argmax(asym)), asym.shape))
        raise FilterDivergedError(
            f"{name} is not symmetric: {name}[{i},{j}] = {P[i, j]:.6e} vs "
            f"{name}[{j},{i}] = {P[j, i]:.6e}",
            t,
        )
    w = np.linalg.eigvalsh(0.5 * (C + C.T))
    if P.dtype == np.float64 or w[0] < -rtol:
        raise FilterDivergedError(
            f"{name} is not positive semi-definite: smallest eigenvalue of its correlation "
            f"form is {w[0]:.3e} (tolerance -{rtol:.1e})",
            t,
        )


def _check_matrix(a: np.ndarray, shape: tuple[int, ...], name: str) -> None:
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _finite(a: np.ndarray, name: str, t: float | None) -> None:
    if not np.isfinite(a).all():
        raise FilterDivergedError(f"{name} has non-finite entries", t)


# --------------------------------------------------------------------------------------------
# predict / correct


@kernel(inline="always")
def transition_rows_kernel(F: np.ndarray, r: int, dt: float, M: np.ndarray) -> None:
    """Eq. (3) compiled for an F that is zero outside its first r rows: those rows of Phi.

    F (>= r, nc) holds the non-zero columns of F, the first r of them being states 0..r-1 (the
    other rows of F, if any, are ignored: zero); M (r, nc) receives rows 0..r-1 of Phi over the
    same columns. The other rows of Phi are those of the identity.
    """
    nc = F.shape[1]
    h = 0.5 * dt * dt
    for i in range(r):  # (F dt)^2 [0:r, :] = F[0:r, 0:r] F[0:r, :] dt^2, row i summed over k
        for j in range(nc):  # in M[i] (exact zeros of F skipped: the same sums)
            M[i, j] = 0.0
        for k in range(r):
            a = F[i, k]
            if a != 0.0:
                for j in range(nc):
                    M[i, j] += a * F[k, j]
        for j in range(nc):
            M[i, j] = F[i, j] * dt + h * M[i, j]
        M[i, i] += 1.0


@kernel(inline="always")
def markov_rows_kernel(P: np.ndarray, rate: np.ndarray, q: np.ndarray, dt: float) -> None:
    """Eqs. (5a), (6) in place for the first-order Markov states of ``P``: those with
    ``rate[i] = 1 / tau_i > 0`` (the others are left as they are), whose rows and columns of
    F hold nothing else: ``P <- A P A + Qd``, A the identity but ``a_i`` on their diagonal, and
    ``Qd_ii = q_i (1 - a_i^2) / (2 rate_i)`` with ``q_i`` the density of their white noise.
    Applied after the prediction of the other states (the two transitions commute), it gives
    the prediction of the whole state."""
    n = P.shape[0]
    for i in range(n):
        b = rate[i]
        if b > 0.0:
            a = math.exp(-b * dt)
            for j in range(n):  # row and column i; the diagonal scaled twice: a^2
                P[i, j] *= a
                P[j, i] *= a
            P[i, i] += q[i] * -math.expm1(-2.0 * b * dt) / (2.0 * b)


def markov_transition(rate: np.ndarray, q: np.ndarray, dt: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The diagonal of Phi and of Qd of eq. (5a) over ``dt`` [s] for states of Markov rates
    ``rate`` [1/s] (n,) and white-noise densities ``q`` (n,); a state of rate 0 gets 1 and
    ``q dt`` (a random walk or a constant).

    A random walk and a Markov state of sigma 3 and tau 100 s, over 10^4 s (the latter forgets
    its start and reaches its stationary variance):

    >>> a, qd = markov_transition(np.array([0.0, 0.01]), np.array([2.0, 2 * 3.0**2 * 0.01]), 1e4)
    >>> a.round(6).tolist(), qd.round(6).tolist()
    ([1.0, 0.0], [20000.0, 9.0])
    """
    rate = np.asarray(rate, dtype=float)
    q = np.asarray(q, dtype=float)
    markov = rate > 0.0
    safe = np.where(markov, rate, 1.0)
    a = np.where(markov, np.exp(-safe * dt), 1.0)
    qd = np.where(markov, q * -np.expm1(-2.0 * safe * dt) / (2.0 * safe), q * dt)
    return a, qd


@kernel
def predict_kernel(P: np.ndarray, Phi: np.ndarray, Qd: np.ndarray) -> np.ndarray:
    """Eq. (6) compiled, dense: a new ``P = Phi P Phi^T + Qd``, symmetrised; no checks."""
    n = P.shape[0]
    T = np.empty((n, n))
    for i in range(n):  # T = Phi P
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += Phi[i, k] * P[k, j]
            T[i, j] = s
    out = np.empty((n, n))
    for i in range(n):  # T Phi^T, its lower triangle mirrored (P symmetric)
        for j in range(i + 1):
            s = 0.0
            for k in range(n):
                s += T[i, k] * Phi[j, k]
            v = s + 0.5 * (Qd[i, j] + Qd[j, i])
            out[i, j] = v
            out[j, i] = v
    return out


@kernel(inline="always")
def predict_rows_kernel(
    P: np.ndarray, M: np.ndarray, cols: np.ndarray, Qd: np.ndarray, T: np.ndarray
) -> np.ndarray:
    """Eq. (6) compiled for a Phi that is the identity but for its first r rows.

    ``Phi[0:r, cols] = M`` (r, nc) and ``Phi[0:r, other columns] = 0``, with ``cols[:r]`` =
    0..r-1 (the diagonal); rows r.. of Phi are those of the identity (random constants and
    random walks). Then only rows and columns 0..r-1 of ``Phi P Phi^T`` differ from P:
    ``T = M P[cols, :]`` gives them and ``T[:, cols] M^T`` their r x r block, at most
    ``r nc (n + r)`` products instead of ``2 n^3``: the products with an exact zero of M (the
    zero blocks of an error model) are skipped, which leaves every sum as it was for finite
    P. T (r, n) is scratch. Returns a new ``P = Phi P Phi^T + Qd``, symmetric; no checks.
    """
    n = P.shape[0]
    r, nc = M.shape
    for i in range(r):  # T = M P[cols, :], row i summed over k; exact zeros of M skipped
        for j in range(n):
            T[i, j] = 0.0
        for k in range(nc):
            a = M[i, k]
            if a != 0.0:
                p = cols[k]
                for j in range(n):
                    T[i, j] += a * P[p, j]
    out = np.empty((n, n))
    for i in range(n):
        for j in range(i + 1):
            if i < r:  # row block: j < i < r
                s = 0.0
                for k in range(nc):
                    b = M[j, k]
                    if b != 0.0:
                        s += T[i, cols[k]] * b
            elif j < r:
                s = T[j, i]
            else:
                s = 0.5 * (P[i, j] + P[j, i])
            v = s + 0.5 * (Qd[i, j] + Qd[j, i])
            out[i, j] = v
            out[j, i] = v
    return out


def predict(
    x: np.ndarray,
    P: np.ndarray,
    Phi: np.ndarray,
    Qd: np.ndarray,
    *,
    t: float | None = None,
    check: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Time update, eq. (6).

    Parameters
    ----------
    x : ndarray, shape (n,)
    P : ndarray, shape (n, n)
    Phi : ndarray, shape (n, n)
    Qd : ndarray, shape (n, n)
    t : float, optional
        Filter time [s] after the step, for error messages.
    check : bool
        Check the shapes and that the predicted P is symmetric PSD.

    Returns
    -------
    x, P : ndarray
        Predicted state (n,) and covariance (n, n).
    """
    n = x.shape[0]
    if check:
        if x.ndim != 1:
            raise ValueError(f"x must be a vector (n,), got shape {x.shape}")
        _check_matrix(P, (n, n), "P")
        _check_matrix(Phi, (n, n), "Phi")
        _check_matrix(Qd, (n, n), "Qd")
        _finite(Phi, "Phi", t)
    x = Phi @ x
    P = predict_kernel(_f64(P), _f64(Phi), _f64(Qd))
    if check:
        check_covariance(P, name="predicted P", t=t)
    return x, P


_NO_FROZEN = np.zeros(0, dtype=np.bool_)


@kernel
def _correct_kernel(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray,
    frozen: np.ndarray,
):
    """Eqs. (7)-(13) compiled; returns (x, P, nu, S, L^-1 nu, S positive definite).

    Plain loops over preallocated outputs: no temporaries per step, and a fraction of the
    compile time of numba's matrix products."""
    n = x.shape[0]
    m = z.shape[0]
    nu = np.empty(m)
    nu_w = np.empty(m)  # L^-1 nu, below
    HP = np.empty((m, n))
    W = np.empty((m, n))  # L^-1 H P, then K^T, below
    for i in range(m):  # (7) nu = z - H x, and H P
        acc = z[i]
        for k in range(n):
            acc -= H[i, k] * x[k]
        nu[i] = acc
        nu_w[i] = acc
        j = 0
        while j < n:  # (each sum over k in order, four of them at a time)
            if j + 4 <= n:
                a0 = a1 = a2 = a3 = 0.0
                for k in range(n):
                    h = H[i, k]
                    a0 += h * P[k, j]
                    a1 += h * P[k, j + 1]
                    a2 += h * P[k, j + 2]
                    a3 += h * P[k, j + 3]
                HP[i, j] = W[i, j] = a0
                HP[i, j + 1] = W[i, j + 1] = a1
                HP[i, j + 2] = W[i, j + 2] = a2
                HP[i, j + 3] = W[i, j + 3] = a3
                j += 4
            else:
                acc = 0.0
                for k in range(n):
                    acc += H[i, k] * P[k, j]
                HP[i, j] = W[i, j] = acc
                j += 1
    S = np.empty((m, m))
    for i in range(m):  # (8) S = H P H^T + R, symmetrised
        for j in range(i + 1):
            a = 0.0
            b = 0.0
            for k in range(n):
                a += HP[i, k] * H[j, k]
                b += HP[j, k] * H[i, k]
            v = 0.5 * ((a + R[i, j]) + (b + R[j, i]))
            S[i, j] = v
            S[j, i] = v
    L = np.zeros((m, m))  # (8) S = L L^T
    for j in range(m):
        for i in range(j, m):
            c = S[i, j]
            for k in range(j):
                c -= L[i, k] * L[j, k]
            if i == j:
                if not c > 0.0:
                    return x, P, nu, S, nu, False
                L[j, j] = np.sqrt(c)
            else:
                L[i, j] = c / L[j, j]
    # (9), (13): W = L^-1 [nu, H P] by forward substitution
    for i in range(m):
        for k in range(i):
            nu_w[i] -= L[i, k] * nu_w[k]
            for j in range(n):
                W[i, j] -= L[i, k] * W[k, j]
        nu_w[i] /= L[i, i]
        for j in range(n):
            W[i, j] /= L[i, i]
    # (9): K^T = L^-T W by back substitution, in place; (10) frozen rows of K are 0
    for i in range(m - 1, -1, -1):
        for k in range(i + 1, m):
            for j in range(n):
                W[i, j] -= L[k, i] * W[k, j]
        for j in range(n):
            W[i, j] /= L[i, i]
    for j in range(frozen.shape[0]):
        if frozen[j]:
            for i in range(m):
                W[i, j] = 0.0
    x_new = np.empty(n)  # (11) x + K nu
    for j in range(n):
        acc = x[j]
        for i in range(m):
            acc += W[i, j] * nu[i]
        x_new[j] = acc
    # (12) Joseph form P+ = A P A^T + K R K^T, A = I - K H, associated as
    # A P = P - K (H P) and (A P) A^T = A P - ((A P) H^T) K^T: O(n^2 m)
    AP = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            acc = P[i, j]
            for k in range(m):
                acc -= W[k, i] * HP[k, j]
            AP[i, j] = acc
    G = np.empty((n, m))  # (A P) H^T - K R
    for k in range(m):
        i = 0
        while i < n:  # (each sum over j in order, four of them at a time)
            if i + 4 <= n:
                a0 = a1 = a2 = a3 = 0.0
                for j in range(n):
                    h = H[k, j]
                    a0 += AP[i, j] * h
                    a1 += AP[i + 1, j] * h
                    a2 += AP[i + 2, j] * h
                    a3 += AP[i + 3, j] * h
                G[i, k] = a0
                G[i + 1, k] = a1
                G[i + 2, k] = a2
                G[i + 3, k] = a3
                i += 4
            else:
                acc = 0.0
                for j in range(n):
                    acc += AP[i, j] * H[k, j]
                G[i, k] = acc
                i += 1
    for i in range(n):
        for k in range(m):
            acc = G[i, k]
            for j in range(m):
                acc -= W[j, i] * R[j, k]
            G[i, k] = acc
    P_new = np.empty((n, n))
    for i in range(n):
        for j in range(i + 1):
            a = AP[i, j]
            b = AP[j, i]
            for k in range(m):
                a -= G[i, k] * W[k, j]
                b -= G[j, k] * W[k, i]
            v = 0.5 * (a + b)
            P_new[i, j] = v
            P_new[j, i] = v
    return x_new, P_new, nu, S, nu_w, True


def correct(
    x: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    *,
    frozen: np.ndarray | None = None,
    t: float | None = None,
    check: bool = True,
) -> Correction:
    """Measurement update with a Cholesky solve and the Joseph form, eqs. (7)-(13).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Prior state (zeros for an error-state filter after feedback).
    P : ndarray, shape (n, n)
        Prior covariance.
    z : ndarray, shape (m,)
        Measurement; the innovation is ``z - H x``.
    H : ndarray, shape (m, n)
        Measurement matrix.
    R : ndarray, shape (m, m) or (m,)
        Measurement noise covariance (a diagonal as a vector).
    frozen : ndarray of bool, shape (n,), optional
        States that the update must not change (Schmidt consider states): their gain rows are
        0, eq. (10), so their estimate and (by the Joseph form) their own covariance block stay
        as they were; their cross-covariance with the corrected states does change, as it must.
    t : float, optional
        Filter time [s], for error messages.
    check : bool
        Check shapes, finiteness, R and the posterior P. (S is checked by its Cholesky
        factorisation in any case.)

    Returns
    -------
    Correction
        ``(x, P, nis, nu, S, nu_normalised)``.

    Raises
    ------
    ValueError
        Inconsistent shapes.
    FilterDivergedError
        S not positive definite, or a non-finite / non-PSD result.
    """
    n = x.shape[0]
    m = z.shape[0]
    if R.ndim == 1:
        R = np.diag(R)
    if check:
        if x.ndim != 1 or z.ndim != 1:
            raise ValueError(
                f"x and z must be vectors (n,), (m,); got shapes {x.shape}, {z.shape}"
            )
        _check_matrix(P, (n, n), "P")
        _check_matrix(H, (m, n), "H")
        _check_matrix(R, (m, m), "R")
        _finite(z, "z", t)
        _finite(H, "H", t)
        check_covariance(R, name="R", t=t)
    if frozen is None:
        frozen = _NO_FROZEN
    else:
        frozen = np.asarray(frozen, dtype=np.bool_)
        if frozen.shape != (n,):
            raise ValueError(f"frozen must have shape ({n},), got {frozen.shape}")
    out = _correct_kernel(
        np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(P, dtype=np.float64),
        np.ascontiguousarray(z, dtype=np.float64), np.ascontiguousarray(H, dtype=np.float64),
        np.ascontiguousarray(R, dtype=np.float64), frozen,
    )
    x, P, nu, S, nu_w, ok = out
    if not ok:
        raise FilterDivergedError(
            f"innovation covariance S is not positive definite (diag {np.diagonal(S)})", t
        )
    if check:
        _finite(x, "corrected x", t)
        check_covariance(P, name="corrected P", t=t)
    nis = float(nu_w @ nu_w)  # (13)
    return Correction(x, P, nis, nu, S, nu_w)


# --------------------------------------------------------------------------------------------
# prediction and correction of a stack of independent filters (Monte Carlo fast paths)


def _mT(a: np.ndarray) -> np.ndarray:
    return np.swapaxes(a, -1, -2)


def _cholesky_batch(A: np.ndarray, name: str, t: float | None) -> np.ndarray:
    """Lower Cholesky factor of a stack of SPD matrices (..., n, n), column by column.

    Raises :class:`FilterDivergedError` if any matrix is not positive definite.
    """
    n = A.shape[-1]
    L = np.zeros_like(A)
    for j in range(n):
        Lj = L[..., j, :j]
        d = A[..., j, j] - np.einsum("...k,...k->...", Lj, Lj)
        if not np.all(d > 0.0):
            raise FilterDivergedError(f"{name} is not positive definite", t)
        L[..., j, j] = np.sqrt(d)
        if j + 1 < n:
            L[..., j + 1:, j] = (
                A[..., j + 1:, j] - np.einsum("...ik,...k->...i", L[..., j + 1:, :j], Lj)
            ) / L[..., j, j, None]
    return L


def _solve_lower_batch(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Forward substitution ``L X = B`` over a stack: L (..., n, n) lower, B (..., n, k).

    Vectorised across the stack, looping over the n rows (LAPACK's per-matrix call costs more
    than the arithmetic for small n).
    """
    X = np.empty(np.broadcast_shapes(L.shape[:-2], B.shape[:-2]) + B.shape[-2:])
    for i in range(L.shape[-1]):
        acc = B[..., i, :] - np.einsum("...j,...jk->...k", L[..., i, :i], X[..., :i, :])
        X[..., i, :] = acc / L[..., i, i, None]
    return X


def _solve_lower_T_batch(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Back substitution ``L^T X = B`` over a stack: L (..., n, n) lower, B (..., n, k)."""
    n = L.shape[-1]
    X = np.empty(np.broadcast_shapes(L.shape[:-2], B.shape[:-2]) + B.shape[-2:])
    for i in range(n - 1, -1, -1):
        acc = B[..., i, :] - np.einsum("...j,...jk->...k", L[..., i + 1:, i], X[..., i + 1:, :])
        X[..., i, :] = acc / L[..., i, i, None]
    return X


def predict_batch(
    x: np.ndarray, P: np.ndarray, Phi: np.ndarray, Qd: np.ndarray, *, t: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`predict` for a stack of independent filters (leading axes B...), eq. (6).

    Parameters
    ----------
    x : ndarray, shape (B..., n)
    P : ndarray, shape (B..., n, n)
    Phi, Qd : ndarray, shape (n, n) or (B..., n, n)
    t : float, optional
        Filter time [s] after the step, for error messages.

    Returns
    -------
    x, P : ndarray
        Predicted states and covariances (symmetrised). Only finiteness is checked here; the
        Cholesky factorisations of :func:`correct_batch` catch a covariance that lost its
        meaning.
    """
    x = (Phi @ x[..., None])[..., 0] if x.any() else np.zeros_like(x)  # error states: often 0
    P = Phi @ P @ _mT(Phi) + Qd
    P = 0.5 * (P + _mT(P))
    if not np.all(np.isfinite(P)):
        raise FilterDivergedError("non-finite predicted covariance", t)
    return x, P


def correct_batch(
    x: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    *,
    t: float | None = None,
) -> Correction:
    """:func:`correct` for a stack of independent filters (leading axes B...), vectorised.

    The same equations (7)-(13): Cholesky factor of S, two triangular solves for the gain, the
    Joseph form; the factorisation and the solves loop over the m rows and run across the
    stack. Checks: S and the corrected P positive definite (every state must keep a variance:
    stricter than :func:`check_covariance`), the result finite; there are no frozen states.

    Parameters
    ----------
    x : ndarray, shape (B..., n)
        Prior states.
    P : ndarray, shape (B..., n, n)
    z : ndarray, shape (B..., m)
    H : ndarray, shape (B..., m, n)
    R : ndarray, shape (B..., m, m) or (B..., m)
        Measurement noise covariances (diagonals as vectors).
    t : float, optional
        Filter time [s], for error messages.

    Returns
    -------
    Correction
        As :func:`correct`, each field with the leading axes B... (``nis`` an array).

    Raises
    ------
    FilterDivergedError
        Some S or corrected P is not positive definite, or a result is not finite.
    """
    n = P.shape[-1]
    m = H.shape[-2]
    diagonal_R = R.ndim == H.ndim - 1
    prior = bool(x.any())  # an error state after feedback is 0: skip its products
    nu = z - (H @ x[..., None])[..., 0] if prior else z.copy()  # (7)
    HP = H @ P
    S = HP @ _mT(H)  # (8)
    if diagonal_R:
        S[..., np.arange(m), np.arange(m)] += R
    else:
        S += R
    S = 0.5 * (S + _mT(S))
    L = _cholesky_batch(S, "innovation covariance S", t)  # (8)
    W = _solve_lower_batch(L, np.concatenate([nu[..., None], HP], axis=-1))  # (9), (13)
    nu_w = W[..., 0]
    K = _mT(_solve_lower_T_batch(L, W[..., 1:]))  # (9)
    dx = (K @ nu[..., None])[..., 0]  # (11)
    x = x + dx if prior else dx
    IKH = -K @ H  # (12)
    IKH[..., np.arange(n), np.arange(n)] += 1.0
    P = IKH @ P @ _mT(IKH)
    P += ((K * R[..., None, :]) if diagonal_R else (K @ R)) @ _mT(K)
    P = 0.5 * (P + _mT(P))
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
        raise FilterDivergedError("non-finite corrected state or covariance", t)
    _cholesky_batch(P, "corrected P", t)
    return Correction(x, P, np.einsum("...i,...i->...", nu_w, nu_w), nu, S, nu_w)  # (13)
