"""Independent ROS 2 bags for the real-log tests, written with rosbags (not navreplay's writer).

The motion comes from navreplay.sim (a still start, then a drive with turns); the bag holds a
sensor_msgs/Imu, a NavSatFix, and the truth as nav_msgs/Odometry (local positions from the
first truth point), in ENU/FLU or NED/FRD conventions.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from navreplay.geo import earth
from navreplay.geo.rotations import quat_mult
from navreplay.sim.trajectory import Channel, Manoeuvre, Route, generate

STORE = get_typestore(Stores.ROS2_HUMBLE)
T = STORE.types
T0_NS = 1_750_000_000_000_000_000
LAT, LON, H = math.radians(45.0), math.radians(7.0), 300.0
Q_ENU_NED = np.array([0.0, math.sqrt(0.5), math.sqrt(0.5), 0.0])
Q_FRD_FLU = np.array([0.0, 1.0, 0.0, 0.0])
FLIP = np.array([1.0, -1.0, -1.0])


def trajectory(duration: float, rate: float):
    route = Route(lat=LAT, lon=LON, h=H, heading=0.4, speed=0.0, manoeuvres=(
        Manoeuvre(channel=Channel.SPEED, start=60.0, duration=20.0, change=10.0),
        Manoeuvre(channel=Channel.HEADING, start=100.0, duration=20.0, change=math.radians(90.0)),
        Manoeuvre(channel=Channel.HEADING, start=160.0, duration=30.0, change=math.radians(-120.0)),
        Manoeuvre(channel=Channel.PITCH, start=200.0, duration=10.0, change=math.radians(3.0)),
        Manoeuvre(channel=Channel.PITCH, start=220.0, duration=10.0, change=math.radians(-3.0)),
    ))
    return generate(route, duration, rate)


def _stamp(t_ns: int):
    return T["builtin_interfaces/msg/Time"](sec=int(t_ns // 1_000_000_000),
                                           nanosec=int(t_ns % 1_000_000_000))


def _header(t_ns: int, frame: str):
    return T["std_msgs/msg/Header"](stamp=_stamp(t_ns), frame_id=frame)


def _v3(v):
    return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _q(q_wxyz):
    return T["geometry_msgs/msg/Quaternion"](x=float(q_wxyz[1]), y=float(q_wxyz[2]),
                                             z=float(q_wxyz[3]), w=float(q_wxyz[0]))


def write_bag(path: Path, *, ned: bool = False, noisy: bool = False, storage: str = "mcap",
              imu_frame: str | None = None, duration: float = 300.0, rate: float = 50.0,
              seed: int = 0) -> Path:
    """Write a rosbag2 folder at ``path``; ``imu_frame`` overrides the IMU frame id (a
    mislabelled FRD IMU: ``ned=True, imu_frame="imu_link"``)."""
    rng = np.random.default_rng(seed)
    tr = trajectory(duration, rate)
    t_ns = T0_NS + np.rint(tr.t * 1e9).astype(np.int64)
    w, f = tr.omega_ib_b.copy(), tr.f_b.copy()
    if noisy:
        dt = 1.0 / rate
        w += math.radians(0.5) / 3600 * rng.standard_normal(3)
        w += math.radians(0.1) / 60 / math.sqrt(dt) * rng.standard_normal(w.shape)
        f += 3e-4 * 9.81 * rng.standard_normal(3)
        f += 50e-6 * 9.81 / math.sqrt(dt) * rng.standard_normal(f.shape)
    body = "base_link_frd" if ned else "base_link"
    world = "odom_ned" if ned else "odom"
    imu_frame = imu_frame or ("imu_frd" if ned else "imu_link")
    d_ned = earth.lla_to_ned_offset(LAT, LON, H, *tr.pos.T)
    q = tr.q_nb if ned else quat_mult(quat_mult(Q_ENU_NED, tr.q_nb), Q_FRD_FLU)
    pos_w = d_ned if ned else d_ned[:, [1, 0, 2]] * np.array([1.0, 1.0, -1.0])
    v_b = np.einsum("kji,kj->ki", _dcm(tr.q_nb), tr.v_n)
    if not ned:
        w, f, v_b = w * FLIP, f * FLIP, v_b * FLIP
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    gps_sigma = np.array([1.5, 1.5, 3.0]) if noisy else np.array([0.01, 0.01, 0.01])
    with Writer(path, version=9, storage_plugin=plugin) as bag:
        c_imu = bag.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=STORE)
        c_fix = bag.add_connection("/gnss/fix", "sensor_msgs/msg/NavSatFix", typestore=STORE)
        c_odo = bag.add_connection("/ground_truth/odom", "nav_msgs/msg/Odometry",
                                   typestore=STORE)
        zero9 = np.zeros(9)
        ocov = zero9.copy()
        ocov[0] = -1.0
        for k in range(1, len(t_ns)):
            msg = T["sensor_msgs/msg/Imu"](
                header=_header(t_ns[k], imu_frame), orientation=_q([1.0, 0, 0, 0]),
                orientation_covariance=ocov, angular_velocity=_v3(w[k - 1]),
                angular_velocity_covariance=zero9, linear_acceleration=_v3(f[k - 1]),
                linear_acceleration_covariance=zero9)
            bag.write(c_imu, int(t_ns[k]), STORE.serialize_cdr(msg, msg.__msgtype__))
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
            bag.write(c_fix, int(t_ns[k]), STORE.serialize_cdr(msg, msg.__msgtype__))
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
            bag.write(c_odo, int(t_ns[k]), STORE.serialize_cdr(msg, msg.__msgtype__))
    return path


def _dcm(q):
    from navreplay.geo.rotations import quat_to_dcm

    return quat_to_dcm(q)
