"""The filters' colours, picked by name so a filter keeps its colour from run to run and in
every output that draws it (the Rerun view, the report, the Foxglove layout of the exports);
grey is reserved for the truth."""

from __future__ import annotations

import zlib
from collections.abc import Collection

TRUTH_COLOR = (150, 150, 150)


PALETTE = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (188, 189, 34), (23, 190, 207),
)  # fmt: skip
"""Filter colours (grey is reserved for the truth): a label's colour is picked by its name
(:func:`color_index`), so a filter keeps its colour from run to run."""


def color_index(label: str, taken: Collection[int] = ()) -> int:
    """The :data:`PALETTE` index of a label: a CRC-32 of its name, or the next index not
    ``taken`` by another label of the same view when two names fall on one colour (then the
    label that came first keeps its own). The built-in filters have distinct colours."""
    k = zlib.crc32(label.encode()) % len(PALETTE)
    if len(taken) >= len(PALETTE):
        return k
    while k in taken:
        k = (k + 1) % len(PALETTE)
    return k
