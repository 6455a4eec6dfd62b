"""Compiled GNSS measurement models of ``gps-ins`` and the update they feed.

The equations are those of :mod:`navreplay.filters.gps_ins` (position eqs. 4-7, velocity
eqs. 8-11, update and feedback eq. 12), written as numba kernels that fill preallocated
arrays: one call per update, no temporaries in Python. :func:`gps_update` is the whole update
of the error-state filter: model, :func:`navreplay.filters.kalman._correct_kernel` (Cholesky,
Joseph form) on the zero error state, the checks of :func:`navreplay.filters.kalman.correct`
and the feedback into the navigation solution and the estimates.

State layout (indices into the error state, :class:`Layout`): navigation errors and biases as
:mod:`navreplay.filters.ins_error` (0-14), the lever arm at 15-17 when ``lever``, the gyro
scale-factor and misalignment states at ``gz`` (three per column of ``S_g + M_g``, the columns
z, x, y: ``ng`` of them; :data:`~navreplay.filters.ins_error.GYRO_COLUMNS`), the
accelerometer's at ``ga`` (the columns x, y, z: ``na``) and the
GNSS Gauss-Markov position error N, E, D at ``gp`` (-1: none).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navreplay.core.jit import kernel
from navreplay.filters.ins_error import GYRO_COLUMNS
from navreplay.filters.kalman import _correct_kernel, _covariance_ok
from navreplay.geo import kernels

POSITION = 1
"""Kind code of a GPS position fix."""
VELOCITY = 2
"""Kind code of a GPS NED velocity."""

WHITE_FLOOR = 0.01
"""With Gauss-Markov states, the white part of a fix's variance is ``sigma^2 - sigma_gm^2``,
but at least this fraction of ``sigma^2``."""

_TWO_PI = 2.0 * math.pi


class Layout(NamedTuple):
    """Where the optional states are (see the module docstring): lever arm at 15-17, gyro states
    at ``gz`` (``ng`` columns), accelerometer states at ``ga`` (``na`` columns), GNSS
    Gauss-Markov position error at ``gp``; -1 and 0 for none."""

    lever: bool
    gz: int
    ng: int
    ga: int
    na: int
    gp: int


class Estimates(NamedTuple):
    """The estimates the feedback corrects, in place: accelerometer and gyro biases (3,),
    lever arm (3,), gyro (3 ng,) and accelerometer (3 na,) scale-factor and misalignment
    columns, the GNSS Gauss-Markov position error N, E, D (3,) [m] as it was at the time
    ``gm_t[0]`` [s] (1,)."""

    b_a: np.ndarray
    b_g: np.ndarray
    lever: np.ndarray
    k_g: np.ndarray
    k_a: np.ndarray
    gm: np.ndarray
    gm_t: np.ndarray


class GaussMarkov(NamedTuple):
    """The GNSS Gauss-Markov position error of the model: correlation time [s] and stationary
    variance N, E, D (3,) [m^2]."""

    tau: float
    var: np.ndarray


@kernel(inline="always")
def gm_at(gm: np.ndarray, gm_t: float, t: float, tau: float, out: np.ndarray) -> None:
    """The Gauss-Markov estimate ``gm`` of time ``gm_t`` carried to time t: ``gm exp(-(t -
    gm_t) / tau)`` (the mean of a first-order Markov process decays), into ``out`` (3,)."""
    a = math.exp(-(t - gm_t) / tau)
    for i in range(3):
        out[i] = gm[i] * a


@kernel(inline="always")
def _all_finite(a: np.ndarray) -> bool:
    for v in a.flat:
        if not math.isfinite(v):
            return False
    return True


@kernel(inline="always")
def _skew_into(M: np.ndarray, r: int, c: int, x: float, y: float, z: float) -> None:
    """M[r:r+3, c:c+3] = [v x], v = (x, y, z)."""
    M[r, c] = 0.0
    M[r, c + 1] = -z
    M[r, c + 2] = y
    M[r + 1, c] = z
    M[r + 1, c + 1] = 0.0
    M[r + 1, c + 2] = -x
    M[r + 2, c] = -y
    M[r + 2, c + 1] = x
    M[r + 2, c + 2] = 0.0


@kernel(inline="always")
def _matmul3(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += A[i, k] * B[k, j]
            out[i, j] = s


@kernel(inline="always")
def _matvec3(A: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    for i in range(3):
        s = 0.0
        for k in range(3):
            s += A[i, k] * v[k]
        out[i] = s


@kernel
def position_model(nav: np.ndarray, lever: np.ndarray, pos_gps: np.ndarray,
                   pos_sigma: np.ndarray, scale: float, lag: float, lever_states: bool,
                   gp: int, gm: np.ndarray, gm_var: np.ndarray,
                   z: np.ndarray, H: np.ndarray, R: np.ndarray) -> None:
    """GPS position, gps_ins eqs. (4)-(7): residual z (3,) [m], H (3, n) (every entry
    written) and R (3, 3) [m^2] with the sigmas ``pos_sigma * scale``. With Gauss-Markov states
    at ``gp`` (>= 0) the predicted fix is off by their estimate ``gm`` (3,) [m] and R holds the
    white part of the variance, ``(pos_sigma scale)^2 - gm_var``, at least
    :data:`WHITE_FLOOR` of it (eqs. 6a, 7a)."""
    lat = nav[0]
    h = nav[2]
    s = math.sin(lat)
    w = 1.0 - kernels._E2 * (s * s)
    D0 = kernels._A * (1.0 - kernels._E2) / w**1.5 + h
    D1 = (kernels._A / math.sqrt(w) + h) * math.cos(lat)
    C = kernels.quat_to_dcm(nav[6:10])
    l_n = np.empty(3)
    _matvec3(C, lever, l_n)
    d1 = nav[1] - pos_gps[1]
    d1 = (d1 + math.pi) % _TWO_PI - math.pi
    z[0] = D0 * (nav[0] - pos_gps[0]) + l_n[0] + nav[3] * lag  # (4), (5)
    z[1] = D1 * d1 + l_n[1] + nav[4] * lag
    z[2] = -1.0 * (nav[2] - pos_gps[2]) + l_n[2] + nav[5] * lag
    H[:, :] = 0.0  # (6)
    H[0, 0] = D0
    H[1, 1] = D1
    H[2, 2] = -1.0
    _skew_into(H, 0, 6, l_n[0], l_n[1], l_n[2])
    if lever_states:
        for i in range(3):
            for j in range(3):
                H[i, 15 + j] = C[i, j]
    R[:, :] = 0.0  # (7)
    for i in range(3):
        sig = pos_sigma[i] * scale
        R[i, i] = sig * sig
    if gp >= 0:  # (6a), (7a)
        for i in range(3):
            z[i] += gm[i]
            H[i, gp + i] = 1.0
            R[i, i] = max(R[i, i] - gm_var[i], WHITE_FLOOR * R[i, i])


@kernel
def velocity_model(nav: np.ndarray, lever: np.ndarray, omega: np.ndarray, v_gps: np.ndarray,
                   vel_sigma: np.ndarray, scale: float, lever_states: bool, gz: int, ng: int,
                   z: np.ndarray, H: np.ndarray, R: np.ndarray) -> None:
    """GPS velocity, gps_ins eqs. (8)-(11), with ``omega`` the compensated body rate:
    residual z (3,) [m/s], H (3, n) (every entry written), R (3, 3) [(m/s)^2]; the gyro
    states of ``ng`` columns at ``gz`` (:data:`GYRO_COLUMNS`) enter through the lever arm's
    rotation (eq. 10a)."""
    lat = nav[0]
    C = kernels.quat_to_dcm(nav[6:10])
    ie0, ie1, ie2 = kernels.earth_rate(lat)
    en0, en1, en2 = kernels.transport_rate(lat, nav[2], nav[3], nav[4])
    W = np.empty((3, 3))
    _skew_into(W, 0, 0, ie0 + en0, ie1 + en1, ie2 + en2)
    L = np.empty((3, 3))
    _skew_into(L, 0, 0, lever[0], lever[1], lever[2])
    l_n = np.empty(3)
    _matvec3(C, lever, l_n)
    a = np.empty(3)  # -L omega = omega x l
    for i in range(3):
        acc = 0.0
        for k in range(3):
            acc += -L[i, k] * omega[k]
        a[i] = acc
    rot_n = np.empty(3)
    _matvec3(C, a, rot_n)
    wl = np.empty(3)
    _matvec3(W, l_n, wl)
    for i in range(3):
        z[i] = nav[3 + i] + rot_n[i] - wl[i] - v_gps[i]  # (8), (9)
    H[:, :] = 0.0  # (10)
    S1 = np.empty((3, 3))
    _skew_into(S1, 0, 0, l_n[0], l_n[1], l_n[2])
    WS = np.empty((3, 3))
    _matmul3(W, S1, WS)
    _skew_into(S1, 0, 0, rot_n[0], rot_n[1], rot_n[2])
    CL = np.empty((3, 3))
    _matmul3(C, L, CL)
    for i in range(3):
        H[i, 3 + i] = 1.0
        for j in range(3):
            H[i, 6 + j] = S1[i, j] - WS[i, j]
            H[i, 12 + j] = CL[i, j]
    for c in range(ng):  # (10a): domega = -db_g - dK omega, column by column
        w_c = omega[GYRO_COLUMNS[c]]
        for i in range(3):
            for j in range(3):
                H[i, gz + 3 * c + j] = CL[i, j] * w_c
    if lever_states:
        _skew_into(S1, 0, 0, omega[0], omega[1], omega[2])
        CW = np.empty((3, 3))
        _matmul3(C, S1, CW)
        _matmul3(W, C, WS)
        for i in range(3):
            for j in range(3):
                H[i, 15 + j] = CW[i, j] - WS[i, j]
    R[:, :] = 0.0  # (11)
    for i in range(3):
        sig = vel_sigma[i] * scale
        R[i, i] = sig * sig


@kernel
def feedback(nav: np.ndarray, dx: np.ndarray, est: Estimates, layout: Layout) -> np.ndarray:
    """Eq. (12): subtract the estimated errors dx from a new copy of the navigation vector
    (returned; :func:`navreplay.filters.ins_error.apply_correction`, height form) and, in
    place, from the estimates of ``est`` that ``layout`` places in the state."""
    out = nav.copy()
    out[0] -= dx[0]
    out[1] -= dx[1]
    out[2] -= dx[2]
    for i in range(3):
        out[3 + i] -= dx[3 + i]
    out[6], out[7], out[8], out[9] = kernels.correct_quat(
        0.5 * dx[6], 0.5 * dx[7], 0.5 * dx[8], out[6], out[7], out[8], out[9])
    for i in range(3):
        est.b_a[i] -= dx[9 + i]
        est.b_g[i] -= dx[12 + i]
    if layout.lever:
        for i in range(3):
            est.lever[i] -= dx[15 + i]
    for i in range(3 * layout.ng):
        est.k_g[i] -= dx[layout.gz + i]
    for i in range(3 * layout.na):
        est.k_a[i] -= dx[layout.ga + i]
    if layout.gp >= 0:
        for i in range(3):
            est.gm[i] -= dx[layout.gp + i]
    return out


@kernel
def gps_update(kind: int, nav: np.ndarray, P: np.ndarray, t: float, sample: np.ndarray,
               sigma: np.ndarray, scale: float, lag: float, omega: np.ndarray,
               est: Estimates, layout: Layout, gauss_markov: GaussMarkov, rtol: float,
               dx_sum: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One GPS update (``kind`` :data:`POSITION` or :data:`VELOCITY`) of the error state 0 at
    time t [s] (that of P).

    Returns (ok, nav, P, nu, S). When ok, nav and P are the corrected ones, the estimates
    were corrected in place (the Gauss-Markov estimate carried to t first, :func:`gm_at`) and
    the error state fed back was added to ``dx_sum`` (n,) (for a smoother; shape (0,): not
    kept);
    when not (z, H or R not finite, R not PSD, S not positive definite, or the corrected x or
    P not finite / not PSD within ``rtol``: the checks of
    :func:`navreplay.filters.kalman.correct`), nothing was changed and the caller reports
    what is wrong."""
    n = P.shape[0]
    z = np.empty(3)
    H = np.empty((3, n))
    R = np.empty((3, 3))
    gm = np.zeros(3)
    if layout.gp >= 0:
        gm_at(est.gm, est.gm_t[0], t, gauss_markov.tau, gm)
    if kind == POSITION:
        position_model(nav, est.lever, sample, sigma, scale, lag, layout.lever, layout.gp, gm,
                       gauss_markov.var, z, H, R)
    else:
        velocity_model(nav, est.lever, omega, sample, sigma, scale, layout.lever, layout.gz,
                       layout.ng, z, H, R)
    if not (_all_finite(z) and _all_finite(H) and _covariance_ok(R, rtol)):
        return False, nav, P, z, R
    x, P_new, nu, S, _, ok = _correct_kernel(np.zeros(n), P, z, H, R,
                                              np.zeros(0, dtype=np.bool_))
    if not (ok and _all_finite(x) and _covariance_ok(P_new, rtol)):
        return False, nav, P, nu, S
    if layout.gp >= 0:
        for i in range(3):
            est.gm[i] = gm[i]
        est.gm_t[0] = t
    if dx_sum.shape[0] == n:
        for i in range(n):
            dx_sum[i] += x[i]
    return True, feedback(nav, x, est, layout), P_new, nu, S
