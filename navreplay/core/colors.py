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


class LabelColors:
    """The colours of the labels drawn together in one output (a view, a figure, a layout), in
    first-use order: each label's own :func:`color_index`, moved on only when an earlier label
    holds it, so the labels stay distinct while the palette lasts."""

    def __init__(self) -> None:
        self._index: dict[str, int] = {}

    def index(self, label: str) -> int:
        """The :data:`PALETTE` index of ``label`` (given on its first use)."""
        if label not in self._index:
            self._index[label] = color_index(label, set(self._index.values()))
        return self._index[label]

    def rgb(self, label: str) -> tuple[int, int, int]:
        """The colour of ``label`` as 8-bit RGB."""
        return PALETTE[self.index(label)]

    def order(self, label: str) -> int:
        """The position of ``label`` in first-use order."""
        self.index(label)
        return list(self._index).index(label)
