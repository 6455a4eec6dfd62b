"""PX4 ULog files written from the format's specification (header, flag bits, format and info
messages, add-logged and data messages; little endian, packed, no terminating NULs), with the
message layouts of PX4's uORB topics: a simulated navreplay recording's IMU, GNSS and
magnetometer as PX4 logs them, and its truth with known errors as PX4's estimate."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np

from navreplay.core.streams import Recording, StreamKind
from navreplay.geo import earth
from navreplay.geo.rotations import euler_to_quat, quat_mult

MAGIC = b"ULog\x01\x12\x35"
BOOT_US = 5_000_000
"""The autopilot's clock at the recording's start [us since boot]."""

TYPES = {"uint64_t": "<u8", "int64_t": "<i8", "uint32_t": "<u4", "int32_t": "<i4",
         "uint16_t": "<u2", "int16_t": "<i2", "uint8_t": "u1", "int8_t": "i1", "float": "<f4",
         "double": "<f8", "bool": "u1", "char": "S1"}

FORMATS = {
    "sensor_combined": "uint64_t timestamp;float[3] gyro_rad;uint32_t gyro_integral_dt;"
    "int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;"
    "uint32_t accelerometer_integral_dt;uint8_t accelerometer_clipping;uint8_t gyro_clipping;"
    "uint8_t accel_calibration_count;uint8_t gyro_calibration_count;",
    "vehicle_imu": "uint64_t timestamp;uint64_t timestamp_sample;uint32_t accel_device_id;"
    "uint32_t gyro_device_id;float[3] delta_angle;float[3] delta_velocity;"
    "uint16_t delta_angle_dt;uint16_t delta_velocity_dt;uint8_t delta_angle_clipping;"
    "uint8_t delta_velocity_clipping;uint8_t accel_calibration_count;"
    "uint8_t gyro_calibration_count;",
    # PX4 up to v1.14: positions in 1e-7 deg and mm
    "vehicle_gps_position": "uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;"
    "int32_t lat;int32_t lon;int32_t alt;int32_t alt_ellipsoid;float s_variance_m_s;"
    "float c_variance_rad;uint8_t fix_type;uint8_t[3] _padding0;float eph;float epv;"
    "float hdop;float vdop;int32_t noise_per_ms;uint16_t automatic_gain_control;"
    "uint8_t jamming_state;uint8_t[1] _padding1;int32_t jamming_indicator;float vel_m_s;"
    "float vel_n_m_s;float vel_e_m_s;float vel_d_m_s;float cog_rad;bool vel_ned_valid;"
    "uint8_t[3] _padding2;int32_t timestamp_time_relative;uint64_t time_utc_usec;"
    "uint8_t satellites_used;uint8_t[3] _padding3;float heading;float heading_offset;"
    "float heading_accuracy;",
    # PX4 v1.15 on: degrees and metres in doubles
    "sensor_gps": "uint64_t timestamp;uint64_t timestamp_sample;double latitude_deg;"
    "double longitude_deg;double altitude_msl_m;double altitude_ellipsoid_m;"
    "uint32_t device_id;float s_variance_m_s;float c_variance_rad;float eph;float epv;"
    "float hdop;float vdop;float vel_m_s;float vel_n_m_s;float vel_e_m_s;float vel_d_m_s;"
    "float cog_rad;uint8_t fix_type;bool vel_ned_valid;uint8_t satellites_used;"
    "uint8_t[1] _padding0;",
    "vehicle_magnetometer": "uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;"
    "float[3] magnetometer_ga;uint8_t calibration_count;uint8_t[3] _padding0;",
    "vehicle_local_position": "uint64_t timestamp;uint64_t timestamp_sample;bool xy_valid;"
    "bool z_valid;bool v_xy_valid;bool v_z_valid;float x;float y;float z;float vx;float vy;"
    "float vz;float eph;float epv;float evh;float evv;double ref_lat;double ref_lon;"
    "float ref_alt;uint8_t[4] _padding0;",
    "vehicle_global_position": "uint64_t timestamp;uint64_t timestamp_sample;double lat;"
    "double lon;float alt;float alt_ellipsoid;float eph;float epv;",
    "vehicle_attitude": "uint64_t timestamp;uint64_t timestamp_sample;float[4] q;"
    "float[4] delta_q_reset;uint8_t quat_reset_counter;uint8_t[7] _padding0;",
}


def dtype(fmt: str) -> np.dtype:
    """The packed little-endian layout of a format's fields."""
    fields = []
    for item in fmt.strip(";").split(";"):
        ty, name = item.split(" ")
        count = 1
        if "[" in ty:
            ty, n = ty[:-1].split("[")
            count = int(n)
        fields.append((name, TYPES[ty], (count,)) if count > 1 or "[" in item else
                      (name, TYPES[ty]))
    return np.dtype(fields, align=False)


def logged_size(dt: np.dtype) -> int:
    """Bytes of a data message's payload: a padding field at the end is not logged."""
    names = list(dt.names or ())
    last = names[-1]
    return int(dt.fields[last][1]) if last.startswith("_padding") else dt.itemsize


def _message(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


class ULogWriter:
    """Topics (name, instance, rows as a structured array with ``timestamp``) written as one
    ULog file, their data messages in time order."""

    def __init__(self) -> None:
        self.topics: list[tuple[str, int, np.ndarray]] = []

    def add(self, name: str, rows: dict[str, np.ndarray], instance: int = 0) -> None:
        dt = dtype(FORMATS[name])
        n = len(rows["timestamp"])
        arr = np.zeros(n, dtype=dt)
        for key, value in rows.items():
            arr[key] = value
        self.topics.append((name, instance, arr))

    def bytes(self) -> bytes:
        start = min(int(a["timestamp"][0]) for _, _, a in self.topics)
        out = [MAGIC, b"\x01", struct.pack("<Q", start)]
        out.append(_message(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0)))
        for name in sorted({n for n, _, _ in self.topics}):
            out.append(_message(b"F", f"{name}:{FORMATS[name]}".encode()))
        key = b"char[10] sys_name"
        out.append(_message(b"I", bytes([len(key)]) + key + b"PX4 (test)"))
        rows = []
        for msg_id, (name, instance, arr) in enumerate(self.topics):
            out.append(_message(b"A", struct.pack("<BH", instance, msg_id) + name.encode()))
            size = logged_size(arr.dtype)
            for r in arr:
                rows.append((int(r["timestamp"]), msg_id,
                             _message(b"D", struct.pack("<H", msg_id) + r.tobytes()[:size])))
        rows.sort(key=lambda x: (x[0], x[1]))
        out += [m for _, _, m in rows]
        return b"".join(out)

    def write(self, path: Path) -> Path:
        path.write_bytes(self.bytes())
        return path


def us(rec: Recording, t_ns: np.ndarray) -> np.ndarray:
    """Recording times -> the autopilot's clock [us]."""
    return BOOT_US + (np.asarray(t_ns) - rec.t0_ns) // 1000


EKF2_ERRORS = {"north": 1.0, "v_east": 0.1, "yaw_deg": 1.0}
"""The errors of the estimate written as PX4's: 1 m north, 0.1 m/s east, 1 deg of yaw."""


def write_px4_log(path: Path, rec: Recording, *, imu: str = "sensor_combined",
                  ekf2: bool = True, utc: bool = True) -> Path:
    """The recording's IMU (as ``sensor_combined`` or ``vehicle_imu``), GNSS (as
    ``vehicle_gps_position`` in PX4 v1.14's layout and ``sensor_gps`` in v1.15's), magnetometer
    and, with ``ekf2``, its truth with :data:`EKF2_ERRORS` as PX4's estimate at 50 Hz; with
    ``utc``, the GNSS logs the recording's times as UTC (``time_utc_usec``)."""
    w = ULogWriter()
    s = rec[StreamKind.IMU]
    t = us(rec, s.t_ns)
    if imu == "sensor_combined":
        w.add(imu, {"timestamp": t, "gyro_rad": s["omega_ib_b"],
                    "accelerometer_m_s2": s["f_b"], "gyro_integral_dt": 10_000,
                    "accelerometer_integral_dt": 10_000})
    else:
        dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
        w.add(imu, {"timestamp": t + 200, "timestamp_sample": t,
                    "delta_angle": s["omega_ib_b"] * (dt * 1e-6)[:, None],
                    "delta_velocity": s["f_b"] * (dt * 1e-6)[:, None],
                    "delta_angle_dt": dt, "delta_velocity_dt": dt})
    g = rec[StreamKind.GPS]
    gv = rec[StreamKind.GPS_VEL]
    assert np.array_equal(g.t_ns, gv.t_ns)
    tg = us(rec, g.t_ns)
    lat, lon = np.degrees(g["pos"][:, 0]), np.degrees(g["pos"][:, 1])
    common = {"timestamp": tg + 50_000, "timestamp_sample": tg, "fix_type": 3,
              "time_utc_usec": g.t_ns // 1000 if utc else 0, "timestamp_time_relative": -50_000,
              "eph": g["pos_sigma"][:, 0], "epv": g["pos_sigma"][:, 2],
              "s_variance_m_s": gv["vel_sigma"][:, 0], "vel_ned_valid": 1,
              "vel_n_m_s": gv["v_n"][:, 0], "vel_e_m_s": gv["v_n"][:, 1],
              "vel_d_m_s": gv["v_n"][:, 2]}
    w.add("vehicle_gps_position", {**common, "lat": np.rint(lat * 1e7),
                                   "lon": np.rint(lon * 1e7),
                                   "alt_ellipsoid": np.rint(g["pos"][:, 2] * 1e3),
                                   "alt": np.rint((g["pos"][:, 2] - 40.0) * 1e3)})
    del common["time_utc_usec"], common["timestamp_time_relative"]  # not in v1.15's layout
    w.add("sensor_gps", {**common, "latitude_deg": lat, "longitude_deg": lon,
                         "altitude_ellipsoid_m": g["pos"][:, 2],
                         "altitude_msl_m": g["pos"][:, 2] - 40.0})
    if StreamKind.MAG in rec:
        m = rec[StreamKind.MAG]
        tm = us(rec, m.t_ns)
        w.add("vehicle_magnetometer", {"timestamp": tm, "timestamp_sample": tm,
                                       "magnetometer_ga": m["m_b"] * 1e4})
    if ekf2:
        _add_estimate(w, rec)
    return w.write(path)


def _add_estimate(w: ULogWriter, rec: Recording) -> None:
    truth = rec[StreamKind.TRUTH]
    step = max(1, int(round(0.02 / float(np.median(np.diff(truth.t_ns)) * 1e-9))))
    k = np.arange(0, len(truth), step)
    t = us(rec, truth.t_ns[k])
    pos, v, q = truth["pos"][k], truth["v_n"][k].copy(), truth["q_nb"][k]
    lat, lon, h = earth.ned_offset_to_lla(pos[:, 0], pos[:, 1], pos[:, 2],
                                          np.array([EKF2_ERRORS["north"], 0.0, 0.0]))
    v[:, 1] += EKF2_ERRORS["v_east"]
    dq = euler_to_quat(np.array([0.0, 0.0, math.radians(EKF2_ERRORS["yaw_deg"])]))
    q = quat_mult(np.broadcast_to(dq, q.shape), q)
    ref = pos[0]
    n = len(k)
    w.add("vehicle_local_position", {
        "timestamp": t + 100, "timestamp_sample": t, "xy_valid": 1, "z_valid": 1,
        "v_xy_valid": 1, "v_z_valid": 1, "vx": v[:, 0], "vy": v[:, 1], "vz": v[:, 2],
        "eph": np.full(n, math.sqrt(2.0)), "epv": np.full(n, 1.5),
        "evh": np.full(n, 0.1 * math.sqrt(2.0)), "evv": np.full(n, 0.1),
        "ref_lat": math.degrees(ref[0]), "ref_lon": math.degrees(ref[1]), "ref_alt": ref[2]})
    w.add("vehicle_global_position", {
        "timestamp": t + 100, "timestamp_sample": t, "lat": np.degrees(lat),
        "lon": np.degrees(lon), "alt_ellipsoid": h, "alt": h - 40.0,
        "eph": np.full(n, math.sqrt(2.0)), "epv": np.full(n, 1.5)})
    w.add("vehicle_attitude", {"timestamp": t + 100, "timestamp_sample": t, "q": q})
