"""Layout of Monte Carlo statistics in the Rerun view: one plot per error component with the
RMS over runs and the mean predicted sigma, and the average NEES and NIS with their bounds."""

from __future__ import annotations

import math

import numpy as np

from navreplay.metrics import EnsembleResult, chi2_bounds_per_count
from navreplay.viz.naming import resolve_unit
from navreplay.viz.sink import Sink

_ENSEMBLE_NAV = (("pos_ned", "position", ("N", "E", "D"), "m", 1.0),
                 ("v_n", "velocity", ("N", "E", "D"), "m/s", 1.0),
                 ("phi", "attitude", ("phi_N", "phi_E", "phi_D"), "deg", 180.0 / math.pi))


def log_ensemble(sink: Sink, label: str, ens: EnsembleResult) -> None:
    """Log one filter's Monte Carlo statistics: RMS error vs mean predicted sigma over time for
    the navigation errors and scored states, average NEES and NIS with their 95 % bounds."""
    t = ens.t
    for key, what, axes, unit, scale in _ENSEMBLE_NAV:
        if key not in ens.rms:
            continue
        for i, axis in enumerate(axes):
            sigma = ens.sigma.get(key)
            series = {f"{label} RMS": ens.rms[key][:, i] * scale}
            if sigma is not None and np.isfinite(sigma[:, i]).any():
                series[f"{label} σ"] = sigma[:, i] * scale
            sink.log_ensemble(f"{what} error {axis}", t, series, unit=unit)
    for j, name in enumerate(ens.state_names):
        u = resolve_unit(name)
        sink.log_ensemble(
            f"{name} error", t,
            {f"{label} RMS": ens.state_rms[:, j] * u.scale,
             f"{label} σ": ens.state_sigma[:, j] * u.scale},
            unit=u.label,
        )
    if ens.nees_dof and np.isfinite(ens.nees_mean).any():
        sink.log_ensemble(f"{label} NEES (dof {ens.nees_dof}, {ens.runs} runs)", t,
                          {f"{label} NEES": ens.nees_mean}, unit="-", bounds=ens.nees_bounds)
    for meas, (t_k, mean, count, dof) in ens.nis_mean.items():
        lo, hi = chi2_bounds_per_count(dof, count)
        sink.log_ensemble(f"{label} NIS {meas} (dof {dof})", t_k[: mean.shape[0]],
                          {f"{label} NIS": mean}, unit="-", bounds=(lo, hi))
