"""Rerun output: .rrd written, read back with rerun's chunk reader, entities and values asserted;
unreachable viewers fail fast; saving is atomic."""

from __future__ import annotations

import dataclasses
import socket
import sys
import time

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr

from navreplay.filters import ins_error as ie
from navreplay.geo import (
    euler_to_quat,
    lla_to_ned_offset,
    ned_offset_to_lla,
    quat_to_dcm,
    quat_wxyz_to_xyzw,
    quat_xyzw_to_wxyz,
    radii,
)
from navreplay.replay.result import InnovationSeries, RunResult
from navreplay.streams import Metadata, Recording, Stream, StreamKind
from navreplay.units import DEG, DEG_PER_HOUR, MILLI_G
from navreplay.viz import (
    Connect,
    Save,
    Spawn,
    VizUnavailableError,
    chi2_bounds,
    convert,
    naming,
    open_sink,
    targets,
)
from navreplay.viz.blueprint import Catalog, build_blueprint

STATES = tuple(dataclasses.replace(s, name=s.name.replace("b_", "db_", 1))
               if s.name.startswith("b_") else s for s in ie.nav_states())
T0_NS = 1_700_000_000_123_456_789
REF = np.array([0.6544, 2.2131, 12.0])  # lat, lon [rad], h [m]
M = 5000  # output rows at 10 Hz: more than one 4096-row chunk


# ----------------------------------------------------------------------------------------------
# synthetic inputs


def make_truth(duration: float = 500.0, rate: float = 50.0) -> Recording:
    t = np.arange(0.0, duration + 1e-9, 1.0 / rate)
    ned = np.stack([4.0 * t, 50.0 * np.sin(t / 40.0), -0.01 * t], axis=1)
    v = np.stack([np.full_like(t, 4.0), 50.0 / 40.0 * np.cos(t / 40.0), np.full_like(t, -0.01)], 1)
    pos = np.stack(ned_offset_to_lla(REF[0], REF[1], REF[2], ned), axis=1)
    euler = np.stack([0.05 * np.sin(t / 5.0), 0.02 * np.cos(t / 7.0), 0.3 + t / 2000.0], axis=1)
    truth = Stream(
        StreamKind.TRUTH,
        T0_NS + np.rint(t * 1e9).astype(np.int64),
        {"pos": pos, "v_n": v, "q_nb": euler_to_quat(euler), "theta_f": 0.01 * np.sin(t)},
    )
    return Recording({StreamKind.TRUTH: truth}, Metadata(scenario="synthetic"), T0_NS)


def make_result(label: str, seed: int, truth: Recording | None = None, m: int = M) -> RunResult:
    rng = np.random.default_rng(seed)
    t = np.arange(m) * 0.1
    n = len(STATES)
    x = rng.normal(size=(m, n)) * 1e-3
    A = rng.normal(size=(m, n, n)) * 1e-2
    P = A @ A.transpose(0, 2, 1) + np.eye(n) * 1e-6
    nav = {}
    if truth is not None:
        tr = truth[StreamKind.TRUTH]
        k = np.searchsorted(tr.t_ns, T0_NS + np.rint(t * 1e9).astype(np.int64))
        nav = dict(nav_pos=tr["pos"][k], nav_v_n=tr["v_n"][k], nav_q_nb=tr["q_nb"][k])
    k = m // 20
    innov = InnovationSeries(
        t=t[::20][:k],
        nu=rng.normal(size=(k, 3)),
        S=np.tile(np.diag([1.0, 4.0, 9.0]), (k, 1, 1)),
        nis=rng.chisquare(3, k),
    )
    return RunResult(
        filter_name="gps-ins", label=label, recording="synthetic", t0_ns=T0_NS, t=t,
        states=STATES, x=x, P=P, extras={"misalignment_euler": rng.normal(size=(m, 3))},
        innovations={"gps_pos": innov}, **nav,
    )  # fmt: skip


# ----------------------------------------------------------------------------------------------
# read back


def read_rrd(path) -> dict[str, dict[str, np.ndarray]]:
    """Temporal columns per entity path (time-sorted, chunks concatenated), plus static ones
    under the key ``"static"``."""
    store = rr.chunk.RrdReader(path).stream().collect()
    parts: dict[str, list[pa.RecordBatch]] = {}
    static: dict[str, pa.RecordBatch] = {}
    for chunk in store.stream().to_chunks():
        rb = chunk.to_record_batch()
        if chunk.is_static:
            static[chunk.entity_path] = rb
        else:
            parts.setdefault(chunk.entity_path, []).append(rb)
    out: dict[str, dict[str, np.ndarray]] = {}
    for path, batches in parts.items():
        cols: dict[str, list[np.ndarray]] = {}
        for rb in batches:
            for name in rb.schema.names:
                if name.startswith("rerun.controls"):
                    continue
                col = rb.column(name)
                if name in ("time", "timestamp"):
                    cols.setdefault(name, []).append(col.cast(pa.int64()).to_numpy())
                else:
                    flat = col
                    while pa.types.is_list(flat.type) or pa.types.is_fixed_size_list(flat.type):
                        flat = flat.flatten()
                    values = flat.to_numpy(zero_copy_only=False).astype(np.float64)
                    cols.setdefault(name, []).append(values.reshape(len(col), -1))
        merged = {k: np.concatenate(v) for k, v in cols.items()}
        order = np.argsort(merged["time"], kind="stable")
        out[path] = {k: v[order] for k, v in merged.items()}
    out["static"] = static  # type: ignore[assignment]
    return out


def scalars(data, path) -> np.ndarray:
    return data[path]["Scalars:scalars"].reshape(len(data[path]["time"]), -1)


# ----------------------------------------------------------------------------------------------
# .rrd contents


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    truth = make_truth()
    a = make_result("gps-ins", 1, truth)
    b = make_result("gps-ins[q=2]", 2, truth)  # a label that needs escaping
    path = tmp_path_factory.mktemp("rrd") / "run.rrd"
    err = a.x[:, 12] - 1e-4
    with open_sink(Save(path), recording_name="synthetic") as sink:
        sink.log_run(a, truth=truth, metrics={"db_g_x": err})
        sink.log_run(b, truth=truth)
        sink.log_ensemble(
            "NEES", a.t, {"gps-ins": np.full(M, 15.2)}, unit="-", bounds=chi2_bounds(15, 50)
        )
        recording_id = sink.recording_id
    return path, truth, a, b, err, recording_id, sink, read_rrd(path)


def test_entity_tree(saved):
    path, *_, data = saved
    b = naming.entity_path("gps-ins[q=2]")
    expected = [
        "/truth/nav/roll", "/truth/nav/v_N", "/truth/nav/p_E", "/truth/extra/theta_f",
        "/gps-ins/state/phi_N", "/gps-ins/sigma/db_g_z", "/gps-ins/error/db_g_x",
        "/gps-ins/error/roll", "/gps-ins/error/p_N", "/gps-ins/nav/yaw",
        "/gps-ins/extra/misalignment_euler", "/gps-ins/innovation/gps_pos/0",
        "/gps-ins/innovation/gps_pos/nis", f"{b}/state/db_a_y", f"{b}/error/v_D",
        "/world/gps-ins/body", "/world/gps-ins/covariance", "/world/truth/body",
        "/ensemble/NEES/gps-ins", "/ensemble/NEES/bounds",
    ]  # fmt: skip
    missing = [p for p in expected if p not in data]
    assert not missing
    for p in ("/world", "/world/truth/trajectory", "/world/gps-ins/trajectory",
              "/gps-ins/error/db_g_x", "/world/gps-ins/body/axes"):  # fmt: skip
        assert p in data["static"], p
    reader = rr.chunk.RrdReader(path)
    (entry,) = reader.recordings()
    assert entry.application_id == "navreplay"
    assert entry.recording_id == saved[5]
    assert reader.blueprints(), "the default blueprint is in the file"


def test_state_sigma_and_time_columns(saved):
    path, _, a, *_, data = saved
    t_ns = np.rint(a.t * 1e9).astype(np.int64)
    phi = data["/gps-ins/state/phi_N"]
    np.testing.assert_array_equal(phi["time"], t_ns)
    np.testing.assert_array_equal(phi["timestamp"], t_ns + T0_NS)
    np.testing.assert_allclose(
        scalars(data, "/gps-ins/state/phi_N")[:, 0], a.x[:, 6] / DEG, rtol=1e-12
    )
    np.testing.assert_allclose(
        scalars(data, "/gps-ins/state/db_a_x")[:, 0], a.x[:, 9] / MILLI_G, rtol=1e-12
    )
    np.testing.assert_allclose(
        scalars(data, "/gps-ins/sigma/db_g_z")[:, 0],
        np.sqrt(a.P[:, 14, 14]) / DEG_PER_HOUR,
        rtol=1e-12,
    )


def test_error_with_three_sigma_bounds(saved):
    path, _, a, _, err, *_, data = saved
    e = scalars(data, "/gps-ins/error/db_g_x")
    assert e.shape == (M, 3)
    sig = np.sqrt(a.P[:, 12, 12]) / DEG_PER_HOUR
    np.testing.assert_allclose(e[:, 0], err / DEG_PER_HOUR, rtol=1e-12)
    np.testing.assert_allclose(e[:, 1], 3 * sig, rtol=1e-12)
    np.testing.assert_allclose(e[:, 2], -3 * sig, rtol=1e-12)
    style = data["static"]["/gps-ins/error/db_g_x"].to_pydict()
    assert style["SeriesLines:names"][0] == ["gps-ins", "gps-ins +3σ", "gps-ins -3σ"]


def test_navigation_errors_and_bounds(saved):
    # the nav solution equals the truth at the output times: errors ~ 0; position bounds from P
    path, _, a, *_, data = saved
    np.testing.assert_allclose(scalars(data, "/gps-ins/error/roll")[:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(scalars(data, "/gps-ins/error/p_N")[:, 0], 0.0, atol=1e-6)
    R_M, _ = radii(a.nav_pos[:, 0])
    sig_n = (R_M + a.nav_pos[:, 2]) * np.sqrt(a.P[:, 0, 0])
    np.testing.assert_allclose(scalars(data, "/gps-ins/error/p_N")[:, 1], 3 * sig_n, rtol=1e-9)
    np.testing.assert_allclose(
        scalars(data, "/gps-ins/error/v_E")[:, 2], -3 * np.sqrt(a.P[:, 4, 4]), rtol=1e-12
    )
    # truth decimated from 50 Hz to one sample per 50 ms slot
    roll = data["/truth/nav/roll"]
    assert roll["time"].shape == (10_001,) and np.diff(roll["time"]).max() <= 60_000_000


def test_world_attitude_is_xyzw_and_ned(saved):
    path, truth, a, *_, data = saved
    body = data["/world/gps-ins/body"]
    assert body["time"].shape == (M,)  # 10 Hz outputs, 10 Hz transforms
    np.testing.assert_allclose(
        body["Transform3D:quaternion"].reshape(M, 4), quat_wxyz_to_xyzw(a.nav_q_nb), atol=1e-7
    )
    ref = truth[StreamKind.TRUTH]["pos"][0]
    ned = lla_to_ned_offset(*ref, a.nav_pos[:, 0], a.nav_pos[:, 1], a.nav_pos[:, 2])
    np.testing.assert_allclose(body["Transform3D:translation"].reshape(M, 3), ned, atol=2e-3)
    cov = data["/world/gps-ins/covariance"]
    assert cov["time"].shape == (M // 10,)  # 1 Hz ellipsoids


def test_innovations_and_nis(saved):
    path, _, a, *_, data = saved
    s = a.innovations["gps_pos"]
    nu1 = scalars(data, "/gps-ins/innovation/gps_pos/1")
    np.testing.assert_allclose(nu1[:, 0], s.nu[:, 1], rtol=1e-12)
    np.testing.assert_allclose(nu1[:, 1], 6.0)  # 3 sqrt(S_11) = 3 * 2
    nis = scalars(data, "/gps-ins/innovation/gps_pos/nis")
    np.testing.assert_allclose(nis[:, 0], s.nis, rtol=1e-12)
    lo, hi = chi2_bounds(3)
    np.testing.assert_allclose(nis[0, 1:], [lo, hi])


def test_ensemble_bounds(saved):
    path, *_, data = saved
    lo, hi = chi2_bounds(15, 50)
    np.testing.assert_allclose(scalars(data, "/ensemble/NEES/bounds")[0], [lo, hi])
    np.testing.assert_allclose(scalars(data, "/ensemble/NEES/gps-ins")[:, 0], 15.2)


def test_blueprint_adapts_to_what_was_logged(saved):
    *_, sink, _ = saved
    plots = sink.catalog.plots
    assert list(plots["attitude"])[:3] == ["nav:roll", "nav:pitch", "nav:yaw"]
    assert plots["attitude"]["error:roll"][0] == "roll error [deg]"
    assert plots["position"]["error:p_N"][0] == "position N error [m]"
    # components of a prefix share one plot; both filters overlay
    assert len(plots["sensor"]["state:db_g"][1]) == 6
    # a state with an error plot leaves the sigma plot (its bounds are in the error plot)
    assert "/gps-ins/sigma/db_g_x" not in plots["sensor"]["sigma:db_g"][1]
    assert "/gps-ins/sigma/db_g_y" in plots["sensor"]["sigma:db_g"][1]
    assert plots["innovation"]["nis:gps_pos"][0] == "gps_pos NIS (dof 3) [-]"
    assert sink.catalog.world
    # a filter without nav solution or innovations: no attitude/innovation tabs
    bare = Catalog()
    bare.add("sensor", "state:b", "b [SI]", "/f/state/b")
    build_blueprint(bare)  # builds
    assert not bare.plots["attitude"] and not bare.plots["innovation"]


# ----------------------------------------------------------------------------------------------
# live logging


def test_observer_then_log_run_logs_each_row_once(tmp_path):
    truth = make_truth(duration=60.0)
    r = make_result("live", 3, truth, m=600)
    path = tmp_path / "live.rrd"
    with open_sink(path) as sink:
        observe = sink.observer(truth)
        for stop in (0, 150, 151, 400, 600):
            view = RunResult(
                r.filter_name, r.label, r.recording, r.t0_ns, r.t[:stop], r.states,
                r.x[:stop], r.P[:stop], r.nav_pos[:stop], r.nav_v_n[:stop], r.nav_q_nb[:stop],
                {k: v[:stop] for k, v in r.extras.items()},
            )  # fmt: skip
            observe(view)
        sink.log_run(r, truth=truth)
    data = read_rrd(path)
    col = data["/live/state/dv_N"]
    np.testing.assert_array_equal(col["time"], np.rint(r.t * 1e9).astype(np.int64))
    np.testing.assert_allclose(col["Scalars:scalars"][:, 0], r.x[:, 3])
    assert data["/world/live/body"]["time"].shape == (600,)
    assert "/live/innovation/gps_pos/nis" in data


def test_observer_without_navigation_solution(tmp_path):
    r = make_result("bare", 7, m=300)
    path = tmp_path / "bare.rrd"
    with open_sink(path) as sink:
        observe = sink.observer()
        for stop in (100, 300):
            observe(
                RunResult(
                    r.filter_name,
                    r.label,
                    r.recording,
                    r.t0_ns,
                    r.t[:stop],
                    r.states,
                    r.x[:stop],
                    r.P[:stop],
                )  # fmt: skip
            )
        sink.log_run(r)
    data = read_rrd(path)
    assert data["/bare/state/phi_E"]["time"].shape == (300,)
    assert not any(p.startswith("/world") for p in [*data, *data["static"]])


def test_run_logged_twice_is_refused(tmp_path):
    r = make_result("twice", 4, m=20)
    with open_sink(tmp_path / "t.rrd") as sink:
        sink.log_run(r)
        with pytest.raises(ValueError, match="already logged"):
            sink.log_run(r)


def test_two_sinks_are_two_recordings(tmp_path):
    ids = []
    for i in range(2):
        with open_sink(tmp_path / f"{i}.rrd") as sink:
            sink.log_run(make_result("f", i, m=10))
            ids.append(sink.recording_id)
    assert ids[0] != ids[1]
    assert rr.chunk.RrdReader(tmp_path / "1.rrd").recordings()[0].recording_id == ids[1]


# ----------------------------------------------------------------------------------------------
# sinks: reachability and atomicity


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_connect_to_closed_port_fails_fast(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    port = free_port()
    start = time.perf_counter()
    with pytest.raises(VizUnavailableError) as info:
        open_sink(Connect(f"rerun+http://127.0.0.1:{port}/proxy"))
    assert time.perf_counter() - start < 2.0
    msg = str(info.value)
    assert "\n" not in msg and str(port) in msg
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="display check is Linux-only")
def test_spawn_without_display_fails_fast(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(targets, "find_viewer", lambda: "/usr/bin/true")
    start = time.perf_counter()
    with pytest.raises(VizUnavailableError, match="no display"):
        open_sink(Spawn(port=free_port()))
    assert time.perf_counter() - start < 2.0


def test_spawn_without_viewer_executable(monkeypatch):
    monkeypatch.setattr(targets, "find_viewer", lambda: None)
    with pytest.raises(VizUnavailableError, match="executable"):
        open_sink(Spawn(port=free_port()))


def test_save_is_atomic_on_failure(tmp_path):
    target = tmp_path / "out.rrd"
    target.write_bytes(b"previous")
    with pytest.raises(RuntimeError, match="boom"):
        with open_sink(Save(target)) as sink:
            sink.log_run(make_result("f", 5, m=50))
            assert target.read_bytes() == b"previous"  # nothing under the name while writing
            raise RuntimeError("boom")
    assert target.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.rrd"]
    fresh = tmp_path / "new.rrd"
    with pytest.raises(ValueError):
        with open_sink(fresh) as sink:
            sink.log_run(make_result("f", 6, m=50), metrics={"dv_N": np.zeros(3)})  # wrong rows
    assert not fresh.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.rrd"]


def test_save_refuses_to_overwrite_when_asked(tmp_path):
    target = tmp_path / "out.rrd"
    target.write_bytes(b"x")
    with pytest.raises(FileExistsError):
        open_sink(Save(target, overwrite=False))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.rrd"]


def test_parse_url():
    assert targets.parse_url("rerun+http://10.0.0.2:9000/proxy")[1:] == ("10.0.0.2", 9000)
    assert targets.parse_url("rerun://example.org")[2] == 443
    with pytest.raises(ValueError, match="scheme"):
        targets.parse_url("http://localhost:9876")


# ----------------------------------------------------------------------------------------------
# conversions


def test_ellipsoid_axes_of_a_rotated_covariance():
    C = quat_to_dcm(euler_to_quat([0.1, -0.2, 0.7]))
    P = C @ np.diag([4.0, 1.0, 0.25]) @ C.T
    half, q_xyzw = convert.ellipsoids(P[None])
    order = np.argsort(half[0])
    np.testing.assert_allclose(half[0][order], 3.0 * np.array([0.5, 1.0, 2.0]))
    V = quat_to_dcm(quat_xyzw_to_wxyz(q_xyzw[0]))
    np.testing.assert_allclose(V @ np.diag((half[0] / 3.0) ** 2) @ V.T, P, atol=1e-12)


def test_chi2_bounds_shrink_with_runs():
    lo1, hi1 = chi2_bounds(2)
    lo, hi = chi2_bounds(2, runs=100)
    assert lo1 < lo < 2.0 < hi < hi1
    np.testing.assert_allclose([lo1, hi1], [0.0506356, 7.3777589], rtol=1e-6)


def test_truth_interpolation_is_nan_outside():
    t = np.array([0.0, 1.0, 2.0])
    q = euler_to_quat(np.array([[0, 0, 0.0], [0, 0, 0.2], [0, 0, 0.4]]))
    nav = convert.NavColumns(t, np.zeros((3, 3)), np.arange(9.0).reshape(3, 3), q)
    at = nav.at(np.array([-0.1, 0.5, 2.0, 2.5]))
    np.testing.assert_allclose(at.v_n[1], [1.5, 2.5, 3.5])
    np.testing.assert_allclose(convert.euler(at.q_nb[1:3])[:, 2], [0.1, 0.4], atol=1e-3)
    assert np.isnan(at.v_n[[0, 3]]).all() and np.isnan(at.q_nb[[0, 3]]).all()


def test_units_and_groups_follow_the_state_names():
    assert naming.resolve_unit("phi_D").label == "deg"
    assert naming.resolve_unit("db_g_x").label == "deg/h"
    assert naming.resolve_unit("dk").label == "SI"
    assert naming.resolve_unit("dk", {"dk": "-"}).label == "-"
    assert naming.quantity_of("dd") is naming.Quantity.POSITION
    assert naming.group_of("dVc_N") == "dVc"
