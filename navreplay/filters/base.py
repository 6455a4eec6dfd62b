"""The filter interface: what the replay engine calls and what a filter hands back.

A filter is a class registered under a name (see :mod:`navreplay.filters.registry`). The replay
engine owns the loop: it merges the recording's streams by time and, for every aiding sample,
first hands the filter the IMU samples up to that time as one block (:meth:`Filter.propagate`),
then the sample itself (:meth:`Filter.update`). After every event, and at the output ticks of a
recording without aiding samples, it asks for :meth:`Filter.estimate` and stores it in columns.

Filters never print, never touch files and never import rerun.

Time inside a filter is float seconds since the recording start.

The engine hands a filter its events in runs (:class:`EventRun`: the IMU samples of a stretch
without gaps and the events in it) through :meth:`Filter.run_events`, whose default calls
``propagate``, ``update`` and ``estimate`` event by event; a filter with a compiled fast path
overrides it (see its docstring).

Declared states
---------------
A filter says once, as data, what each entry of ``Estimate.x`` is: a :class:`State` with its
name, SI unit, :class:`Quantity` and what it is scored against (``truth``), and whether it
counts in the run's NEES. The replay engine copies the declarations into the run result;
metrics, the Rerun view and the tables read them from there, so a plug-in filter is scored and
shown exactly as a built-in one::

    states = (
        State("dlat", "rad", Quantity.POSITION, NavError(Nav.LAT), nees=True),
        State("b_a_x", "m/s^2", Quantity.ACCEL_BIAS, TruthColumn("accel_bias", (0,))),
        State("s_g_z", "-", Quantity.GYRO_SCALE_FACTOR,
              TrueConstant("imu.gyro_scale_factor", (2,))),
    )

What a state is scored against (``truth``), with e the estimation error of the state:

:class:`NavError`
    The state *is* an error of the navigation solution (an error-state filter, estimate minus
    reference): ``e = (nav_hat - ref)_q - x`` for ``q`` in :class:`Nav`.
:class:`TruthColumn`
    A column of the reference (truth) stream, interpolated to the estimate times:
    ``e = x - truth[column][index]``.
:class:`TrueConstant`
    A constant of ``metadata.true_errors`` (dotted key): ``e = x - value[index]``.
None
    Not scored (shown with its sigma only).

A reference without the column a state needs (a real log with only positions, say) leaves
that state unscored instead of failing.

Declared measurements
---------------------
The innovations a filter returns from ``update`` are declared the same way, once, as data: a
:class:`MeasurementKind` per measurement names its rows and gives each row's SI unit::

    measurements = (
        MeasurementKind("gps_pos", ("N", "E", "D"), "m"),
        MeasurementKind("rpm", ("forward", "lateral", "vertical"), "m/s"),
    )

The engine copies them into the run result and checks that every returned
:class:`Innovation` names a declared measurement and has its number of rows; the Rerun view,
the report and the summary take the units and row names from there. A filter that declares
nothing (``measurements = None``, the default of this base class) is still replayed: its
innovations are not checked against a declaration and their units are guessed from their names.
"""

from __future__ import annotations

import abc
import dataclasses
import enum
import math
from collections.abc import Collection, Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from navreplay.core.streams import Metadata, StreamKind

if TYPE_CHECKING:
    from navreplay.filters.smoothable import SmoothingSteps
    from navreplay.sensors.specs import SensorSpecs


class Quantity(enum.StrEnum):
    """What a state (or a scored extra) is: its tab in the view, its group in tables."""

    POSITION = "position"
    VELOCITY = "velocity"
    ATTITUDE = "attitude"
    ACCEL_BIAS = "accel_bias"
    GYRO_BIAS = "gyro_bias"
    ACCEL_SCALE_FACTOR = "accel_scale_factor"
    GYRO_SCALE_FACTOR = "gyro_scale_factor"
    ACCEL_MISALIGNMENT = "accel_misalignment"
    GYRO_MISALIGNMENT = "gyro_misalignment"
    LEVER_ARM = "lever_arm"
    GNSS_ERROR = "gnss_error"
    """A time-correlated error of a GNSS receiver's solution."""
    MISALIGNMENT = "misalignment"
    """Mounting / boresight misalignment between two frames."""
    SPEED_SCALE_FACTOR = "speed_scale_factor"
    CURRENT = "current"
    CLOCK = "clock"
    """Time offsets and delays."""
    OTHER = "other"


class Nav(enum.StrEnum):
    """Components of the navigation solution an error state can be the error of.

    Units: ``lat``, ``lon`` rad; ``h`` m (positive up); ``depth`` m (positive down, so its
    error is ``-(h_hat - h)``); ``v_N, v_E, v_D`` m/s; ``phi_N, phi_E, phi_D`` rad, the attitude
    error of :func:`navreplay.geo.attitude_error` (``C_nb_hat = (I - [phi x]) C_nb``).
    """

    LAT = "lat"
    LON = "lon"
    H = "h"
    DEPTH = "depth"
    V_N = "v_N"
    V_E = "v_E"
    V_D = "v_D"
    PHI_N = "phi_N"
    PHI_E = "phi_E"
    PHI_D = "phi_D"


@dataclasses.dataclass(frozen=True)
class NavError:
    """The state is the error of the navigation solution in ``q``: ``e = (nav_hat - ref)_q - x``."""

    q: Nav

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", Nav(self.q))


@dataclasses.dataclass(frozen=True)
class TruthColumn:
    """The state estimates ``column[index]`` of the reference (truth) stream: ``e = x - truth``.

    ``index`` selects within one row (``()`` for the whole row of a scored extra)."""

    column: str
    index: tuple[int, ...] = ()


@dataclasses.dataclass(frozen=True)
class TrueConstant:
    """The state estimates a constant of ``metadata.true_errors``: ``key`` is dotted
    (``"imu.gyro_misalignment"``), ``index`` selects within its value; ``e = x - value``."""

    key: str
    index: tuple[int, ...] = ()


Truth = NavError | TruthColumn | TrueConstant
"""What a state is scored against."""


@dataclasses.dataclass(frozen=True)
class State:
    """Declaration of one entry of ``Estimate.x`` (or of one scored ``Estimate.extras`` key).

    Attributes
    ----------
    name : str
        E.g. ``"dv_N"``; unique within the filter.
    unit : str
        SI unit as shown on axes: ``"rad"``, ``"m"``, ``"m/s"``, ``"m/s^2"``, ``"rad/s"``,
        ``"s"``, ``"-"``. The view converts angles, rates and accelerations to display units.
    quantity : Quantity
    truth : NavError, TruthColumn, TrueConstant or None
        What the estimate is scored against (see the module docstring).
    nees : bool
        Counts in the run's NEES (needs ``truth``).
    """

    name: str
    unit: str
    quantity: Quantity
    truth: Truth | None = None
    nees: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"state name must be a non-empty string, got {self.name!r}")
        object.__setattr__(self, "quantity", Quantity(self.quantity))
        if self.truth is not None and not isinstance(self.truth, Truth):
            raise TypeError(f"state {self.name}: truth must be NavError, TruthColumn, "
                            f"TrueConstant or None, got {self.truth!r}")
        if self.nees and self.truth is None:
            raise ValueError(f"state {self.name}: nees=True needs a truth to score against")


@dataclasses.dataclass(frozen=True)
class MeasurementKind:
    """Declaration of one measurement a filter updates with: the rows of its innovation.

    Attributes
    ----------
    name : str
        :attr:`Innovation.name` of its updates, e.g. ``"gps_pos"``; unique within the filter.
    rows : tuple[str, ...]
        Name of each row of ``nu``, in order: the axis (``"N"``, ``"E"``, ``"D"``;
        ``"forward"``, ``"lateral"``, ``"vertical"``) or component (``"q0"``).
    units : tuple[str, ...]
        SI unit of each row, as for :attr:`State.unit`; one string stands for every row.
    """

    name: str
    rows: tuple[str, ...]
    units: tuple[str, ...] | str

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"measurement name must be a non-empty string, got {self.name!r}")
        if isinstance(self.rows, str) or not all(isinstance(r, str) and r for r in self.rows):
            raise TypeError(f"measurement {self.name}: rows must be a tuple of non-empty "
                            f"strings, got {self.rows!r}")
        rows = tuple(self.rows)
        if not rows or len(set(rows)) != len(rows):
            raise ValueError(f"measurement {self.name}: rows must be at least one, each named "
                             f"once, got {rows!r}")
        units = (self.units,) * len(rows) if isinstance(self.units, str) else tuple(self.units)
        if len(units) != len(rows) or not all(isinstance(u, str) and u for u in units):
            raise ValueError(f"measurement {self.name}: units must be one non-empty unit string "
                             f"or one per row ({len(rows)}), got {self.units!r}")
        object.__setattr__(self, "rows", rows)
        object.__setattr__(self, "units", units)

    @property
    def dim(self) -> int:
        """Number of rows of the innovation."""
        return len(self.rows)


def check_measurements(measurements: object, what: str = "measurements"
                       ) -> tuple[MeasurementKind, ...] | None:
    """``measurements`` as a tuple of :class:`MeasurementKind` with unique names (None stays
    None: nothing declared), or ``TypeError`` / ``ValueError`` naming what is wrong."""
    if measurements is None:
        return None
    if not isinstance(measurements, tuple | list) or not all(
            isinstance(m, MeasurementKind) for m in measurements):
        raise TypeError(f"{what} must be a tuple of navreplay.filters.base.MeasurementKind, "
                        f"got {measurements!r}")
    names = [m.name for m in measurements]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"{what}: names declared twice: {', '.join(dupes)}")
    return tuple(measurements)


def check_states(states: object, what: str = "states") -> tuple[State, ...]:
    """``states`` as a tuple of :class:`State` with unique names, or ``TypeError`` /
    ``ValueError`` naming what is wrong."""
    if not isinstance(states, tuple | list) or not all(isinstance(s, State) for s in states):
        raise TypeError(f"{what} must be a tuple of navreplay.filters.base.State, got {states!r}")
    names = [s.name for s in states]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"{what}: names declared twice: {', '.join(dupes)}")
    return tuple(states)


def state_names(states: tuple[State, ...]) -> tuple[str, ...]:
    """The names of declared states, in order."""
    return tuple(s.name for s in states)


@dataclasses.dataclass(frozen=True, kw_only=True)
class FilterParams:
    """Base of every filter's parameters: a frozen, keyword-only dataclass in SI units.

    Subclasses document the unit of each field in its docstring and validate in
    ``__post_init__`` (raise ``ValueError`` naming the field and the accepted range, e.g. with
    :func:`check_number`).
    """


def check_number(
    params: object, name: str, *, positive: bool = False, upper: float | None = None
) -> None:
    """Raise ``ValueError`` unless the field ``name`` of ``params`` is None or a finite number
    ``>= 0`` (``> 0`` with ``positive``) and ``<= upper`` when given.

    Examples
    --------
    >>> import dataclasses
    >>> @dataclasses.dataclass
    ... class P:
    ...     dt: float = 0.0
    >>> check_number(P(), "dt", positive=True)
    Traceback (most recent call last):
    ...
    ValueError: dt must be finite and > 0, got 0.0
    """
    v = getattr(params, name)
    if v is None:
        return
    ok = isinstance(v, int | float) and math.isfinite(v) and (v > 0.0 if positive else v >= 0.0)
    if ok and upper is not None:
        ok = v <= upper
    if not ok:
        band = "> 0" if positive else ">= 0"
        if upper is not None:
            band += f" and <= {upper:g}"
        raise ValueError(f"{name} must be finite and {band}, got {v!r}")


@dataclasses.dataclass(frozen=True)
class FilterContext:
    """What a filter may know before the first sample.

    Attributes
    ----------
    metadata : Metadata
        The recording's metadata. ``metadata.initial_nav`` is the externally supplied initial
        solution; a filter must not read ``metadata.true_errors`` (that is for scoring).
    t0_ns : int
        Recording start [ns]; filter time t = 0 here.
    streams : frozenset[StreamKind]
        Streams the recording holds.
    """

    metadata: Metadata
    t0_ns: int
    streams: frozenset[StreamKind]


@dataclasses.dataclass(frozen=True)
class NavSolution:
    """Standard navigation solution.

    pos : (3,) latitude [rad], longitude [rad], height [m]; v_n : (3,) [m/s]; q_nb : (4,).
    """

    pos: np.ndarray
    v_n: np.ndarray
    q_nb: np.ndarray

    @classmethod
    def from_vector(cls, nav: np.ndarray) -> NavSolution:
        """From a navigation vector ``[lat, lon, h, v_N, v_E, v_D, q0, q1, q2, q3]`` (10,), the
        layout of :mod:`navreplay.geo.strapdown`; the fields are views of ``nav``."""
        return cls(pos=nav[0:3], v_n=nav[3:6], q_nb=nav[6:10])


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A filter's output at one time.

    Attributes
    ----------
    t : float
        Time [s since the recording start].
    x : ndarray, shape (n,)
        State vector, one entry per ``Filter.states``; for an error-state filter with feedback,
        the *total* estimates of the error quantities it tracks (e.g. the bias estimate), or the
        error estimate itself where there is no total (document which in the filter).
    P : ndarray, shape (n, n)
        Covariance of the state's error.
    nav : NavSolution | None
        The navigation solution, when the filter has one.
    extras : dict[str, ndarray]
        Further named outputs of fixed shape (e.g. ``"misalignment_euler"``), SI; those the
        filter declares in ``Filter.scored_extras`` are scored like states.
    """

    t: float
    x: np.ndarray
    P: np.ndarray
    nav: NavSolution | None = None
    extras: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class Innovation:
    """One measurement update: innovation ``nu = z - H x`` and its covariance ``S``.

    ``name`` identifies the measurement (e.g. ``"gps_pos"``), one of the filter's declared
    ``measurements``; ``nu`` has shape (m,) with m its rows, ``S`` (m, m).
    """

    name: str
    t: float
    nu: np.ndarray
    S: np.ndarray


NAV_PARTS = ("pos", "v_n", "q_nb")
"""The parts of a navigation solution, in order: of the initial solution a filter starts from
(:attr:`Filter.initial`) and of the solution it outputs (:attr:`Filter.navigation`)."""

NAV_PART: dict[Nav, str] = {
    Nav.LAT: "pos", Nav.LON: "pos", Nav.H: "pos", Nav.DEPTH: "pos",
    Nav.V_N: "v_n", Nav.V_E: "v_n", Nav.V_D: "v_n",
    Nav.PHI_N: "q_nb", Nav.PHI_E: "q_nb", Nav.PHI_D: "q_nb",
}
"""The part of the navigation solution each navigation quantity is an error of."""


OUTPUT_LIMIT = 1e100
"""Largest magnitude of any entry of an estimate (states, covariance, solution, extras): a
value beyond it is no estimate but an overflow waiting to happen (its square, or a latitude
turned into metres and squared, overflows in the scores), and stops the run like a non-finite
one."""
LATITUDE_SLACK = 1e-9
"""How far beyond a pole [rad] a latitude of the solution may lie (rounding)."""


def output_problem(part: str, values: np.ndarray) -> tuple[np.ndarray, str]:
    """Rows of an estimate column that cannot be an estimate, and why.

    Parameters
    ----------
    part : str
        ``pos``, ``v_n`` or ``q_nb`` for the solution's parts (``pos`` rows are lat, lon [rad],
        h [m]), anything else for states, covariances and extras.
    values : ndarray, shape (N, ...)

    Returns
    -------
    bad : ndarray of bool, shape (N,)
        Non-finite, beyond :data:`OUTPUT_LIMIT`, or (``pos``) a latitude beyond a pole.
    why : str
        What the first bad row has, for the message.
    """
    flat = values.reshape(len(values), -1)
    finite = np.isfinite(flat).all(axis=1)
    with np.errstate(invalid="ignore"):
        huge = (np.abs(flat) > OUTPUT_LIMIT).any(axis=1) & finite
        pole = np.zeros(len(flat), bool)
        if part == "pos" and flat.shape[1] >= 1:
            pole = (np.abs(flat[:, 0]) > np.pi / 2 + LATITUDE_SLACK) & finite & ~huge
    bad = ~finite | huge | pole
    if not bad.any():
        return bad, ""
    i = int(np.argmax(bad))
    if not finite[i]:
        why = "non-finite"
    elif huge[i]:
        why = f"overflowing ({float(np.max(np.abs(flat[i]))):.3g}, beyond {OUTPUT_LIMIT:g})"
    else:
        why = f"impossible (latitude {float(flat[i, 0]):.6g} rad, beyond a pole)"
    return bad, why


def initial_parts(classes: Sequence[type[Filter]]) -> tuple[str, ...]:
    """The parts of the initial solution that any of ``classes`` starts from, in the order of
    :data:`NAV_PARTS`; an undeclared part name is refused with the filter's name."""
    wanted: set[str] = set()
    for cls in classes:
        unknown = set(cls.initial) - set(NAV_PARTS)
        if unknown:
            raise ValueError(f"filter {cls.name!r}: initial names unknown parts "
                             f"{sorted(unknown)}; use some of {', '.join(NAV_PARTS)}")
        wanted |= set(cls.initial)
    return tuple(k for k in NAV_PARTS if k in wanted)


def navigation_parts(cls: type[Filter], states: Sequence[State] = ()) -> tuple[str, ...]:
    """The parts of the navigation solution ``cls`` outputs (:attr:`Filter.navigation`), in
    the order of :data:`NAV_PARTS`; an unknown or repeated part name, none at all, or a
    ``NavError`` state of ``states`` in a part not declared is refused with the filter's name."""
    parts = cls.navigation
    if isinstance(parts, str) or not isinstance(parts, tuple | list):
        raise TypeError(f"filter {cls.name!r}: navigation must be a tuple of part names "
                        f"({', '.join(NAV_PARTS)}), got {parts!r}")
    unknown = sorted(str(p) for p in set(parts) - set(NAV_PARTS))
    if unknown or not parts or len(set(parts)) != len(parts):
        raise ValueError(f"filter {cls.name!r}: navigation names "
                         f"{'unknown parts ' + str(unknown) if unknown else repr(tuple(parts))}"
                         f"; declare each of some of {', '.join(NAV_PARTS)} once")
    outside = [s.name for s in states
               if isinstance(s.truth, NavError) and NAV_PART[s.truth.q] not in parts]
    if outside:
        raise ValueError(f"filter {cls.name!r}: states {', '.join(outside)} are errors of parts "
                         f"of the navigation solution it does not declare (navigation = "
                         f"{tuple(parts)!r})")
    return tuple(k for k in NAV_PARTS if k in parts)


def consumed_streams(cls: type[Filter]) -> tuple[StreamKind, ...] | None:
    """The aiding streams a filter is handed: ``requires`` + ``optional``, or None (all) when
    it declares no stream at all."""
    declared = tuple(cls.requires) + tuple(cls.optional)
    return declared or None


TICK = -1
"""Event code of an output tick (an aiding event's code is the index of its stream in
:attr:`EventRun.kinds`)."""


class EventRun(abc.ABC):
    """A run of replay events, handed to :meth:`Filter.run_events` by the engine.

    Event ``e`` (``0 <= e < len(run)``) at time ``t_ev[e]`` [s] is: the IMU samples of its
    segment ``[ends[e-1], ends[e])`` of the block (``0`` for ``e = 0``) to ``propagate``
    (none when the segment is empty); unless ``codes[e]`` is :data:`TICK`, row ``rows[e]`` of
    the aiding stream ``kinds[codes[e]]`` (columns ``samples[codes[e]]``) to ``update``; when
    ``record[e]``, the estimate after it to :meth:`add_estimate`. The block holds no IMU gap
    (the engine bridges gaps between runs).

    Attributes
    ----------
    t : ndarray, shape (k,)
        IMU sample times of the block [s].
    imu : mapping
        The block's IMU columns, ``omega_ib_b`` and ``f_b`` (k, 3).
    ends : ndarray of int64, shape (E,)
        End of each event's IMU segment (indices into ``t``, non-decreasing).
    kinds : tuple of StreamKind
        The aiding streams the filter consumes, in priority order.
    codes, rows : ndarray of int64, shape (E,)
        Stream of each event (index into ``kinds``, or :data:`TICK`) and row of its sample.
    t_ev : ndarray, shape (E,)
        Event times [s].
    record : ndarray of bool, shape (E,)
        Whether an estimate is recorded after the event (once per distinct time).
    samples : sequence of mappings
        The columns of each aiding stream, by its index in ``kinds``.
    done : int
        Events applied so far (:meth:`Filter.run_events` keeps it current, so that an error
        names the event that raised it).
    """

    t: np.ndarray
    imu: Mapping[str, np.ndarray]
    ends: np.ndarray
    kinds: tuple[StreamKind, ...]
    codes: np.ndarray
    rows: np.ndarray
    t_ev: np.ndarray
    record: np.ndarray
    samples: Sequence[Mapping[str, np.ndarray]]
    done: int = 0

    def __len__(self) -> int:
        return int(self.ends.shape[0])

    @abc.abstractmethod
    def add_estimate(self, est: Estimate) -> None:
        """Record the estimate after an event (the engine checks it)."""

    @abc.abstractmethod
    def add_innovations(self, items: Sequence[Innovation]) -> None:
        """The innovations an update returned."""

    @abc.abstractmethod
    def out(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For a compiled run: free rows ``(t (E,), x (E, n), P (E, n, n), nav (E, 10))`` to
        write the estimates into (``nav`` the navigation vectors of :mod:`navreplay.geo.strapdown`);
        :meth:`add_rows` then says how many were written."""

    @abc.abstractmethod
    def add_rows(self, m: int, checked: bool = False,
                 steps: SmoothingSteps | None = None) -> None:
        """The first ``m`` rows of :meth:`out` hold estimates; ``checked``: their covariances
        were checked as :func:`navreplay.filters.kalman.check_covariance` checks them;
        ``steps``: what a smoother needs of each (a :class:`~navreplay.filters.smoothable.
        Smoothable` filter after ``start_smoothing``; required then)."""

    @abc.abstractmethod
    def add_innovation_rows(self, name: str, t: np.ndarray, nu: np.ndarray,
                            S: np.ndarray) -> None:
        """Updates of measurement ``name`` made by a compiled run: times (K,) [s], innovations
        (K, m) and their covariances (K, m, m)."""


class Filter(abc.ABC):
    """Base class of every filter.

    Class attributes
    ----------------
    name : str
        Registry name (``navreplay run NAME``), lowercase with dashes.
    summary : str
        One line for ``navreplay filters``.
    requires : tuple[StreamKind, ...]
        Streams that must be present; ``run`` fails before starting otherwise.
    optional : tuple[StreamKind, ...]
        Streams used when present.
    required_columns : dict[StreamKind, tuple[str, ...]]
        For a required stream, the columns the filter needs when not all the standard ones of
        :data:`navreplay.core.streams.FIELDS` (e.g. ``{StreamKind.IMU: ("f_b",)}`` for an
        accelerometer-only filter); the engine checks them before running.
    Params : type[FilterParams]
        Parameter dataclass.
    states : tuple[State, ...]
        One declaration per entry of ``Estimate.x``, in order (a class attribute, or an
        instance attribute set in ``__init__`` when it depends on the parameters).
    scored_extras : tuple[State, ...]
        Declarations of ``Estimate.extras`` keys scored against a truth (``name`` is the key;
        a ``TruthColumn`` with ``index=()`` compares the whole extra with the column row).
    measurements : tuple[MeasurementKind, ...] or None
        One declaration per measurement whose innovations ``update`` returns: its rows and
        their units (class or instance attribute, as ``states``); ``()`` for a filter without
        updates. None (the default): not declared, innovations unchecked, units guessed.
    initial : tuple[str, ...]
        The parts of the initial solution ``metadata.initial_nav`` the filter starts from:
        ``pos``, ``v_n``, ``q_nb`` (all three, the default). ``run`` asks the recording, the
        ``[initial]`` table or ``--init`` for these only; a filter that initialises itself from
        its measurements declares fewer (``()``: none).
    navigation : tuple[str, ...]
        The parts of the navigation solution ``Estimate.nav`` the filter outputs, among the
        same names (all three, the default). A filter that estimates attitude only (an AHRS)
        declares ``("q_nb",)`` and returns NaN in the parts it does not estimate; they are
        neither checked nor scored nor shown. Its ``NavError`` states may only name
        quantities of the declared parts.

    Fast path
    ---------
    :meth:`run_events` applies a run of events; its default calls ``propagate``, ``update``
    and ``estimate`` event by event. A filter with a compiled kernel overrides it to apply
    the whole run in one call (``ins`` and ``gps-ins``), bit for bit as the default would;
    it falls back to the default where its kernel does not apply (a subclass that changes
    ``propagate``, ``update`` or ``estimate``).

    Settings from the sensors
    -------------------------
    settings_from_sensors(sensors) -> dict  (classmethod)
        The parameter values that follow from the recording's sensor specifications
        (:class:`navreplay.sensors.specs.SensorSpecs`: ``sensors.imu.gyro_arw`` [rad/sqrt(s)],
        ``sensors.gps.pos_sigma``, ...), by parameter name, in SI. Only values of stated
        fields (``sensors.has("imu", "gyro_arw")``) may be used. The replay builds the filter's
        ``Params`` from the user's values over these over the defaults
        (:func:`navreplay.filters.settings.build_params`), and the run summary says where each
        came from. The base class derives nothing.
    default_sensors() -> SensorSpecs  (classmethod)
        The sensors the defaults of ``Params`` stand for (e.g. a tactical IMU): a run whose
        recording does not state them says once that it uses these defaults. Empty by default.
    modelled_terms(params) -> mapping or None  (classmethod)
        The error terms of the sensor specifications (the fields of each record's
        ``error_terms``, e.g. ``ImuModel.error_terms``) that the filter models with ``params``,
        by sensor kind: ``{"imu": {"gyro_arw", ...}, "gps": {"pos_sigma", ...}}``. A run whose
        recording states a term (not zero) of a sensor the filter consumes that the filter
        does not model says so once ("gps-ins does not model the gps time-correlated velocity
        error (vel_gm_sigma)"; :func:`navreplay.filters.settings.build_params`). None (the
        default): not declared, nothing said.

    Optional method
    ---------------
    bridge_imu_gap(t: float, since: float) -> None
        Called when the IMU stream has a gap (an interval longer than a few nominal ones,
        :mod:`navreplay.replay.gaps`): bring the state to time ``t`` [s] without IMU samples
        since ``since`` [s], with a covariance that honestly covers the unknown motion. The
        engine calls it up to each aiding sample inside the gap (before ``update``) and up to
        one nominal interval before the first sample after it, which ``propagate`` then gets
        as usual. Not defined on this base class on purpose: a filter without it cannot be
        replayed over a gap, and the run stops with one line naming the filter and the gap.
    """

    name: ClassVar[str]
    summary: ClassVar[str] = ""
    requires: ClassVar[tuple[StreamKind, ...]] = ()
    optional: ClassVar[tuple[StreamKind, ...]] = ()
    required_columns: ClassVar[Mapping[StreamKind, tuple[str, ...]]] = {}
    Params: ClassVar[type[FilterParams]] = FilterParams

    states: tuple[State, ...] = ()
    scored_extras: tuple[State, ...] = ()
    measurements: tuple[MeasurementKind, ...] | None = None
    initial: ClassVar[tuple[str, ...]] = NAV_PARTS
    navigation: ClassVar[tuple[str, ...]] = NAV_PARTS

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the declared states, in order."""
        return state_names(self.states)

    @classmethod
    def settings_from_sensors(cls, sensors: SensorSpecs) -> dict[str, Any]:
        """Parameter values derived from the recording's sensor specifications (see the class
        docstring); none here."""
        return {}

    @classmethod
    def default_sensors(cls) -> SensorSpecs:
        """The sensor specifications the ``Params`` defaults stand for; none here."""
        from navreplay.sensors.specs import SensorSpecs

        return SensorSpecs()

    @classmethod
    def modelled_terms(cls, params: FilterParams) -> Mapping[str, Collection[str]] | None:
        """The error terms of the sensor specifications the filter models with ``params``, by
        sensor kind (see the class docstring); None here: not declared."""
        return None

    def __init__(self, params: FilterParams, context: FilterContext) -> None:
        self.params = params
        self.context = context

    @abc.abstractmethod
    def propagate(self, t: np.ndarray, imu: Mapping[str, np.ndarray]) -> None:
        """Advance over a block of IMU samples.

        Parameters
        ----------
        t : ndarray, shape (k,)
            Sample times [s]; each sample is the mean over (t[i-1], t[i]] (the previous block's
            last time for i = 0).
        imu : mapping
            ``omega_ib_b`` (k, 3) [rad/s] and ``f_b`` (k, 3) [m/s^2], FRD.
        """

    @abc.abstractmethod
    def update(
        self, kind: StreamKind, t: float, sample: Mapping[str, Any]
    ) -> list[Innovation] | None:
        """Process one aiding sample (one row of the stream, columns by name) at time t [s].

        Returns the innovations of the updates made (for NIS), or None.
        """

    @abc.abstractmethod
    def estimate(self) -> Estimate | None:
        """The current estimate, or None before the filter is initialised."""

    def run_events(self, run: EventRun) -> int:
        """Apply the events of ``run`` in order (see :class:`EventRun`) and return how many
        were applied.

        This default hands each event's IMU segment to :meth:`propagate`, its sample to
        :meth:`update` and records :meth:`estimate`: the reference of every fast path. An
        override may apply fewer events than the run holds (a compiled run that stops before
        an event failing one of its checks, its state as before that event): the engine then
        applies the next event through this default, which names the problem, and goes on.
        """
        propagate, update, estimate = self.propagate, self.update, self.estimate
        t, imu = run.t, tuple(run.imu.items())
        kinds = run.kinds
        samples = [tuple(s.items()) for s in run.samples]
        ends, codes, rows = run.ends.tolist(), run.codes.tolist(), run.rows.tolist()
        t_ev, record = run.t_ev.tolist(), run.record.tolist()
        a = 0
        for e in range(len(ends)):
            run.done = e
            b = ends[e]
            if b > a:
                propagate(t[a:b], {k: v[a:b] for k, v in imu})
                a = b
            c = codes[e]
            if c != TICK:
                r = rows[e]
                inn = update(kinds[c], t_ev[e], {k: v[r] for k, v in samples[c]})
                if inn:
                    run.add_innovations(inn)
            if record[e]:
                est = estimate()
                if est is not None:
                    run.add_estimate(est)
        run.done = len(ends)
        return len(ends)


def overrides(obj: Filter, base: type[Filter], *names: str) -> bool:
    """Whether the class of ``obj`` defines any of the methods ``names`` otherwise than
    ``base`` does (a subclass that changes what a compiled fast path of ``base`` assumes)."""
    cls = type(obj)
    return any(getattr(cls, n) is not getattr(base, n) for n in names)
