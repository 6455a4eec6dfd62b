"""The smoother's side of a replay: the forward pass stored on disk in chunks, the backward
pass over them latest first, and the smoothed run handed back in time order.

A filter that declares :class:`~navreplay.filters.smoothable.Smoothable` and is replayed with
``smooth=True`` (:func:`navreplay.replay.pipeline.replay_file`) records, at every estimate, the
estimate and its :class:`~navreplay.filters.smoothable.SmoothingStep` into a
:class:`ForwardStore`: rows are collected into chunks of :data:`CHUNK` epochs, each written as
one folder of ``.npy`` files (no zip, whose checksums would cost as much as the writing) in a
temporary directory. :func:`smoothed_blocks` runs the backward pass
(:func:`navreplay.filters.rts.backward_chunk`) over the chunks from the last to the first,
writes each smoothed chunk beside its forward one, and then reads them back in time order as
blocks of a :class:`~navreplay.filters.result.RunResult`. The truth windows the forward pass
saw are stored the same way (:class:`TruthStore`), so the smoothed run is scored as the
forward one, window by window. One chunk at a time is in memory: the memory does not grow
with the log.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.core.streams import Stream, StreamKind
from navreplay.filters import rts
from navreplay.filters.base import Estimate
from navreplay.filters.result import RunResult
from navreplay.filters.smoothable import Smoothable, SmoothingStep, SmoothingSteps

CHUNK = 1024
"""Epochs per stored chunk."""
BACKWARD_COST = 0.4
"""The backward pass of a filter's run, in forward passes of it (in the progress bar;
``benchmarks/bench_smoothing.py`` measures 0.41 for gps-ins)."""
SCORING_COST = 0.2
"""The scoring and output of a smoothed run, in forward passes of its filter (in the progress
bar; ``bench_smoothing`` measures 0.20 for gps-ins with its exports)."""
SUFFIX = "/rts"
"""The label of a smoothed run: its filter's label and this."""


def smoothed_label(label: str) -> str:
    """The label of the smoothed run of the filter labelled ``label``."""
    return label + SUFFIX


class ForwardStore:
    """The forward pass of one filter, on disk in chunks of :data:`CHUNK` epochs.

    Parameters
    ----------
    directory : Path
        Where the chunks go (an existing, private directory).
    chunk : int
    """

    def __init__(self, directory: Path, chunk: int = CHUNK) -> None:
        self.directory = directory
        self.chunk = int(chunk)
        self.paths: list[Path] = []
        self.epochs = 0
        self._buf: dict[str, np.ndarray] | None = None
        self._m = 0

    def _alloc(self, n: int, nav: bool, reset: bool) -> dict[str, np.ndarray]:
        c = self.chunk
        buf = {"t": np.empty(c), "x": np.empty((c, n)), "P": np.empty((c, n, n)),
               "phi": np.empty((c, n, n)), "P_prior": np.empty((c, n, n)),
               "dx": np.empty((c, n))}
        if nav:
            buf["nav"] = np.empty((c, 10))
        if reset:
            buf["reset"] = np.empty((c, n, n))
        return buf

    def add(self, est: Estimate, step: SmoothingStep) -> None:
        """The estimate of one epoch and what the smoother needs of it."""
        nav = None if est.nav is None else np.concatenate(
            [est.nav.pos, est.nav.v_n, est.nav.q_nb])[None]
        n = est.x.shape[0]
        self._add({"t": np.array([est.t]), "x": est.x[None], "P": est.P[None],
                   "phi": step.phi[None], "P_prior": step.P_prior[None], "dx": step.dx[None],
                   **({} if nav is None else {"nav": nav}),
                   **({} if step.reset is None else {"reset": step.reset[None]})},
                  reset_given=step.reset is not None, n=n)

    def add_rows(self, t: np.ndarray, x: np.ndarray, P: np.ndarray, nav: np.ndarray | None,
                 steps: SmoothingSteps) -> None:
        """The estimates of m epochs a compiled run wrote, ``t`` (m,), ``x`` (m, n), ``P``
        (m, n, n), navigation vectors ``nav`` (m, 10) or None, and their steps."""
        rows = {"t": t, "x": x, "P": P, "phi": steps.phi, "P_prior": steps.P_prior,
                "dx": steps.dx, **({} if nav is None else {"nav": nav})}
        self._add(rows, reset_given=False, n=x.shape[1])

    def _add(self, rows: dict[str, np.ndarray], reset_given: bool, n: int) -> None:
        m, i = rows["t"].shape[0], 0
        while i < m:
            if self._buf is None:
                self._buf = self._alloc(n, "nav" in rows, reset_given)
            b = self._buf
            k = min(m - i, self.chunk - self._m)
            for name, col in b.items():
                given = name != "reset" or reset_given
                col[self._m:self._m + k] = rows[name][i:i + k] if given else np.eye(n)
            self._m += k
            self.epochs += k
            i += k
            if self._m == self.chunk:
                self.flush()

    def flush(self) -> None:
        """Write the rows collected so far as a chunk."""
        if self._buf is None or self._m == 0:
            return
        path = self.directory / f"forward-{len(self.paths):06d}"
        _write(path, {k: v[:self._m] for k, v in self._buf.items()})
        self.paths.append(path)
        self._m = 0


class TruthStore:
    """The truth windows of a replay, on disk one file each, to be read again in order."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.paths: list[Path] = []
        self.frame_id = ""

    def add(self, truth: Stream) -> None:
        path = self.directory / f"truth-{len(self.paths):06d}"
        _write(path, {"t_ns": truth.t_ns, **{f"c_{k}": v for k, v in truth.columns.items()}})
        self.frame_id = truth.frame_id
        self.paths.append(path)

    def __iter__(self) -> Iterator[Stream]:
        for path in self.paths:
            f = _read(path)
            yield Stream(StreamKind.TRUTH, f["t_ns"],
                         {k[2:]: v for k, v in f.items() if k.startswith("c_")}, self.frame_id)


def backward(store: ForwardStore, filt: Smoothable,
             progress: Callable[[int], None] | None = None) -> list[Path]:
    """The backward pass over a stored forward pass, latest chunk first; each smoothed chunk is
    written beside its forward one (their paths, in time order). ``progress(epochs)`` after
    each chunk."""
    store.flush()
    out: list[Path] = [store.directory / f"smoothed-{i:06d}" for i in range(len(store.paths))]
    carry: rts.Carry | None = None
    for i in reversed(range(len(store.paths))):
        c = _read(store.paths[i])
        d, P_s, carry = rts.backward_chunk(c["P"], c["phi"], c["P_prior"], c["dx"], carry,
                                           c.get("reset"))
        x_s, nav_s = filt.apply_smoothed(c["x"], c.get("nav"), d)
        arrays = {"t": c["t"], "x": x_s, "P": P_s}
        if nav_s is not None:
            arrays["nav"] = nav_s
        _write(out[i], arrays)
        if progress is not None:
            progress(c["t"].shape[0])
    return out


def smoothed_blocks(paths: list[Path], meta: dict[str, Any]) -> Iterator[RunResult]:
    """The smoothed chunks, in time order, as blocks of a result with the fields ``meta``
    (label, states, settings, ...: those of the forward run, with its smoothed label)."""
    for path in paths:
        f = _read(path)
        nav = f.get("nav")
        yield RunResult(
            t=f["t"], x=f["x"], P=f["P"],
            nav_pos=None if nav is None else nav[:, 0:3],
            nav_v_n=None if nav is None else nav[:, 3:6],
            nav_q_nb=None if nav is None else nav[:, 6:10],
            **{**meta, "navigation": meta.get("navigation") if nav is not None else ()})


def _write(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """A chunk: a new folder ``path`` with one ``NAME.npy`` per array."""
    path.mkdir()
    for name, a in arrays.items():
        np.save(path / f"{name}.npy", a, allow_pickle=False)


def _read(path: Path) -> dict[str, np.ndarray]:
    """The arrays of a chunk written by :func:`_write`."""
    return {p.stem: np.load(p, allow_pickle=False) for p in sorted(path.glob("*.npy"))}
