"""Sample checks shared by the writer and the reader: finite values, increasing time, gaps."""

from __future__ import annotations

import numpy as np

from navreplay.streams import Stream

GAP_FACTOR = 5.0
"""An interval longer than this many times a topic's median interval counts as a gap."""


def when(t_ns: int, t0_ns: int) -> str:
    """``t = <s> s (<ns> ns)``: a time relative to the recording start and absolute."""
    return f"t = {(int(t_ns) - int(t0_ns)) * 1e-9:.9f} s ({int(t_ns)} ns)"


def first_problem(stream: Stream, t0_ns: int) -> str | None:
    """Describe the first bad sample or timestamp, or return None.

    Bad: a non-finite value, a negative standard deviation (columns named ``*_sigma``), a
    timestamp that repeats or goes backwards.
    """
    t = stream.t_ns
    n = len(t)
    if n == 0:
        return None
    bad_row = n
    bad_col = ""
    bad_what = ""
    for name, col in stream.columns.items():
        flat = col.reshape(n, -1)
        good = np.isfinite(flat).all(axis=1)
        what = "non-finite value"
        if name.endswith("_sigma"):
            good &= ~(flat < 0).any(axis=1)
            what = "non-finite or negative value"
        if not good.all():
            row = int(np.argmin(good))
            if row < bad_row:
                bad_row, bad_col, bad_what = row, name, what
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if back.size and back[0] + 1 <= bad_row:
        i = int(back[0]) + 1
        how = "repeats" if t[i] == t[i - 1] else "goes backwards"
        return (
            f"timestamp {how} at {when(t[i], t0_ns)}; the previous message is at "
            f"{when(t[i - 1], t0_ns)}"
        )
    if bad_row < n:
        value = stream.columns[bad_col][bad_row]
        return f"{bad_what} in column {bad_col!r} ({value}) at {when(t[bad_row], t0_ns)}"
    return None


def gap_report(stream: Stream, t0_ns: int, factor: float = GAP_FACTOR) -> str | None:
    """Describe intervals longer than ``factor`` x the median interval, or return None."""
    if len(stream) < 3:
        return None
    step = np.diff(stream.t_ns)
    median = float(np.median(step))
    if median <= 0:
        return None
    gaps = np.flatnonzero(step > factor * median)
    if not gaps.size:
        return None
    worst = int(gaps[np.argmax(step[gaps])])
    return gap_text(gaps.size, median, int(step[worst]), int(stream.t_ns[worst]), t0_ns, factor)


def gap_text(count: int, median_ns: float, longest_ns: int, start_ns: int, t0_ns: int,
             factor: float = GAP_FACTOR) -> str:
    """The line of :func:`gap_report`: how many gaps, the median interval, the longest."""
    return (
        f"{count} gap(s) longer than {factor:g} x the median interval ({median_ns * 1e-9:.6g} s); "
        f"the longest, {longest_ns * 1e-9:.6g} s, starts at {when(start_ns, t0_ns)}"
    )
