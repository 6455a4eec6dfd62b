"""A recorded solution as a row of the pipeline: its samples handed out as the windows
advance, its covariance from the logged 1-sigma (north/east metres as latitude/longitude
radians), rows without a finite part or variance left out."""

from __future__ import annotations

import numpy as np

from navreplay.core.streams import StreamKind
from navreplay.geo.earth import radii
from navreplay.io.solution import RecordedSolution
from navreplay.replay.recorded import RecordedSession


def _solution(n: int = 6) -> RecordedSolution:
    t = np.arange(1, n + 1, dtype=np.int64) * 10**9
    pos = np.column_stack([np.full(n, 0.7), np.full(n, 0.2), np.full(n, 250.0)])
    v = np.tile([1.0, 2.0, 0.0], (n, 1))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    pos_sigma = np.tile([2.0, 3.0, 4.0], (n, 1))
    nan = np.full((n, 3), np.nan)
    return RecordedSolution("ins", "test", t, pos, v, q, pos_sigma, nan, nan.copy())


def test_rows_without_a_part_or_its_variance_are_left_out() -> None:
    sol = _solution()
    sol.pos[1] = np.nan  # no position yet
    sol.pos_sigma[3] = np.inf  # PX4 before its global origin
    kept, dropped = sol.complete()
    assert dropped == 2 and kept.t_ns.tolist() == [1e9, 3e9, 5e9, 6e9]
    assert kept.parts() == ("pos", "v_n", "q_nb") and kept.with_sigma() == ("pos",)


def test_blocks_follow_the_imu_and_carry_the_logged_covariance() -> None:
    sol = _solution()
    session = RecordedSession(sol, source="log", t0_ns=0)
    first = session.feed({}, known={StreamKind.IMU: int(2.5e9)})
    again = session.feed({}, known={StreamKind.IMU: int(2.5e9)})
    rest = session.feed({}, final=True)
    assert first.t.tolist() == [1.0, 2.0] and again.t.size == 0 and rest.t.size == 4
    R_M, R_N = radii(0.7)
    sigma = np.sqrt(np.diagonal(rest.P[0]))
    expected = [2.0 / (R_M + 250.0), 3.0 / ((R_N + 250.0) * np.cos(0.7)), 4.0]
    np.testing.assert_allclose(sigma, expected, rtol=1e-12)
    assert [s.name for s in rest.states] == ["dlat", "dlon", "dh"]
    assert all(s.nees for s in rest.states) and not rest.x.any()
    np.testing.assert_array_equal(rest.nav_v_n, sol.v_n[2:])
    assert rest.navigation == ("pos", "v_n", "q_nb")


def test_a_solution_without_variances_has_no_states() -> None:
    sol = _solution()
    sol.pos_sigma[:] = np.nan
    block = RecordedSession(sol, source="log", t0_ns=0).feed({}, final=True)
    assert block.states == () and block.P.shape == (6, 0, 0)
    np.testing.assert_array_equal(block.nav_pos, sol.pos)
