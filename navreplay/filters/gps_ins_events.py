"""A run of replay events of ``gps-ins`` in one compiled call.

:func:`run_events` does for each event what the replay engine's one-by-one path does through
:meth:`~navreplay.filters.gps_ins.GpsInsFilter.propagate`,
:meth:`~navreplay.filters.gps_ins.GpsInsFilter.update` and
:meth:`~navreplay.filters.gps_ins.GpsInsFilter.estimate`, with the same kernels in the same
order (so the same bits): the IMU segment up to the event (bias, gyro and accelerometer
scale-factor and misalignment compensation, strapdown, covariance steps), the GPS update
(:func:`navreplay.filters.gnss_models.gps_update`), the estimate when the event is the last of
its time. The first event that fails any check is undone and the call returns: the engine
replays that event one by one, which names the problem.

The small state that carries over between events is packed into one vector (:data:`LAYOUT`)
so that an event is undone by copying it back.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from navreplay.core.jit import kernel
from navreplay.filters import gnss_models as gnss
from navreplay.filters.ins_time_update import (
    _TIME_TOL,
    Imu,
    Model,
    Open,
    Work,
    _close_step,
    _propagate_segment,
    compensate_accel,
    compensate_gyro,
)
from navreplay.filters.kalman import _covariance_ok

TICK = 0
"""Event code: no measurement (an output tick or a stream the filter does not use)."""

LAYOUT = {"prev": (0, 6), "open_nav": (6, 16), "open_sums": (16, 23), "b_a": (23, 26),
          "b_g": (26, 29), "k_g": (29, 38), "k_a": (38, 47), "lever": (47, 50),
          "omega": (50, 53), "gm": (53, 56), "gm_t": (56, 57)}
"""Slices of the packed state: coning/sculling increments, the open covariance step, the
bias, gyro and accelerometer scale-factor and misalignment (up to three columns each),
lever-arm estimates, the last compensated body rate, the GNSS Gauss-Markov estimate and its
time."""
PACKED = 57


class Events(NamedTuple):
    """The events of a run (:class:`navreplay.filters.base.EventRun`, codes mapped to the
    kernel's): IMU segment ends (E,), :data:`TICK`, ``gnss.POSITION`` or ``gnss.VELOCITY``
    (E,), sample rows (E,), times [s] (E,), whether an estimate is recorded (E,)."""

    ends: np.ndarray
    codes: np.ndarray
    rows: np.ndarray
    t_ev: np.ndarray
    record: np.ndarray


class Gnss(NamedTuple):
    """The GNSS samples of a run: positions and their sigmas (K, 3), velocities and their
    sigmas (L, 3), and the sigma scales of each."""

    pos: np.ndarray
    pos_sigma: np.ndarray
    vel: np.ndarray
    vel_sigma: np.ndarray
    pos_scale: float
    vel_scale: float


class Options(NamedTuple):
    """The filter's options a run needs: lever-arm states, the first GNSS Gauss-Markov state
    (-1: none) and the model of that error, and the relative tolerance of the covariance
    checks."""

    lever_states: bool
    gp: int
    gauss_markov: gnss.GaussMarkov
    rtol: float


class Rows(NamedTuple):
    """The rows the estimates go to: times (E,), states (E, n), covariances (E, n, n),
    navigation vectors (E, 10)."""

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    nav: np.ndarray


class Smoothing(NamedTuple):
    """What a smoother needs of the run (:class:`~navreplay.filters.ins_smoothing.InsSmoothing`;
    off when ``dx`` has no entries): the sum of the corrections fed back since the last
    output (n,), the covariance before the first update since then (n, n) and whether it is
    kept (1,), all carried over between runs and updated in place; and the rows each output
    of the run writes: the transition from the previous output (R, n, n, the product kept in
    the time update's ``work.Phi``), the covariance before the updates (R, n, n) and the
    corrections (R, n)."""

    dx: np.ndarray
    P_prior: np.ndarray
    has_prior: np.ndarray
    phi_out: np.ndarray
    P_prior_out: np.ndarray
    dx_out: np.ndarray


NO_SMOOTHING = Smoothing(np.zeros(0), np.zeros((0, 0)), np.zeros(1), np.zeros((0, 0, 0)),
                         np.zeros((0, 0, 0)), np.zeros((0, 0)))
"""A run without a smoother."""


class Updates(NamedTuple):
    """The rows the innovations go to: measurement code (U,), time (U,), nu (U, 3),
    S (U, 3, 3)."""

    code: np.ndarray
    t: np.ndarray
    nu: np.ndarray
    S: np.ndarray


@kernel
def _any(a: np.ndarray) -> bool:
    for v in a:
        if v != 0.0:
            return True
    return False


@kernel(inline="always")
def _copy(dst: np.ndarray, src: np.ndarray) -> None:
    """``dst[...] = src`` (same shape, 1 or 2 dimensions) by loops: an array assignment
    compiles numba's formatted shape error, a few seconds of a first compilation."""
    for i in range(src.size):
        dst.flat[i] = src.flat[i]


@kernel
def _smoothing_row(sm: Smoothing, m: int, Phi: np.ndarray, P: np.ndarray) -> None:
    """Row m of the smoother's rows at an estimate with covariance P: the transition since
    the previous one, the covariance before the updates (P without update), the corrections;
    then the next step starts."""
    n = P.shape[0]
    held = sm.has_prior[0] != 0.0
    for r in range(n):
        sm.dx_out[m, r] = sm.dx[r]
        sm.dx[r] = 0.0
        for c in range(n):
            sm.phi_out[m, r, c] = Phi[r, c]
            Phi[r, c] = 1.0 if r == c else 0.0
            sm.P_prior_out[m, r, c] = sm.P_prior[r, c] if held else P[r, c]
    sm.has_prior[0] = 0.0


@kernel(nogil=True)  # an export's writing thread goes on meanwhile
def run_events(
    nav: np.ndarray, P: np.ndarray, t_nav: float, s: np.ndarray, imu: Imu, events: Events,
    gnss_samples: Gnss, options: Options, step: float, model: Model, work: Work, out: Rows,
    updates: Updates, smoothing: Smoothing,
) -> tuple[int, int, int, np.ndarray, np.ndarray, float]:
    """Apply the events of ``events`` in order (see the module docstring).

    ``ends[e]`` is the end of the IMU segment handed over before event e (indices into
    ``imu``); ``codes[e]`` :data:`TICK`, ``gnss.POSITION`` or ``gnss.VELOCITY`` with the
    sample in row ``rows[e]`` of its columns in ``gnss_samples``; ``record[e]`` asks for an
    estimate after it. Estimates go to the rows of ``out``, innovations to ``updates``; ``s``
    is the packed state (:data:`LAYOUT`), ``step``, ``model`` and ``work`` those of the
    filter's :class:`~navreplay.filters.ins_time_update.TimeUpdate`. With a smoother
    (``smoothing``), each estimate also writes its row of ``smoothing`` as
    :meth:`~navreplay.filters.ins_smoothing.InsSmoothing.smoothing_step` returns it.

    Returns (done, estimates, innovations, nav, P, t_nav): the events applied (all, or up to
    the first that failed, undone), the rows written and the state after them; ``s`` holds
    the packed state after them.
    """
    t, omega, f = imu
    ends, codes, rows, t_ev, record = events
    gps_pos, gps_pos_sigma, gps_vel, gps_vel_sigma, pos_scale, vel_scale = gnss_samples
    lever_states, gp, gauss_markov, rtol = options
    t_out, x_out, P_out, nav_out = out
    inn_code, inn_t, inn_nu, inn_S = updates
    gz, ga, ng, na = model.gz, model.ga, model.ng, model.na
    n = P.shape[0]
    prev = s[0:6]
    open_nav = s[6:16]
    open_sums = s[16:23]
    b_a = s[23:26]
    b_g = s[26:29]
    k_z = s[29:29 + 3 * ng]
    k_a = s[38:38 + 3 * na]
    lever = s[47:50]
    w_last = s[50:53]
    open_step = Open(open_nav, open_sums)
    est = gnss.Estimates(b_a, b_g, lever, k_z, k_a, s[53:56], s[56:57])
    layout = gnss.Layout(lever_states, gz, ng, ga, na, gp)
    gm_now = np.empty(3)
    snap = np.empty(s.shape[0])
    smooth = smoothing.dx.shape[0] == n
    acc, prior, has_prior = smoothing.dx, smoothing.P_prior, smoothing.has_prior
    Phi = work.Phi
    phi_snap = np.empty(Phi.shape)
    acc_snap = np.empty(acc.shape[0])
    m = 0
    k = 0
    a = 0
    for e in range(codes.shape[0]):
        for c in range(s.shape[0]):  # (loops: an array assignment compiles numba's
            snap[c] = s[c]  # formatted shape error)
        nav0, P0, t0, k0 = nav, P, t_nav, k
        prior0 = has_prior[0]
        if smooth:
            _copy(phi_snap, Phi)
            _copy(acc_snap, acc)
        ok = True
        b = ends[e]
        if b > a:
            w = omega[a:b]
            if _any(k_z):
                w = compensate_gyro(w, b_g, k_z)
            fb = f[a:b]
            if _any(k_a):
                fb = compensate_accel(fb, b_a, k_a)
            first = 0
            while first < b - a and t[a + first] <= t_nav + _TIME_TOL:
                first += 1
            if first < b - a:
                code, nav_b, P_b = _propagate_segment(
                    nav, P, t[a:b], t_nav, w, fb, b_a, b_g, first, b - a, prev, step, model,
                    open_step, work, w_last)
                if code == -1:
                    nav, P, t_nav = nav_b, P_b, t[b - 1]
                    closes = open_sums[0] > 0.0 and (record[e] or (
                        codes[e] != TICK and not t_ev[e] < t_nav - 1e-6))
                    if not closes:  # else P is checked after the close that follows
                        ok = _covariance_ok(P, rtol)
                else:
                    ok = False
        kind = codes[e]
        if ok and kind != TICK and not t_ev[e] < t_nav - 1e-6:
            if open_sums[0] > 0.0:
                P = _close_step(P, model, open_step, work)
                ok = _covariance_ok(P, rtol)
            if ok:
                if smooth and not has_prior[0]:
                    _copy(prior, P)
                    has_prior[0] = 1.0
                r = rows[e]
                if kind == gnss.POSITION:
                    lag = max(t_ev[e] - t_nav, 0.0)
                    ok, nav, P, nu, S = gnss.gps_update(
                        kind, nav, P, t_nav, gps_pos[r], gps_pos_sigma[r], pos_scale, lag,
                        w_last, est, layout, gauss_markov, rtol, acc)
                else:
                    ok, nav, P, nu, S = gnss.gps_update(
                        kind, nav, P, t_nav, gps_vel[r], gps_vel_sigma[r], vel_scale, 0.0,
                        w_last, est, layout, gauss_markov, rtol, acc)
                if ok:
                    inn_code[k] = kind
                    inn_t[k] = t_ev[e]
                    for i in range(3):
                        inn_nu[k, i] = nu[i]
                        for j in range(3):
                            inn_S[k, i, j] = S[i, j]
                    k += 1
        if ok and record[e]:
            if open_sums[0] > 0.0:
                P = _close_step(P, model, open_step, work)
                ok = _covariance_ok(P, rtol)
            if ok:
                t_out[m] = t_nav
                for c in range(n):
                    x_out[m, c] = 0.0
                for c in range(3):
                    x_out[m, 9 + c] = b_a[c]
                    x_out[m, 12 + c] = b_g[c]
                    if lever_states:
                        x_out[m, 15 + c] = lever[c]
                for c in range(3 * ng):
                    x_out[m, gz + c] = k_z[c]
                for c in range(3 * na):
                    x_out[m, ga + c] = k_a[c]
                if gp >= 0:
                    gnss.gm_at(est.gm, est.gm_t[0], t_nav, gauss_markov.tau, gm_now)
                    for c in range(3):
                        x_out[m, gp + c] = gm_now[c]
                for r in range(n):
                    for c in range(n):
                        P_out[m, r, c] = P[r, c]
                for c in range(nav.shape[0]):
                    nav_out[m, c] = nav[c]
                if smooth:
                    _smoothing_row(smoothing, m, Phi, P)
                m += 1
        if not ok:  # undo the event: the engine replays it one by one
            for c in range(s.shape[0]):
                s[c] = snap[c]
            if smooth:
                _copy(Phi, phi_snap)
                _copy(acc, acc_snap)
                has_prior[0] = prior0
            return e, m, k0, nav0, P0, t0
        a = b
    return codes.shape[0], m, k, nav, P, t_nav
