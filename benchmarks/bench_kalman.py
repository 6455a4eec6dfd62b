"""The covariance prediction: does the structure-exploiting kernel pay, and where?

``P <- Phi P Phi^T + Qd`` (kalman eq. 6) for the shapes of the built-in filters, each a
thousand steps in one compiled loop (no Python call in between, as inside the INS time update
and the transfer-alignment step), measured in the same run:

- dense: :func:`navreplay.filters.kalman.predict_kernel`;
- rows: :func:`navreplay.filters.kalman.predict_rows_kernel`, for a Phi that is the identity
  but for its first r rows (non-zero over nc columns);
- numpy: ``Phi @ P @ Phi.T + Qd`` and its symmetrisation, per Python call (what
  :func:`navreplay.filters.kalman.predict` did before it used the dense kernel).

The ratio dense / rows says where the structure pays (the filters use the rows kernel there).

    python -m benchmarks kalman
"""

from __future__ import annotations

import numba
import numpy as np

from benchmarks import best
from navreplay.filters import kalman

STEPS = 1000
SHAPES = (  # label, n, r, nc
    ("ins (15 states)", 15, 9, 15),
    ("gps-ins, gyro z-rate states (18)", 18, 9, 18),
    ("gps-ins, lever arm + gyro z-rate (21)", 21, 9, 18),
    ("rpm-aided-ins (24)", 24, 9, 15),
    ("transfer-alignment partial (9)", 9, 6, 6),
)


@numba.njit(cache=False)
def _dense_loop(P: np.ndarray, Phi: np.ndarray, Qd: np.ndarray, steps: int) -> np.ndarray:
    for _ in range(steps):
        P = kalman.predict_kernel(P, Phi, Qd)
    return P


@numba.njit(cache=False)
def _rows_loop(P: np.ndarray, M: np.ndarray, cols: np.ndarray, Qd: np.ndarray, steps: int
               ) -> np.ndarray:
    T = np.empty((M.shape[0], P.shape[0]))
    for _ in range(steps):
        P = kalman.predict_rows_kernel(P, M, cols, Qd, T)
    return P


def _numpy_loop(P: np.ndarray, Phi: np.ndarray, Qd: np.ndarray, steps: int) -> np.ndarray:
    for _ in range(steps):
        P = Phi @ P @ Phi.T + Qd
        P = 0.5 * (P + P.T)
    return P


def main(*, quick: bool = False) -> None:
    steps, repeat = (20, 1) if quick else (STEPS, 5)  # quick: the same loops, a few steps
    rng = np.random.default_rng(0)
    print(f"{'P <- Phi P Phi^T + Qd, us per step':40s} {'n':>3s} {'r':>3s} {'numpy':>7s} "
          f"{'dense':>7s} {'rows':>7s} {'dense/rows':>11s}")
    for label, n, r, nc in SHAPES:
        A = rng.normal(size=(n, n))
        P = A @ A.T / n + np.eye(n)
        F = np.zeros((n, n))
        F[:r, :nc] = 1e-3 * rng.normal(size=(r, nc))
        Phi = kalman.discretize(F, 0.01)
        M = np.ascontiguousarray(Phi[:r, :nc])
        cols = np.arange(nc, dtype=np.int64)
        Qd = np.diag(rng.uniform(1e-12, 1e-10, size=n))
        dense = _dense_loop(P, Phi, Qd, steps)
        rows = _rows_loop(P, M, cols, Qd, steps)
        np.testing.assert_allclose(rows, dense, rtol=1e-12, atol=1e-15)
        t_np, t_dense, t_rows = (
            best(lambda f=f, a=a: f(*a, steps), repeat=repeat)
            for f, a in ((_numpy_loop, (P, Phi, Qd)), (_dense_loop, (P, Phi, Qd)),
                         (_rows_loop, (P, M, cols, Qd)))
        )
        print(f"{label:40s} {n:3d} {r:3d} {t_np / steps * 1e6:7.2f} {t_dense / steps * 1e6:7.2f} "
              f"{t_rows / steps * 1e6:7.2f} {t_dense / t_rows:11.1f}")


if __name__ == "__main__":
    main()
