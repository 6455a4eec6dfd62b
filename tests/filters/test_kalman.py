"""Shared Kalman math: closed-form problems, Joseph form, checks, frozen states, NIS."""

import functools

import numpy as np
import pytest
from scipy import stats

from navreplay.filters import kalman
from navreplay.filters.kalman import FilterDivergedError


def test_scalar_random_constant_closed_form():
    # x constant, z_k = x + v_k, v ~ N(0, R): P_k = P0 R / (R + k P0) and
    # x_k = (R x0 + P0 sum z) / (R + k P0)
    rng = np.random.default_rng(1)
    P0, R, x0 = 4.0, 0.25, 0.3
    x, P = np.array([x0]), np.array([[P0]])
    H = np.ones((1, 1))
    zs = 2.0 + rng.normal(0.0, np.sqrt(R), 50)
    for k, zk in enumerate(zs, start=1):
        x, P = kalman.predict(x, P, np.eye(1), np.zeros((1, 1)))
        c = kalman.correct(x, P, np.array([zk]), H, np.array([R]))
        x, P = c.x, c.P
        assert P[0, 0] == pytest.approx(P0 * R / (R + k * P0), rel=1e-12)
        assert x[0] == pytest.approx((R * x0 + P0 * zs[:k].sum()) / (R + k * P0), rel=1e-12)


def _textbook_cv(x, P, zs, dt, q, r):
    """Constant-velocity filter written the textbook way (explicit inverse, standard form)."""
    Phi = np.array([[1.0, dt], [0.0, 1.0]])
    Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    H = np.array([[1.0, 0.0]])
    out = []
    for zk in zs:
        x = Phi @ x
        P = Phi @ P @ Phi.T + Q
        S = H @ P @ H.T + r
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (np.array([zk]) - H @ x)
        P = (np.eye(2) - K @ H) @ P
        out.append((x.copy(), P.copy()))
    return out


def test_constant_velocity_matches_textbook():
    rng = np.random.default_rng(2)
    dt, q, r = 0.5, 0.01, 0.04
    zs = 0.3 * np.arange(40) * dt + rng.normal(0.0, 0.2, 40)
    F = np.array([[0.0, 1.0], [0.0, 0.0]])
    G = np.array([[0.0], [1.0]])
    Phi, Qd = kalman.van_loan(F, G, np.array([q]), dt)
    # exact: F^2 = 0, so the second-order series is exact too
    np.testing.assert_allclose(kalman.discretize(F, dt), Phi, atol=1e-15)
    np.testing.assert_allclose(
        Qd, q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), rtol=1e-12
    )
    x, P = np.zeros(2), np.diag([1.0, 1.0])
    ref = _textbook_cv(x.copy(), P.copy(), zs, dt, q, r)
    H = np.array([[1.0, 0.0]])
    for zk, (x_ref, P_ref) in zip(zs, ref):
        x, P = kalman.predict(x, P, Phi, Qd)
        c = kalman.correct(x, P, np.array([zk]), H, np.array([[r]]))
        x, P = c.x, c.P
        np.testing.assert_allclose(x, x_ref, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(P, P_ref, rtol=1e-9, atol=1e-14)


def test_discrete_noise_approaches_van_loan_for_small_steps():
    rng = np.random.default_rng(3)
    F = 0.1 * rng.normal(size=(6, 6))
    G = rng.normal(size=(6, 3))
    Qc = np.array([1.0, 2.0, 0.5])
    _, Qd_exact = kalman.van_loan(F, G, Qc, 1e-3)
    Qd = kalman.discrete_noise(G, Qc, 1e-3)
    np.testing.assert_allclose(Qd, Qd_exact, rtol=1e-3, atol=1e-3 * np.abs(Qd_exact).max())
    np.testing.assert_allclose(
        kalman.discrete_noise(G, np.diag(Qc), 0.1), kalman.discrete_noise(G, Qc, 0.1)
    )


def test_joseph_form_keeps_P_psd_where_the_standard_form_does_not():
    # ill-conditioned: huge prior, almost perfect measurements of combinations of the states
    rng = np.random.default_rng(4)
    n = 6
    P = np.diag([1e8, 1e6, 1.0, 1e-4, 1e4, 1e2])
    P_std = P.copy()
    x = np.zeros(n)
    for _ in range(30):
        H = rng.normal(size=(2, n))
        R = np.diag([1e-10, 1e-9])
        c = kalman.correct(x, P, rng.normal(size=2), H, R)
        P = c.P
        kalman.check_covariance(P)
        assert np.linalg.eigvalsh(P / np.sqrt(np.outer(np.diag(P), np.diag(P)))).min() > -1e-9
        K = P_std @ H.T @ np.linalg.inv(H @ P_std @ H.T + R)
        P_std = (np.eye(n) - K @ H) @ P_std
    # the standard form has lost symmetry / definiteness by now
    with pytest.raises(FilterDivergedError):
        kalman.check_covariance(P_std)


def test_psd_violation_raises_with_time():
    P = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3 and -1
    with pytest.raises(FilterDivergedError, match=r"t = 12\.500000 s.*positive semi-definite"):
        kalman.check_covariance(P, t=12.5)
    with pytest.raises(FilterDivergedError, match="not symmetric"):
        kalman.check_covariance(np.array([[1.0, 0.1], [0.2, 1.0]]))
    with pytest.raises(FilterDivergedError, match="negative variance"):
        kalman.check_covariance(np.diag([1.0, -1e-30]))
    with pytest.raises(FilterDivergedError, match="non-finite"):
        kalman.check_covariance(np.array([[np.nan, 0.0], [0.0, 1.0]]))
    with pytest.raises(FilterDivergedError, match="t = 3.000000 s"):
        kalman.predict(np.zeros(2), P, np.eye(2), np.zeros((2, 2)), t=3.0)
    with pytest.raises(FilterDivergedError, match="S is not positive definite"):
        kalman.correct(np.zeros(2), np.zeros((2, 2)), np.zeros(1), np.ones((1, 2)), np.zeros(1))


def test_shapes_checked():
    with pytest.raises(ValueError, match="H must have shape"):
        kalman.correct(np.zeros(3), np.eye(3), np.zeros(2), np.ones((2, 2)), np.ones(2))
    with pytest.raises(ValueError, match="vector"):
        kalman.correct(np.zeros((3, 1)), np.eye(3), np.zeros(1), np.ones((1, 3)), np.ones(1))
    with pytest.raises(ValueError, match="Phi must have shape"):
        kalman.predict(np.zeros(3), np.eye(3), np.eye(2), np.eye(3))


def test_zero_variance_states_are_allowed():
    # inert states: zero rows and columns, PSD but not PD
    P = np.diag([1.0, 0.0, 1e-14, 0.0])
    kalman.check_covariance(P)
    c = kalman.correct(np.zeros(4), P, np.ones(2), np.eye(2, 4), np.ones(2))
    assert c.P[1, 1] == 0.0 and c.P[3, 3] == 0.0


def test_frozen_states_not_updated():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(5, 5))
    P = A @ A.T + np.eye(5)
    x = rng.normal(size=5)
    H = rng.normal(size=(3, 5))
    frozen = np.array([False, True, False, False, True])
    c = kalman.correct(x, P, rng.normal(size=3), H, np.ones(3), frozen=frozen)
    np.testing.assert_array_equal(c.x[frozen], x[frozen])
    np.testing.assert_allclose(c.P[np.ix_(frozen, frozen)], P[np.ix_(frozen, frozen)], rtol=1e-12)
    free = ~frozen
    assert np.all(np.diag(c.P)[free] < np.diag(P)[free])
    # the suboptimal (masked) gain gives a larger covariance than the optimal one
    c_opt = kalman.correct(x, P, np.zeros(3), H, np.ones(3))
    assert np.linalg.eigvalsh(c.P - c_opt.P).min() > -1e-12


@functools.cache
def _cv2d():
    dt, q = 0.1, 0.5
    F = np.zeros((4, 4))
    F[0, 2] = F[1, 3] = 1.0
    G = np.zeros((4, 2))
    G[2, 0] = G[3, 1] = 1.0
    Phi, Qd = kalman.van_loan(F, G, np.array([q, q]), dt)
    return Phi, Qd, np.linalg.cholesky(Qd + 1e-18 * np.eye(4))


def _run_cv2d(rng, steps):
    Phi, Qd, Lq = _cv2d()
    H = np.eye(2, 4)
    R = np.diag([0.3**2, 0.5**2])
    x_true = np.array([0.0, 0.0, 1.0, -1.0])
    P = np.diag([1.0, 1.0, 0.5, 0.5])
    x = x_true + np.linalg.cholesky(P) @ rng.normal(size=4)
    nis = np.empty(steps)
    for k in range(steps):
        x_true = Phi @ x_true + Lq @ rng.normal(size=4)
        x, P = kalman.predict(x, P, Phi, Qd)
        z = H @ x_true + np.sqrt(np.diag(R)) * rng.normal(size=2)
        c = kalman.correct(x, P, z, H, R)
        x, P = c.x, c.P
        nis[k] = c.nis
    assert c.nis == pytest.approx(c.nu @ np.linalg.solve(c.S, c.nu))
    e = x - x_true
    return nis, e @ np.linalg.solve(P, e)


def test_nis_of_a_simulated_linear_system_inside_chi2_bounds():
    # innovations of a consistent filter are white: the time average has N*m dof
    nis, _ = _run_cv2d(np.random.default_rng(6), 2000)
    lo, hi = stats.chi2.ppf([0.025, 0.975], 2 * nis.size) / nis.size
    assert lo < nis.mean() < hi


def test_nees_of_a_simulated_linear_system_inside_chi2_bounds():
    # estimation errors are correlated in time: average over independent runs instead
    rng = np.random.default_rng(7)
    runs = 150
    nees = np.array([_run_cv2d(rng, 30)[1] for _ in range(runs)])
    lo, hi = stats.chi2.ppf([0.025, 0.975], 4 * runs) / runs
    assert lo < nees.mean() < hi


@pytest.mark.parametrize("prior", ["zero", "nonzero"])
@pytest.mark.parametrize("full_R", [False, True])
def test_batched_correction_equals_the_shared_kalman_correction(prior, full_R):
    rng = np.random.default_rng(7)
    B = 5
    A = rng.normal(size=(B, 3, 3))
    P = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(3)
    H = rng.normal(size=(B, 6, 3))
    z = rng.normal(size=(B, 6))
    R = rng.uniform(0.1, 2.0, size=(B, 6))
    if full_R:
        G = 0.3 * rng.normal(size=(B, 6, 6))
        R = G @ np.swapaxes(G, -1, -2) + R[..., None] * np.eye(6)
    x = np.zeros((B, 3)) if prior == "zero" else rng.normal(size=(B, 3))
    c = kalman.correct_batch(x, P, z, H, R)
    for i in range(B):
        k = kalman.correct(x[i], P[i], z[i], H[i], R[i])
        np.testing.assert_allclose(c.x[i], k.x, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(c.P[i], k.P, rtol=1e-12, atol=1e-14)
        assert c.nis[i] == pytest.approx(k.nis, rel=1e-12)
        np.testing.assert_allclose(c.nu[i], k.nu, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(c.S[i], k.S, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(c.nu_normalised[i], k.nu_normalised, rtol=1e-12, atol=1e-14)
    bad = P.copy()
    bad[2] = -np.eye(3)
    with pytest.raises(FilterDivergedError):
        kalman.correct_batch(x, bad, z, H, np.full((B, 6), -10.0))


def test_batched_prediction_equals_the_shared_kalman_prediction():
    rng = np.random.default_rng(8)
    B, n = 4, 5
    A = rng.normal(size=(B, n, n))
    P = A @ np.swapaxes(A, -1, -2)
    x = rng.normal(size=(B, n))
    Phi = np.eye(n) + 0.1 * rng.normal(size=(B, n, n))
    Qd = np.diag(rng.uniform(0.01, 0.1, n))
    xb, Pb = kalman.predict_batch(x, P, Phi, Qd)
    for i in range(B):
        xi, Pi = kalman.predict(x[i], P[i], Phi[i], Qd)
        np.testing.assert_allclose(xb[i], xi, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(Pb[i], Pi, rtol=1e-14, atol=1e-15)
    with pytest.raises(FilterDivergedError, match="t = 2.000000 s"):
        kalman.predict_batch(x, np.full((B, n, n), np.nan), Phi, Qd, t=2.0)


@pytest.mark.parametrize(("n", "r", "nc"), [(15, 9, 15), (21, 9, 18), (24, 9, 15), (9, 6, 6)])
def test_row_prediction_kernel_equals_the_dense_one_and_numpy(n, r, nc):
    # Phi differs from I only in its first r rows, over the columns cols (the INS error model:
    # 9 navigation rows; the gyro z-rate columns placed after other states)
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n))
    P = A @ A.T + np.eye(n)
    cols = np.r_[np.arange(r), rng.choice(np.arange(r, n), nc - r, replace=False)].astype(np.int64)
    F = np.zeros((n, n))
    F[np.ix_(np.arange(r), cols)] = 0.1 * rng.normal(size=(r, nc))
    Phi = kalman.discretize(F, 0.1)
    np.testing.assert_allclose(Phi, np.eye(n) + F * 0.1 + (F @ F) * 0.005, atol=1e-15)
    Fc = np.ascontiguousarray(F[np.ix_(np.arange(r), cols)])
    M = np.empty((r, nc))
    kalman.transition_rows_kernel(Fc, r, 0.1, M)
    np.testing.assert_allclose(M, Phi[np.ix_(np.arange(r), cols)], rtol=0, atol=1e-15)
    Qd = rng.normal(size=(n, n)) * 1e-3
    Qd = Qd @ Qd.T
    ref = Phi @ P @ Phi.T + Qd
    ref = 0.5 * (ref + ref.T)
    dense = kalman.predict_kernel(P, Phi, Qd)
    rows = kalman.predict_rows_kernel(P, M, cols, Qd, np.empty((r, n)))
    for got in (dense, rows):
        np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-13)
        np.testing.assert_array_equal(got, got.T)


def test_measurement_shape_and_innovation_record():
    # a stacked measurement (z, H, R) applied once; the record of a block of rows is that block
    rng = np.random.default_rng(3)
    A = rng.normal(size=(4, 4))
    P = A @ A.T + np.eye(4)
    m = kalman.Measurement(rng.normal(size=3), rng.normal(size=(3, 4)), np.array([1.0, 2.0, 3.0]))
    c = kalman.correct(np.zeros(4), P, *m, t=1.5)
    S = m.H @ P @ m.H.T + np.diag(m.R)
    np.testing.assert_allclose(c.S, S, rtol=1e-12)
    np.testing.assert_allclose(c.nu, m.z)
    assert c.nis == pytest.approx(m.z @ np.linalg.solve(S, m.z), rel=1e-12)
    rec = c.innovation("velocity", 1.5, slice(0, 2))
    assert (rec.name, rec.t) == ("velocity", 1.5)
    np.testing.assert_array_equal(rec.nu, c.nu[:2])
    np.testing.assert_array_equal(rec.S, c.S[:2, :2])
    whole = c.innovation("all", 1.5)
    np.testing.assert_array_equal(whole.S, c.S)


def test_markov_states_are_van_loans_exact_discretisation():
    """Eq. (5a) in place on the Markov rows and columns of a full P equals the dense
    prediction with Van Loan's exact Phi and Qd for F = diag(0, ..., -1/tau) (a random walk,
    a random constant and two Markov states of other time constants); a single state reaches
    its stationary variance."""
    rng = np.random.default_rng(4)
    n = 4
    A = rng.normal(size=(n, n))
    P = A @ A.T
    rate = np.array([0.0, 0.0, 1.0 / 60.0, 1.0 / 600.0])
    q = np.array([0.3, 0.0, 2.0 * 4.0 / 60.0, 2.0 * 0.25 / 600.0])
    dt = 7.0
    Phi, Qd = kalman.van_loan(np.diag(-rate), np.eye(n), q, dt)
    _, ref = kalman.predict(np.zeros(n), P, Phi, Qd)
    got = P.copy()
    for i in (0, 1):  # the random walk and the constant: Phi = 1, Qd = q dt
        got[i, i] += q[i] * dt
    kalman.markov_rows_kernel(got, rate, q, dt)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-14)
    one = np.array([[9.0]])
    for _ in range(200):
        kalman.markov_rows_kernel(one, np.array([0.1]), np.array([2.0 * 4.0 * 0.1]), 1.0)
    np.testing.assert_allclose(one, [[4.0]], rtol=1e-8)
