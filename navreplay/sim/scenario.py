"""Scenario interface and registry, and the pieces every scenario builds its recording from.

A scenario turns (parameters, seed) into a :class:`~navreplay.core.streams.Recording`: truth
trajectory, sensor streams and metadata. It is a pure function of its inputs: the same
parameters and seed give byte-identical recordings.

Metadata (:meth:`Scenario.metadata`)
    ``params`` holds every field of the scenario's ``Params`` in SI (plus derived values a
    filter may use, such as a surveyed lever arm); ``true_errors`` the true value of every
    random constant drawn for the run (time-varying errors such as Gauss-Markov biases and
    flexure are truth-stream columns); ``initial_nav``, for filters that do not initialise
    themselves, what an external alignment hands over: the truth plus drawn errors with their
    sigmas (:func:`navreplay.sim.trajectory.initial_nav`), or a surveyed site that the
    scenario's filter is meant to know; ``extra`` the site, date, rates and a description of
    every truth column; ``sensors`` the specification of every sensor it simulated
    (:class:`navreplay.sensors.specs.SensorSpecs`, SI), the records the filters derive their
    settings from.

Sensors (:meth:`Scenario.sensor_specs`)
    A scenario builds its sensors from its parameters (the IMU grade, the paper's table);
    ``[sensors.KIND]`` tables (``simulate --config``, or ``-p sensors.KIND.FIELD=VALUE``) are
    written over them before the run (:func:`scenario_inputs`), and the scenario simulates
    exactly the records it is handed.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

import navreplay
from navreplay.core import params as _params
from navreplay.core.streams import Metadata, Recording, Stream, StreamKind, nanoseconds
from navreplay.sensors.imu import ImuErrors, ImuMeasurement, effective_biases
from navreplay.sensors.specs import SensorSpecs, specs_from_tables
from navreplay.sim.trajectory import Trajectory

_REGISTRY: dict[str, type[Scenario]] = {}


class Scenario(abc.ABC):
    """Base class: subclasses set ``name``, ``summary``, ``streams``, ``Params`` and implement
    :meth:`sensor_specs` and :meth:`simulate`.

    ``Params`` is a frozen keyword-only dataclass in SI (datasheet units converted with
    :mod:`navreplay.core.units`) with a ``duration`` field [s] where the length is free.
    """

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    streams: ClassVar[tuple[StreamKind, ...]] = ()
    Params: ClassVar[type]

    @abc.abstractmethod
    def sensor_specs(self, params: Any) -> SensorSpecs:
        """The specifications of the scenario's sensors for ``params`` (one record per kind it
        simulates, with its source)."""

    @abc.abstractmethod
    def simulate(self, params: Any, rng: np.random.Generator, seed: int,
                 sensors: SensorSpecs) -> Recording:
        """Simulate one run with the sensors ``sensors`` (:meth:`sensor_specs`, perhaps with
        tables written over it). ``seed`` is recorded in the metadata; draw only from
        ``rng``."""

    def metadata(
        self,
        params: Any,
        seed: int,
        *,
        true_errors: Mapping[str, Any],
        extra: Mapping[str, Any],
        sensors: SensorSpecs,
        initial_nav: Mapping[str, Any] | None = None,
        derived: Mapping[str, Any] | None = None,
    ) -> Metadata:
        """The metadata of one run (see the module docstring).

        Parameters
        ----------
        params : Params
            The run's parameters, recorded field by field.
        seed : int
        true_errors, extra : mapping
        sensors : SensorSpecs
            The sensors simulated.
        initial_nav : mapping, optional
            For scenarios whose filters do not initialise themselves.
        derived : mapping, optional
            Values computed from the parameters and the draws, appended to ``params``.
        """
        return Metadata(
            scenario=self.name,
            seed=seed,
            params={**_params.as_dict(params), **(derived or {})},
            true_errors=dict(true_errors),
            initial_nav=dict(initial_nav or {}),
            navreplay_version=navreplay.__version__,
            extra=dict(extra),
            sensors=sensors.to_metadata(),
        )


def register_scenario(cls: type[Scenario]) -> type[Scenario]:
    """Class decorator adding a scenario to the registry under ``cls.name``."""
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise ValueError(f"scenario {cls.name!r} registered twice")
    _REGISTRY[cls.name] = cls
    return cls


def scenarios() -> dict[str, type[Scenario]]:
    """All registered scenarios by name (imports the built-ins)."""
    import navreplay.sim.scenarios  # noqa: F401  (registers the built-ins)

    return dict(sorted(_REGISTRY.items()))


def get_scenario(name: str) -> type[Scenario]:
    table = scenarios()
    if name not in table:
        raise KeyError(f"unknown scenario {name!r}; available: {', '.join(table)}")
    return table[name]


SENSORS_KEY = "sensors"
"""The key of a scenario's values that holds ``[sensors.KIND]`` tables (datasheet units)."""


def scenario_inputs(
    cls: type[Scenario], values: Mapping[str, Any] | None = None
) -> tuple[Any, SensorSpecs]:
    """The parameters and the sensors of a run of scenario ``cls``.

    ``values`` are parameter values (strings or values) and, under :data:`SENSORS_KEY`,
    ``[sensors.KIND]`` tables written over the scenario's own sensors
    (:func:`navreplay.sensors.specs.specs_from_tables`). Raises
    :class:`navreplay.core.params.ParamError` with one line.
    """
    values = dict(values or {})
    tables = values.pop(SENSORS_KEY, None) or {}
    p = _params.build(cls.Params, values, where=f"scenario {cls.name}")
    scenario = cls()
    base = scenario.sensor_specs(p)
    foreign = sorted(set(tables) - set(base.models))
    if foreign:
        raise _params.ParamError(
            f"scenario {cls.name} simulates no {', '.join(foreign)} (its sensors: "
            f"{', '.join(base.models) or 'none'}): remove [sensors.{foreign[0]}]")
    return p, specs_from_tables(tables, base=base)


def simulate(
    name: str, values: dict[str, Any] | None = None, seed: int = 0
) -> Recording:
    """Simulate scenario ``name`` with parameter overrides ``values`` (strings or values, and
    ``[sensors.KIND]`` tables under ``"sensors"``: :func:`scenario_inputs`)."""
    cls = get_scenario(name)
    p, sensors = scenario_inputs(cls, values)
    rng = np.random.default_rng(seed)
    return cls().simulate(p, rng, seed, sensors)


# --------------------------------------------------------------------------------------------
# streams shared by the scenarios


def check_sensor_rate(kind: str, rate: float, imu_rate: float) -> None:
    """Raise ``ValueError`` unless a sensor's ``rate`` [Hz] divides the IMU (truth) rate a
    whole number of times (it is sampled at every k-th truth sample)."""
    k = imu_rate / rate
    if round(k) < 1 or abs(k - round(k)) > 1e-9 * k:
        raise ValueError(f"the {kind} rate ({rate:g} Hz) must divide imu_rate ({imu_rate:g} Hz) "
                         "a whole number of times")


def imu_stream(
    t: np.ndarray, meas: ImuMeasurement, t0_ns: int, frame_id: str = "imu_frd"
) -> Stream:
    """The IMU stream of truth times ``t`` (N,) [s]: samples k = 1..N-1, each the mean over
    ``(t[k-1], t[k]]`` and stamped at ``t[k]``."""
    return Stream(StreamKind.IMU, nanoseconds(t[1:], t0_ns), meas.columns(), frame_id)


def truth_stream(
    traj: Trajectory,
    meas: ImuMeasurement,
    t0_ns: int,
    index: np.ndarray | None = None,
    errors: ImuErrors | None = None,
    *,
    level_biases: bool = False,
    **columns: np.ndarray,
) -> Stream:
    """The truth stream of a route: ``pos``, ``v_n``, ``q_nb``, ``euler``, the scenario's own
    ``columns`` (truth-rate arrays, N rows), then the true total IMU biases ``gyro_bias`` and
    ``accel_bias`` and, given the run's ``errors``, the effective biases ``gyro_bias_eff`` and
    ``accel_bias_eff`` (:func:`navreplay.sensors.imu.effective_biases`, at the level attitude
    with ``level_biases``); at the truth samples ``index`` (default: all)."""
    cols = {"pos": traj.pos, "v_n": traj.v_n, "q_nb": traj.q_nb, "euler": traj.euler,
            **columns, "gyro_bias": meas.gyro_bias, "accel_bias": meas.accel_bias}
    if errors is not None:
        cols["gyro_bias_eff"], cols["accel_bias_eff"] = effective_biases(
            errors, meas, traj.q_nb, traj.pos, level=level_biases)
    t = traj.t
    if index is not None:
        t = t[index]
        cols = {k: v[index] for k, v in cols.items()}
    return Stream(StreamKind.TRUTH, nanoseconds(t, t0_ns), cols, "ned")
