"""Independent ROS 2 and ROS 1 bags for the real-log tests, written with rosbags (not
navreplay's writer).

The motion comes from navreplay.sim (a still start of 60 s, then a drive with turns); the bag
holds a sensor_msgs/Imu, a NavSatFix, and the truth as nav_msgs/Odometry (local positions from
the first truth point), in ENU/FLU or NED/FRD conventions; optionally a MagneticField (the WMM
field at the site, rotated into the body), the truth as PoseStamped and
PoseWithCovarianceStamped, and IMU log times that lag the header stamps.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from navreplay.geo import earth
from navreplay.geo.rotations import quat_mult
from navreplay.sim.trajectory import Channel, Manoeuvre, Route, generate

STORE = get_typestore(Stores.ROS2_HUMBLE)
STORE1 = get_typestore(Stores.ROS1_NOETIC)
T = STORE.types
T0_NS = 1_750_000_000_000_000_000
LAT, LON, H = math.radians(45.0), math.radians(7.0), 300.0
Q_ENU_NED = np.array([0.0, math.sqrt(0.5), math.sqrt(0.5), 0.0])
Q_FRD_FLU = np.array([0.0, 1.0, 0.0, 0.0])
FLIP = np.array([1.0, -1.0, -1.0])


def trajectory(duration: float, rate: float, speed: float = 10.0):
    """Still for 60 s, then up to ``speed`` [m/s] at 0.5 m/s^2, turns and a climb."""
    route = Route(lat=LAT, lon=LON, h=H, heading=0.4, speed=0.0, manoeuvres=(
        Manoeuvre(channel=Channel.SPEED, start=60.0, duration=2.0 * speed, change=speed),
        Manoeuvre(channel=Channel.HEADING, start=100.0, duration=20.0, change=math.radians(90.0)),
        Manoeuvre(channel=Channel.HEADING, start=160.0, duration=30.0, change=math.radians(-120.0)),
        Manoeuvre(channel=Channel.PITCH, start=200.0, duration=10.0, change=math.radians(3.0)),
        Manoeuvre(channel=Channel.PITCH, start=220.0, duration=10.0, change=math.radians(-3.0)),
    ))
    return generate(route, duration, rate)


def wmm_ned(lat: float, lon: float, h: float) -> np.ndarray:
    """The World Magnetic Model 2025 field NED [T] at the bags' date (pygeomag)."""
    from pygeomag import GeoMag

    r = GeoMag(coefficients_file="wmm/WMM_2025.COF").calculate(
        glat=math.degrees(lat), glon=math.degrees(lon), alt=h / 1000.0, time=2025.45)
    return np.array([r.x, r.y, r.z]) * 1e-9


def _stamp(t_ns: int):
    return T["builtin_interfaces/msg/Time"](sec=int(t_ns // 1_000_000_000),
                                           nanosec=int(t_ns % 1_000_000_000))


def _header(t_ns: int, frame: str):
    if T is STORE1.types:  # a ROS 1 header has a sequence number
        return T["std_msgs/msg/Header"](seq=0, stamp=_stamp(t_ns), frame_id=frame)
    return T["std_msgs/msg/Header"](stamp=_stamp(t_ns), frame_id=frame)


class _Ros1Bag:
    """rosbags' ROS 1 writer behind the calls write_bag makes of the ROS 2 one."""

    def __init__(self, path: Path) -> None:
        self._writer = Writer1(path)

    def __enter__(self):
        self._writer.open()
        return self

    def __exit__(self, *exc) -> None:
        self._writer.close()

    def add_connection(self, topic: str, msgtype: str, typestore=None):
        return self._writer.add_connection(topic, msgtype, typestore=STORE1)

    def write(self, conn, t: int, data: bytes) -> None:
        self._writer.write(conn, t, data)


def _v3(v):
    return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _q(q_wxyz):
    return T["geometry_msgs/msg/Quaternion"](x=float(q_wxyz[1]), y=float(q_wxyz[2]),
                                             z=float(q_wxyz[3]), w=float(q_wxyz[0]))


TACTICAL = (0.5, 0.1, 3e-4 * 9.81, 50e-6 * 9.81)
"""IMU grade of ``noisy=True``: gyro bias [deg/h], ARW [deg/sqrt(h)], accelerometer bias
[m/s^2], velocity random walk [m/s^2/sqrt(Hz)] (1-sigma; biases drawn per axis)."""


def write_bag(path: Path, *, ned: bool = False, noisy: bool = False, storage: str = "mcap",
              imu_frame: str | None = None, duration: float = 300.0, rate: float = 50.0,
              seed: int = 0, imu_grade: tuple[float, float, float, float] | None = None,
              gyro_bias_dph: tuple[float, float, float] | None = None, mag: bool = False,
              mag_frame: str | None = None, mag_bias_nT: float = 0.0, poses: bool = False,
              imu_lag: float = 0.0, imu_zero_stamps: bool = False,
              imu_frame_after: tuple[float, str] | None = None,
              gyro_spike: tuple[float, float] | None = None,
              world_frame: str | None = None, imu: bool = True,
              text_topic: str | None = None, ros1: bool = False, speed: float = 10.0,
              gps_vel: bool = False) -> Path:
    """Write a rosbag2 folder at ``path``.

    ``imu_frame`` overrides the IMU frame id (a mislabelled FRD IMU: ``ned=True,
    imu_frame="imu_link"``), ``mag_frame`` the magnetometer's (data in the bag's body
    convention). ``imu_grade`` (as :data:`TACTICAL`) replaces the noise of ``noisy`` (which still
    sets the GNSS noise); ``gyro_bias_dph`` fixes the gyro bias instead of drawing it.
    ``mag_bias_nT`` adds a hard-iron bias along body x. ``imu_lag`` [s]: the IMU messages are
    logged that long after their header stamps; ``imu_zero_stamps``: their stamps are zero.
    ``imu_frame_after`` (t [s], frame id): the IMU's frame id from that time on; ``gyro_spike``
    (t [s], rate [rad/s]): the gyro x sample at that time replaced; ``world_frame``: the
    Odometry's frame id; ``imu=False``: no IMU topic; ``text_topic``: a std_msgs/String topic
    of that name beside the others; ``ros1``: a ROS 1 bag file at ``path`` (rosbags' rosbag1
    writer, ROS 1 serialisation) instead of a rosbag2 folder. ``speed`` [m/s]: the speed
    driven after the still start (1 for a walk); ``gps_vel``: a
    TwistWithCovarianceStamped ``/gnss/vel`` beside the fixes (world frame, 1 Hz, the noise of
    the fixes' grade: 0.1 m/s with ``noisy``).
    """
    global T
    T = (STORE1 if ros1 else STORE).types
    try:
        return _write_bag(path, ned=ned, noisy=noisy, storage=storage, imu_frame=imu_frame,
                          duration=duration, rate=rate, seed=seed, imu_grade=imu_grade,
                          gyro_bias_dph=gyro_bias_dph, mag=mag, mag_frame=mag_frame,
                          mag_bias_nT=mag_bias_nT, poses=poses, imu_lag=imu_lag,
                          imu_zero_stamps=imu_zero_stamps, imu_frame_after=imu_frame_after,
                          gyro_spike=gyro_spike, world_frame=world_frame, imu=imu,
                          text_topic=text_topic, ros1=ros1, speed=speed, gps_vel=gps_vel)
    finally:
        T = STORE.types


def _write_bag(path: Path, *, ned, noisy, storage, imu_frame, duration, rate, seed, imu_grade,
               gyro_bias_dph, mag, mag_frame, mag_bias_nT, poses, imu_lag, imu_zero_stamps,
               imu_frame_after, gyro_spike, world_frame, imu, text_topic, ros1, speed,
               gps_vel) -> Path:
    rng = np.random.default_rng(seed)
    tr = trajectory(duration, rate, speed)
    t_ns = T0_NS + np.rint(tr.t * 1e9).astype(np.int64)
    w, f = tr.omega_ib_b.copy(), tr.f_b.copy()
    grade = imu_grade or (TACTICAL if noisy else None)
    if grade is not None:
        dt = 1.0 / rate
        bias = (np.asarray(gyro_bias_dph) if gyro_bias_dph is not None
                else grade[0] * rng.standard_normal(3))
        w += np.radians(bias) / 3600
        w += math.radians(grade[1]) / 60 / math.sqrt(dt) * rng.standard_normal(w.shape)
        f += grade[2] * rng.standard_normal(3)
        f += grade[3] / math.sqrt(dt) * rng.standard_normal(f.shape)
    body = "base_link_frd" if ned else "base_link"
    world = world_frame or ("odom_ned" if ned else "odom")
    imu_frame = imu_frame or ("imu_frd" if ned else "imu_link")
    d_ned = earth.lla_to_ned_offset(LAT, LON, H, *tr.pos.T)
    q = tr.q_nb if ned else quat_mult(quat_mult(Q_ENU_NED, tr.q_nb), Q_FRD_FLU)
    pos_w = d_ned if ned else d_ned[:, [1, 0, 2]] * np.array([1.0, 1.0, -1.0])
    v_b = np.einsum("kji,kj->ki", _dcm(tr.q_nb), tr.v_n)
    m_b = np.einsum("kji,j->ki", _dcm(tr.q_nb), wmm_ned(LAT, LON, H))
    m_b[:, 0] += mag_bias_nT * 1e-9
    if not ned:
        w, f, v_b, m_b = w * FLIP, f * FLIP, v_b * FLIP, m_b * FLIP
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    gps_sigma = np.array([1.5, 1.5, 3.0]) if noisy else np.array([0.01, 0.01, 0.01])
    store = STORE1 if ros1 else STORE
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    with (_Ros1Bag(path) if ros1 else Writer(path, version=9, storage_plugin=plugin)) as bag:
        c_imu = bag.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=STORE)
        c_fix = bag.add_connection("/gnss/fix", "sensor_msgs/msg/NavSatFix", typestore=STORE)
        c_odo = bag.add_connection("/ground_truth/odom", "nav_msgs/msg/Odometry",
                                   typestore=STORE)
        if poses:
            c_pose = bag.add_connection("/truth/pose", "geometry_msgs/msg/PoseStamped",
                                        typestore=STORE)
            c_pcov = bag.add_connection("/truth/pose_cov",
                                        "geometry_msgs/msg/PoseWithCovarianceStamped",
                                        typestore=STORE)
        zero9 = np.zeros(9)
        ocov = zero9.copy()
        ocov[0] = -1.0
        lag = int(round(imu_lag * 1e9))
        if gyro_spike is not None:
            w[int(round(gyro_spike[0] * rate)) - 1, 0] = gyro_spike[1]
        if text_topic is not None:
            c_text = bag.add_connection(text_topic, "std_msgs/msg/String", typestore=STORE)
            for k in range(0, len(t_ns), int(rate)):
                msg = T["std_msgs/msg/String"](data=f"status {k}")
                bag.write(c_text, int(t_ns[k]), serialize(msg, msg.__msgtype__))
        for k in range(1, len(t_ns) if imu else 0):
            frame = imu_frame
            if imu_frame_after is not None and tr.t[k] >= imu_frame_after[0]:
                frame = imu_frame_after[1]
            msg = T["sensor_msgs/msg/Imu"](
                header=_header(0 if imu_zero_stamps else t_ns[k], frame),
                orientation=_q([1.0, 0, 0, 0]),
                orientation_covariance=ocov, angular_velocity=_v3(w[k - 1]),
                angular_velocity_covariance=zero9, linear_acceleration=_v3(f[k - 1]),
                linear_acceleration_covariance=zero9)
            bag.write(c_imu, int(t_ns[k]) + lag, serialize(msg, msg.__msgtype__))
        if mag:
            c_mag = bag.add_connection("/imu/mag", "sensor_msgs/msg/MagneticField",
                                       typestore=STORE)
            frame = mag_frame or ("imu_frd" if ned else "imu_link")
            for k in range(0, len(t_ns), int(rate) // 10):
                msg = T["sensor_msgs/msg/MagneticField"](
                    header=_header(t_ns[k], frame), magnetic_field=_v3(m_b[k]),
                    magnetic_field_covariance=zero9)
                bag.write(c_mag, int(t_ns[k]), serialize(msg, msg.__msgtype__))
        step = int(rate)
        for k in range(0, len(t_ns), step):
            pos = tr.pos[k].copy()
            if noisy:
                pos = np.array(earth.ned_offset_to_lla(
                    *tr.pos[k], gps_sigma * rng.standard_normal(3))).ravel()
            cov = np.zeros(9)
            cov[[0, 4, 8]] = gps_sigma[[1, 0, 2]] ** 2
            msg = T["sensor_msgs/msg/NavSatFix"](
                header=_header(t_ns[k], "gnss"),
                status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
                latitude=math.degrees(pos[0]), longitude=math.degrees(pos[1]), altitude=pos[2],
                position_covariance=cov, position_covariance_type=2)
            bag.write(c_fix, int(t_ns[k]), serialize(msg, msg.__msgtype__))
        if gps_vel:
            c_vel = bag.add_connection("/gnss/vel", "geometry_msgs/msg/TwistWithCovarianceStamped",
                                       typestore=STORE)
            vel_sigma = 0.1 if noisy else 0.01
            cov = np.zeros(36)
            cov[[0, 7, 14]] = vel_sigma**2
            for k in range(0, len(t_ns), step):
                v = tr.v_n[k] + vel_sigma * rng.standard_normal(3) * noisy
                v_w = v if ned else np.array([v[1], v[0], -v[2]])
                msg = T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                    header=_header(t_ns[k], world),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](
                        twist=T["geometry_msgs/msg/Twist"](linear=_v3(v_w),
                                                           angular=_v3([0, 0, 0])),
                        covariance=cov))
                bag.write(c_vel, int(t_ns[k]), serialize(msg, msg.__msgtype__))
        for k in range(0, len(t_ns), step // 10):
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](
                        x=float(pos_w[k, 0]), y=float(pos_w[k, 1]), z=float(pos_w[k, 2])),
                    orientation=_q(q[k])), covariance=np.zeros(36))
            twist = T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=_v3(v_b[k]), angular=_v3([0, 0, 0])),
                covariance=np.zeros(36))
            msg = T["nav_msgs/msg/Odometry"](header=_header(t_ns[k], world), child_frame_id=body,
                                             pose=pose, twist=twist)
            bag.write(c_odo, int(t_ns[k]), serialize(msg, msg.__msgtype__))
            if poses:
                for conn, msg in (
                        (c_pose, T["geometry_msgs/msg/PoseStamped"](
                            header=_header(t_ns[k], world), pose=pose.pose)),
                        (c_pcov, T["geometry_msgs/msg/PoseWithCovarianceStamped"](
                            header=_header(t_ns[k], world), pose=pose))):
                    bag.write(conn, int(t_ns[k]), serialize(msg, msg.__msgtype__))
    return path


def truth_table(duration: float = 300.0, rate: float = 50.0) -> dict[str, np.ndarray]:
    """The truth of :func:`write_bag` at its Odometry times (10 Hz): ``t_ns``, geodetic
    ``lla`` [rad, rad, m], ``enu`` [m] from the first point, ``q_enu_flu`` (w, x, y, z),
    ``v_n`` [m/s] and ``euler`` (roll, pitch, yaw [rad], FRD -> NED)."""
    from navreplay.geo.rotations import quat_to_euler

    tr = trajectory(duration, rate)
    k = np.arange(0, len(tr.t), int(rate) // 10)
    d_ned = earth.lla_to_ned_offset(LAT, LON, H, *tr.pos[k].T)
    return {"t_ns": T0_NS + np.rint(tr.t[k] * 1e9).astype(np.int64), "lla": tr.pos[k],
            "enu": d_ned[:, [1, 0, 2]] * np.array([1.0, 1.0, -1.0]),
            "q_enu_flu": quat_mult(quat_mult(Q_ENU_NED, tr.q_nb[k]), Q_FRD_FLU),
            "v_n": tr.v_n[k], "euler": quat_to_euler(tr.q_nb[k])}


def _dcm(q):
    from navreplay.geo.rotations import quat_to_dcm

    return quat_to_dcm(q)
