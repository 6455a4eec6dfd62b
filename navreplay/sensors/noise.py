"""Random processes of sensor error models and the conversions between noise specifications.

White noise is specified by its (one-sided) density N [unit*sqrt(s)], e.g. angle random walk in
rad/sqrt(s) or velocity random walk in (m/s)/sqrt(s). How it maps to a per-sample 1-sigma
depends on what a sample is:

- a mean over the sample interval dt (strapdown IMU output, ``navreplay`` convention):
  sigma = N / sqrt(dt)  (:func:`sample_sigma`);
- an instantaneous reading band-limited to the Nyquist frequency 1/(2 dt):
  sigma = N * sqrt(1 / (2 dt))  (:func:`nyquist_sample_sigma`).

Datasheets sometimes give white noise as the 1-sigma of a T-second average (e.g. "0.1 deg/h"
meaning the 1-s average); :func:`density_from_average_sigma` turns that into a density.

Examples
--------
The 20 ug "white noise" of a 1-s average, at a 100 Hz IMU:

>>> from navreplay.core.units import MICRO_G
>>> N = density_from_average_sigma(20 * MICRO_G)          # (m/s^2)*sqrt(s)
>>> round(sample_sigma(N, 0.01) / MICRO_G, 6)             # per-sample sigma [ug]
200.0
"""

from __future__ import annotations

import math

import numpy as np


def sample_sigma(density: float, dt: float) -> float:
    """Per-sample 1-sigma of white noise averaged over the sample interval.

    Parameters
    ----------
    density : float
        White-noise density N [unit*sqrt(s)].
    dt : float
        Sample interval [s].

    Returns
    -------
    float
        ``N / sqrt(dt)`` [unit].
    """
    return density / math.sqrt(dt)


def density_from_average_sigma(sigma_avg: float, averaging_time: float = 1.0) -> float:
    """Density of white noise whose T-second average has 1-sigma ``sigma_avg``.

    Parameters
    ----------
    sigma_avg : float
        1-sigma of the average over ``averaging_time`` [unit].
    averaging_time : float
        Averaging time T [s]; datasheets that quote white noise in rate units mean 1 s.

    Returns
    -------
    float
        ``sigma_avg * sqrt(T)`` [unit*sqrt(s)]: numerically unchanged for T = 1 s, but now a
        density, so that a sample at any rate gets the right sigma.
    """
    return sigma_avg * math.sqrt(averaging_time)


def nyquist_sample_sigma(density: float, dt: float) -> float:
    """Per-sample 1-sigma of an instantaneous reading with noise band-limited to Nyquist.

    Parameters
    ----------
    density : float
        White-noise density [unit/sqrt(Hz)] = [unit*sqrt(s)].
    dt : float
        Sample interval [s].

    Returns
    -------
    float
        ``density * sqrt(1 / (2 dt))`` [unit].
    """
    return density * math.sqrt(0.5 / dt)


def gauss_markov(
    n: int,
    dt: float,
    sigma: float | np.ndarray,
    tau: float,
    rng: np.random.Generator,
    dims: int = 3,
    x0: np.ndarray | None = None,
) -> np.ndarray:
    """Stationary first-order Gauss-Markov process, exactly discretised.

    ``b[k] = a b[k-1] + w[k]`` with ``a = exp(-dt/tau)``, ``w ~ N(0, sigma^2 (1 - a^2))`` and
    ``b[0] ~ N(0, sigma^2)`` (or ``x0``), so every sample has variance sigma^2 and the
    autocorrelation at lag tau is exp(-1).

    Parameters
    ----------
    n : int
        Number of samples.
    dt : float
        Sample interval [s].
    sigma : float or ndarray, shape (dims,)
        Steady-state 1-sigma [unit], per component or common; all zero gives zeros without
        drawing.
    tau : float
        Correlation time [s], > 0.
    rng : numpy.random.Generator
    dims : int
        Number of independent components.
    x0 : ndarray, shape (dims,), optional
        Initial state [unit]; drawn from the stationary distribution when omitted.

    Returns
    -------
    ndarray, shape (n, dims)
    """
    sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (dims,))
    if not np.any(sigma) or n == 0:
        return np.zeros((n, dims))
    a = math.exp(-dt / tau)
    x = rng.standard_normal((n, dims))
    x[0] = x[0] * sigma if x0 is None else x0
    x[1:] *= sigma * math.sqrt(-math.expm1(-2.0 * dt / tau))
    from scipy.signal import lfilter  # scipy.signal costs a second at start-up: only here

    return lfilter([1.0], [1.0, -a], x, axis=0)


def random_walk(
    n: int, dt: float, density: float, rng: np.random.Generator, dims: int = 3
) -> np.ndarray:
    """Random walk starting at 0: ``r[k] = r[k-1] + density sqrt(dt) n[k]``.

    Parameters
    ----------
    n : int
        Number of samples; ``r[0] = 0``.
    dt : float
        Sample interval [s].
    density : float
        Random-walk density [unit/sqrt(s)] (e.g. rate random walk in (rad/s)/sqrt(s));
        0 gives zeros without drawing.
    rng : numpy.random.Generator
    dims : int
        Number of independent components.

    Returns
    -------
    ndarray, shape (n, dims)
    """
    out = np.zeros((n, dims))
    if density == 0.0 or n <= 1:
        return out
    steps = rng.standard_normal((n - 1, dims))
    steps *= density * math.sqrt(dt)
    np.cumsum(steps, axis=0, out=out[1:])
    return out
