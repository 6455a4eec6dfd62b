"""Linear time-invariant stochastic systems: discretisation of ``dx/dt = F x + G w``.

Shared by the simulators (exact discretisation of Markov noise processes, e.g. hull flexure)
and the filters (transition and process-noise matrices). Equation numbers refer to the model
block of :mod:`navreplay.filters.kalman`::

    Phi = I + F dt + (F dt)^2 / 2                         (3)
    Qd  = G Qc G^T dt                                     (4)
    Qd  = Phi B12,  [[B11, B12], [0, B22]] = expm([[-F, G Qc G^T], [0, F^T]] dt)   (5)
"""

from __future__ import annotations

import numpy as np

from navreplay.core.jit import kernel


@kernel
def discretize(F: np.ndarray, dt: float) -> np.ndarray:
    """Transition matrix by the second-order series, eq. (3) (compiled: callable from Python
    and from the filters' numba kernels).

    Parameters
    ----------
    F : ndarray, shape (n, n)
        Continuous system matrix.
    dt : float
        Step [s].

    Returns
    -------
    Phi : ndarray, shape (n, n)
    """
    n = F.shape[0]
    h = 0.5 * dt * dt
    Phi = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += F[i, k] * F[k, j]
            Phi[i, j] = F[i, j] * dt + h * s
        Phi[i, i] += 1.0
    return Phi


def discrete_noise(G: np.ndarray, Qc: np.ndarray, dt: float) -> np.ndarray:
    """Discrete process noise ``Qd = G Qc G^T dt``, eq. (4).

    Parameters
    ----------
    G : ndarray, shape (n, p)
        Noise input matrix.
    Qc : ndarray, shape (p,) or (p, p)
        Continuous noise power spectral densities (a diagonal as a vector), units of
        ``w^2 s``.
    dt : float
        Step [s].

    Returns
    -------
    Qd : ndarray, shape (n, n)
    """
    if Qc.ndim == 1:
        GQ = G * Qc[None, :]
    else:
        GQ = G @ Qc
    Qd = GQ @ G.T
    Qd *= dt
    return Qd


def van_loan(
    F: np.ndarray, G: np.ndarray, Qc: np.ndarray, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretisation for constant F and white noise (Van Loan's method), eq. (5).

    Parameters
    ----------
    F : ndarray, shape (n, n)
    G : ndarray, shape (n, p)
    Qc : ndarray, shape (p,) or (p, p)
    dt : float

    Returns
    -------
    Phi : ndarray, shape (n, n)
        ``expm(F dt)``.
    Qd : ndarray, shape (n, n)
        ``integral_0^dt expm(F s) G Qc G^T expm(F s)^T ds``.
    """
    from scipy.linalg import expm

    n = F.shape[0]
    GQG = discrete_noise(G, Qc, 1.0)
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -F
    M[:n, n:] = GQG
    M[n:, n:] = F.T
    E = expm(M * dt)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    return Phi, 0.5 * (Qd + Qd.T)


def second_order_markov(
    sigma: float, zeta: float, wn: float, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Exact (Phi, Qd) of the stationary second-order Markov process ``s = [theta, theta']``::

        theta'' + 2 zeta wn theta' + wn^2 theta = w,   E[w w] = 4 zeta wn^3 sigma^2 delta

    whose steady-state covariance is ``diag(sigma^2, (wn sigma)^2)`` (e.g. hull flexure).

    Parameters
    ----------
    sigma : float
        Steady-state 1 sigma of theta.
    zeta, wn : float
        Damping ratio [-] and natural frequency [rad/s].
    dt : float
        Step [s].

    Returns
    -------
    Phi, Qd : ndarray, shape (2, 2)
    """
    F = np.array([[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]])
    G = np.array([[0.0], [1.0]])
    return van_loan(F, G, np.array([4.0 * zeta * wn**3 * sigma * sigma]), dt)
