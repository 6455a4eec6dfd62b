"""The RTS backward pass (navreplay.filters.rts) against the batch least-squares solution of a
linear-Gaussian model, in open-loop and error-state (feedback) form, in one chunk and many."""

import numpy as np
import pytest

from navreplay.filters import rts


def _model(seed, n=4, N=40, frozen=False):
    """A random linear-Gaussian model: x0 ~ N(m0, P0), x_{k+1} = Phi_k x_k + w_k,
    z_k = H_k x_k + v_k at some epochs (none at others)."""
    rng = np.random.default_rng(seed)
    m0 = rng.normal(size=n)
    A = rng.normal(size=(n, n))
    P0 = A @ A.T + n * np.eye(n)
    phis, Qs, Hs, Rs = [], [], [], []
    for k in range(N):
        phis.append(np.eye(n) + 0.1 * rng.normal(size=(n, n)))
        B = 0.3 * rng.normal(size=(n, n))
        Q = B @ B.T + 0.01 * np.eye(n)
        if frozen:  # the last state a random constant: no process noise
            Q[-1, :] = Q[:, -1] = 0.0
            phis[-1][-1, :] = 0.0
            phis[-1][-1, -1] = 1.0
        Qs.append(Q)
        if k % 3 == 1:  # no measurement at two epochs of three
            Hs.append(None)
            Rs.append(None)
        else:
            m = 2
            Hs.append(rng.normal(size=(m, n)))
            C = rng.normal(size=(m, m))
            Rs.append(C @ C.T + 0.5 * np.eye(m))
    x = rng.multivariate_normal(m0, P0)
    zs = []
    for k in range(N):
        if k > 0:
            x = phis[k] @ x + rng.multivariate_normal(np.zeros(n), Qs[k])
        zs.append(None if Hs[k] is None
                  else Hs[k] @ x + rng.multivariate_normal(np.zeros(Rs[k].shape[0]), Rs[k]))
    return m0, P0, phis, Qs, Hs, Rs, zs


def _batch(m0, P0, phis, Qs, Hs, Rs, zs):
    """Information form of the whole problem: the MAP of all states and its covariance."""
    n, N = m0.shape[0], len(phis)
    Lam = np.zeros((N * n, N * n))
    eta = np.zeros(N * n)

    def add(J, W, r):  # residual r - J X with weight W over the stacked states
        nonlocal Lam, eta
        Lam += J.T @ W @ J
        eta += J.T @ W @ r

    J = np.zeros((n, N * n))
    J[:, :n] = np.eye(n)
    add(J, np.linalg.inv(P0), m0)
    for k in range(1, N):
        J = np.zeros((n, N * n))
        J[:, k * n:(k + 1) * n] = np.eye(n)
        J[:, (k - 1) * n:k * n] = -phis[k]
        add(J, np.linalg.pinv(Qs[k]), np.zeros(n))
    for k in range(N):
        if Hs[k] is not None:
            J = np.zeros((Hs[k].shape[0], N * n))
            J[:, k * n:(k + 1) * n] = Hs[k]
            add(J, np.linalg.inv(Rs[k]), zs[k])
    X = np.linalg.solve(Lam, eta).reshape(N, n)
    cov = np.linalg.inv(Lam)
    return X, np.stack([cov[k * n:(k + 1) * n, k * n:(k + 1) * n] for k in range(N)])


def _forward(m0, P0, phis, Qs, Hs, Rs, zs, feedback):
    """Kalman filter storing what the smoother needs. With ``feedback``: an error-state filter
    with a nominal state it corrects after each update (error = nominal - truth), storing the
    nominal; else open loop (dx = x+ - x-)."""
    n, N = m0.shape[0], len(phis)
    x, P = m0.copy(), P0.copy()
    out = {k: [] for k in ("x", "P", "phi", "P_prior", "dx")}
    for k in range(N):
        if k > 0:
            x = phis[k] @ x
            P = phis[k] @ P @ phis[k].T + Qs[k]
        P_prior = P.copy()
        dx = np.zeros(n)
        if Hs[k] is not None:
            H, R = Hs[k], Rs[k]
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T
            if feedback:  # estimate of e = x_nom - x, fed back
                dx = K @ (H @ x - zs[k])
                x = x - dx
            else:
                dx = K @ (zs[k] - H @ x)
                x = x + dx
            I_KH = np.eye(n) - K @ H
            P = I_KH @ P @ I_KH.T + K @ R @ K.T
        for key, v in (("x", x), ("P", P), ("phi", phis[k] if k else np.eye(n)),
                       ("P_prior", P_prior), ("dx", dx)):
            out[key].append(np.array(v))
    return {k: np.stack(v) for k, v in out.items()}


@pytest.mark.parametrize("feedback", [False, True])
@pytest.mark.parametrize("chunk", [None, 7])
def test_equals_batch_least_squares(feedback, chunk):
    model = _model(11)
    X_ls, P_ls = _batch(*model)
    f = _forward(*model, feedback=feedback)
    if chunk is None:
        d, P_s = rts.smooth(f["P"], f["phi"], f["P_prior"], f["dx"])
    else:  # chunks backward, carrying across their boundaries
        N = f["dx"].shape[0]
        d, P_s = np.empty_like(f["dx"]), np.empty_like(f["P"])
        carry = None
        for a in reversed(range(0, N, chunk)):
            b = min(a + chunk, N)
            d[a:b], P_s[a:b], carry = rts.backward_chunk(
                f["P"][a:b], f["phi"][a:b], f["P_prior"][a:b], f["dx"][a:b], carry)
    x_s = f["x"] - d if feedback else f["x"] + d
    scale = 1.0 + np.abs(X_ls).max()
    np.testing.assert_allclose(x_s, X_ls, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(P_s, P_ls, rtol=0, atol=1e-9 * (1.0 + np.abs(P_ls).max()))
    # invariants: the last epoch is the filter's; smoothing never adds uncertainty
    np.testing.assert_array_equal(d[-1], 0.0)
    np.testing.assert_array_equal(P_s[-1], f["P"][-1])
    for k in range(len(P_s)):
        assert np.linalg.eigvalsh(f["P"][k] - P_s[k]).min() > -1e-10
    # and it is not the filter: the measurements after each epoch moved the estimate
    assert np.abs(d[:-1]).max() > 1e-3


def test_frozen_state_zero_variance():
    """A state with zero a-priori variance is known exactly: the pseudo-inverse gain keeps it."""
    m0, P0, phis, Qs, Hs, Rs, zs = _model(5, frozen=True)
    P0 = P0.copy()
    P0[-1, :] = P0[:, -1] = 0.0  # known from the start: no variance ever
    f = _forward(m0, P0, phis, Qs, Hs, Rs, zs, feedback=True)
    d, P_s = rts.smooth(f["P"], f["phi"], f["P_prior"], f["dx"])
    assert np.all(np.isfinite(d)) and np.all(np.isfinite(P_s))
    np.testing.assert_array_equal(d[:, -1], 0.0)
    np.testing.assert_array_equal(P_s[:, -1, :], 0.0)
    # the other states as the batch solution with the frozen state's value fixed at m0
    sub = slice(0, 3)
    n = 3
    zs_sub = [None if z is None else z - H[:, -1] * m0[-1] for z, H in zip(zs, Hs, strict=True)]
    phis_sub = [p[sub, sub] for p in phis]
    # the frozen state feeds the others through Phi: a known input, moved into the model
    X_ls, P_ls = _batch_with_input(m0[sub], P0[sub, sub], phis_sub,
                                   [p[sub, -1] * m0[-1] for p in phis], [q[sub, sub] for q in Qs],
                                   [None if H is None else H[:, sub] for H in Hs], Rs, zs_sub, n)
    np.testing.assert_allclose(f["x"][:, sub] - d[:, sub], X_ls, atol=1e-9)
    np.testing.assert_allclose(P_s[:, sub, sub], P_ls, atol=1e-9)


def _batch_with_input(m0, P0, phis, u, Qs, Hs, Rs, zs, n):
    N = len(phis)
    Lam = np.zeros((N * n, N * n))
    eta = np.zeros(N * n)
    J = np.zeros((n, N * n))
    J[:, :n] = np.eye(n)
    Lam += J.T @ np.linalg.inv(P0) @ J
    eta += J.T @ np.linalg.inv(P0) @ m0
    for k in range(1, N):
        J = np.zeros((n, N * n))
        J[:, k * n:(k + 1) * n] = np.eye(n)
        J[:, (k - 1) * n:k * n] = -phis[k]
        W = np.linalg.inv(Qs[k])
        Lam += J.T @ W @ J
        eta += J.T @ W @ u[k]
    for k in range(N):
        if Hs[k] is not None:
            J = np.zeros((Hs[k].shape[0], N * n))
            J[:, k * n:(k + 1) * n] = Hs[k]
            W = np.linalg.inv(Rs[k])
            Lam += J.T @ W @ J
            eta += J.T @ W @ zs[k]
    X = np.linalg.solve(Lam, eta).reshape(N, n)
    cov = np.linalg.inv(Lam)
    return X, np.stack([cov[k * n:(k + 1) * n, k * n:(k + 1) * n] for k in range(N)])


def test_reset_jacobian_identity_is_no_reset():
    model = _model(3, N=12)
    f = _forward(*model, feedback=True)
    a = rts.smooth(f["P"], f["phi"], f["P_prior"], f["dx"])
    b = rts.smooth(f["P"], f["phi"], f["P_prior"], f["dx"],
                   reset=np.broadcast_to(np.eye(4), f["P"].shape).copy())
    np.testing.assert_allclose(a[0], b[0], atol=1e-12)
    np.testing.assert_allclose(a[1], b[1], atol=1e-12)
