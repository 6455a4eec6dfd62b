"""Monte Carlo statistics accumulated run by run, without keeping the runs: RMS and mean of
the errors per time index, filter sigma, run-averaged NEES and NIS with their chi-square bounds,
CEP50 and DT CEP50 (:class:`EnsembleStats`)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from navreplay.filters.base import State
from navreplay.metrics.consistency import ConsistencyStats, EnsembleConsistency
from navreplay.metrics.outages import ensemble_outages
from navreplay.metrics.run import RunMetrics
from navreplay.metrics.stats import CEP50_FACTOR, chi2_bounds_per_count, rms


class _Acc:
    """Per-index running sums that grow with the longest run."""

    def __init__(self) -> None:
        self.sum: np.ndarray | None = None
        self.sq: np.ndarray | None = None
        self.n: np.ndarray | None = None

    def add(self, a: np.ndarray) -> None:
        a = np.asarray(a, dtype=float)
        ok = np.isfinite(a)
        v = np.where(ok, a, 0.0)
        if self.sum is None:
            self.sum = np.zeros_like(v)
            self.sq = np.zeros_like(v)
            self.n = np.zeros(v.shape, dtype=np.int64)
        assert self.sq is not None and self.n is not None  # created with the sum
        m = v.shape[0]
        if m > self.sum.shape[0]:
            grow = ((0, m - self.sum.shape[0]),) + ((0, 0),) * (v.ndim - 1)
            self.sum = np.pad(self.sum, grow)
            self.sq = np.pad(self.sq, grow)
            self.n = np.pad(self.n, grow)
        if v.shape[1:] != self.sum.shape[1:]:
            raise ValueError(f"runs disagree in shape: {v.shape[1:]} vs {self.sum.shape[1:]}")
        self.sum[:m] += v
        self.sq[:m] += v * v
        self.n[:m] += ok

    def counts(self) -> np.ndarray:
        """Samples per index (a run added first)."""
        if self.n is None:
            raise ValueError("no run added")
        return self.n

    def mean(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.asarray(self.sum) / self.counts()

    def rms(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(np.asarray(self.sq) / self.counts())


@dataclasses.dataclass
class EnsembleResult:
    """Statistics of N runs per time index (see :class:`EnsembleStats`).

    Attributes
    ----------
    label : str
    runs : int
    t : ndarray, shape (M,)
    rms : dict[str, ndarray (M, 3)]
        RMS over runs of the ``pos_ned``, ``v_n``, ``phi``, ``euler`` errors (those scored in
        any run).
    mean : dict[str, ndarray (M, 3)]
        Mean over runs of the same errors.
    sigma : dict[str, ndarray (M, 3)]
        ``sqrt(mean predicted variance)`` of ``pos_ned``, ``v_n``, ``phi``.
    state_names : tuple of str
    states : tuple of State
        Their declarations (units, quantities).
    state_rms, state_mean, state_sigma : ndarray, shape (M, k)
    nees_mean : ndarray, shape (M,)
    nees_count : ndarray, shape (M,)
        Runs with a finite NEES per index.
    nees_dof : int
    nees_bounds : tuple of ndarray (M,)
    nis_mean : dict[str, tuple[ndarray (K,) t, ndarray (K,) mean, ndarray (K,) count, int dof]]
    nis_rows_mean : dict[str, dict[str, ndarray (K,)]]
        Per measurement of several rows: each row's NIS (:func:`row_nis`) averaged over the
        runs (the counts of ``nis_mean``).
    cep50 : ndarray, shape (M,)
        ``0.5887 (LatRMS + LongRMS)`` [m].
    distance : ndarray, shape (M,)
        Mean true distance travelled [m].
    consistency : EnsembleConsistency or None
        Per-axis RMS/sigma with intervals and checks, and the per-run time-averaged NEES tests
        (:mod:`navreplay.metrics.consistency`).
    outages : tuple of (start, end)
        The GNSS outages [s] the runs share (none when their recordings differ in them),
        scored one by one in the summary (:func:`navreplay.metrics.outages.ensemble_outages`).
    """

    label: str
    runs: int
    t: np.ndarray
    rms: dict[str, np.ndarray]
    mean: dict[str, np.ndarray]
    sigma: dict[str, np.ndarray]
    state_names: tuple[str, ...]
    states: tuple[State, ...]
    state_rms: np.ndarray
    state_mean: np.ndarray
    state_sigma: np.ndarray
    nees_mean: np.ndarray
    nees_count: np.ndarray
    nees_dof: int
    nees_bounds: tuple[np.ndarray, np.ndarray]
    nis_mean: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, int]]
    cep50: np.ndarray
    distance: np.ndarray
    nis_rows_mean: dict[str, dict[str, np.ndarray]] = dataclasses.field(default_factory=dict)
    consistency: EnsembleConsistency | None = None
    outages: tuple[tuple[float, float], ...] = ()

    @property
    def dt_cep50(self) -> np.ndarray:
        """CEP50 / DT x 100 [%] per index (NaN before the vehicle moved)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.distance > 0.0, 100.0 * self.cep50 / self.distance, np.nan)

    def summary(self, probability: float = 0.95) -> dict[str, Any]:
        """Scalar scores at the final index and over time (SI; see :data:`SUMMARY_UNITS`)."""
        out: dict[str, Any] = {"runs": self.runs}
        if self.t.size == 0:
            return out
        out["duration"] = float(self.t[-1] - self.t[0])
        out["distance"] = float(self.distance[-1])
        if "pos_ned" in self.rms and np.isfinite(self.rms["pos_ned"]).any():
            r = self.rms["pos_ned"][-1]
            out["lat_rms_final"] = float(r[0])
            out["long_rms_final"] = float(r[1])
            out["cep50_final"] = float(self.cep50[-1])
            if self.distance[-1] > 0.0:
                out["dt_cep50_final"] = float(self.dt_cep50[-1])
            out["pos_rms_h"] = float(np.sqrt(np.nanmean(np.sum(self.rms["pos_ned"][:, :2] ** 2,
                                                                 axis=1))))
        if "phi" in self.rms and np.isfinite(self.rms["phi"]).any():
            out["att_rms_level"] = float(rms(self.rms["phi"][:, :2], None))
            out["att_rms_heading"] = float(rms(self.rms["phi"][:, 2], None))
        _chi2_summary(out, "nees", "", self.nees_mean, self.nees_count, self.nees_dof,
                      probability)
        for name, (_, m, c, dof) in self.nis_mean.items():
            _chi2_summary(out, "nis", f"_{name}", m, c, dof, probability)
            for row, v in self.nis_rows_mean.get(name, {}).items():
                _chi2_summary(out, "nis", f"_{name}.{row}", v, c, 1, probability)
        if self.consistency is not None:
            out.update(self.consistency.summary())
        if self.outages and "pos_ned" in self.rms:
            out["gnss_outages"] = ensemble_outages(self.t, self.rms["pos_ned"],
                                                   self.sigma["pos_ned"], self.runs,
                                                   self.outages)
        return out


class EnsembleStats:
    """Monte Carlo statistics accumulated run by run, without keeping the runs.

    Keeps running sums per time index of the errors, their squares and the predicted
    variances, the NEES and the NIS; :meth:`result` turns them into RMS, mean, filter sigma,
    run-averaged NEES / NIS with their chi-square bounds, CEP50 and DT CEP50. Runs must share
    their output times (the same scenario and rates); a longer run extends the arrays.

    Examples
    --------
    >>> stats = EnsembleStats()
    >>> for m in run_metrics_list:                 # doctest: +SKIP
    ...     stats.add(m)
    >>> res = stats.result()                       # doctest: +SKIP
    >>> print(format_table({"gps-ins": res.summary()}))  # doctest: +SKIP
    """

    def __init__(self, label: str = "") -> None:
        self.label = label
        self.runs = 0
        self._t: np.ndarray | None = None
        self._nav = {k: _Acc() for k in ("pos_ned", "v_n", "phi", "euler")}
        self._var = {k: _Acc() for k in ("pos_ned", "v_n", "phi")}
        self._state = _Acc()
        self._state_var = _Acc()
        self._nees = _Acc()
        self._dist = _Acc()
        self._nis: dict[str, tuple[_Acc, list, int]] = {}
        self._nis_rows: dict[str, dict[str, _Acc]] = {}
        self._consistency = ConsistencyStats()
        self._state_names: tuple[str, ...] | None = None
        self._nees_states: tuple[str, ...] | None = None
        self._states: tuple[State, ...] = ()
        self._outages: tuple[tuple[float, float], ...] | None = None  # None: no run yet

    def add(self, m: RunMetrics) -> None:
        """Add one run's metrics."""
        if self._t is None or m.t.shape[0] > self._t.shape[0]:
            ref = self._t
            if ref is not None and not np.allclose(m.t[: ref.shape[0]], ref, atol=1e-6):
                raise ValueError(f"run {self.runs + 1} ({m.label}) has other output times")
            self._t = m.t.copy()
        elif not np.allclose(m.t, self._t[: m.t.shape[0]], atol=1e-6):
            raise ValueError(f"run {self.runs + 1} ({m.label}) has other output times")
        if self._state_names is None:
            self._state_names, self._nees_states = m.state_names, m.nees_states
            self._states = m.states
            self.label = self.label or m.label
        elif m.state_names != self._state_names or m.nees_states != self._nees_states:
            raise ValueError(f"run {self.runs + 1} ({m.label}) scores other states")
        # outages are scored over the ensemble when every run has the same
        self._outages = m.outages if self._outages in (None, m.outages) else ()
        if m.nav is not None:
            for k, acc in self._nav.items():
                acc.add(getattr(m.nav, k))
            for k, acc in self._var.items():
                acc.add(m.nav_sigma[k] ** 2)
        self._state.add(m.state_error)
        self._state_var.add(m.state_var)
        self._consistency.add(m.state_error, m.state_var, m.nees,
                              np.array([m.state_names.index(n) for n in m.nees_states], int))
        self._nees.add(m.nees)
        self._dist.add(m.distance)
        for name, (t, v, dof) in m.nis.items():
            if name not in self._nis:
                self._nis[name] = (_Acc(), [t.copy()], dof)
            acc, tref, d = self._nis[name]
            if d != dof:
                raise ValueError(f"measurement {name}: dof {dof} differs from {d}")
            if t.shape[0] > tref[0].shape[0]:
                tref[0] = t.copy()
            acc.add(v)
            for row, w in m.nis_rows.get(name, {}).items():
                self._nis_rows.setdefault(name, {}).setdefault(row, _Acc()).add(w)
        self.runs += 1

    def result(self) -> EnsembleResult:
        """The statistics of the runs added so far."""
        if self._t is None:
            raise ValueError("no runs added")
        M = self._t.shape[0]
        nan3 = np.full((M, 3), np.nan)
        # errors never scored (a part of the solution the filters do not output, a column the
        # reference lacks) are absent
        scored = {k: a for k, a in self._nav.items() if a.sum is not None and a.counts().any()}
        rms_ = {k: a.rms() for k, a in scored.items()}
        mean = {k: a.mean() for k, a in scored.items()}
        sigma = {k: np.sqrt(a.mean()) if a.sum is not None else nan3
                 for k, a in self._var.items()}
        k_states = len(self._state_names or ())
        empty = np.zeros((M, k_states))
        nees_count = self._nees.n if self._nees.n is not None else np.zeros(M, int)
        dof = len(self._nees_states or ())
        if dof:
            lo, hi = chi2_bounds_per_count(dof, nees_count)
        else:
            lo, hi = np.full(M, np.nan), np.full(M, np.nan)
        if "pos_ned" in rms_:
            c50 = CEP50_FACTOR * (rms_["pos_ned"][:, 0] + rms_["pos_ned"][:, 1])
        else:
            c50 = np.full(M, np.nan)
        return EnsembleResult(
            label=self.label,
            runs=self.runs,
            t=self._t.copy(),
            rms=rms_,
            mean=mean,
            sigma=sigma,
            state_names=self._state_names or (),
            states=self._states,
            state_rms=self._state.rms() if self._state.sum is not None else empty,
            state_mean=self._state.mean() if self._state.sum is not None else empty,
            state_sigma=(np.sqrt(self._state_var.mean()) if self._state_var.sum is not None
                         else empty),
            nees_mean=self._nees.mean() if self._nees.sum is not None else np.full(M, np.nan),
            nees_count=nees_count,
            nees_dof=dof,
            nees_bounds=(lo, hi),
            nis_mean={name: (tref[0], acc.mean(), acc.counts(), d)
                      for name, (acc, tref, d) in self._nis.items()},
            cep50=c50,
            distance=self._dist.mean(),
            nis_rows_mean={name: {row: acc.mean() for row, acc in rows.items()}
                           for name, rows in self._nis_rows.items()},
            consistency=self._consistency.result(self._state_names or (),
                                                 self._nees_states or ()),
            outages=self._outages or (),
        )


def _chi2_summary(out: dict, kind: str, suffix: str, values: np.ndarray, count: np.ndarray,
                  dof: int, probability: float) -> None:
    """Add ``<kind>_dof<suffix>``, ``<kind>_mean<suffix>`` and ``<kind>_in_bounds<suffix>``
    (the fraction of indexes inside the chi-square bounds of their run count) of a NEES or NIS
    series to ``out``."""
    ok = count > 0
    if dof == 0 or not ok.any():
        return
    v = values[ok]
    out[f"{kind}_dof{suffix}"] = dof
    out[f"{kind}_mean{suffix}"] = float(np.mean(v))
    lo, hi = chi2_bounds_per_count(dof, count[ok], probability)
    out[f"{kind}_in_bounds{suffix}"] = float(np.mean((v >= lo) & (v <= hi)))
