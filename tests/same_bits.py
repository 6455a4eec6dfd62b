"""The one bit-identity assertion of the tests: two replays of one recording on this machine
(windowed and whole, compiled and one by one) gave the same estimates and innovations."""

from __future__ import annotations

import numpy as np

from navreplay.filters.result import RunResult


def assert_same_results(a: RunResult, b: RunResult) -> None:
    """The same bits: times, states, covariances, navigation solution, innovations."""
    assert a.t.shape == b.t.shape and a.t.shape[0] > 100
    for name in ("t", "x", "P", "nav_pos", "nav_v_n", "nav_q_nb"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.innovations.keys() == b.innovations.keys()
    for k in a.innovations:
        np.testing.assert_array_equal(a.innovations[k].t, b.innovations[k].t, err_msg=k)
        np.testing.assert_array_equal(a.innovations[k].nu, b.innovations[k].nu, err_msg=k)
