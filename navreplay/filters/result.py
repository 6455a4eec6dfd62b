"""A filter's estimates over a recording, in columns: what a replay hands back and what scoring,
the view and the exports read."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from navreplay.filters.base import (
    NAV_PARTS,
    MeasurementKind,
    State,
    check_measurements,
    check_states,
)
from navreplay.filters.settings import FilterSettings

_EVERY_PART: tuple[str, ...] = tuple(["the parts of the solution the result holds"])
"""The default of :attr:`RunResult.navigation` (a sentinel, replaced on creation)."""


@dataclasses.dataclass
class InnovationSeries:
    """All updates of one measurement: t (K,) [s], nu (K, m), S (K, m, m), nis (K,)."""

    t: np.ndarray
    nu: np.ndarray
    S: np.ndarray
    nis: np.ndarray


@dataclasses.dataclass
class RunResult:
    """Estimates of one filter over one recording, in columns.

    Attributes
    ----------
    filter_name, label : str
        Registry name and display label (unique per run command, e.g. ``gps-ins`` or
        ``transfer-alignment[match=vel_only]``).
    recording : str
        Path or name of the recording.
    t0_ns : int
        Recording start [ns]; ``t`` is relative to it.
    t : (M,) [s]
    states : tuple[State, ...]
        The filter's declarations of the entries of ``x`` (name, unit, quantity, truth, NEES):
        what metrics and the view read.
    x : (M, n)
    P : (M, n, n)
    nav_pos : (M, 3) or None   latitude, longitude [rad], height [m]
    nav_v_n : (M, 3) or None
    nav_q_nb : (M, 4) or None
    navigation : tuple[str, ...]
        The parts of the navigation solution the filter outputs (``pos``, ``v_n``, ``q_nb``;
        :attr:`navreplay.filters.base.Filter.navigation`); the columns of the others are NaN
        and nothing downstream scores or shows them. Empty without a solution.
    extras : dict[str, (M, ...)]
    innovations : dict[str, InnovationSeries]
    scored_extras : tuple[State, ...]
        Declarations of the ``extras`` that are scored.
    measurements : tuple[MeasurementKind, ...]
        The filter's declarations of its measurements (rows and units of each innovation);
        empty when the filter declares none (:meth:`measurement` is then None).
    settings : FilterSettings or None
        The filter's parameters and where each came from (sensor specifications, TOML, -p,
        defaults; :mod:`navreplay.filters.settings`).
    """

    filter_name: str
    label: str
    recording: str
    t0_ns: int
    t: np.ndarray
    states: tuple[State, ...]
    x: np.ndarray
    P: np.ndarray
    nav_pos: np.ndarray | None = None
    nav_v_n: np.ndarray | None = None
    nav_q_nb: np.ndarray | None = None
    extras: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    innovations: dict[str, InnovationSeries] = dataclasses.field(default_factory=dict)
    scored_extras: tuple[State, ...] = ()
    measurements: tuple[MeasurementKind, ...] = ()
    navigation: tuple[str, ...] = dataclasses.field(default_factory=lambda: _EVERY_PART)
    settings: FilterSettings | None = None

    def __post_init__(self) -> None:
        self.states = check_states(self.states, f"{self.label}: states")
        self.scored_extras = check_states(self.scored_extras, f"{self.label}: scored_extras")
        self.measurements = check_measurements(self.measurements,
                                               f"{self.label}: measurements") or ()
        if self.navigation is None or self.navigation is _EVERY_PART:
            # not given: every part of the solution there is
            self.navigation = NAV_PARTS if self.nav_pos is not None else ()
        self.navigation = tuple(self.navigation)

    def has(self, part: str) -> bool:
        """Whether the result holds part ``part`` (``pos``, ``v_n``, ``q_nb``) of a navigation
        solution."""
        return part in self.navigation and getattr(self, f"nav_{part}") is not None

    def measurement(self, name: str) -> MeasurementKind | None:
        """The declaration of measurement ``name``, or None when the filter declares none."""
        return next((m for m in self.measurements if m.name == name), None)

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the states, in order."""
        return tuple(s.name for s in self.states)

    @property
    def sigma(self) -> np.ndarray:
        """1-sigma of each state, (M, n)."""
        return np.sqrt(np.clip(np.diagonal(self.P, axis1=1, axis2=2), 0.0, None))

    def rows(self, a: int, b: int) -> RunResult:
        """Rows [a, b) of the estimates, without the innovations (views)."""
        def cut(v: np.ndarray | None) -> np.ndarray | None:
            return None if v is None else v[a:b]

        return dataclasses.replace(
            self, t=self.t[a:b], x=self.x[a:b], P=self.P[a:b], nav_pos=cut(self.nav_pos),
            nav_v_n=cut(self.nav_v_n), nav_q_nb=cut(self.nav_q_nb),
            extras={k: v[a:b] for k, v in self.extras.items()}, innovations={},
        )


def concat(blocks: Sequence[RunResult], *, consume: bool = False) -> RunResult:
    """The blocks of one run, in time order, as one result (their estimates and innovations
    joined, as ``np.concatenate`` joins them).

    ``consume``: ``blocks`` is a list that is emptied as its blocks are copied, so each
    block's memory goes as soon as it is copied (when nothing else holds it): the peak is the
    whole run and one block instead of the run twice (the covariances of an hour's outputs
    of gps-ins are 310 MB)."""
    full: list[RunResult | None] = [b for b in blocks if b.t.size] or [blocks[0]]
    first = full[0]
    assert first is not None
    innovations = concat_innovations(blocks)
    if consume:
        assert isinstance(blocks, list)  # emptied below
        blocks.clear()
    names = [n for n in _ROW_ARRAYS if getattr(first, n) is not None]
    total = sum(b.t.shape[0] for b in full if b is not None)

    def joined(parts: list[np.ndarray]) -> np.ndarray:
        """The array np.concatenate(parts) gives, not filled yet."""
        dtype = np.result_type(*(p.dtype for p in parts))
        return np.empty((total, *parts[0].shape[1:]), dtype=dtype)

    out: dict[str, Any] = {n: joined([getattr(b, n) for b in full if b is not None])
                           for n in names}
    extras = {k: joined([b.extras[k] for b in full if b is not None]) for k in first.extras}
    a = 0
    for i, b in enumerate(full):
        assert b is not None
        k = b.t.shape[0]
        for n, v in out.items():
            v[a:a + k] = getattr(b, n)
        for n, v in extras.items():
            v[a:a + k] = b.extras[n]
        a += k
        if consume:  # (the first stays held, for its metadata: one block)
            full[i] = None
        del b
    return dataclasses.replace(first, **out, extras=extras, innovations=innovations)


_ROW_ARRAYS = ("t", "x", "P", "nav_pos", "nav_v_n", "nav_q_nb")
"""The arrays of a result with a row per estimate (``extras`` besides)."""


def concat_innovations(blocks: Sequence[RunResult]) -> dict[str, InnovationSeries]:
    """The innovations of the blocks of one run, joined per measurement."""
    names = dict.fromkeys(n for b in blocks for n in b.innovations)
    return {
        name: InnovationSeries(*(np.concatenate([getattr(b.innovations[name], f)
                                                 for b in blocks if name in b.innovations])
                                 for f in ("t", "nu", "S", "nis")))
        for name in names
    }
