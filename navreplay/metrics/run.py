"""The scores of one filter run against its reference (:func:`run_metrics`): errors of the
navigation solution and of the declared states, predicted sigmas, NEES and NIS, per estimate,
in a compact picklable record (what an ensemble accumulates)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from navreplay.core.streams import Recording, StreamKind
from navreplay.filters.base import NAV_PARTS, State, TruthColumn
from navreplay.filters.result import RunResult
from navreplay.metrics.errors import (
    NavErrors,
    extra_errors,
    nav_errors,
    nav_sigma,
    state_errors,
)
from navreplay.metrics.reference import Reference
from navreplay.metrics.stats import nees
from navreplay.metrics.summary import RunSummary


@dataclasses.dataclass
class RunMetrics:
    """Compact scores of one filter run (picklable; what an ensemble accumulates).

    Attributes
    ----------
    label : str
    t : ndarray, shape (M,)
        Estimate times [s].
    nav : NavErrors or None
        Navigation errors (None for a filter without a navigation solution).
    nav_sigma : dict[str, ndarray (M, 3)]
        Predicted 1-sigma of ``pos_ned`` [m], ``v_n`` [m/s], ``phi`` [rad]; NaN where the
        filter has no state for it.
    state_names : tuple of str
        States scored against a truth.
    state_error : ndarray, shape (M, k)
        Their estimation errors.
    state_var : ndarray, shape (M, k)
        Their predicted variances.
    nees : ndarray, shape (M,)
        NEES over ``nees_states`` (NaN where their covariance is singular).
    nees_states : tuple of str
    nis : dict[str, tuple[ndarray (K,), ndarray (K,), int]]
        Per measurement: update times [s], NIS, dof.
    nis_rows : dict[str, dict[str, ndarray (K,)]]
        Per measurement of several rows: the NIS of each row by its declared name
        (:func:`row_nis`).
    distance : ndarray, shape (M,)
        True distance travelled up to each estimate [m].
    extra_error : dict[str, ndarray (M, ...)]
        Errors of the scored extras (``RunResult.scored_extras``).
    states : tuple of State
        The declarations of the scored states (``state_names``, same order): units and
        quantities for tables, exports and plots.
    outages : tuple of (start, end)
        The GNSS outages of the recording [s] (:attr:`Reference.outages`), scored one by one
        in the summary.
    """

    label: str
    t: np.ndarray
    nav: NavErrors | None
    nav_sigma: dict[str, np.ndarray]
    state_names: tuple[str, ...]
    state_error: np.ndarray
    state_var: np.ndarray
    nees: np.ndarray
    nees_states: tuple[str, ...]
    nis: dict[str, tuple[np.ndarray, np.ndarray, int]]
    distance: np.ndarray
    extra_error: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    states: tuple[State, ...] = ()
    nis_rows: dict[str, dict[str, np.ndarray]] = dataclasses.field(default_factory=dict)
    outages: tuple[tuple[float, float], ...] = ()

    def summary(self, probability: float = 0.95) -> dict[str, Any]:
        """Scalar scores (SI; see :data:`navreplay.metrics.tables.SUMMARY_UNITS`) for tables and
        JSON: those of :class:`~navreplay.metrics.summary.RunSummary` with the run as one block."""
        summary = RunSummary(probability)
        summary.add(self)
        return summary.result()


def row_nis(result: RunResult, name: str) -> dict[str, np.ndarray]:
    """The normalised innovation squared of each row of measurement ``name``,
    ``nu_i^2 / S_ii`` (chi-square of one degree of freedom for a consistent filter), by the
    row names the filter declares (else ``"0"``, ``"1"``, ...); empty for a measurement of one
    row (its NIS is that of the row). Which row of a measurement is inconsistent."""
    s = result.innovations[name]
    m = s.nu.shape[1]
    if m < 2:
        return {}
    declared = result.measurement(name)
    rows = declared.rows if declared is not None else tuple(str(i) for i in range(m))
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.square(s.nu) / np.diagonal(s.S, axis1=1, axis2=2)
    return {row: v[:, i] for i, row in enumerate(rows)}




def run_metrics(
    result: RunResult,
    reference: Recording | Reference | None,
    *,
    states: tuple[State, ...] | None = None,
) -> RunMetrics:
    """Score one filter run against a reference (the recording's truth, or any
    :class:`Reference`); what the reference lacks is left unscored. Without a reference (None,
    or a recording without a truth stream) only the innovation statistics are kept.

    Parameters
    ----------
    result : RunResult
    reference : Recording or Reference or None
        The recording the filter ran over (truth stream and ``metadata.true_errors``), or a
        reference built from elsewhere, or None.
    states : tuple of State, optional
        Score with these declarations instead of ``result.states`` (same names and order),
        e.g. against other truth columns.

    Returns
    -------
    RunMetrics
    """
    nis = {name: (s.t.copy(), s.nis.copy(), int(s.nu.shape[1]))
           for name, s in result.innovations.items()}
    nis_rows = {name: rows for name in result.innovations if (rows := row_nis(result, name))}
    M = result.t.shape[0]
    if reference is None or (isinstance(reference, Recording)
                             and StreamKind.TRUTH not in reference):
        return RunMetrics(
            label=result.label, t=result.t.copy(), nav=None, nav_sigma=nav_sigma(result),
            state_names=(), state_error=np.zeros((M, 0)), state_var=np.zeros((M, 0)),
            nees=np.full(M, np.nan), nees_states=(), nis=nis, distance=np.full(M, np.nan),
            nis_rows=nis_rows,
        )
    ref = Reference.of(reference)
    states = result.states if states is None else states
    if tuple(s.name for s in states) != result.state_names:
        raise ValueError(f"{result.label}: the scoring declarations name other states than "
                         f"the result ({', '.join(result.state_names)})")
    # the columns scored: the navigation solution's and those the declarations name
    named = {s.truth.column for s in (*states, *result.scored_extras)
             if isinstance(s.truth, TruthColumn)}
    truth = ref.at(result.t, {*NAV_PARTS, *named})
    nav = None
    if result.nav_pos is not None:
        assert result.nav_v_n is not None and result.nav_q_nb is not None  # with the position
        nav = nav_errors(result.nav_pos, result.nav_v_n, result.nav_q_nb, truth,
                         result.navigation)
    nav_for_states = nav if nav is not None else NavErrors(*(np.full((M, 3), np.nan),) * 4)
    names, e, P = state_errors(result, truth, ref.true_errors, states, nav_for_states)
    by_name = {st.name: st for st in states}
    var = np.diagonal(P, axis1=1, axis2=2).copy()
    in_nees = {s.name for s in states if s.nees}
    sel = [i for i, n in enumerate(names) if n in in_nees]
    ix = np.array(sel, dtype=int)
    nees_v = nees(e[:, ix], P[:, ix[:, None], ix[None, :]])
    return RunMetrics(
        label=result.label,
        t=result.t.copy(),
        nav=nav,
        nav_sigma=nav_sigma(result, states),
        state_names=names,
        state_error=e,
        state_var=var,
        nees=nees_v,
        nees_states=tuple(names[i] for i in sel),
        nis=nis,
        nis_rows=nis_rows,
        distance=np.asarray(ref.distance(result.t)),
        states=tuple(by_name[n] for n in names),
        extra_error=extra_errors(result, truth, ref.true_errors),
        outages=ref.outages,
    )
