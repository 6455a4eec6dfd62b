"""Synthetic recordings with random values, for tests and benchmarks of the recording format.

The values have the right shapes, units and magnitudes but no physics: they exercise encoding,
decoding and damage handling without the simulator.

>>> import numpy as np
>>> rec = random_recording(np.random.default_rng(0), duration_s=2.0)
>>> sorted(k.value for k in rec.kinds())[:3], len(rec["imu"])
(['depth', 'gps', 'gps_vel'], 400)
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from navreplay.core.streams import Metadata, Recording, Stream, StreamKind

T0_NS = 1_700_000_000_000_000_000
"""Default recording start [ns since the UNIX epoch] (2023-11-14)."""

RATES_HZ: dict[StreamKind, float] = {
    StreamKind.IMU: 200.0,
    StreamKind.MASTER_INS: 50.0,
    StreamKind.GPS: 1.0,
    StreamKind.GPS_VEL: 1.0,
    StreamKind.MAG: 10.0,
    StreamKind.SPEED_LOG: 5.0,
    StreamKind.DEPTH: 2.0,
    StreamKind.TRUTH: 200.0,
}
"""Sample rate per stream kind [Hz]."""

FRAMES: dict[StreamKind, str] = {
    StreamKind.IMU: "imu_frd",
    StreamKind.MASTER_INS: "ned",
    StreamKind.GPS: "gps_antenna",
    StreamKind.GPS_VEL: "ned",
    StreamKind.MAG: "mag_frd",
    StreamKind.SPEED_LOG: "speed_log",
    StreamKind.DEPTH: "depth",
    StreamKind.TRUTH: "ned",
}


def _times(rate_hz: float, duration_s: float, t0_ns: int, rng: np.random.Generator) -> np.ndarray:
    n = max(1, int(duration_s * rate_hz))
    period = 1e9 / rate_hz
    jitter = rng.integers(0, max(1, int(period * 1e-3)), n)  # sub-permille, keeps order
    return t0_ns + np.rint(np.arange(1, n + 1) * period).astype(np.int64) + jitter


def _pos(rng: np.random.Generator, n: int) -> np.ndarray:
    lat = rng.uniform(-1.4, 1.4, n)
    lon = rng.uniform(-np.pi, np.pi, n)
    h = rng.normal(0.0, 100.0, n)
    return np.column_stack([lat, lon, h])


def _quaternions(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    return q


def random_stream(
    kind: StreamKind | str,
    rng: np.random.Generator,
    *,
    duration_s: float = 10.0,
    t0_ns: int = T0_NS,
    gyro: bool = True,
    aux: bool = True,
) -> Stream:
    """One stream of ``kind`` at its :data:`RATES_HZ` rate with random values.

    Parameters
    ----------
    kind : StreamKind or str
    rng : numpy.random.Generator
    duration_s : float
        Length [s].
    t0_ns : int
        Recording start [ns]; the first sample is one period later.
    gyro : bool
        IMU only: include ``omega_ib_b`` (False: an accelerometer-only IMU).
    aux : bool
        Truth only: add extra columns ``gyro_bias`` (3,) [rad/s], ``accel_bias`` (3,) [m/s^2],
        ``misalignment`` (3, 3) [rad] and ``current_speed`` () [m/s].
    """
    kind = StreamKind(kind)
    t_ns = _times(RATES_HZ[kind], duration_s, t0_ns, rng)
    n = len(t_ns)
    cols: dict[str, np.ndarray]
    if kind is StreamKind.IMU:
        cols = {"f_b": rng.normal(0.0, 0.5, (n, 3)) + [0.0, 0.0, -9.81]}
        if gyro:
            cols = {"omega_ib_b": rng.normal(0.0, 0.05, (n, 3)), **cols}
    elif kind is StreamKind.MASTER_INS:
        euler = np.column_stack(
            [rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), rng.uniform(-np.pi, np.pi, n)]
        )
        cols = {"euler": euler, "v_n": rng.normal(0.0, 5.0, (n, 3)), "pos": _pos(rng, n)}
    elif kind is StreamKind.GPS:
        cols = {"pos": _pos(rng, n), "pos_sigma": rng.uniform(0.5, 5.0, (n, 3))}
    elif kind is StreamKind.GPS_VEL:
        cols = {"v_n": rng.normal(0.0, 5.0, (n, 3)), "vel_sigma": rng.uniform(0.01, 0.5, (n, 3))}
    elif kind is StreamKind.MAG:
        cols = {"m_b": rng.normal(0.0, 3e-5, (n, 3))}
    elif kind is StreamKind.SPEED_LOG:
        cols = {"rpm": rng.uniform(0.0, 300.0, n)}
    elif kind is StreamKind.DEPTH:
        cols = {"depth": rng.uniform(0.0, 200.0, n)}
    else:
        cols = {
            "pos": _pos(rng, n),
            "v_n": rng.normal(0.0, 5.0, (n, 3)),
            "q_nb": _quaternions(rng, n),
        }
        if aux:
            cols["gyro_bias"] = rng.normal(0.0, 1e-5, (n, 3))
            cols["accel_bias"] = rng.normal(0.0, 1e-3, (n, 3))
            cols["misalignment"] = rng.normal(0.0, 1e-3, (n, 3, 3))
            cols["current_speed"] = rng.uniform(0.0, 2.0, n)
    return Stream(kind, t_ns, cols, FRAMES[kind])


def random_metadata(rng: np.random.Generator) -> Metadata:
    """Metadata exercising every field (nested JSON, floats that need all 17 digits)."""
    return Metadata(
        scenario="synthetic",
        seed=int(rng.integers(0, 2**31)),
        params={
            "duration_s": 10.0,
            "imu": {"rate_hz": 200.0, "gyro_bias_sigma": 4.84813681109536e-6},
        },
        true_errors={
            "gyro_bias": rng.normal(0.0, 1e-5, 3).tolist(),
            "lever_arm_b": [1.5, -0.25, 0.1],
            "scale_factor_ppm": 120.0,
        },
        initial_nav={"t_ns": T0_NS, "pos": [0.6, 2.2, 10.0], "sigma": {"yaw": 0.01}},
        navreplay_version="0.1.0",
        extra={"site": "Gimpo", "note": "unicode \u00b0 ok", "empty": None},
    )


def random_recording(
    rng: np.random.Generator,
    *,
    duration_s: float = 10.0,
    kinds: Iterable[StreamKind | str] | None = None,
    t0_ns: int = T0_NS,
    gyro: bool = True,
    aux: bool = True,
) -> Recording:
    """A recording with a random stream of each kind (all kinds by default) and full metadata.

    See :func:`random_stream` for the parameters.
    """
    chosen = list(StreamKind) if kinds is None else [StreamKind(k) for k in kinds]
    streams = {
        k: random_stream(k, rng, duration_s=duration_s, t0_ns=t0_ns, gyro=gyro, aux=aux)
        for k in StreamKind
        if k in chosen
    }
    return Recording(streams, random_metadata(rng), t0_ns)
