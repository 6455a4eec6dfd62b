"""How the view looks: the filters' colours (one per label in every plot; grey for the truth),
lighter and dimmer shades, the shaded bands, the +-3 sigma bounds and the order of the plots
inside a tab."""

from __future__ import annotations

import functools

from navreplay.core.colors import PALETTE as PALETTE  # the colours, shared with the exports
from navreplay.core.colors import TRUTH_COLOR as TRUTH_COLOR
from navreplay.core.colors import LabelColors as LabelColors
from navreplay.core.colors import color_index as color_index

N_SIGMA = 3.0


BAND_LINES = 48
"""A shaded band (NEES/NIS 95 % interval) is drawn as this many dim lines between its bounds:
Rerun 0.41's time-series view has no fill between two series."""


BAND_WIDTH = 8.0
"""Width of each band line [px]."""


TRUTH_COMPONENT_COLORS = ((235, 150, 150), (150, 225, 150), (160, 180, 245))
"""The components x, y, z of a truth column drawn beside an estimate's: the axis colours
(x red, y green, z blue) greyed, so the three are told apart and still read as the truth."""


OUTAGE_COLOR = (235, 160, 40)
"""GNSS outages: the true track inside them, and (dimmed) the bands that shade them."""


AXIS_COLORS = ((230, 60, 60), (60, 200, 60), (70, 110, 240))


SIGMA_SHADE = 0.5
"""A predicted sigma beside its RMS is drawn in the same colour this much lighter, and thinner."""


_BACKGROUND = (18, 18, 18)
"""The viewer's dark plot background, that band colours are blended towards."""


# plot ranks (order inside a tab): overlays first, then per-filter rows
RANK_NAV, RANK_ERROR, RANK_STATE, RANK_SIGMA, RANK_EXTRA, RANK_TRUTH = (
    0, 100, 300, 400, 500, 600
)


def lighter(color: tuple[int, ...], f: float) -> tuple[int, int, int]:
    """``color`` moved a fraction ``f`` towards white."""
    return _lighter(tuple(color[:3]), float(f))


@functools.lru_cache(maxsize=1024)
def _lighter(color: tuple[int, ...], f: float) -> tuple[int, int, int]:
    r, g, b = (int(round(c + (255 - c) * f)) for c in color)
    return r, g, b


def dimmer(color: tuple[int, ...], f: float) -> tuple[int, int, int]:
    """``color`` moved a fraction ``f`` towards the plot background (an opaque 'transparent'
    colour: Rerun's plot lines ignore alpha)."""
    r, g, b = (int(round(c + (bg - c) * f)) for c, bg in zip(color[:3], _BACKGROUND, strict=True))
    return r, g, b
