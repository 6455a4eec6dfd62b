"""Initial navigation solutions for logs: ``--init metadata|reference|align`` and ``[initial]``.

Each method produces a ``metadata.initial_nav`` of the shape the filters read
(:func:`navreplay.filters.ins.initial_solution`): ``t_ns``, ``pos``, ``v_n``, ``q_nb`` and
``sigma`` (``pos_ned`` [m], ``v_n`` [m/s], ``phi`` [rad]), plus ``method`` and optional
``accel_bias`` [m/s^2] and ``gyro_bias`` [rad/s]. Values of the ``[initial]`` table replace the
method's, one by one (with their sigmas).

``align`` (self-alignment, while still at the start,
:func:`~navreplay.logs.framecheck.still_window`):

* levelling: roll = atan2(-f_y, -f_z), pitch = atan2(f_x, hypot(f_y, f_z)) of the mean specific
  force (FRD); 1-sigma sqrt(b_a^2 + s_f^2 / n) / g with s_f the sample scatter and b_a the
  accelerometer bias: ``[initial] accel_bias_sigma`` when given, else the typical bias of the
  grade the gyro shows at rest (:func:`grade_accel_bias`), and never less than the vertical
  bias the data show (``| |f| - g |``): horizontal biases are not observable at rest, so the
  sigma must come from what the sensor is, not from the fit;
* heading by gyrocompassing: the mean rate levelled, psi = atan2(-w_y, w_x); its 1-sigma
  sqrt(s_w^2 + b_g^2) / (Omega cos lat) with s_w the standard error of the 1 s block means and
  b_g the larger of the assumed gyro bias (``gyro_bias_sigma_dph``) and the bias the data show
  (vertical rate minus -Omega sin lat, horizontal magnitude minus Omega cos lat), combined with
  the levelling sigma times tan(lat) (a tilt turns vertical earth rate into horizontal). Used
  when that sigma is below :data:`GYROCOMPASS_MAX_SIGMA`;
* else magnetometer heading (levelled field + WMM declination), 1-sigma
  :data:`MAG_HEADING_SIGMA` (local disturbances) combined with the levelling sigma times
  tan(dip);
* else GNSS course over ground at the first velocity faster than :data:`COG_MIN_SPEED`, carried
  back to the start by the integrated yaw rate; 1-sigma from the velocity noise and
  :data:`COG_SIDESLIP` (the vehicle moving along its x axis);
* else (no velocity topic, or never that fast: a walk) the GNSS track: the chord from the still
  position to the first fix :data:`CHORD_LENGTH` away, carried back by half the yaw turned
  meanwhile; 1-sigma from the fixes' noise over the chord, the sideslip and that half turn.

Position: the GNSS fix nearest the start (its covariance, else :data:`GNSS_POS_SIGMA`), else
``[initial]``. Velocity zero (still), 1-sigma :data:`STILL_VEL_SIGMA`. The solution is stamped
at the end of the still window: alignment uses the data before it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from navreplay.core.streams import Recording, Stream, StreamKind, seconds
from navreplay.core.units import DEG_PER_HOUR, MICRO_G
from navreplay.filters.base import NAV_PARTS
from navreplay.geo import earth
from navreplay.geo.rotations import euler_to_dcm, euler_to_quat, quat_to_euler, wrap_angle
from navreplay.io.errors import RecordingError
from navreplay.logs.framecheck import still_window, wmm_field_ned
from navreplay.logs.options import InitMethod
from navreplay.metrics.initial import RECORDING

GYROCOMPASS_MAX_SIGMA = math.radians(5.0)
MAG_HEADING_SIGMA = math.radians(3.0)
COG_MIN_SPEED = 2.0
COG_SIDESLIP = math.radians(2.0)
CHORD_LENGTH = 30.0
GNSS_POS_SIGMA = 5.0
STILL_VEL_SIGMA = 0.02
MIN_STILL_S = 2.0
GRADE_ACCEL_BIAS: tuple[tuple[float, float, str], ...] = (
    (0.05 * DEG_PER_HOUR, 50.0 * MICRO_G, "navigation"),
    (5.0 * DEG_PER_HOUR, 1000.0 * MICRO_G, "tactical"),
    (math.inf, 20000.0 * MICRO_G, "MEMS"),
)
"""(largest gyro bias shown at rest [rad/s], typical accelerometer bias [m/s^2], grade name):
the accelerometer bias assumed for levelling when ``[initial] accel_bias_sigma`` is not given."""
OMEGA_E = 7.292115e-5
REF_DIFF_VEL_SIGMA = 0.05
"""1-sigma [m/s] of a start velocity differenced from a reference without velocity."""


class InitialisationError(RecordingError):
    """No initial solution can be made with the method asked for; says what is missing."""


def _vec3(value: Any) -> np.ndarray:
    v = np.atleast_1d(np.asarray(value, dtype=float))
    return np.full(3, v[0]) if v.size == 1 else v.reshape(3)


STATE_KEYS = ("lat_deg", "lon_deg", "h", "v_n", "roll_deg", "pitch_deg", "yaw_deg",
              "pos_sigma", "vel_sigma", "att_sigma_deg", "accel_bias", "gyro_bias_dph")
"""The ``[initial]`` keys that are part of the initial state (the others are assumptions of
``--init align``)."""


def _from_table(nav: dict[str, Any], table: Mapping[str, Any]) -> dict[str, Any]:
    """Apply the ``[initial]`` values over a solution (any part may be missing)."""
    nav = dict(nav)
    sigma = dict(nav.get("sigma", {}))
    if "lat_deg" in table and "lon_deg" in table:
        nav["pos"] = [math.radians(table["lat_deg"]), math.radians(table["lon_deg"]),
                      float(table.get("h", 0.0))]
    if "v_n" in table:
        nav["v_n"] = list(_vec3(table["v_n"]))
    angles = ("roll_deg", "pitch_deg", "yaw_deg")
    if any(k in table for k in angles):
        base = (quat_to_euler(np.asarray(nav["q_nb"])) if "q_nb" in nav
                else np.full(3, np.nan))
        euler = np.array([math.radians(table[k]) if k in table else base[i]
                          for i, k in enumerate(angles)])
        if np.isfinite(euler).all():
            nav["q_nb"] = list(euler_to_quat(euler))
    for key, name, scale in (("pos_sigma", "pos_ned", 1.0), ("vel_sigma", "v_n", 1.0),
                             ("att_sigma_deg", "phi", math.pi / 180.0)):
        if key in table:
            sigma[name] = list(_vec3(table[key]) * scale)
    if "accel_bias" in table:
        nav["accel_bias"] = list(_vec3(table["accel_bias"]))
    if "gyro_bias_dph" in table:
        nav["gyro_bias"] = list(_vec3(table["gyro_bias_dph"]) * DEG_PER_HOUR)
    nav["sigma"] = sigma
    return nav


def _complete(nav: Mapping[str, Any], needs: Sequence[str] = NAV_PARTS) -> list[str]:
    return [k for k in needs if k not in nav]


def _interp_stream(s: Stream, t_ns: int, col: str) -> np.ndarray:
    t = (s.t_ns - s.t_ns[0]).astype(float)
    x = float(t_ns - s.t_ns[0])
    v = s[col]
    if v.ndim == 1:
        return np.array(np.interp(x, t, v))
    return np.array([np.interp(x, t, v[:, i]) for i in range(v.shape[1])])


def from_reference(recording: Recording) -> dict[str, Any]:
    """Initial solution from the reference's sample at the first IMU sample (a reference
    without velocity: the difference of its two positions around that time)."""
    ref = recording[StreamKind.TRUTH]
    imu = recording[StreamKind.IMU]
    t_ns = int(max(imu.t_ns[0], ref.t_ns[0]))
    nav: dict[str, Any] = {"t_ns": t_ns, "method": "reference"}
    if "pos" in ref.columns:
        nav["pos"] = list(_interp_stream(ref, t_ns, "pos"))
    s_v = 0.01
    if "v_n" in ref.columns:
        nav["v_n"] = list(_interp_stream(ref, t_ns, "v_n"))
    elif "pos" in ref.columns:  # a pose reference: the velocity of its bracketing positions
        i = int(np.clip(np.searchsorted(ref.t_ns, t_ns, side="right"), 1, len(ref) - 1))
        d = earth.lla_to_ned_offset(*ref["pos"][i - 1], *ref["pos"][i])
        nav["v_n"] = list(np.asarray(d, dtype=float) / ((ref.t_ns[i] - ref.t_ns[i - 1]) * 1e-9))
        s_v = REF_DIFF_VEL_SIGMA
    if "q_nb" in ref.columns:
        i = int(np.clip(np.searchsorted(ref.t_ns, t_ns), 0, len(ref) - 1))
        nav["q_nb"] = list(ref["q_nb"][i])
    nav["sigma"] = {"pos_ned": [0.1] * 3, "v_n": [s_v] * 3, "phi": [math.radians(0.1)] * 3}
    return nav


def _gnss_position(recording: Recording, t_ns: int) -> tuple[np.ndarray, np.ndarray] | None:
    if StreamKind.GPS not in recording or not len(recording[StreamKind.GPS]):
        return None
    gps = recording[StreamKind.GPS]
    i = int(np.argmin(np.abs(gps.t_ns - t_ns)))
    sig = gps["pos_sigma"][i] if "pos_sigma" in gps.columns else np.full(3, GNSS_POS_SIGMA)
    return gps["pos"][i], np.maximum(sig, 0.1)


def align(recording: Recording, table: Mapping[str, Any]) -> tuple[dict[str, Any], str]:
    """Self-alignment (module docstring); returns the solution and how it was made."""
    imu = recording[StreamKind.IMU]
    _, stop = still_window(recording)
    t = seconds(imu.t_ns, imu.t_ns[0])
    if stop < 2 or t[stop - 1] < MIN_STILL_S:
        raise InitialisationError(
            f"--init align needs the vehicle still for {MIN_STILL_S:g} s at the start; the IMU "
            f"moves after {t[max(stop - 1, 0)]:.1f} s: use --init reference (with --reference) "
            "or [initial] with lat_deg, lon_deg, h, roll_deg, pitch_deg, yaw_deg")
    t_ns = int(imu.t_ns[stop - 1])
    gnss = _gnss_position(recording, t_ns)
    if gnss is not None:
        pos, pos_sigma = gnss
    elif "lat_deg" in table and "lon_deg" in table:
        pos = np.array([math.radians(table["lat_deg"]), math.radians(table["lon_deg"]),
                        float(table.get("h", 0.0))])
        pos_sigma = _vec3(table.get("pos_sigma", GNSS_POS_SIGMA))
    else:
        raise InitialisationError("--init align needs a position: a NavSatFix topic, or "
                                  "lat_deg, lon_deg, h in [initial]")
    f = imu["f_b"][:stop]
    g = float(earth.gravity(pos[0], pos[2]))
    fm = f.mean(axis=0)
    roll = math.atan2(-fm[1], -fm[2])
    pitch = math.atan2(fm[0], math.hypot(fm[1], fm[2]))
    if "accel_bias_sigma" in table:
        b_a, grade = float(table["accel_bias_sigma"]), "[initial] accel_bias_sigma"
    else:
        b_a, grade = grade_accel_bias(imu, stop)
    b_a = max(b_a, abs(float(np.linalg.norm(fm)) - g))
    s_level = math.sqrt(b_a**2 + float(np.mean(f.var(axis=0))) / stop) / g
    C_lb = euler_to_dcm(np.array([roll, pitch, 0.0]))
    lat = float(pos[0])
    how, yaw, s_yaw = _heading(recording, stop, C_lb, lat, pos, table, s_level)
    nav = {
        "t_ns": t_ns, "pos": list(pos), "v_n": [0.0, 0.0, 0.0],
        "q_nb": list(euler_to_quat(np.array([roll, pitch, yaw]))),
        "sigma": {"pos_ned": list(pos_sigma), "v_n": [STILL_VEL_SIGMA] * 3,
                  "phi": [s_level, s_level, s_yaw]},
        "method": f"align ({how})",
    }
    note = (f"align over the still start ({t[stop - 1]:.1f} s): roll {math.degrees(roll):.2f}, "
            f"pitch {math.degrees(pitch):.2f} deg (1-sigma {math.degrees(s_level):.3f} deg, "
            f"accelerometer bias {b_a / (1000.0 * MICRO_G):.2g} mg: {grade}), "
            f"yaw {math.degrees(yaw):.2f} deg by {how} (1-sigma {math.degrees(s_yaw):.2f} deg)")
    return nav, note


def gyro_bias_shown(omega_ib_b: np.ndarray) -> float:
    """A lower bound of the gyro bias [rad/s] from rates at rest (N, 3): at rest the true rate
    is the earth rate whatever the attitude, so ``| |mean rate| - Omega |`` <= |bias|."""
    return abs(float(np.linalg.norm(omega_ib_b.mean(axis=0))) - OMEGA_E)


def grade_accel_bias(imu: Stream, stop: int) -> tuple[float, str]:
    """Typical accelerometer bias [m/s^2] of the grade the gyro shows over the still window
    (:data:`GRADE_ACCEL_BIAS`), and a note naming the grade; tactical without gyros."""
    if "omega_ib_b" not in imu.columns:
        return GRADE_ACCEL_BIAS[1][1], "tactical assumed (no gyro to tell the grade)"
    shown = gyro_bias_shown(imu["omega_ib_b"][:stop])
    for limit, b_a, name in GRADE_ACCEL_BIAS:
        if shown <= limit:
            return b_a, (f"{name} grade, the gyro shows {shown / DEG_PER_HOUR:.2g} deg/h at "
                         "rest")
    raise AssertionError("unreachable: the last grade has no limit")


def _heading(recording: Recording, stop: int, C_lb: np.ndarray, lat: float, pos: np.ndarray,
             table: Mapping[str, Any], s_level: float) -> tuple[str, float, float]:
    imu = recording[StreamKind.IMU]
    reasons = []
    if "yaw_deg" in table:
        return "[initial] yaw_deg", math.radians(table["yaw_deg"]), math.radians(
            float(_vec3(table.get("att_sigma_deg", 1.0))[2]))
    if "omega_ib_b" in imu.columns:
        w = imu["omega_ib_b"][:stop] @ C_lb.T  # levelled, heading 0
        t = seconds(imu.t_ns[:stop], imu.t_ns[0])
        blocks = np.floor(t).astype(int)
        means = np.array([w[blocks == k].mean(axis=0) for k in np.unique(blocks)])
        wm = w.mean(axis=0)
        s_w = float(np.sqrt(np.mean(means[:, :2].var(axis=0)) / max(len(means) - 1, 1)))
        horiz = OMEGA_E * math.cos(lat)
        shown = max(abs(wm[2] + OMEGA_E * math.sin(lat)), abs(math.hypot(wm[0], wm[1]) - horiz))
        b_g = max(float(table.get("gyro_bias_sigma_dph", 0.0)) * DEG_PER_HOUR, shown)
        # a level error phi couples the vertical earth rate into the horizontal: tan(lat) phi
        sigma = math.hypot(math.sqrt(s_w**2 + b_g**2) / max(horiz, 1e-12),
                           s_level * abs(math.tan(lat)))
        if sigma < GYROCOMPASS_MAX_SIGMA:
            return "gyrocompassing", math.atan2(-wm[1], wm[0]), sigma
        reasons.append(f"gyrocompassing would give {math.degrees(sigma):.0f} deg")
    if StreamKind.MAG in recording and len(recording[StreamKind.MAG]):
        mag = recording[StreamKind.MAG]
        n = max(int(np.searchsorted(mag.t_ns, imu.t_ns[stop - 1])), 1)
        m_l = C_lb @ mag["m_b"][:n].mean(axis=0)
        field = wmm_field_ned(pos[0], pos[1], pos[2], int(imu.t_ns[0]))
        decl = math.atan2(field[1], field[0])
        # a level error phi turns the vertical field into the horizontal: tan(dip) phi
        tan_dip = abs(field[2]) / max(math.hypot(field[0], field[1]), 1e-12)
        sigma = math.hypot(MAG_HEADING_SIGMA, s_level * tan_dip)
        return (_because("magnetometer", reasons),
                float(wrap_angle(math.atan2(-m_l[1], m_l[0]) + decl)), sigma)
    reasons.append("no magnetometer")
    cog = _course_over_ground(recording, stop, C_lb)
    if cog is None:  # too slow or no velocity: the track over a distance
        reasons.append(f"no GNSS velocity over {COG_MIN_SPEED:g} m/s"
                       if StreamKind.GPS_VEL in recording else "no GNSS velocity topic")
        cog = _chord(recording, stop, C_lb)
    if cog is not None:
        return _because(cog[0], reasons), cog[1], cog[2]
    reasons.append(f"no GNSS track of {CHORD_LENGTH:g} m")
    raise InitialisationError(
        "--init align cannot find the heading (" + "; ".join(reasons) + "): give yaw_deg in "
        "[initial], a magnetometer topic, or use --init reference")


def _because(how: str, reasons: list[str]) -> str:
    return f"{how}; {', '.join(reasons)}" if reasons else how


def _course_over_ground(recording: Recording, stop: int, C_lb: np.ndarray
                        ) -> tuple[str, float, float] | None:
    """Heading from the first GNSS velocity faster than :data:`COG_MIN_SPEED` after the still
    window, carried back by the yaw turned meanwhile; None without such a velocity."""
    imu = recording[StreamKind.IMU]
    if StreamKind.GPS_VEL not in recording:
        return None
    s = recording[StreamKind.GPS_VEL]
    t_v, v = s.t_ns, s["v_n"][:, :2]
    s_v = s["vel_sigma"][:, :2].max(axis=1) if "vel_sigma" in s.columns else np.full(
        len(s), 0.1)
    speed = np.hypot(v[:, 0], v[:, 1])
    after = (t_v > imu.t_ns[stop - 1]) & (speed > COG_MIN_SPEED)
    if not after.any():
        return None
    k = int(np.argmax(after))
    cog = math.atan2(v[k, 1], v[k, 0])
    j = int(np.clip(np.searchsorted(imu.t_ns, t_v[k]), stop, len(imu) - 1))
    turned = _turned(imu, stop, j, C_lb)
    sigma = math.hypot(float(s_v[k]) / speed[k], COG_SIDESLIP)
    return "GNSS course over ground", float(wrap_angle(cog - turned)), sigma


def _turned(imu: Stream, stop: int, j: int, C_lb: np.ndarray) -> float:
    """Yaw turned between the end of the still window and IMU row j [rad] (levelled z rate)."""
    if "omega_ib_b" not in imu.columns or j < stop:
        return 0.0
    dts = np.diff(imu.t_ns[stop - 1: j + 1]) * 1e-9
    return float(np.sum((imu["omega_ib_b"][stop:j + 1] @ C_lb.T)[:, 2] * dts))


def _chord(recording: Recording, stop: int, C_lb: np.ndarray
           ) -> tuple[str, float, float] | None:
    """Heading from the chord between the mean still position and the first fix
    :data:`CHORD_LENGTH` away, carried back by the yaw turned meanwhile (half of it: the chord
    of a steady turn points along the mean heading)."""
    if StreamKind.GPS not in recording or len(recording[StreamKind.GPS]) < 2:
        return None
    imu, gps = recording[StreamKind.IMU], recording[StreamKind.GPS]
    still = gps.t_ns <= imu.t_ns[stop - 1]
    if not still.any():
        return None
    ned = earth.lla_to_ned_offset(*gps["pos"][still][-1], *gps["pos"].T)
    home = ned[still].mean(axis=0)
    dist = np.hypot(*(ned[:, :2] - home[:2]).T)
    away = ~still & (dist > CHORD_LENGTH)
    if not away.any():
        return None
    k = int(np.argmax(away))
    sig = float(gps["pos_sigma"][k, :2].max()) if "pos_sigma" in gps.columns else GNSS_POS_SIGMA
    j = int(np.clip(np.searchsorted(imu.t_ns, gps.t_ns[k]), stop, len(imu) - 1))
    turned = _turned(imu, stop, j, C_lb)
    d = ned[k, :2] - home[:2]
    sigma = math.hypot(sig * math.sqrt(1.0 + 1.0 / still.sum()) / dist[k], COG_SIDESLIP,
                       0.5 * turned)
    return ("GNSS track", float(wrap_angle(math.atan2(d[1], d[0]) - 0.5 * turned)), sigma)


def initial_nav(method: InitMethod | None, recording: Recording, table: Mapping[str, Any],
                needs: Sequence[str] = NAV_PARTS) -> tuple[dict[str, Any], str]:
    """The initial solution by ``method`` with ``[initial]`` applied, and a line saying how.

    With ``method`` None: the recording's own when it has one, else the ``[initial]`` table when
    it has every part in ``needs``, else ``{}`` (a filter that needs a start then says which
    options give one). ``needs``: the parts the filters start from
    (:func:`navreplay.filters.base.initial_parts`); a missing one is an error.
    """
    meta = recording.metadata.initial_nav
    if method is None:
        if meta:
            method = InitMethod.METADATA
        elif table and not _complete(_from_table({}, table), needs) and StreamKind.IMU in recording:
            method = InitMethod.TABLE
        else:
            return {}, ""
    if method is not InitMethod.METADATA and not (
            StreamKind.IMU in recording and len(recording[StreamKind.IMU])):
        raise InitialisationError(
            f"--init {method.value}: {recording.metadata.extra.get('source', 'the log')} has no "
            "IMU samples to start from; name the IMU topic with --topic imu=TOPIC (navreplay "
            "info lists the topics)")
    if method is InitMethod.METADATA:
        if not meta:
            raise InitialisationError("--init metadata: the recording has no initial solution; "
                                      "use --init align, --init reference or [initial]")
        nav, note = dict(meta), "initial solution from the recording's metadata"
        nav.setdefault("method", RECORDING)
    elif method is InitMethod.REFERENCE:
        nav, note = from_reference(recording), "initial solution from the reference"
    elif method is InitMethod.ALIGN:
        nav, note = align(recording, table)
    else:
        imu = recording[StreamKind.IMU]
        nav = {"t_ns": int(imu.t_ns[0]), "method": "[initial]",
               "sigma": {"pos_ned": [GNSS_POS_SIGMA] * 3, "v_n": [0.1] * 3,
                         "phi": [math.radians(1.0)] * 3}}
        note = "initial solution from [initial]"
    if table:
        nav = _from_table(nav, table)
        note += " with [initial] values"
        used = [k for k in table if k in STATE_KEYS]
        if method is not InitMethod.TABLE and used:
            nav["method"] = f"{nav['method']} + [initial] {', '.join(used)}"
    if method is InitMethod.TABLE:
        nav.setdefault("v_n", [0.0, 0.0, 0.0])
    missing = _complete(nav, needs)
    if missing:
        names = {"pos": "a position (lat_deg, lon_deg, h)", "v_n": "a velocity (v_n)",
                 "q_nb": "an attitude (roll_deg, pitch_deg, yaw_deg)"}
        raise InitialisationError(
            f"--init {method.value}: missing {', '.join(names[k] for k in missing)}; add them "
            "to [initial] or use --init align")
    return nav, note
