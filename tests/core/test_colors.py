"""Filter colours by name: stable across runs, distinct within one output."""

from __future__ import annotations

import itertools

from navreplay.core.colors import PALETTE, LabelColors, color_index


def _colliding_pair() -> tuple[str, str]:
    """Two labels whose names fall on one palette colour."""
    seen: dict[int, str] = {}
    for n in itertools.count():
        label = f"filter-{n}"
        k = color_index(label)
        if k in seen:
            return seen[k], label
        seen[k] = label
    raise AssertionError  # unreachable: the palette is finite


def test_a_label_keeps_its_own_colour_whatever_comes_before_it_if_free():
    a = LabelColors()
    b = LabelColors()
    b.index("ins")
    b.index("rpm-aided-ins")
    assert a.rgb("gps-ins") == b.rgb("gps-ins") == PALETTE[color_index("gps-ins")]


def test_colliding_labels_get_distinct_colours_and_the_first_keeps_its_own():
    first, second = _colliding_pair()
    assert color_index(first) == color_index(second)
    colors = LabelColors()
    assert colors.index(first) == color_index(first)
    assert colors.index(second) != colors.index(first)
    assert colors.index(first) == color_index(first)  # asked again: unchanged
    assert (colors.order(first), colors.order(second)) == (0, 1)


def test_distinct_while_the_palette_lasts():
    colors = LabelColors()
    labels = [f"f{n}" for n in range(len(PALETTE))]
    assert len({colors.index(label) for label in labels}) == len(PALETTE)
    assert 0 <= colors.index("one-more") < len(PALETTE)  # beyond: its own, shared
