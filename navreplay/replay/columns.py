"""The estimates of a replay in columns, and the checks of what a filter hands back: finite
states, symmetric positive semi-definite covariances, declared measurements and their rows."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from navreplay.filters.base import NAV_PARTS, Estimate, output_problem
from navreplay.filters.result import InnovationSeries, RunResult
from navreplay.replay.errors import BadOutput, diverged, invalid

_NAV_COLUMN = {"pos": "position", "v_n": "velocity", "q_nb": "attitude"}
"""The name of each part of the navigation solution in messages."""


CHECK_ROWS = 1024
"""Covariances checked at once (:meth:`Columns.check`; the checks' temporaries are several
copies of the rows checked: a whole run's would be gigabytes)."""


class Columns:
    """Estimate columns allocated at a known upper bound of rows (the operating system backs
    only the rows written with memory, so they are neither grown nor copied)."""

    def __init__(self, first: Estimate | None, upper: int, n: int = 0,
                 navigation: tuple[str, ...] = NAV_PARTS) -> None:
        self.navigation = navigation
        self.upper = max(upper, 1)
        self.cap = self.upper
        self.m = 0
        n = first.x.shape[0] if first is not None else n
        self.t = np.empty(self.cap)
        self.x = np.empty((self.cap, n))
        self.P = np.empty((self.cap, n, n))
        self.has_nav = first is None or first.nav is not None
        if self.has_nav:
            self.pos = np.empty((self.cap, 3))
            self.v_n = np.empty((self.cap, 3))
            self.q_nb = np.empty((self.cap, 4))
        extras = first.extras.items() if first is not None else ()
        self.extras = {k: np.empty((self.cap, *np.shape(v))) for k, v in extras}

    def _grow(self) -> None:
        cap = min(self.upper, 2 * self.cap)
        if cap <= self.cap:  # more outputs than events: cannot happen, but never lose data
            cap = 2 * self.cap
        names = ["t", "x", "P"] + (["pos", "v_n", "q_nb"] if self.has_nav else [])
        for name in names:
            old = getattr(self, name)
            new = np.empty((cap, *old.shape[1:]))
            new[: self.m] = old[: self.m]
            setattr(self, name, new)
        for k, old in self.extras.items():
            new = np.empty((cap, *old.shape[1:]))
            new[: self.m] = old[: self.m]
            self.extras[k] = new
        self.cap = cap

    def add(self, est: Estimate) -> None:
        m = self.m
        n = self.x.shape[1]
        if np.shape(est.x) != (n,) or np.shape(est.P) != (n, n):
            raise BadOutput(
                f"x has shape {np.shape(est.x)} and P {np.shape(est.P)}; the filter declares "
                f"{n} states"
            )
        if m == self.cap:
            self._grow()
        self.t[m] = est.t
        self.x[m] = est.x
        self.P[m] = est.P
        if self.has_nav:
            nav = est.nav
            assert nav is not None  # checked against the filter's navigation before
            self.pos[m] = nav.pos
            self.v_n[m] = nav.v_n
            self.q_nb[m] = nav.q_nb
        for k, col in self.extras.items():
            col[m] = est.extras[k]
        self.m = m + 1

    def free(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Views ``(t, x, P)`` of the next ``k`` rows, for a compiled run to write into."""
        while self.m + k > self.cap:
            self._grow()
        m = self.m
        return self.t[m:m + k], self.x[m:m + k], self.P[m:m + k]

    def written(self, k: int, nav: np.ndarray) -> None:
        """The next ``k`` rows of :meth:`free` were written (``nav``: their navigation vectors
        (k, 10))."""
        m = self.m
        if self.has_nav:
            self.pos[m:m + k] = nav[:k, 0:3]
            self.v_n[m:m + k] = nav[:k, 3:6]
            self.q_nb[m:m + k] = nav[:k, 6:10]
        self.m = m + k

    def first_nonfinite(self, start: int) -> tuple[int, str] | None:
        """First row >= start with a non-finite or overflowing entry
        (:func:`navreplay.filters.base.output_problem`), and what is wrong with which column."""
        stop = self.m
        if stop <= start:
            return None
        cols: list[tuple[str, str, np.ndarray]] = [("state", "state", self.x),
                                                   ("covariance", "covariance", self.P)]
        if self.has_nav:
            cols += [(part, what, getattr(self, part)) for part, what in _NAV_COLUMN.items()
                     if part in self.navigation]
        cols += [(k, k, v) for k, v in self.extras.items()]
        found: tuple[int, str] | None = None
        for part, name, col in cols:
            bad, why = output_problem(part, col[start:stop])
            if bad.any():
                i = start + int(np.argmax(bad))
                if found is None or i < found[0]:
                    found = (i, f"{why} {name}")
        return found

    def view(self, start: int = 0, **kw: Any) -> RunResult:
        """Rows [start, m) as a result, without copying (the rows never written were never
        backed by memory)."""
        a, m = start, self.m
        return RunResult(
            t=self.t[a:m],
            x=self.x[a:m],
            P=self.P[a:m],
            nav_pos=self.pos[a:m] if self.has_nav else None,
            nav_v_n=self.v_n[a:m] if self.has_nav else None,
            nav_q_nb=self.q_nb[a:m] if self.has_nav else None,
            navigation=self.navigation if self.has_nav else (),
            extras={k: v[a:m] for k, v in self.extras.items()},
            **kw,
        )

    def check(self, start: int, label: str, source: str, names: tuple[str, ...]) -> None:
        """Check rows [start, m): finite, covariances symmetric PSD (errors name the filter,
        the recording and the time)."""
        bad = self.first_nonfinite(start)
        stop = self.m if bad is None else bad[0]
        for a in range(start, stop, CHECK_ROWS):  # temporaries of a bounded size
            cov = covariance_problem(self.P[a:min(stop, a + CHECK_ROWS)], names)
            if cov is not None:
                raise invalid(label, source, float(self.t[a + cov[0]]), cov[1])
        if bad is not None:
            raise diverged(label, source, float(self.t[bad[0]]), f"{bad[1]} estimate")


def undeclared(name: str, items: list[tuple[float, np.ndarray, np.ndarray]],
                rows_of: Mapping[str, int] | None) -> tuple[float, str] | None:
    """The first update of measurement ``name`` that its declaration (``rows_of``: rows by
    declared name; None when the filter declares nothing) does not allow, as (t, why)."""
    if rows_of is None:
        return None
    if name not in rows_of:
        return items[0][0], (f"innovation {name!r} is not a declared measurement (declared: "
                             f"{', '.join(rows_of) or 'none'}; set Filter.measurements)")
    m = rows_of[name]
    k = next((k for k, it in enumerate(items) if np.shape(it[1]) != (m,)), None)
    if k is None:
        return None
    return items[k][0], (f"innovation {name!r} has shape {np.shape(items[k][1])}; the filter "
                         f"declares {m} rows")


def innovation_series(
    items: list[tuple[float, np.ndarray, np.ndarray]],
) -> tuple[InnovationSeries, tuple[int, str] | None]:
    """The series of one measurement and its first invalid update (index, what), if any:
    nu (m,) and S (m, m) finite, S symmetric positive semi-definite and not singular."""
    t = np.array([it[0] for it in items], dtype=np.float64)
    m = np.shape(items[0][1])
    bad_shape = next((k for k, it in enumerate(items)
                      if np.shape(it[1]) != m or np.shape(it[2]) != m + m), None)
    if len(m) != 1 or bad_shape is not None:
        k = bad_shape or 0
        empty = InnovationSeries(t=t, nu=np.zeros((len(t), 0)), S=np.zeros((len(t), 0, 0)),
                                 nis=np.zeros(len(t)))
        return empty, (k, f"nu has shape {np.shape(items[k][1])} and S "
                          f"{np.shape(items[k][2])}; expected (m,) and (m, m)")
    nu = np.stack([np.asarray(it[1], dtype=np.float64) for it in items])
    S = np.stack([np.asarray(it[2], dtype=np.float64) for it in items])
    nan = np.full(len(t), np.nan)
    bad_nu, why = output_problem("nu", nu)
    problem = covariance_problem(S)
    first: tuple[int, str] | None = None
    if bad_nu.any():
        first = (int(np.argmax(bad_nu)), "nu is not finite" if why == "non-finite"
                 else f"nu is {why}")
    if problem is not None and (first is None or problem[0] < first[0]):
        first = (problem[0], problem[1].replace("covariance P", "S"))
    if first is not None:
        return InnovationSeries(t=t, nu=nu, S=S, nis=nan), first
    try:
        nis = np.einsum("ki,ki->k", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    except np.linalg.LinAlgError:
        k = int(np.argmin(np.abs(np.linalg.det(S))))
        return InnovationSeries(t=t, nu=nu, S=S, nis=nan), (k, "S is singular")
    return InnovationSeries(t=t, nu=nu, S=S, nis=nis), None


PSD_TOLERANCE = 1e-6
"""Tolerance of the covariance checks, relative to the standard deviations: a covariance is
accepted as symmetric when ``|P_ij - P_ji| <= tol sqrt(P_ii P_jj)`` and as positive
semi-definite when the smallest eigenvalue of its correlation matrix is ``>= -tol``."""


def covariance_problem(P: np.ndarray, names: tuple[str, ...] | None = None
                       ) -> tuple[int, str] | None:
    """The first of a stack of covariances (K, n, n) that is not finite, symmetric and positive
    semi-definite within :data:`PSD_TOLERANCE`, and what is wrong; None if all are.

    ``names`` name the rows (states) in the message."""
    K = P.shape[0]
    if K == 0 or P.shape[1] == 0:
        return None
    what = (lambda j: names[j]) if names else (lambda j: f"[{j}]")
    flat = P.reshape(K, -1)
    finite = np.isfinite(flat).all(axis=1)
    d = np.diagonal(P, axis1=1, axis2=2)
    neg = (d < 0.0) & finite[:, None]
    scale = np.sqrt(np.where(d > 0.0, d, 1.0))
    with np.errstate(invalid="ignore", over="ignore"):
        C = P / (scale[:, :, None] * scale[:, None, :])
        asym = np.abs(C - C.transpose(0, 2, 1)).max(axis=(1, 2)) > PSD_TOLERANCE
    bad_rows = ~finite | neg.any(axis=1) | asym
    first: tuple[int, str] | None = None
    if bad_rows.any():
        k = int(np.argmax(bad_rows))
        if not finite[k]:
            first = (k, "covariance P is not finite")
        elif neg[k].any():
            j = int(np.argmax(neg[k]))
            first = (k, f"covariance P has a negative variance {P[k, j, j]:.3g} of state "
                        f"{what(j)}")
        else:
            first = (k, "covariance P is not symmetric")
    ok = ~bad_rows if first is None else ~bad_rows & (np.arange(K) < first[0])
    if ok.any():
        idx = np.flatnonzero(ok)
        sym = 0.5 * (C[idx] + C[idx].transpose(0, 2, 1))
        try:  # all positive definite after a shift of the tolerance: the common, cheap case
            np.linalg.cholesky(sym + PSD_TOLERANCE * np.eye(sym.shape[1]))
            return first
        except np.linalg.LinAlgError:
            pass
        lam = np.linalg.eigvalsh(sym)[:, 0]
        low = lam < -PSD_TOLERANCE
        if low.any():
            k = int(idx[np.argmax(low)])
            first = (k, f"covariance P is not positive semi-definite (smallest eigenvalue of "
                        f"its correlation matrix {lam[np.argmax(low)]:.3g})")
    return first
