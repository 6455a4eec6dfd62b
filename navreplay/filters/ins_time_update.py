"""The time update of an INS filter over the error model of :mod:`navreplay.filters.ins_error`.

``P <- Phi P Phi^T + Qd`` with ``Phi = I + F T + (F T)^2 / 2`` (kalman eqs. 3, 6) in compiled
loops that use the structure of F: it has non-zero rows only for position, velocity and
attitude and non-zero columns only for the 15 states here and the optional three of eq. (22)
(the states a larger filter adds are random constants or random walks), so only 9 rows and
columns of P change.
:func:`propagate_covariance` steps over given points, :func:`accumulate_covariance` collects
IMU samples into steps of a given length, and :class:`TimeUpdate` is the whole time update of
an INS filter over an IMU block (bias compensation, :mod:`navreplay.strapdown`, covariance) in
one compiled call; ``ins``, ``gps-ins`` and ``rpm-aided-ins`` use it.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np

from navreplay import strapdown
from navreplay.filters.ins_error import N_GYRO_Z, N_STATES, Vertical, fill_system_matrix
from navreplay.filters.kalman import FilterDivergedError, check_covariance
from navreplay.geo import kernels

N_NAV = 9
"""Rows of F that are not zero: position, velocity and attitude."""
_TIME_TOL = 1e-9
"""Slack [s] when comparing sample times with the time of the navigation solution."""


@numba.njit(cache=True)
def _covariance_step(
    P: np.ndarray, nav: np.ndarray, f_b: np.ndarray, omega_b: np.ndarray, dt: float,
    q: np.ndarray, k_acc: float, k_gyro: float, depth: bool, curvature: bool, gz: int,
    F: np.ndarray, M: np.ndarray, T: np.ndarray,
) -> np.ndarray:
    """One step of kalman eqs. (3), (4), (6) with F from eqs. (6)-(19), (22) and Qd from (20),
    (21); returns a new P.

    F has non-zero rows only for position, velocity and attitude and non-zero columns only for
    the 15 navigation states and, with ``gz >= 0``, the three gyro z-rate states at
    ``gz, gz + 1, gz + 2`` (eq. 22), so ``Phi = [[M], [0 I]]`` with M (9 x nc) its first 9 rows
    over those nc columns, and only the first 9 rows and columns of P change:
    ``T = M P[cols, :]`` gives the new rows and ``T[:, cols] M^T`` the new 9 x 9 block.
    F (15, nc), M (9, nc) and T (9, n) are scratch (nc = 15, or 18 with ``gz >= 0``).
    """
    n = P.shape[0]
    nc = F.shape[1]
    F[:, :] = 0.0
    C = kernels.quat_to_dcm(nav[6:10])
    fill_system_matrix(nav[0], nav[2], nav[3], nav[4], nav[5], C, f_b, depth, curvature, F)
    if gz >= 0:  # (22): F[phi, (dm_xz, dm_yz, ds_z)] = C_nb_hat[:, j] omega_z
        for i in range(3):
            for j in range(3):
                F[6 + i, N_STATES + j] = C[i, j] * omega_b[2]
    h = 0.5 * dt * dt
    for i in range(N_NAV):  # kalman (3): (F dt)^2 [0:9, :] = F[0:9, 0:9] F[0:9, :] dt^2
        for j in range(nc):
            s = 0.0
            for k in range(N_NAV):
                s += F[i, k] * F[k, j]
            M[i, j] = F[i, j] * dt + h * s
        M[i, i] += 1.0
    for i in range(N_NAV):  # kalman (6)
        for j in range(n):
            s = 0.0
            for k in range(nc):
                s += M[i, k] * P[k if k < N_STATES else gz + k - N_STATES, j]
            T[i, j] = s
    out = P.copy()
    for i in range(N_NAV):
        for j in range(i + 1):
            s = 0.0
            for k in range(nc):
                s += T[i, k if k < N_STATES else gz + k - N_STATES] * M[j, k]
            out[i, j] = s
            out[j, i] = s
        for j in range(N_NAV, n):
            out[i, j] = T[i, j]
            out[j, i] = T[i, j]
    for i in range(n):
        out[i, i] += q[i] * dt  # kalman (4), diagonal (20)
    if k_acc > 0.0:  # (21): |a_n|^2 = |C f_b + g_n|^2, g on the ellipsoid
        g = kernels.gravity(nav[0], 0.0)
        a2 = 0.0
        for i in range(3):
            a = C[i, 0] * f_b[0] + C[i, 1] * f_b[1] + C[i, 2] * f_b[2]
            if i == 2:
                a += g
            a2 += a * a
        for i in range(3, 6):
            out[i, i] += k_acc * a2 * dt
    if k_gyro > 0.0:  # (21): |omega_ib_b|^2
        w2 = omega_b[0] ** 2 + omega_b[1] ** 2 + omega_b[2] ** 2
        for i in range(6, 9):
            out[i, i] += k_gyro * w2 * dt
    return out


@numba.njit(cache=True)
def _scratch(n: int, gz: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """F, M, T of :func:`_covariance_step` for n states (gyro z-rate states at ``gz``, or
    none for -1) and the means of :func:`_close_step`."""
    nc = N_STATES + (N_GYRO_Z if gz >= 0 else 0)
    return (np.zeros((N_STATES, nc)), np.zeros((N_NAV, nc)), np.zeros((N_NAV, n)),
            np.zeros((2, 3)))


@numba.njit(cache=True)
def _propagate_covariance(
    P: np.ndarray, nav: np.ndarray, f_b: np.ndarray, omega_b: np.ndarray, dt: np.ndarray,
    q: np.ndarray, k_acc: float, k_gyro: float, depth: bool, curvature: bool, gz: int,
) -> np.ndarray:
    F, M, T, _ = _scratch(P.shape[0], gz)
    for k in range(dt.shape[0]):
        P = _covariance_step(P, nav[k], f_b[k], omega_b[k], dt[k], q, k_acc, k_gyro, depth,
                             curvature, gz, F, M, T)
    return P


@numba.njit(cache=True)
def _close_step(
    P: np.ndarray, q: np.ndarray, k_acc: float, k_gyro: float, depth: bool, curvature: bool,
    gz: int, open_nav: np.ndarray, open_sums: np.ndarray, F: np.ndarray, M: np.ndarray,
    T: np.ndarray, mean: np.ndarray,
) -> np.ndarray:
    """P propagated over the open step, with F at its start and the mean specific force and
    body rate over it; the step is then cleared (P itself when none is open)."""
    dt = open_sums[0]
    if dt <= 0.0:
        return P
    for j in range(3):
        mean[0, j] = open_sums[1 + j] / dt
        mean[1, j] = open_sums[4 + j] / dt
    P = _covariance_step(P, open_nav, mean[0], mean[1], dt, q, k_acc, k_gyro, depth, curvature,
                         gz, F, M, T)
    open_sums[:] = 0.0
    return P


@numba.njit(cache=True)
def _accumulate_covariance(
    P: np.ndarray, hist: np.ndarray, f_b: np.ndarray, omega_b: np.ndarray, dt: np.ndarray,
    step: float, q: np.ndarray, k_acc: float, k_gyro: float, depth: bool, curvature: bool,
    gz: int, open_nav: np.ndarray, open_sums: np.ndarray,
) -> np.ndarray:
    F, M, T, mean = _scratch(P.shape[0], gz)
    for k in range(dt.shape[0]):
        if open_sums[0] == 0.0:
            open_nav[:] = hist[k]
        open_sums[0] += dt[k]
        for j in range(3):
            open_sums[1 + j] += f_b[k, j] * dt[k]
            open_sums[4 + j] += omega_b[k, j] * dt[k]
        if open_sums[0] >= step - 1e-9:
            P = _close_step(P, q, k_acc, k_gyro, depth, curvature, gz, open_nav, open_sums, F, M,
                            T, mean)
    return P


@numba.njit(cache=True)
def _propagate_block(
    nav: np.ndarray, P: np.ndarray, t: np.ndarray, t_nav: float, omega: np.ndarray,
    f: np.ndarray, b_a: np.ndarray, b_g: np.ndarray, prev: np.ndarray, step: float,
    q: np.ndarray, k_acc: float, k_gyro: float, depth: bool, curvature: bool, gz: int,
    open_nav: np.ndarray, open_sums: np.ndarray,
) -> tuple[int, int, np.ndarray, np.ndarray]:
    """Bias compensation, strapdown and the covariance steps over the samples of a block after
    ``t_nav`` (the time of ``nav``).

    Returns (code, first, nav, P) with ``first`` the index of the first sample used and code -1
    when all went well; -4 when no sample is after ``t_nav``; -5 when P is not (n, n) with n
    the length of q; the strapdown's codes (the index of the first invalid sample from
    ``first`` on, -2 for a non-finite state) with nav and P unchanged; -3 when the propagated P
    (returned for the message) has a negative or non-finite variance.
    """
    if P.shape[0] != q.shape[0] or P.shape[1] != q.shape[0]:
        return -5, 0, nav, P
    first = 0
    while first < t.shape[0] and t[first] <= t_nav + _TIME_TOL:
        first += 1
    k = t.shape[0] - first
    if k == 0:
        return -4, first, nav, P
    dt = np.empty(k)
    w = np.empty((k, 3))
    fc = np.empty((k, 3))
    t_prev = t_nav
    for i in range(k):
        dt[i] = t[first + i] - t_prev
        t_prev = t[first + i]
        for j in range(3):
            w[i, j] = omega[first + i, j] - b_g[j]
            fc[i, j] = f[first + i, j] - b_a[j]
    hist = np.empty((k + 1, strapdown.NAV_SIZE))
    code = strapdown.integrate_kernel(nav, w, fc, dt, prev, hist)
    if code != -1:
        return code, first, nav, P
    for j in range(3):  # the last sample's increments: coning and sculling of the next block
        prev[j] = w[k - 1, j] * dt[k - 1]
        prev[3 + j] = fc[k - 1, j] * dt[k - 1]
    P = _accumulate_covariance(P, hist, fc, w, dt, step, q, k_acc, k_gyro, depth, curvature,
                               gz, open_nav, open_sums)
    for i in range(P.shape[0]):
        if not (P[i, i] >= 0.0 and math.isfinite(P[i, i])):
            return -3, first, nav, P
    return code, first, hist[k].copy(), P


@dataclasses.dataclass(frozen=True)
class ProcessNoise:
    """Process noise of the covariance propagation, per second.

    Attributes
    ----------
    q : ndarray, shape (n,)
        Diagonal of ``G Qc G^T`` (isotropic triad noise, :func:`process_noise_diagonal` with
        dt = 1), units of state^2/s; entries beyond 15 belong to a larger filter's states.
    k_acc : float
        Velocity noise per unit squared acceleration, eq. (21) [(m/s)^2/s per (m/s^2)^2 = s].
    k_gyro : float
        Attitude noise per unit squared body rate, eq. (21) [rad^2/s per (rad/s)^2 = s].
    """

    q: np.ndarray
    k_acc: float = 0.0
    k_gyro: float = 0.0
    gyro_z_states: int = -1
    """Index of the first of the three gyro z-rate error states (dm_xz, dm_yz, ds_z) of
    eq. (22), which a larger filter places after the 15; -1: none."""

    def __post_init__(self) -> None:
        q = np.ascontiguousarray(self.q, dtype=np.float64)
        if q.ndim != 1 or not np.all(np.isfinite(q)) or np.any(q < 0.0):
            raise ValueError(f"process noise q must be a vector of values >= 0, got {q}")
        gz = self.gyro_z_states
        if not (gz == -1 or N_STATES <= gz <= q.shape[0] - N_GYRO_Z):
            raise ValueError(
                f"gyro_z_states must be -1 or an index in 15..{q.shape[0] - N_GYRO_Z} (three "
                f"states within the {q.shape[0]}), got {gz!r}"
            )
        object.__setattr__(self, "gyro_z_states", int(gz))
        for name in ("k_acc", "k_gyro"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        object.__setattr__(self, "q", q)

    @staticmethod
    def motion_coefficient(sigma: float, correlation_time: float) -> float:
        """``k = sigma^2 tau`` of eq. (21) for scale-factor / misalignment errors of 1-sigma
        ``sigma`` [-, rad] treated as white over ``correlation_time`` [s]."""
        return sigma * sigma * correlation_time


class OpenStep:
    """The covariance step in progress: its start state and the sums over its IMU samples.

    Attributes
    ----------
    nav : ndarray, shape (10,)
        Navigation vector at the start of the step (valid while ``dt > 0``).
    sums : ndarray, shape (7,)
        Length of the step so far [s], the integral of the specific force over it [m/s, body]
        and of the body rate [rad].
    """

    def __init__(self) -> None:
        self.nav = np.zeros(10)
        self.sums = np.zeros(7)

    @property
    def dt(self) -> float:
        """Length of the open step [s] (0: none open)."""
        return float(self.sums[0])


def _model_args(
    shape: tuple[int, ...], noise: ProcessNoise, vertical: Vertical, curvature_derivatives: bool
) -> tuple[np.ndarray, float, float, bool, bool, int]:
    """Check the shape of P against the model; the arguments the compiled kernels take."""
    n = noise.q.shape[0]
    if shape != (n, n) or n < N_STATES:
        raise ValueError(
            f"P must be (n, n) with n >= 15 the length of the process noise ({n}), got {shape}"
        )
    return (noise.q, noise.k_acc, noise.k_gyro, vertical is Vertical.DEPTH,
            bool(curvature_derivatives), noise.gyro_z_states)


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def propagate_covariance(
    P: np.ndarray,
    nav: np.ndarray,
    f_b: np.ndarray,
    omega_b: np.ndarray,
    dt: np.ndarray,
    noise: ProcessNoise,
    *,
    vertical: Vertical = Vertical.HEIGHT,
    curvature_derivatives: bool = True,
) -> np.ndarray:
    """Covariance propagation over k steps of a filter whose first 15 states are these.

    The same as k calls of ``kalman.predict`` with ``Phi = kalman.discretize(F, dt)``
    (``F = system_matrix(...)`` in the top-left block, ``gyro_z_rate_matrix(C_nb, omega_z)``
    in the attitude rows of the gyro z-rate states when ``noise.gyro_z_states`` is set, 0
    elsewhere: extra states are random constants or random walks) and ``Qd`` of eqs.
    (20)-(21), compiled into one loop that
    exploits the structure of F (only the rows and columns of the 9 navigation errors change).
    The result is symmetric but not checked: check it with ``kalman.check_covariance``.

    Parameters
    ----------
    P : ndarray, shape (n, n), n >= 15
        Covariance at the start.
    nav : ndarray, shape (k, 10)
        Navigation vector at which F is evaluated for each step.
    f_b : ndarray, shape (k, 3)
        Bias-compensated mean specific force of each step, body [m/s^2].
    omega_b : ndarray, shape (k, 3)
        Bias-compensated mean body rate of each step [rad/s] (for eq. 21).
    dt : ndarray, shape (k,)
        Step lengths [s].
    noise : ProcessNoise
    vertical : Vertical
    curvature_derivatives : bool
        As :func:`system_matrix`.

    Returns
    -------
    P : ndarray, shape (n, n)
    """
    args = _model_args(P.shape, noise, vertical, curvature_derivatives)
    k = dt.shape[0]
    if nav.shape != (k, 10) or f_b.shape != (k, 3) or omega_b.shape != (k, 3):
        raise ValueError(
            f"nav must be ({k}, 10), f_b and omega_b ({k}, 3) for {k} steps; got {nav.shape}, "
            f"{f_b.shape}, {omega_b.shape}"
        )
    return _propagate_covariance(_f64(P), _f64(nav), _f64(f_b), _f64(omega_b), _f64(dt), *args)


def accumulate_covariance(
    P: np.ndarray,
    hist: np.ndarray,
    f_b: np.ndarray,
    omega_b: np.ndarray,
    dt: np.ndarray,
    step: float,
    noise: ProcessNoise,
    open_step: OpenStep,
    *,
    vertical: Vertical = Vertical.HEIGHT,
    curvature_derivatives: bool = True,
) -> np.ndarray:
    """Propagate P over IMU samples in steps of length ``step`` (compiled loop).

    Samples are collected into the open step; when it reaches ``step`` seconds, P is
    propagated over it as in :func:`propagate_covariance`, with F at the navigation state at the
    start of the step and the mean specific force and body rate over it. A step still open at
    the end stays in ``open_step`` (updated in place) for the next call; close it early with
    :func:`close_step`.

    Parameters
    ----------
    P : ndarray, shape (n, n), n >= 15
    hist : ndarray, shape (k + 1, 10)
        Navigation states at the start of each sample and after the last (the output of
        :func:`navreplay.strapdown.integrate`).
    f_b : ndarray, shape (k, 3)
        Bias-compensated specific force of each sample, body [m/s^2].
    omega_b : ndarray, shape (k, 3)
        Bias-compensated body rate of each sample [rad/s].
    dt : ndarray, shape (k,)
        Sample intervals [s].
    step : float
        Step length [s].
    noise : ProcessNoise
    open_step : OpenStep
        The step carried over from the previous call; updated in place.
    vertical : Vertical
    curvature_derivatives : bool

    Returns
    -------
    P : ndarray, shape (n, n)
        Symmetric, not checked.
    """
    q, k_acc, k_gyro, depth, curvature, gz = _model_args(P.shape, noise, vertical,
                                                         curvature_derivatives)
    k = dt.shape[0]
    if hist.shape != (k + 1, 10) or f_b.shape != (k, 3) or omega_b.shape != (k, 3):
        raise ValueError(
            f"hist must be ({k + 1}, 10), f_b and omega_b ({k}, 3); got {hist.shape}, "
            f"{f_b.shape}, {omega_b.shape}"
        )
    return _accumulate_covariance(
        _f64(P), _f64(hist), _f64(f_b), _f64(omega_b), _f64(dt), float(step), q, k_acc, k_gyro,
        depth, curvature, gz, open_step.nav, open_step.sums,
    )


def close_step(
    P: np.ndarray, noise: ProcessNoise, open_step: OpenStep, *,
    vertical: Vertical = Vertical.HEIGHT, curvature_derivatives: bool = True,
) -> np.ndarray:
    """Propagate P over the open step (if any) and clear it; P at the last sample's time."""
    model = _model_args(P.shape, noise, vertical, curvature_derivatives)
    return _close_step(_f64(P), *model, open_step.nav, open_step.sums,
                       *_scratch(P.shape[0], noise.gyro_z_states))


class TimeUpdate:
    """The time update of an INS filter: strapdown and covariance over blocks of IMU samples.

    Each :meth:`propagate` compensates the IMU with the bias estimates (``f_hat = f_b - b_a``,
    ``omega_hat = omega_ib_b - b_g``), integrates it with
    :func:`navreplay.strapdown.integrate_kernel` and propagates P as
    :func:`accumulate_covariance` does, in one compiled call. What carries over from one block
    to the next is kept here: the increments of the last sample (the coning and sculling terms
    of the next) and the open covariance step.

    Parameters
    ----------
    noise : ProcessNoise
        Its length fixes the number of states n (>= 15).
    step : float
        Covariance step [s].
    vertical : Vertical
    curvature_derivatives : bool
        As :func:`system_matrix`.
    """

    def __init__(
        self, noise: ProcessNoise, step: float, *, vertical: Vertical = Vertical.HEIGHT,
        curvature_derivatives: bool = True,
    ) -> None:
        n = noise.q.shape[0]
        self._shape = (n, n)
        self._model = _model_args(self._shape, noise, vertical, curvature_derivatives)
        self._work = _scratch(n, noise.gyro_z_states)  # of the compiled close
        self.step = float(step)
        self.prev = np.zeros(6)
        """Increments [dtheta, dv] of the last sample [rad, m/s]."""
        self.open_step = OpenStep()

    def propagate(
        self, nav: np.ndarray, P: np.ndarray, t_nav: float, t: np.ndarray,
        omega_ib_b: np.ndarray, f_b: np.ndarray, b_a: np.ndarray, b_g: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, float] | None:
        """Propagate over a block of IMU samples; samples at or before ``t_nav`` are skipped.

        Parameters
        ----------
        nav : ndarray, shape (10,)
            Navigation vector at ``t_nav`` [s].
        P : ndarray, shape (n, n)
        t_nav : float
        t : ndarray, shape (k,)
            Sample times [s], increasing.
        omega_ib_b, f_b : ndarray, shape (k, 3)
            Raw IMU samples [rad/s], [m/s^2].
        b_a, b_g : ndarray, shape (3,)
            Bias estimates [m/s^2], [rad/s].

        Returns
        -------
        (nav, P, t) or None
            The navigation vector (10,), P (n, n) (symmetric, variances checked, not yet
            checked for PSD) and the time [s] of the last sample; None when no sample is after
            ``t_nav``.

        Raises
        ------
        ValueError
            A sample that is not finite or not after the previous one.
        FilterDivergedError
            A non-finite navigation state or a negative or non-finite variance.
        """
        code, first, nav, P = _propagate_block(
            nav, P, t, t_nav, omega_ib_b, f_b, b_a, b_g, self.prev, self.step, *self._model,
            self.open_step.nav, self.open_step.sums,
        )
        if code == -1:
            return nav, P, float(t[-1])
        if code == -4:
            return None
        if code == -5:
            raise ValueError(f"P must be {self._shape} as the process noise, got {P.shape}")
        if code == -3:
            check_covariance(P, t=float(t[-1]))  # names what is wrong
            raise FilterDivergedError("P has a negative or non-finite variance", float(t[-1]))
        if code == -2:
            raise FilterDivergedError("navigation state is not finite", t_nav)
        i = first + code
        raise ValueError(
            f"IMU sample at t = {t[i]:.6f} s (previous {t[i - 1] if code else t_nav:.6f} s): "
            f"omega_ib_b = {omega_ib_b[i]}, f_b = {f_b[i]}: not finite, or the time does not "
            "increase"
        )

    def close(self, P: np.ndarray, t: float) -> np.ndarray:
        """P at the time t [s] of the last sample: propagated over the open covariance step,
        which is then cleared, and checked (:func:`navreplay.filters.kalman.check_covariance`);
        P itself when no step is open."""
        if self.open_step.sums[0] <= 0.0:
            return P
        if P.shape != self._shape:
            raise ValueError(f"P must be {self._shape} as the process noise, got {P.shape}")
        P = _close_step(P, *self._model, self.open_step.nav, self.open_step.sums, *self._work)
        check_covariance(P, t=t)
        return P
