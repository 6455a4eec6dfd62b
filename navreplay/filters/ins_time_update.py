"""The time update of an INS filter over the error model of :mod:`navreplay.filters.ins_error`.

``P <- Phi P Phi^T + Qd`` with ``Phi = I + F T + (F T)^2 / 2`` (kalman eqs. 3, 6) by the
compiled kernels of :mod:`navreplay.filters.kalman` for a Phi that is the identity but for a
few rows: F has non-zero rows only for position, velocity and attitude and non-zero columns
only for the 15 states here and the optional scale-factor and misalignment states of
eqs. (22), (23) (the states a larger filter adds are random constants, random walks or
first-order Markov processes, kalman eq. 5a), so only 9 rows and columns of P change (and the
diagonal of the Markov states).
:func:`propagate_covariance` steps over given points, :func:`accumulate_covariance` collects
IMU samples into steps of a given length, and :class:`TimeUpdate` is the whole time update of
an INS filter over an IMU block (bias compensation, :mod:`navreplay.geo.strapdown`, covariance) in
one compiled call; ``ins``, ``gps-ins`` and ``rpm-aided-ins`` use it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from navreplay.core.jit import kernel
from navreplay.core.units import G0
from navreplay.filters import kalman
from navreplay.filters.ins_error import (
    ACCEL_COLUMNS,
    GYRO_COLUMNS,
    N_ACCEL_HF,
    N_GYRO_Z,
    N_STATES,
    Vertical,
    fill_system_matrix,
)
from navreplay.filters.kalman import (
    DEFAULT_RTOL,
    FilterDivergedError,
    _covariance_ok,
    check_covariance,
)
from navreplay.geo import kernels, strapdown

N_NAV = 9
"""Rows of F that are not zero: position, velocity and attitude."""
_TIME_TOL = 1e-9
"""Slack [s] when comparing sample times with the time of the navigation solution."""


class Model(NamedTuple):
    """The error model as the compiled kernels take it (:func:`_model_args`): the process noise
    per second ``q`` (n,), eq. (21)'s ``k_acc`` and ``k_gyro``, depth instead of height, the
    curvature derivatives, the first gyro (``gz``) and accelerometer (``ga``) scale-factor and
    misalignment state (-1 for none) and the columns they hold (``ng``, ``na``; 0 for none),
    and 1 / tau of each first-order Markov state (``rate`` (n,), 0 for the others)."""

    q: np.ndarray
    k_acc: float
    k_gyro: float
    depth: bool
    curvature: bool
    gz: int
    ga: int
    ng: int
    na: int
    rate: np.ndarray


class Work(NamedTuple):
    """Scratch arrays of the covariance step (:func:`_scratch`): F (15, nc), M (9, nc),
    T (9, n), Q (n, n), the columns ``cols`` (nc,) of the states F reaches, and the means
    (2, 3) of an open step; ``Phi`` (n, n) the product of the steps' transitions when it is
    kept for a smoother (:meth:`TimeUpdate.keep_transition`), else (0, 0)."""

    F: np.ndarray
    M: np.ndarray
    T: np.ndarray
    Q: np.ndarray
    cols: np.ndarray
    mean: np.ndarray
    Phi: np.ndarray


class Open(NamedTuple):
    """The open covariance step (:class:`OpenStep`): the navigation vector at its start (10,)
    and the sums over its samples (7,), updated in place."""

    nav: np.ndarray
    sums: np.ndarray


class Imu(NamedTuple):
    """A block of IMU samples: times (k,) [s], body rates and specific forces (k, 3)."""

    t: np.ndarray
    omega: np.ndarray
    f: np.ndarray


class Compensation(NamedTuple):
    """The estimates the IMU samples are compensated with: accelerometer and gyro biases (3,),
    the gyro scale-factor and misalignment errors ``k_z`` (3 per column) of eq. (22) and the
    accelerometer errors ``k_a`` (3 per column) of eq. (23) (zeros: none)."""

    b_a: np.ndarray
    b_g: np.ndarray
    k_z: np.ndarray
    k_a: np.ndarray


class Outputs(NamedTuple):
    """The rows a compiled time update writes: times (m,), navigation vectors (m, 10),
    covariances (m, n, n), and the last compensated body rate (3,)."""

    t: np.ndarray
    nav: np.ndarray
    P: np.ndarray
    w_last: np.ndarray


@kernel
def _covariance_step(
    P: np.ndarray, nav: np.ndarray, f_b: np.ndarray, omega_b: np.ndarray, dt: float,
    model: Model, work: Work,
) -> np.ndarray:
    """One step of kalman eqs. (3), (4), (6) with F from eqs. (6)-(19), (22), (23) and Qd from
    (20), (21); returns a new P.

    F has non-zero rows only for position, velocity and attitude and non-zero columns only for
    the 15 navigation states, the gyro states of ``ng`` columns at ``gz .. gz + 3 ng - 1``
    (eq. 22) and the accelerometer states of ``na`` columns at ``ga .. ga + 3 na - 1``
    (eq. 23), listed in ``cols``: Phi is the identity but for its first 9 rows and the
    diagonal of the first-order Markov states (``rate`` > 0, kalman eq. 5a), and
    :func:`navreplay.filters.kalman.predict_rows_kernel` and
    :func:`navreplay.filters.kalman.markov_rows_kernel` propagate P. F (15, nc), M (9, nc),
    T (9, n) and Q (n, n, diagonal) are scratch (nc = 15 + 3 ng + 3 na).
    """
    q, k_acc, k_gyro, depth, curvature, gz, ga, ng, na, rate = model
    F, M, T, Q, cols = work.F, work.M, work.T, work.Q, work.cols
    n = P.shape[0]
    F[:, :] = 0.0
    C = kernels.quat_to_dcm(nav[6:10])
    fill_system_matrix(nav[0], nav[2], nav[3], nav[4], nav[5], C, f_b, depth, curvature, F)
    c = N_STATES
    for k in range(ng):  # (22): F[phi, (k_j)_i] = C_nb_hat[:, i] omega_j, j = z, x, y
        w = omega_b[GYRO_COLUMNS[k]]
        for i in range(3):
            for r in range(3):
                F[6 + r, c + 3 * k + i] = C[r, i] * w
    c += 3 * ng
    for k in range(na):  # (23): F[v, (k_j)_i] = -C_nb_hat[:, i] u_j, j = x, y, z
        j = ACCEL_COLUMNS[k]
        u = f_b[j] + G0 if j == 2 else f_b[j]
        for i in range(3):
            for r in range(3):
                F[3 + r, c + 3 * k + i] = -C[r, i] * u
    kalman.transition_rows_kernel(F, M.shape[0], dt, M)  # kalman (3)
    if work.Phi.shape[0] == n:  # kept for a smoother: Phi <- Phi_step Phi, T as scratch
        _chain_transition(work.Phi, M, cols, T)
        for i in range(n):  # the Markov states' diagonal of Phi_step (kalman eq. 5a)
            if rate[i] > 0.0:
                a = math.exp(-rate[i] * dt)
                for j in range(n):
                    work.Phi[i, j] *= a
    for i in range(n):
        Q[i, i] = q[i] * dt if rate[i] == 0.0 else 0.0  # kalman (4), diagonal (20)
    if k_acc > 0.0:  # (21): |a_n|^2 = |C f_b + g_n|^2, g on the ellipsoid
        g = kernels.gravity(nav[0], 0.0)
        a2 = 0.0
        for i in range(3):
            a = C[i, 0] * f_b[0] + C[i, 1] * f_b[1] + C[i, 2] * f_b[2]
            if i == 2:
                a += g
            a2 += a * a
        for i in range(3, 6):
            Q[i, i] += k_acc * a2 * dt
    if k_gyro > 0.0:  # (21): |omega_ib_b|^2
        w2 = omega_b[0] ** 2 + omega_b[1] ** 2 + omega_b[2] ** 2
        for i in range(6, 9):
            Q[i, i] += k_gyro * w2 * dt
    P = kalman.predict_rows_kernel(P, M, cols, Q, T)  # kalman (6)
    kalman.markov_rows_kernel(P, rate, q, dt)  # kalman (5a), (6)
    return P


@kernel(inline="always")
def _chain_transition(Phi: np.ndarray, M: np.ndarray, cols: np.ndarray, T: np.ndarray) -> None:
    """``Phi <- Phi_step Phi`` for a step transition that is the identity but for its first r
    rows, ``Phi_step[0:r, cols] = M`` (as :func:`navreplay.filters.kalman.predict_rows_kernel`
    takes it): only rows 0..r-1 of Phi change. T (r, n) is scratch."""
    n = Phi.shape[0]
    r, nc = M.shape
    for i in range(r):
        for j in range(n):
            T[i, j] = 0.0
        for k in range(nc):
            a = M[i, k]
            if a != 0.0:
                p = cols[k]
                for j in range(n):
                    T[i, j] += a * Phi[p, j]
    for i in range(r):
        for j in range(n):
            Phi[i, j] = T[i, j]


def _scratch(n: int, gz: int, ga: int, ng: int, na: int) -> Work:
    """F, M, T, Q, cols of :func:`_covariance_step` for n states (gyro states of ``ng``
    columns at ``gz``, accelerometer states of ``na`` columns at ``ga``) and the means of
    :func:`_close_step`."""
    cols = np.concatenate([np.arange(N_STATES, dtype=np.int64),
                           np.arange(gz, gz + 3 * ng, dtype=np.int64),
                           np.arange(ga, ga + 3 * na, dtype=np.int64)])
    nc = cols.shape[0]
    return Work(np.zeros((N_STATES, nc)), np.zeros((N_NAV, nc)), np.zeros((N_NAV, n)),
                np.zeros((n, n)), cols, np.zeros((2, 3)), np.zeros((0, 0)))


@kernel
def _propagate_covariance(
    P: np.ndarray, nav: np.ndarray, f_b: np.ndarray, omega_b: np.ndarray, dt: np.ndarray,
    model: Model, work: Work,
) -> np.ndarray:
    for k in range(dt.shape[0]):
        P = _covariance_step(P, nav[k], f_b[k], omega_b[k], dt[k], model, work)
    return P


@kernel(inline="always")
def _close_step(P: np.ndarray, model: Model, open_step: Open, work: Work) -> np.ndarray:
    """P propagated over the open step, with F at its start and the mean specific force and
    body rate over it; the step is then cleared (P itself when none is open)."""
    open_sums = open_step.sums
    mean = work.mean
    dt = open_sums[0]
    if dt <= 0.0:
        return P
    for j in range(3):
        mean[0, j] = open_sums[1 + j] / dt
        mean[1, j] = open_sums[4 + j] / dt
    P = _covariance_step(P, open_step.nav, mean[0], mean[1], dt, model, work)
    for j in range(open_sums.shape[0]):
        open_sums[j] = 0.0
    return P


@kernel(inline="always")
def _accumulate_covariance(
    P: np.ndarray, hist: np.ndarray, f_b: np.ndarray, omega_b: np.ndarray, dt: np.ndarray,
    step: float, model: Model, open_step: Open, work: Work,
) -> np.ndarray:
    open_nav, open_sums = open_step
    for k in range(dt.shape[0]):
        if open_sums[0] == 0.0:
            for j in range(open_nav.shape[0]):  # (loops: array assignment compiles a
                open_nav[j] = hist[k, j]  # formatted shape error)
        open_sums[0] += dt[k]
        for j in range(3):
            open_sums[1 + j] += f_b[k, j] * dt[k]
            open_sums[4 + j] += omega_b[k, j] * dt[k]
        if open_sums[0] >= step - 1e-9:
            P = _close_step(P, model, open_step, work)
    return P


@kernel
def compensate_gyro(omega: np.ndarray, b_g: np.ndarray, k_g: np.ndarray) -> np.ndarray:
    """Gyro samples (k, 3) compensated for the scale-factor and misalignment errors of
    ins_error eq. (22), ``k_g`` the estimates of the first ``len(k_g) / 3`` columns of
    :data:`~navreplay.filters.ins_error.GYRO_COLUMNS` (z, x, y), three per column:
    ``omega - sum_j k_j (omega_j - b_g_j)`` (the bias itself is subtracted by the time
    update)."""
    out = np.empty(omega.shape)
    ng = k_g.shape[0] // 3
    for i in range(omega.shape[0]):
        for c in range(3):
            acc = omega[i, c]
            for k in range(ng):
                j = GYRO_COLUMNS[k]
                acc -= (omega[i, j] - b_g[j]) * k_g[3 * k + c]
            out[i, c] = acc
    return out


compensate_gyro_z = compensate_gyro
"""The gyro compensation of the column z alone (``k_g`` of three: m_xz, m_yz, s_z)."""


@kernel
def compensate_accel(f: np.ndarray, b_a: np.ndarray, k_a: np.ndarray) -> np.ndarray:
    """Accelerometer samples (k, 3) compensated for the errors of ins_error eq. (23), ``k_a``
    the estimates of the first ``len(k_a) / 3`` columns of
    :data:`~navreplay.filters.ins_error.ACCEL_COLUMNS` (x, y, z), three per column:
    ``f - sum_j k_j u_j``, ``u_x = f_x - b_a_x``, ``u_y = f_y - b_a_y``, ``u_z = f_z - b_a_z +
    g0`` (the bias itself is subtracted by the time update)."""
    out = np.empty(f.shape)
    na = k_a.shape[0] // 3
    for i in range(f.shape[0]):
        for c in range(3):
            acc = f[i, c]
            for k in range(na):
                j = ACCEL_COLUMNS[k]
                u = f[i, j] - b_a[j]
                if j == 2:
                    u += G0
                acc -= u * k_a[3 * k + c]
            out[i, c] = acc
    return out


@dataclasses.dataclass(frozen=True)
class ProcessNoise:
    """Process noise of the covariance propagation, per second, and the optional states the
    time update moves.

    Attributes
    ----------
    q : ndarray, shape (n,)
        Diagonal of ``G Qc G^T`` (isotropic triad noise, :func:`process_noise_diagonal` with
        dt = 1), units of state^2/s; entries beyond 15 belong to a larger filter's states (for
        a first-order Markov state the density of its driving noise, ``2 sigma^2 / tau``).
    k_acc : float
        Velocity noise per unit squared acceleration, eq. (21) [(m/s)^2/s per (m/s^2)^2 = s].
    k_gyro : float
        Attitude noise per unit squared body rate, eq. (21) [rad^2/s per (rad/s)^2 = s].
    """

    q: np.ndarray
    k_acc: float = 0.0
    k_gyro: float = 0.0
    gyro_z_states: int = -1
    """Index of the first gyro scale-factor and misalignment state of eq. (22), which a larger
    filter places after the 15; -1: none."""
    accel_states: int = -1
    """Index of the first accelerometer scale-factor and misalignment state of eq. (23), after
    the 15 and the gyro states; -1: none."""
    gyro_columns: int = 1
    """Columns of ``S_g + M_g`` the gyro states hold, three states each, in the order of
    :data:`~navreplay.filters.ins_error.GYRO_COLUMNS`: 1 (z: m_xz, m_yz, s_z) or 3 (z, x, y)."""
    accel_columns: int = 2
    """Columns of ``S_a + M_a`` the accelerometer states hold, in the order of
    :data:`~navreplay.filters.ins_error.ACCEL_COLUMNS`: 2 (x, y) or 3 (x, y, z)."""
    markov: np.ndarray | None = None
    """1 / tau [1/s] of each state that is a first-order Markov process (kalman eq. 5a), 0 for
    the others, shape (n,); None: none. Such states must be outside F (after the 15 and the
    IMU error states)."""

    def __post_init__(self) -> None:
        q = np.ascontiguousarray(self.q, dtype=np.float64)
        n = q.shape[0]
        if q.ndim != 1 or not np.all(np.isfinite(q)) or np.any(q < 0.0):
            raise ValueError(f"process noise q must be a vector of values >= 0, got {q}")
        end = N_STATES
        for name, columns, allowed in (("gyro_z_states", "gyro_columns", (1, 3)),
                                       ("accel_states", "accel_columns", (2, 3))):
            k = getattr(self, columns)
            if k not in allowed:
                raise ValueError(f"{columns} must be one of {allowed}, got {k!r}")
            first = getattr(self, name)
            if not (first == -1 or end <= first <= n - 3 * k):
                raise ValueError(
                    f"{name} must be -1 or an index in {end}..{n - 3 * k} ({3 * k} states "
                    f"within the {n}), got {first!r}")
            object.__setattr__(self, name, int(first))
            if first >= 0:
                end = first + 3 * k
        for name in ("k_acc", "k_gyro"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        rate = np.zeros(n) if self.markov is None else np.ascontiguousarray(
            self.markov, dtype=np.float64)
        if rate.shape != (n,) or not np.all(np.isfinite(rate)) or np.any(rate < 0.0):
            raise ValueError(f"markov must be {n} rates >= 0 [1/s], got {self.markov!r}")
        if np.any(rate[:end] > 0.0):
            raise ValueError(f"markov: the states F reaches (0..{end - 1}) cannot be Markov "
                             "states")
        object.__setattr__(self, "markov", rate)
        object.__setattr__(self, "q", q)

    @property
    def columns(self) -> tuple[int, int]:
        """Columns of the gyro and of the accelerometer states (0 without them)."""
        return (self.gyro_columns if self.gyro_z_states >= 0 else 0,
                self.accel_columns if self.accel_states >= 0 else 0)

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
) -> Model:
    """Check the shape of P against the model; the arguments the compiled kernels take."""
    n = noise.q.shape[0]
    if shape != (n, n) or n < N_STATES:
        raise ValueError(
            f"P must be (n, n) with n >= 15 the length of the process noise ({n}), got {shape}"
        )
    assert noise.markov is not None  # an array once the noise is made
    return Model(noise.q, noise.k_acc, noise.k_gyro, vertical is Vertical.DEPTH,
                 bool(curvature_derivatives), noise.gyro_z_states, noise.accel_states,
                 *noise.columns, noise.markov)


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
    in the attitude rows of the gyro z-rate states when ``noise.gyro_z_states`` is set,
    ``accel_motion_matrix(C_nb, f_b)`` in the velocity rows of the accelerometer states when
    ``noise.accel_states`` is set, 0 elsewhere: extra states are random constants or random
    walks) and ``Qd`` of eqs.
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
    return _propagate_covariance(_f64(P), _f64(nav), _f64(f_b), _f64(omega_b), _f64(dt), args,
                                 _scratch(P.shape[0], args.gz, args.ga, args.ng, args.na))


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
        :func:`navreplay.geo.strapdown.integrate`).
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
    model = _model_args(P.shape, noise, vertical, curvature_derivatives)
    k = dt.shape[0]
    if hist.shape != (k + 1, 10) or f_b.shape != (k, 3) or omega_b.shape != (k, 3):
        raise ValueError(
            f"hist must be ({k + 1}, 10), f_b and omega_b ({k}, 3); got {hist.shape}, "
            f"{f_b.shape}, {omega_b.shape}"
        )
    return _accumulate_covariance(
        _f64(P), _f64(hist), _f64(f_b), _f64(omega_b), _f64(dt), float(step), model,
        Open(open_step.nav, open_step.sums),
        _scratch(P.shape[0], model.gz, model.ga, model.ng, model.na),
    )


def close_step(
    P: np.ndarray, noise: ProcessNoise, open_step: OpenStep, *,
    vertical: Vertical = Vertical.HEIGHT, curvature_derivatives: bool = True,
) -> np.ndarray:
    """Propagate P over the open step (if any) and clear it; P at the last sample's time."""
    model = _model_args(P.shape, noise, vertical, curvature_derivatives)
    return _close_step(_f64(P), model, Open(open_step.nav, open_step.sums),
                       _scratch(P.shape[0], model.gz, model.ga, model.ng, model.na))


class TimeUpdate:
    """The time update of an INS filter: strapdown and covariance over blocks of IMU samples.

    Each :meth:`propagate` compensates the IMU with the bias estimates (``f_hat = f_b - b_a``,
    ``omega_hat = omega_ib_b - b_g``), integrates it with
    :func:`navreplay.geo.strapdown.integrate_kernel` and propagates P as
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
        self.model = _model_args(self._shape, noise, vertical, curvature_derivatives)
        """The error model as the compiled kernels take it."""
        self.work = _scratch(n, self.model.gz, self.model.ga, self.model.ng, self.model.na)
        """Their scratch arrays."""
        self.step = float(step)
        self.prev = np.zeros(6)
        """Increments [dtheta, dv] of the last sample [rad, m/s]."""
        self.open_step = OpenStep()

    def keep_transition(self) -> None:
        """From now on, keep the product of the covariance steps' transitions (for a
        smoother): :meth:`take_transition` hands it over."""
        n = self._shape[0]
        self.work = self.work._replace(Phi=np.eye(n))

    def take_transition(self) -> np.ndarray:
        """The transition of the error state over the covariance steps since the last call
        (or :meth:`keep_transition`), and start the next; the steps of the open one are not in
        it yet (close it first)."""
        Phi = self.work.Phi
        if Phi.shape[0] != self._shape[0]:
            raise RuntimeError("the transition is not kept: call keep_transition first")
        out = Phi.copy()
        Phi[:, :] = np.eye(Phi.shape[0])
        return out

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
        t_out, nav_out, P_out, _ = self._run(nav, P, t_nav, t, omega_ib_b, f_b, b_a, b_g,
                                             np.array([t.shape[0]]), None, None, False, -1.0)
        if t_out[0] == t_nav:  # no sample after t_nav
            return None
        return nav_out[0], P_out[0], float(t_out[0])

    def _fail(self, code: int, first: int, t: np.ndarray, t_nav: float, omega_ib_b: np.ndarray,
              f_b: np.ndarray, P: np.ndarray) -> None:
        """Raise the error of a failed segment of :func:`_propagate_outputs` (its code, the
        first sample used)."""
        if code == -5:
            raise ValueError(f"P must be {self._shape} as the process noise, got {P.shape}")
        if code == -3:
            check_covariance(P, t=float(t[-1]))  # names what is wrong
            raise FilterDivergedError("P has a negative or non-finite variance", float(t[-1]))
        if code == -2:
            raise FilterDivergedError("navigation state is not finite", t_nav)
        i = first + code
        raise ValueError(
            f"IMU sample at t = {t[i]:.6f} s (previous {t[i - 1] if i > first else t_nav:.6f} "
            f"s): omega_ib_b = {omega_ib_b[i]}, f_b = {f_b[i]}: not finite, or the time does "
            "not increase"
        )

    def propagate_outputs(
        self, nav: np.ndarray, P: np.ndarray, t_nav: float, t: np.ndarray,
        omega_ib_b: np.ndarray, f_b: np.ndarray, b_a: np.ndarray, b_g: np.ndarray,
        ends: np.ndarray, gyro_z: np.ndarray | None = None, accel_k: np.ndarray | None = None,
        out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`propagate` over each segment ``[ends[j-1], ends[j])`` of a block followed by
        :meth:`close`, in one compiled call; the state after each segment is an output.

        The same arithmetic as the calls one by one (the gyro compensated first for the
        z-rate error estimates ``gyro_z`` (m_xz, m_yz, s_z) of eq. (22), the accelerometer for
        the estimates ``accel_k`` (6,) of eq. (23), if given). ``out``: arrays ``(t_out,
        nav_out, P_out)`` of at least ``len(ends)`` rows to write into.

        Returns
        -------
        t_out : ndarray, shape (m,)
            Time of the state after each segment [s] (that of the last sample used).
        nav_out : ndarray, shape (m, 10)
        P_out : ndarray, shape (m, n, n)
            P at those times, checked.
        w_last : ndarray, shape (3,)
            The last compensated body rate [rad/s] (``t_nav``'s if no sample was used: NaN).

        Raises
        ------
        as :meth:`propagate` and :meth:`close`.
        """
        return self._run(nav, P, t_nav, t, omega_ib_b, f_b, b_a, b_g, ends, gyro_z, accel_k,
                         True, DEFAULT_RTOL, out)

    def close(self, P: np.ndarray, t: float) -> np.ndarray:
        """P at the time t [s] of the last sample: propagated over the open covariance step,
        which is then cleared, and checked (:func:`navreplay.filters.kalman.check_covariance`);
        P itself when no step is open."""
        if self.open_step.sums[0] <= 0.0:
            return P
        if P.shape != self._shape:
            raise ValueError(f"P must be {self._shape} as the process noise, got {P.shape}")
        _, _, P_out, _ = self._run(np.zeros(10), P, t, _NO_TIMES, _NO_SAMPLES, _NO_SAMPLES,
                                   _ZERO3, _ZERO3, _NO_ENDS, None, None, True,
                                   DEFAULT_RTOL)
        return P_out[0]

    def _run(
        self, nav: np.ndarray, P: np.ndarray, t_nav: float, t: np.ndarray,
        omega_ib_b: np.ndarray, f_b: np.ndarray, b_a: np.ndarray, b_g: np.ndarray,
        ends: np.ndarray, gyro_z: np.ndarray | None, accel_k: np.ndarray | None, close: bool,
        rtol: float, out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:func:`_propagate_outputs` with the arrays it takes (one compiled signature for
        every caller); raises the error of a failed segment."""
        m = ends.shape[0]
        if out is None:
            t_out, nav_out, P_out = np.empty(m), np.empty((m, 10)), np.empty((m, *self._shape))
        else:
            t_out, nav_out, P_out = (a[:m] for a in out)
        w_last = np.full(3, np.nan)
        k_z = _NO_GYRO_Z if gyro_z is None else _f64(gyro_z)
        k_a = _NO_ACCEL if accel_k is None else _f64(accel_k)
        t_nav = float(t_nav)
        code, j, first, _, P_j, t_j = _propagate_outputs(
            _f64(nav), _f64(P), t_nav, Imu(_f64(t), _f64(omega_ib_b), _f64(f_b)),
            Compensation(_f64(b_a), _f64(b_g), k_z, k_a), self.prev, self.step, self.model,
            Open(self.open_step.nav, self.open_step.sums), self.work,
            np.ascontiguousarray(ends, dtype=np.int64), close, rtol,
            Outputs(t_out, nav_out, P_out, w_last),
        )
        if code == -1:
            return t_out, nav_out, P_out, w_last
        if code in (-6, -7):
            check_covariance(P_j, t=t_j)  # names what is wrong
            raise FilterDivergedError("P is not symmetric positive semi-definite", t_j)
        a = int(ends[j - 1]) if j else 0
        self._fail(code, first - a, t[a:ends[j]], t_j, omega_ib_b[a:ends[j]], f_b[a:ends[j]],
                   P_j)
        raise AssertionError("unreachable")


_NO_TIMES = np.zeros(0)
_NO_SAMPLES = np.zeros((0, 3))
_NO_ENDS = np.zeros(1, dtype=np.int64)
_NO_GYRO_Z = np.zeros(N_GYRO_Z)
_ZERO3 = _NO_GYRO_Z
_NO_ACCEL = np.zeros(N_ACCEL_HF)


@kernel
def _propagate_segment(
    nav: np.ndarray, P: np.ndarray, t: np.ndarray, t_nav: float, w: np.ndarray, f: np.ndarray,
    b_a: np.ndarray, b_g: np.ndarray, first: int, b: int, prev: np.ndarray, step: float,
    model: Model, open_step: Open, work: Work, w_last: np.ndarray,
) -> tuple[int, np.ndarray, np.ndarray]:
    """Strapdown and the covariance steps over the samples ``first .. b - 1`` (all after
    ``t_nav``, at least one) of the compensated rates ``w`` and specific forces ``f``, the
    biases subtracted; the one segment step of every compiled time update.

    Returns (code, nav, P): code -1 when all went well; the strapdown's codes (the index of the
    first invalid sample from ``first`` on, -2 for a non-finite state) with nav and P
    unchanged; -3 when the propagated P (returned for the message) has a negative or
    non-finite variance. ``prev`` receives the last sample's increments and ``w_last`` its
    compensated body rate.
    """
    k = b - first
    dt = np.empty(k)
    wc = np.empty((k, 3))
    fc = np.empty((k, 3))
    t_prev = t_nav
    for i in range(k):
        dt[i] = t[first + i] - t_prev
        t_prev = t[first + i]
        for c in range(3):
            wc[i, c] = w[first + i, c] - b_g[c]
            fc[i, c] = f[first + i, c] - b_a[c]
    hist = np.empty((k + 1, strapdown.NAV_SIZE))
    code = strapdown.integrate_kernel(nav, wc, fc, dt, prev, hist)
    if code != -1:
        return code, nav, P
    for c in range(3):  # the last sample's increments: coning and sculling of the next
        prev[c] = wc[k - 1, c] * dt[k - 1]
        prev[3 + c] = fc[k - 1, c] * dt[k - 1]
    P = _accumulate_covariance(P, hist, fc, wc, dt, step, model, open_step, work)
    for i in range(P.shape[0]):
        if not (P[i, i] >= 0.0 and math.isfinite(P[i, i])):
            return -3, nav, P
    for c in range(3):
        w_last[c] = wc[k - 1, c]
    return -1, hist[k], P


@kernel
def _propagate_outputs(
    nav: np.ndarray, P: np.ndarray, t_nav: float, imu: Imu, comp: Compensation,
    prev: np.ndarray, step: float, model: Model, open_step: Open, work: Work, ends: np.ndarray,
    close: bool, rtol: float, out: Outputs,
) -> tuple[int, int, int, np.ndarray, np.ndarray, float]:
    """The whole time update of a block in one compiled call: bias compensation, strapdown
    and the covariance steps over the samples of each segment ``[ends[j-1], ends[j])`` after
    ``t_nav`` (the time of ``nav``), then, with ``close``, the open covariance step closed
    (:func:`_close_step`), and (t, nav, P) written into row j of the outputs.

    The gyro samples are compensated first for the scale-factor and misalignment errors
    ``k_z`` (eq. 22, :func:`compensate_gyro`), the accelerometer samples for the errors ``k_a``
    (eq. 23, :func:`compensate_accel`); then the biases are subtracted. Returns
    (code, j, first, nav, P, t_nav) with ``first`` the index of the first sample of segment j
    after ``t_nav``; code -1 when all went well, else for segment j: -5 when P is not (n, n)
    with n the length of q; the strapdown's codes (the index of the first invalid sample from
    ``first`` on, -2 for a non-finite state) with nav and P unchanged; -3 when the propagated
    P (returned for the message) has a negative or non-finite variance; with ``rtol >= 0``,
    -6 when P after the segment fails the check of
    :func:`navreplay.filters.kalman.check_covariance`, -7 when P after the close fails it
    (P is checked once per segment, after the close when a covariance step was open).
    ``w_last`` receives the last compensated body rate. A segment with no sample after
    ``t_nav`` leaves the state as it is (its row repeats the previous one).
    """
    t, omega, f = imu
    b_a, b_g, k_z, k_a = comp
    t_out, nav_out, P_out, w_last = out
    n = model.q.shape[0]
    if P.shape[0] != n or P.shape[1] != n:
        return -5, 0, 0, nav, P, t_nav
    w = omega
    for c in range(k_z.shape[0]):
        if k_z[c] != 0.0:
            w = compensate_gyro(omega, b_g, k_z)
            break
    for c in range(k_a.shape[0]):
        if k_a[c] != 0.0:
            f = compensate_accel(f, b_a, k_a)
            break
    a = 0
    for j in range(ends.shape[0]):
        b = ends[j]
        first = a
        while first < b and t[first] <= t_nav + _TIME_TOL:
            first += 1
        if first < b:
            code, nav_b, P = _propagate_segment(
                nav, P, t, t_nav, w, f, b_a, b_g, first, b, prev, step, model, open_step, work,
                w_last)
            if code != -1:
                return code, j, first, nav, P, t_nav
            nav = nav_b
            t_nav = t[b - 1]
            if rtol >= 0.0 and open_step.sums[0] <= 0.0 and not _covariance_ok(P, rtol):
                return -6, j, first, nav, P, t_nav  # (else checked below)
        a = max(a, b)
        if close and open_step.sums[0] > 0.0:
            P = _close_step(P, model, open_step, work)
            if rtol >= 0.0 and not _covariance_ok(P, rtol):
                return -7, j, a, nav, P, t_nav
        t_out[j] = t_nav
        for c in range(nav.shape[0]):  # (loops: array assignment compiles a formatted shape
            nav_out[j, c] = nav[c]  # error)
        for r in range(n):
            for c in range(n):
                P_out[j, r, c] = P[r, c]
    return -1, ends.shape[0], 0, nav, P, t_nav
