"""Strapdown throughput: the numba kernel against the numpy reference of the same equations.

Figures (one core, best of several repeats, compile time excluded):

- ``integrate`` on 1M IMU samples [samples/s] (target >= 300k samples/s);
- ``propagate_reference`` (plain numpy, one sample at a time) on a few thousand samples,
  the baseline measured in the same run, and the speed-up ratio;
- ``propagate`` called with blocks of k = 10 samples, as a filter does at ~1e4 calls/s: time
  per call and its fixed overhead (call time minus 10 samples of kernel time), with the share
  of that overhead spent in the Python wrapper (shape checks) versus calling the numba kernel
  directly;
- ``imu_from_truth`` (the exact inverse used by the simulators) on 1M samples [samples/s].

Run with ``python -m benchmarks strapdown``.
"""

from __future__ import annotations

import numpy as np

from benchmarks import best
from navreplay.geo import strapdown
from navreplay.geo.rotations import euler_to_quat
from navreplay.sim import kinematics

N_SAMPLES = 1_000_000
N_REFERENCE = 3_000
BLOCK = 10
N_CALLS = 20_000
RATE = 100.0


def _imu(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A manoeuvring-like IMU record: rates ~0.1 rad/s, specific force around -g."""
    omega = rng.normal(0.0, 0.1, (n, 3))
    f = rng.normal(0.0, 1.0, (n, 3))
    f[:, 2] -= 9.8
    return omega, f, np.full(n, 1.0 / RATE)


def main(*, quick: bool = False) -> None:
    # quick: the same calls on a few thousand samples, one repeat
    n_samples, n_reference, n_calls, repeat = (
        (10_000, 300, 500, 1) if quick else (N_SAMPLES, N_REFERENCE, N_CALLS, 3))
    rng = np.random.default_rng(0)
    omega, f, dt = _imu(n_samples, rng)
    nav0 = strapdown.nav_vector(
        [0.65, 2.2, 100.0], [15.0, -5.0, 0.2], euler_to_quat([0.05, -0.02, 1.0])
    )
    strapdown.integrate(nav0, omega[:BLOCK], f[:BLOCK], dt[:BLOCK])  # compile or load cache

    t_int = best(lambda: strapdown.integrate(nav0, omega, f, dt), repeat)
    rate_int = n_samples / t_int

    t_ref = best(
        lambda: strapdown.propagate_reference(
            nav0, omega[:n_reference], f[:n_reference], dt[:n_reference]
        ),
        min(repeat, 2),
    )
    rate_ref = n_reference / t_ref

    blocks = [
        (omega[i : i + BLOCK].copy(), f[i : i + BLOCK].copy(), dt[i : i + BLOCK].copy())
        for i in range(0, BLOCK * 100, BLOCK)
    ]

    def calls() -> None:
        nav = nav0
        for i in range(n_calls):
            w, a, d = blocks[i % 100]
            nav = strapdown.propagate(nav, w, a, d)

    prev = np.zeros(6)
    out = np.empty(strapdown.NAV_SIZE)

    def kernel_calls() -> None:
        for i in range(n_calls):
            w, a, d = blocks[i % 100]
            strapdown.propagate_kernel(nav0, w, a, d, prev, out)

    t_call = best(calls, repeat) / n_calls
    t_kernel_call = best(kernel_calls, repeat) / n_calls
    overhead = t_call - BLOCK / rate_int

    # imu_from_truth on a smooth 1M-sample trajectory
    t = np.arange(n_samples) / RATE
    yaw = 0.3 + 0.2 * np.sin(2 * np.pi * t / 300.0)
    euler = np.stack([0.1 * np.sin(0.7 * t), 0.05 * np.sin(0.3 * t), yaw], axis=-1)
    q = euler_to_quat(euler)
    v = 20.0 * np.stack([np.cos(yaw), np.sin(yaw), 0.0 * t], axis=-1)
    pos = kinematics.integrate_position(t, v, [0.65, 2.2, 100.0])
    kinematics.imu_from_truth(t[:3], pos[:3], v[:3], q[:3])
    t_gen = best(lambda: kinematics.imu_from_truth(t, pos, v, q), min(repeat, 2))

    print(
        f"integrate, {n_samples:,} samples         {rate_int / 1e3:10.0f} k samples/s"
        f"   (target >= 300 k: {'met' if rate_int >= 300e3 else 'NOT met'})"
    )
    print(
        f"propagate_reference (numpy baseline)  {rate_ref / 1e3:10.1f} k samples/s"
        f"   ({n_reference:,} samples)"
    )
    print(f"speed-up integrate / reference        {rate_int / rate_ref:10.0f} x")
    print(
        f"propagate, k = {BLOCK} block              {t_call * 1e6:10.2f} us/call"
        f"   ({1.0 / t_call / 1e3:.0f} k calls/s)"
    )
    print(
        f"  fixed overhead per call             {overhead * 1e6:10.2f} us"
        f"   ({overhead / t_call:.0%} of the call)"
    )
    print(
        f"  of which the Python wrapper         {(t_call - t_kernel_call) * 1e6:10.2f} us"
        f"   (propagate_kernel called directly: {t_kernel_call * 1e6:.2f} us)"
    )
    print(f"imu_from_truth, {n_samples:,} samples    {n_samples / t_gen / 1e3:10.0f} k samples/s")


if __name__ == "__main__":
    main()
