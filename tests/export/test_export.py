"""Exports: the Odometry MCAP opens in rosbags with the filter's covariance rotated to ENU/FLU,
the TUM files follow evo's format, the CSV columns carry units and round-trip the run, ensemble
statistics export, and nothing is overwritten without force."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.writer import Writer as Ros2Writer
from rosbags.highlevel import AnyReader
from whole_runs import export_runs

from navreplay import export
from navreplay.export.odometry import _ODOMETRY_SCHEMA
from navreplay.filters.registry import load_filter
from navreplay.geo import earth
from navreplay.geo.rotations import quat_to_dcm
from navreplay.io import read_recording, write_recording
from navreplay.io.outputs import OutputError
from navreplay.metrics import EnsembleStats, run_metrics
from navreplay.replay import replay
from navreplay.sim.scenario import simulate

FILTERS = ("ins", "gps-ins")
T = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # NED <-> ENU


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("export")
    write_recording(d / "drive.mcap", simulate("vehicle-drive", {"duration": 40.0}, seed=5))
    rec = read_recording(d / "drive.mcap")
    results = {name: replay(rec, load_filter(name), {}, label=name) for name in FILTERS}
    written = export_runs(d / "out", list(results.values()), rec, source="drive.mcap")
    return d / "out", rec, results, list(results.values()), written


def _odometry(path: Path) -> dict[str, list]:
    msgs: dict[str, list] = {}
    with AnyReader([path]) as reader:
        odometry = [c for c in reader.connections if c.msgtype == "nav_msgs/msg/Odometry"]
        for conn, stamp, raw in reader.messages(connections=odometry):
            msg = reader.deserialize(raw, conn.msgtype)
            assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == stamp
            msgs.setdefault(conn.topic, []).append(msg)
    return msgs


def test_files_written(runs) -> None:
    out, rec, _, _, written = runs
    assert sorted(p.name for p in written) == sorted(
        ["ins.csv", "ins.tum", "gps-ins.csv", "gps-ins.tum", "reference.tum",
         "gps-ins.innovations.gps_pos.csv", "gps-ins.innovations.gps_vel.csv",
         "estimates.mcap", "estimates.foxglove-layout.json", "manifest.json"])
    manifest = json.loads((out / "manifest.json").read_text())
    truth0 = rec["truth"]["pos"][0]
    assert manifest["origin"]["lat_deg"] == pytest.approx(math.degrees(truth0[0]), abs=1e-12)
    assert manifest["odometry"]["topics"] == [
        "/estimates/gps_ins/odom", "/estimates/ins/odom", "/reference/odom"]
    assert not list(out.glob(".*.part"))


def test_odometry_opens_in_rosbags_with_rotated_covariance(runs) -> None:
    out, rec, results, _, _ = runs
    msgs = _odometry(out / "estimates.mcap")
    r = results["gps-ins"]
    odo = msgs["/estimates/gps_ins/odom"]
    assert len(odo) == len(r.t) and len(msgs["/estimates/ins/odom"]) == len(results["ins"].t)
    assert len(msgs["/reference/odom"]) == len(rec["truth"])
    assert (odo[0].header.frame_id, odo[0].child_frame_id) == ("map", "base_link")
    i = {n: r.state_names.index(n) for n in ("dlat", "dlon", "dh", "dv_N", "phi_D", "phi_N")}
    for k in (0, len(odo) // 2, len(odo) - 1):
        P, (lat, _, h) = r.P[k], r.nav_pos[k]
        R_M, R_N = earth.radii(lat)
        s_e = (R_N + h) * math.cos(lat)  # east metres per radian of longitude
        cov = np.asarray(odo[k].pose.covariance).reshape(6, 6)
        # ENU x = east, z = up = -down: cov(x, x), cov(x, z), cov(y, z), cov(x, yaw about up)
        assert cov[0, 0] == pytest.approx(s_e**2 * P[i["dlon"], i["dlon"]], rel=1e-6)
        assert cov[1, 1] == pytest.approx((R_M + h) ** 2 * P[i["dlat"], i["dlat"]], rel=1e-6)
        # the local level at the vehicle turns from the origin's by distance / earth radius
        # (< 1e-4 rad over this drive): cross terms agree to that fraction of sigma_a sigma_b
        def tol(a: int, b: int) -> float:
            return 1e-4 * math.sqrt(cov[a, a] * cov[b, b])

        assert cov[0, 2] == pytest.approx(s_e * P[i["dlon"], i["dh"]], abs=tol(0, 2))
        assert cov[5, 5] == pytest.approx(P[i["phi_D"], i["phi_D"]], rel=1e-4)
        assert cov[4, 4] == pytest.approx(P[i["phi_N"], i["phi_N"]], rel=1e-4)
        assert cov[0, 5] == pytest.approx(-s_e * P[i["dlon"], i["phi_D"]], abs=tol(0, 5))
        np.testing.assert_allclose(cov, cov.T, atol=1e-12)
        assert np.all(np.linalg.eigvalsh(cov) > -1e-9 * np.abs(cov).max())
        twist = np.asarray(odo[k].twist.covariance).reshape(6, 6)
        assert list(np.diag(twist)[3:]) == [-1.0, -1.0, -1.0]  # angular rate: not estimated
        # body velocity: FLU of C_nb^T v_n; its x (forward) variance from the NED velocity
        # covariance and the attitude errors (v_b = C^T (dv - [v x] phi))
        C = quat_to_dcm(r.nav_q_nb[k])
        v = r.nav_v_n[k]
        np.testing.assert_allclose(
            [odo[k].twist.twist.linear.x, odo[k].twist.twist.linear.y,
             odo[k].twist.twist.linear.z], (C.T @ v) * [1, -1, -1], atol=1e-9)
        iv = [r.state_names.index(n) for n in ("dv_N", "dv_E", "dv_D", "phi_N", "phi_E", "phi_D")]
        J = C.T[0] @ np.hstack([np.eye(3), -np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]],
                                                      [-v[1], v[0], 0]])])
        assert twist[0, 0] == pytest.approx(J @ P[np.ix_(iv, iv)] @ J, rel=1e-6)
    # orientation: base_link FLU -> map ENU; its x axis is the body's forward axis in ENU
    q = odo[-1].pose.pose.orientation
    C_enu_flu = quat_to_dcm([q.w, q.x, q.y, q.z])
    fwd_ned = quat_to_dcm(r.nav_q_nb[-1])[:, 0]
    np.testing.assert_allclose(C_enu_flu[:, 0], [fwd_ned[1], fwd_ned[0], -fwd_ned[2]], atol=1e-4)
    np.testing.assert_allclose(C_enu_flu[:, 1], -(T @ quat_to_dcm(r.nav_q_nb[-1])[:, 1]), atol=1e-4)


def test_odometry_bytes_equal_the_generic_ros2_serializer(runs, tmp_path) -> None:
    """The bulk CDR records equal mcap-ros2-support's encoding of the same messages."""
    out, *_ = runs
    msgs = _odometry(out / "estimates.mcap")["/estimates/gps_ins/odom"][:3]
    poses = export.Poses(
        np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs]),
        np.array([[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z]
                  for m in msgs]),
        np.array([[m.pose.pose.orientation.x, m.pose.pose.orientation.y,
                   m.pose.pose.orientation.z, m.pose.pose.orientation.w] for m in msgs]),
        np.array([np.reshape(m.pose.covariance, (6, 6)) for m in msgs]),
        np.array([[m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.linear.z]
                  for m in msgs]),
        np.array([np.reshape(m.twist.covariance, (6, 6)) for m in msgs]),
    )
    bulk = export.encode_odometry(poses)
    with open(tmp_path / "g.mcap", "wb") as f:
        w = Ros2Writer(f)
        schema = w.register_msgdef("nav_msgs/msg/Odometry", _ODOMETRY_SCHEMA)
        for m in msgs:
            w.write_message("/o", schema, _as_dict(m), 0)
        w.finish()
    from mcap.reader import make_reader

    with open(tmp_path / "g.mcap", "rb") as f:
        generic = [m.data for _, _, m in make_reader(f).iter_messages()]
    assert [r.tobytes() for r in bulk] == generic


def _as_dict(obj):
    if hasattr(obj, "__dataclass_fields__"):
        return {k: _as_dict(getattr(obj, k)) for k in obj.__dataclass_fields__
                if k != "__msgtype__"}
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj


def _check_tum(path: Path) -> np.ndarray:
    """evo's TUM rules: '#' comment lines, single spaces, 8 entries per row, floats."""
    rows = []
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            continue
        parts = line.split(" ")
        assert len(parts) == 8 and "" not in parts, line
        rows.append([float(p) for p in parts])
    mat = np.array(rows)
    assert np.all(np.diff(mat[:, 0]) > 0)
    np.testing.assert_allclose(np.linalg.norm(mat[:, 4:], axis=1), 1.0, atol=1e-8)
    return mat


def test_tum_follows_evos_format(runs) -> None:
    out, rec, results, outputs, _ = runs
    for name, r in results.items():
        mat = _check_tum(out / f"{name}.tum")
        assert mat.shape[0] == len(r.t)
        np.testing.assert_allclose(mat[:, 0], (r.t0_ns + np.rint(r.t * 1e9)) * 1e-9, atol=1e-9)
    ref = _check_tum(out / "reference.tum")
    np.testing.assert_allclose(ref[0, 1:4], 0.0, atol=1e-6)  # the origin is the first sample
    # ENU: the reference's east offset at the end is its longitude change in metres
    lat0, lon0, _ = rec["truth"]["pos"][0]
    lat1, lon1, h1 = rec["truth"]["pos"][-1]
    _, R_N = earth.radii(lat0)
    assert ref[-1, 1] == pytest.approx((lon1 - lon0) * (R_N + h1) * math.cos(lat0), rel=1e-3)
    assert ref[-1, 2] == pytest.approx(
        earth.lla_to_ned_offset(lat0, lon0, rec["truth"]["pos"][0, 2], lat1, lon1, h1)[0],
        abs=1e-6)


def test_tum_reads_in_evo(runs) -> None:
    file_interface = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics, sync

    out, *_ = runs
    ref = file_interface.read_tum_trajectory_file(str(out / "reference.tum"))
    est = file_interface.read_tum_trajectory_file(str(out / "gps-ins.tum"))
    ref, est = sync.associate_trajectories(ref, est, max_diff=1e-3)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    # gps-ins over 40 s: metre-level, like the summary's horizontal RMS
    assert 0.05 < ape.get_statistic(metrics.StatisticsType.rmse) < 10.0


def test_csv_columns_units_and_values(runs) -> None:
    out, rec, results, outputs, _ = runs
    r = results["gps-ins"]
    with open(out / "gps-ins.csv", newline="") as f:
        rows = list(csv.reader(f))
    header, data = rows[0], np.array(rows[1:], dtype=float)
    assert header[:5] == ["stamp [ns]", "t [s]", "lat [deg]", "lon [deg]", "h [m]"]
    assert all(h.endswith("]") and " [" in h for h in header)
    col = {h: data[:, j] for j, h in enumerate(header)}
    assert data.shape[0] == len(r.t)
    np.testing.assert_allclose(col["t [s]"], r.t, atol=1e-8)
    np.testing.assert_allclose(col["lat [deg]"], np.degrees(r.nav_pos[:, 0]), atol=1e-10)
    j = r.state_names.index("b_g_z")
    np.testing.assert_allclose(col["x.b_g_z [rad/s]"], r.x[:, j], rtol=1e-8)
    np.testing.assert_allclose(col["sigma.dv_E [m/s]"], r.sigma[:, r.state_names.index("dv_E")],
                               rtol=1e-8)
    m = run_metrics(r, rec)
    np.testing.assert_allclose(col["error_north [m]"], m.nav.pos_ned[:, 0], rtol=1e-8,
                               atol=1e-9)
    np.testing.assert_allclose(col["error_phi_D [deg]"], np.degrees(m.nav.phi[:, 2]),
                               rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(col["nees [-]"], m.nees, rtol=1e-8)
    # predicted sigma of the north error is the latitude state's, in metres
    R_M, _ = earth.radii(r.nav_pos[:, 0])
    np.testing.assert_allclose(col["sigma_north [m]"],
                               r.sigma[:, r.state_names.index("dlat")] * (R_M + r.nav_pos[:, 2]),
                               rtol=1e-8)
    manifest = json.loads((out / "manifest.json").read_text())
    documented = [c["name"] for c in manifest["filters"]["gps-ins"]["columns"]]
    assert documented == header


def test_refuses_to_overwrite(runs) -> None:
    out, rec, _, outputs, _ = runs
    before = (out / "ins.csv").read_bytes()
    with pytest.raises(OutputError, match="exists.*--force"):
        export_runs(out, outputs[:1], rec)
    assert (out / "ins.csv").read_bytes() == before
    export_runs(out, outputs[:1], rec, force=True)


def test_ensemble_export(runs, tmp_path) -> None:
    _, rec, results, _, _ = runs
    stats = EnsembleStats("gps-ins")
    m = run_metrics(results["gps-ins"], rec)
    stats.add(m)
    stats.add(m)
    ens = stats.result()
    written = export.export_ensemble(tmp_path, {"gps-ins": ens})
    names = sorted(p.name for p in written)
    assert "gps-ins.ensemble.csv" in names and "gps-ins.nis.gps_pos.csv" in names
    with open(tmp_path / "gps-ins.ensemble.csv", newline="") as f:
        rows = list(csv.reader(f))
    col = {h: np.array([float(r[j]) for r in rows[1:]]) for j, h in enumerate(rows[0])}
    # two identical runs: RMS equals the single run's absolute error
    np.testing.assert_allclose(col["rms_east [m]"], np.abs(m.nav.pos_ned[:, 1]), rtol=1e-8,
                               atol=1e-12)
    assert {"nees_mean [-]", "nees_lo [-]", "nees_hi [-]", "sigma_v_N [m/s]"} <= set(col)
    assert np.all(col["nees_lo [-]"] < col["nees_hi [-]"])
    with pytest.raises(OutputError):
        export.export_ensemble(tmp_path, {"gps-ins": ens})


def test_pose_covariances_as_the_straightforward_products() -> None:
    """ros_poses' compiled kernel and shortcuts (the twist's angular block set, no marking of
    finite covariances, the zero products of the reference, without their factors when these
    are finite) give the plain numpy products marked after: the zeros, NaN and unknown marks
    exactly, the values to the last bits (the kernel sums term by term, numpy's matrix
    products may use fused multiply-adds); the orientation is dcm_to_quat's."""
    from navreplay.export import frames
    from navreplay.geo.rotations import dcm_to_quat, skew

    rng = np.random.default_rng(11)
    M = 40
    pos = np.column_stack([0.65 + 1e-5 * rng.standard_normal(M),
                           2.2 + 1e-5 * rng.standard_normal(M), 40 + rng.standard_normal(M)])
    v_n = rng.standard_normal((M, 3))
    q = rng.standard_normal((M, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    A = rng.standard_normal((M, 9, 9))
    full = A @ A.transpose(0, 2, 1)
    no_velocity = full.copy()
    no_velocity[:, 3:6, :] = np.nan
    no_velocity[:, :, 3:6] = np.nan
    v_bad = v_n.copy()
    v_bad[3] = np.nan
    frame = frames.LocalFrame(0.65, 2.2, 40.0, "test")
    for cov, v in ((full, v_n), (no_velocity, v_n), (np.zeros((M, 9, 9)), v_n),
                   (np.zeros((M, 9, 9)), v_bad)):
        got = frames.ros_poses(frame, np.arange(M), pos, v, q, cov)
        R = frame.rotation(pos)
        C_nb = quat_to_dcm(q)
        B = np.zeros((M, 6, 6))
        B[:, :3, :3] = R
        B[:, 3:, 3:] = R
        J = np.concatenate([np.broadcast_to(np.eye(3), (M, 3, 3)), -skew(v)], axis=2)
        J = frames.F_FRD_FLU @ C_nb.transpose(0, 2, 1) @ J
        with np.errstate(invalid="ignore"):
            pose = B @ cov[:, [0, 1, 2, 6, 7, 8]][:, :, [0, 1, 2, 6, 7, 8]] @ B.transpose(0, 2, 1)
            lin = J @ cov[:, 3:9, 3:9] @ J.transpose(0, 2, 1)
        twist = np.zeros((M, 6, 6))
        twist[:, :3, :3] = lin
        twist[:, 3:, 3:] = np.nan

        def marked(c):
            bad = ~np.isfinite(np.diagonal(c, axis1=1, axis2=2))
            c = np.where(bad[:, :, None] | bad[:, None, :] | ~np.isfinite(c), 0.0, c)
            d = np.arange(c.shape[1])
            c[:, d, d] = np.where(bad, frames.UNKNOWN_VARIANCE, c[:, d, d])
            return c

        for have, want in ((got.pose_cov, marked(pose)), (got.twist_cov, marked(twist))):
            assert np.array_equal(have == 0.0, want == 0.0)  # the zeros and marks exactly
            np.testing.assert_allclose(have, want, rtol=1e-12,
                                       atol=1e-13 * np.abs(want).max() + 1e-300)
        C = R @ C_nb @ frames.F_FRD_FLU
        np.testing.assert_allclose(got.q_xyzw, dcm_to_quat(C)[:, [1, 2, 3, 0]], rtol=0,
                                   atol=1e-15)
        np.testing.assert_allclose(got.v_flu, np.einsum("mji,mj->mi", C_nb, v)
                                   * np.diagonal(frames.F_FRD_FLU), rtol=1e-14, atol=1e-14)
        fix = frames.T_NED_ENU @ cov[:, :3, :3] @ frames.T_NED_ENU
        assert got.fix_cov.tobytes() == fix.tobytes()  # the signs of zeros too
    assert (got.twist_cov[3, :3, :3] == np.diag([-1.0] * 3)).all()  # the velocity unknown


def _truth_stream(n: int, rate: float, t0_ns: int, offset_ns: int = 0):
    from navreplay.core.streams import Stream, StreamKind

    t = t0_ns + offset_ns + np.rint(np.arange(n) / rate * 1e9).astype(np.int64)
    s = np.arange(n) / rate
    pos = np.column_stack([0.65 + 1e-7 * s, 2.2 + 2e-7 * s, 40.0 + 0.01 * s])
    v_n = np.column_stack([np.cos(s), np.sin(s), 0.0 * s])
    q = np.column_stack([np.cos(0.01 * s), 0.0 * s, 0.0 * s, np.sin(0.01 * s)])
    return Stream(StreamKind.TRUTH, t, {"pos": pos, "v_n": v_n, "q_nb": q})


@pytest.mark.parametrize("offset_ns", [0, 3_000_000])
def test_reference_at_the_output_rate(tmp_path, offset_ns) -> None:
    """The reference exported at the output rate: of each output interval its first sample,
    the very lines (and messages) of the full-rate export, however the windows were cut."""
    t0 = 1_483_228_800_000_000_000
    truth = _truth_stream(2000, 100.0, t0, offset_ns)
    full, dec = tmp_path / "full", tmp_path / "dec"
    w = export.RunExport(full, [], has_reference=True, t0_ns=t0)
    w.add_reference(truth)
    w.close()
    w = export.RunExport(dec, [], has_reference=True, reference_rate=10.0, t0_ns=t0)
    for a, b in ((0, 7), (7, 333), (333, 1500), (1500, 2000)):
        w.add_reference(truth.slice(a, b))
    w.close()
    lines = (full / "reference.tum").read_text().splitlines()
    kept = (dec / "reference.tum").read_text().splitlines()
    header = [x for x in lines if x.startswith("#")]
    assert kept[:len(header)] == header
    assert kept[len(header):] == lines[len(header)::10]  # 100 Hz -> 10 Hz
    stamps = np.array([int(x.split()[0].replace(".", "")) for x in kept[len(header):]])
    np.testing.assert_array_equal(np.diff(stamps), 100_000_000)
    assert stamps[0] == t0 + offset_ns
    with AnyReader([dec / export.ODOMETRY_FILE]) as reader:
        n = sum(1 for c, _, _ in reader.messages() if c.topic == "/reference/odom")
    assert n == 200
