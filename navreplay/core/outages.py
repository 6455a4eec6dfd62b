"""GNSS outages as a recording declares them: ``metadata.extra["gnss_outages"]``, a list of
``[start, end]`` pairs [s since the recording start].

The simulator writes the schedule it dropped fixes and velocities by; the scoring finds the
outages there, and the readers excuse the gaps they explain.

>>> recorded_outages({"gnss_outages": [[100, 130], [180, 240.0]]})
((100.0, 130.0), (180.0, 240.0))
>>> recorded_outages({})
()
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

OUTAGES_KEY = "gnss_outages"
"""The key of ``Metadata.extra`` holding a recording's GNSS outages, ``[[start, end], ...]``
[s since the recording start]."""


def recorded_outages(extra: Mapping[str, Any]) -> tuple[tuple[float, float], ...]:
    """The GNSS outages a recording's ``metadata.extra`` holds, as ``((start, end), ...)`` [s
    since the recording start]; empty when it holds none. Raises ``ValueError`` on an entry
    that is not a list of increasing ``[start, end]`` pairs."""
    raw = extra.get(OUTAGES_KEY) or []
    out = []
    for item in raw:
        try:
            start, end = (float(v) for v in item)
        except (TypeError, ValueError):
            raise ValueError(f"metadata.extra[{OUTAGES_KEY!r}]: {item!r} is not a [start, end] "
                             "pair [s]") from None
        if not (math.isfinite(start) and math.isfinite(end) and end > start):
            raise ValueError(f"metadata.extra[{OUTAGES_KEY!r}]: {item!r} is not a [start, end] "
                             "pair with end > start [s]")
        out.append((start, end))
    return tuple(out)
