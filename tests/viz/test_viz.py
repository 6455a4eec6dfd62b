"""Rerun output: .rrd written, read back with rerun's chunk reader, entities and values asserted;
unreachable viewers fail fast; saving is atomic."""

from __future__ import annotations

import dataclasses
import socket
import sys
import time

import numpy as np
import pytest
import rerun as rr
from rrd import read_rrd, scalars

from navreplay.core.streams import Metadata, Recording, Stream, StreamKind
from navreplay.core.units import DEG, DEG_PER_HOUR, MILLI_G
from navreplay.filters import ins_error as ie
from navreplay.filters.result import InnovationSeries, RunResult
from navreplay.geo import (
    euler_to_quat,
    lla_to_ned_offset,
    ned_offset_to_lla,
    quat_to_dcm,
    quat_wxyz_to_xyzw,
    quat_xyzw_to_wxyz,
    radii,
)
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
from navreplay.viz.style import BAND_LINES, PALETTE, TRUTH_COLOR, color_index

STATES = tuple(dataclasses.replace(s, name=s.name.replace("b_", "db_", 1))
               if s.name.startswith("b_") else s for s in ie.nav_states())
T0_NS = 1_700_000_000_123_456_789
REF = np.array([0.6544, 2.2131, 12.0])  # lat, lon [rad], h [m]
M = 5000  # output rows at 10 Hz: more than one 4096-row chunk
GYRO_BIAS = np.array([1e-4, 2e-4, 3e-4])  # the truth of the db_g states [rad/s]


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
        {"pos": pos, "v_n": v, "q_nb": euler_to_quat(euler), "theta_f": 0.01 * np.sin(t),
         "gyro_bias_eff": np.tile(GYRO_BIAS, (t.shape[0], 1))},
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


def log_runs(sink, results, truth: Recording | None = None) -> None:
    """Whole runs into a sink, each as one block, as the replay pipeline hands them over: the
    truth, then each run's innovations and its rows scored against the truth."""
    from navreplay.filters.base import TruthColumn
    from navreplay.metrics import run_metrics
    from navreplay.replay import RunStart

    stream = truth[StreamKind.TRUTH] if truth is not None else None
    columns = {st.truth.column: st.unit for r in results for st in r.states
               if isinstance(st.truth, TruthColumn)}
    sink.start(RunStart("synthetic", tuple(r.label for r in results), T0_NS, truth is not None,
                        Metadata(), columns))
    if stream is not None:
        sink.truth(stream)
    for r in results:
        sink.innovations(r)
        rows = r.rows(0, r.t.shape[0])
        sink.rows(rows, run_metrics(rows, truth) if truth is not None else None, stream)


# ----------------------------------------------------------------------------------------------
# read back


# ----------------------------------------------------------------------------------------------
# .rrd contents


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    truth = make_truth()
    a = make_result("gps-ins", 1, truth)
    b = make_result("gps-ins[q=2]", 2, truth)  # a label that needs escaping
    path = tmp_path_factory.mktemp("rrd") / "run.rrd"
    err = a.x[:, 12] - GYRO_BIAS[0]
    with open_sink(Save(path), recording_name="synthetic", drawn_rate=None) as sink:
        log_runs(sink, [a, b], truth)
        sink.log_ensemble(
            "NEES", a.t, {"gps-ins": np.full(M, 15.2)}, unit="-", bounds=chi2_bounds(15, 50)
        )
        sink.summaries({"gps-ins": {"pos_rms_h": 1.5, "att_rms_heading": 2e-3},
                        "gps-ins[q=2]": {"pos_rms_h": 0.5}})
        recording_id = sink.recording_id
    return path, truth, a, b, err, recording_id, sink, read_rrd(path)


def test_entity_tree(saved):
    path, *_, data = saved
    b = naming.entity_path("gps-ins[q=2]")
    expected = [
        "/truth/nav/roll", "/truth/nav/v_N", "/truth/nav/p_E",
        "/gps-ins/state/phi_N", "/gps-ins/error/db_g_z", "/gps-ins/error/db_g_x",
        "/gps-ins/error/phi_N", "/gps-ins/error/p_N", "/gps-ins/nav/yaw",
        "/gps-ins/extra/misalignment_euler", "/gps-ins/innovation/gps_pos/0",
        "/gps-ins/innovation/gps_pos/nis", f"{b}/state/db_a_y", f"{b}/error/v_D",
        "/world/gps-ins/body", "/world/gps-ins/covariance", "/world/truth/body",
        "/map/gps-ins/position", "/map/truth/position",
        "/ensemble/NEES/gps-ins", "/ensemble/NEES/bounds",
    ]  # fmt: skip
    missing = [p for p in expected if p not in data]
    assert not missing
    # a scored state's sigma is the ±3σ of its error pane, not a series of its own
    assert "/gps-ins/sigma/db_g_z" not in data
    for p in ("/world", "/world/truth/trajectory", "/world/gps-ins/trajectory",
              "/gps-ins/error/db_g_x", "/world/gps-ins/body/axes", "/map/truth/track",
              "/map/gps-ins/track"):  # fmt: skip
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
        scalars(data, "/gps-ins/error/db_g_z")[:, 1],
        3.0 * np.sqrt(a.P[:, 14, 14]) / DEG_PER_HOUR,
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
    assert style["SeriesLines:names"][0] == ["gps-ins", "+3σ", "-3σ"]


def test_navigation_errors_and_bounds(saved):
    # the nav solution equals the truth at the output times: errors ~ 0; bounds from P
    path, _, a, *_, data = saved
    phi = scalars(data, "/gps-ins/error/phi_D")
    np.testing.assert_allclose(phi[:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(phi[:, 1], 3 * np.sqrt(a.P[:, 8, 8]) / DEG, rtol=1e-12)
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
    k = np.arange(0, M, 5)  # 10 Hz outputs, 2 Hz transforms
    assert body["time"].shape == k.shape
    np.testing.assert_allclose(
        body["Transform3D:quaternion"].reshape(-1, 4), quat_wxyz_to_xyzw(a.nav_q_nb[k]),
        atol=1e-7
    )
    ref = truth[StreamKind.TRUTH]["pos"][0]
    ned = lla_to_ned_offset(*ref, a.nav_pos[k, 0], a.nav_pos[k, 1], a.nav_pos[k, 2])
    np.testing.assert_allclose(body["Transform3D:translation"].reshape(-1, 3), ned, atol=2e-3)
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
    band = scalars(data, "/gps-ins/innovation/gps_pos/nis/band")
    assert band.shape == (s.t.shape[0], BAND_LINES)
    np.testing.assert_allclose(band[:, 0], lo)
    np.testing.assert_allclose(band[:, -1], hi)
    assert np.all(np.diff(band, axis=1) > 0)  # lines fill the band


def test_ensemble_bounds(saved):
    path, *_, data = saved
    lo, hi = chi2_bounds(15, 50)
    band = scalars(data, "/ensemble/NEES/bounds")
    np.testing.assert_allclose(band[0, [0, -1]], [lo, hi])
    np.testing.assert_allclose(scalars(data, "/ensemble/NEES/gps-ins")[:, 0], 15.2)


def test_blueprint_adapts_to_what_was_logged(saved):
    path, *_, sink, _ = saved
    plots = sink.catalog.plots
    assert list(plots["attitude"])[:3] == ["nav:roll", "nav:pitch", "nav:yaw"]
    # errors: one pane per filter (own scale), the filter named in the title, no legend
    pane = plots["attitude"]["error:phi_N@gps-ins"]
    assert pane.title == "gps-ins: attitude phi_N error [deg], ±3σ" and not pane.legend
    assert plots["position"]["error:p_N@gps-ins[q=2]"].title.startswith("gps-ins[q=2]: position N")
    # components of a prefix share one plot, a column per filter
    for label in ("gps-ins", "gps-ins[q=2]"):
        pane = plots["states"][f"state:db_g@{label}"]
        assert pane.column == label and pane.row == "db_g"
        assert len([p for p in pane.paths if "/state/" in p]) == 3
        assert "/truth/extra/gyro_bias_eff" in pane.paths  # the truth they are scored against
    sensor = [p for p in plots["sensor"].values()]
    assert sensor and all(p.column in ("gps-ins", "gps-ins[q=2]") for p in sensor)
    tabs, _ = read_blueprint(path)
    # in a column per filter, the state first: a narrow pane cut at its width still names it
    assert tabs["Sensor errors"][:2] == ["db_g_x error [deg/h], ±3σ (gps-ins)",
                                         "db_g_y error [deg/h], ±3σ (gps-ins)"]
    # a state with an error plot leaves the sigma plot (its bounds are in the error plot)
    # (the gyro biases are scored, the accelerometer biases are not: the truth lacks them)
    assert "sigma:db_g@gps-ins" not in plots["states"]
    assert "/gps-ins/sigma/db_a_y" in plots["states"]["sigma:db_a@gps-ins"].paths
    assert plots["consistency"]["nis:gps_pos@gps-ins"].title == (
        "gps-ins: gps_pos NIS (3 dof), 95 % band [-]")
    assert sink.catalog.world is not None and sink.catalog.geo
    # a filter without nav solution or innovations: no attitude/innovation tabs
    bare = Catalog()
    bare.add("sensor", "state:b", "b [-]", "/f/state/b")
    build_blueprint(bare)  # builds
    assert not bare.plots["attitude"] and not bare.plots["innovation"]


# ----------------------------------------------------------------------------------------------
# live logging


def test_rows_block_by_block_log_each_row_once(tmp_path):
    truth = make_truth(duration=60.0)
    r = make_result("live", 3, truth, m=600)
    path = tmp_path / "live.rrd"
    with open_sink(path, drawn_rate=None) as sink:
        log_runs(sink, [r.rows(0, 0)], truth)
        for a, b in ((0, 150), (150, 151), (151, 400), (400, 600)):
            sink.rows(r.rows(a, b), None, truth[StreamKind.TRUTH])
        sink.innovations(r)
    data = read_rrd(path)
    col = data["/live/state/dv_N"]
    np.testing.assert_array_equal(col["time"], np.rint(r.t * 1e9).astype(np.int64))
    np.testing.assert_allclose(col["Scalars:scalars"][:, 0], r.x[:, 3])
    assert data["/world/live/body"]["time"].shape == (120,)  # 2 Hz transforms
    assert "/live/innovation/gps_pos/nis" in data


def test_rows_without_navigation_solution(tmp_path):
    r = make_result("bare", 7, m=300)
    path = tmp_path / "bare.rrd"
    with open_sink(path, drawn_rate=None) as sink:
        for a, b in ((0, 100), (100, 300)):
            sink.rows(r.rows(a, b))
    data = read_rrd(path)
    assert data["/bare/state/phi_E"]["time"].shape == (300,)
    assert not any(p.startswith("/world") for p in [*data, *data["static"]])


def test_two_sinks_are_two_recordings(tmp_path):
    ids = []
    for i in range(2):
        with open_sink(tmp_path / f"{i}.rrd", drawn_rate=None) as sink:
            sink.rows(make_result("f", i, m=10))
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
            sink.rows(make_result("f", 5, m=50))
            assert target.read_bytes() == b"previous"  # nothing under the name while writing
            raise RuntimeError("boom")
    assert target.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.rrd"]
    fresh = tmp_path / "new.rrd"
    bad = make_result("f", 6, m=50)
    with pytest.raises(ValueError, match="state names"):
        with open_sink(fresh) as sink:
            sink.rows(dataclasses.replace(bad, x=bad.x[:, :3]))  # x of other states
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
    assert naming.resolve_unit("dk").label == "-"
    assert naming.resolve_unit("dk", {"dk": "-"}).label == "-"
    assert naming.quantity_of("dd") is naming.Tab.POSITION
    assert naming.group_of("dVc_N") == "dVc"


# ----------------------------------------------------------------------------------------------
# comparison view: colours, blueprint, bands, ensembles, live layout


def read_blueprint(path) -> tuple[dict[str, list[str]], dict[str, tuple[str, list[str]]]]:
    """Tabs (title -> view names) and views (name -> (kind, contents queries)) of the default
    blueprint stored in an .rrd."""
    reader = rr.chunk.RrdReader(path)
    store = reader.stream(store=reader.blueprints()[0]).collect()
    fields: dict[str, dict[str, list]] = {}
    for chunk in store.stream().to_chunks():
        rb = chunk.to_record_batch()
        parts = chunk.entity_path.strip("/").split("/")
        key = "/".join(parts[:2])
        for name in rb.schema.names:
            if ":" in name:
                fields.setdefault(key, {})[name] = rb.column(name).to_pylist()[-1]
    views = {}
    for key, f in fields.items():
        if key.startswith("view/") and "ViewBlueprint:display_name" in f:
            views[key] = (f["ViewBlueprint:display_name"][0],
                          f["ViewBlueprint:class_identifier"][0],
                          f.get("ViewContents:query", []))
    (tabs_box,) = [f for f in fields.values() if "ContainerBlueprint:active_tab" in f]
    tabs = {}
    for ref in tabs_box["ContainerBlueprint:contents"]:
        box = fields[ref]
        stack = list(box.get("ContainerBlueprint:contents", []))
        names = []
        while stack:
            item = stack.pop(0)
            if item in views:
                names.append(views[item][0])
            else:
                stack.extend(fields[item].get("ContainerBlueprint:contents", []))
        tabs[box["ContainerBlueprint:display_name"][0]] = names
    return tabs, {name: (kind, q) for name, kind, q in views.values()}


def first_color(data, path) -> tuple[int, int, int]:
    packed = data["static"][path].to_pydict()["SeriesLines:colors"][0][0]
    return (packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255


def test_blueprint_in_the_file_has_tabs_units_and_per_filter_panes(saved):
    path, *_ = saved
    tabs, views = read_blueprint(path)
    assert list(tabs)[:4] == ["Compare", "Attitude", "Velocity", "Position"]
    assert {"Sensor errors", "NEES / NIS", "Innovations", "Trajectory", "Map",
            "Ensemble"} <= set(tabs)
    # more than ROWS_PER_PAGE rows of a column tab go to further tabs, titled by their rows
    states = [t for t in tabs if t.startswith("State estimates")]
    assert len(states) >= 2 and all(t.startswith("State estimates: ") for t in states)
    assert all(len(t.split(": ", 1)[1].split(", ")) <= 3 for t in states)
    for name, (kind, _) in views.items():
        if kind == "TimeSeries":  # every plot says its unit, never a placeholder
            assert name.endswith("]") or "[" in name, name
            assert "[SI]" not in name and "[0]" not in name, name
    assert "gps-ins: position N error [m], ±3σ" in tabs["Position"]
    assert "gps-ins[q=2]: position N error [m], ±3σ" in tabs["Position"]
    assert tabs["Attitude"][:3] == ["roll [deg]", "pitch [deg]", "yaw (unwrapped) [deg]"]
    assert views["latitude / longitude"][0] == "Map"
    assert {k for k, _ in views.values()} >= {"TimeSeries", "3D", "Map"}
    # each per-filter pane holds that filter's entity only
    q = views["gps-ins: position N error [m], ±3σ"][1]
    assert q == ["+ /gps-ins/error/p_N"]


def test_each_filter_keeps_its_colour_in_every_error_plot(saved):
    path, *_, sink, data = saved
    colors = {}
    for tab in ("attitude", "velocity", "position", "sensor", "innovation", "consistency"):
        for key, plot in sink.catalog.plots[tab].items():
            if "@" not in key:
                continue
            label = key.split("@", 1)[1]
            for p in plot.paths:
                if p.endswith("/band"):
                    continue
                colors.setdefault(label, set()).add(first_color(data, p))
    gps, q2 = PALETTE[color_index("gps-ins")], PALETTE[color_index("gps-ins[q=2]")]
    assert gps != q2
    assert colors["gps-ins"] == {gps} and colors["gps-ins[q=2]"] == {q2}
    # overlays: each filter in its colour, truth grey
    assert first_color(data, "/gps-ins/nav/roll") == gps
    assert first_color(data, "/gps-ins\\[q\\=2\\]/nav/roll") == q2
    assert first_color(data, "/compare/pos_h/gps-ins") == gps
    assert first_color(data, "/truth/nav/roll") == TRUTH_COLOR


def test_single_run_nees_with_band(tmp_path):
    from navreplay.filters.base import Quantity, State, TruthColumn
    from navreplay.metrics import run_metrics

    truth = make_truth(duration=60.0)
    r = make_result("f", 4, truth, m=600)
    # a scored extra: its error is plotted with the declared unit and quantity
    theta = State("theta", "rad", Quantity.MISALIGNMENT, TruthColumn("theta_f"))
    tr = truth[StreamKind.TRUTH]
    k = np.searchsorted(tr.t_ns, T0_NS + np.rint(r.t * 1e9).astype(np.int64))
    r = dataclasses.replace(r, extras={"theta": tr["theta_f"][k] + 1e-3},
                            scored_extras=(theta,))
    m = run_metrics(r, truth)
    path = tmp_path / "nees.rrd"
    with open_sink(path, drawn_rate=None) as sink:
        log_runs(sink, [r], truth)
    data = read_rrd(path)
    np.testing.assert_allclose(scalars(data, "/f/nees")[:, 0], m.nees, rtol=1e-12)
    lo, hi = chi2_bounds(len(m.nees_states))
    band = scalars(data, "/f/nees/band")
    np.testing.assert_allclose(band[:, [0, -1]], np.tile([lo, hi], (600, 1)))
    tabs, _ = read_blueprint(path)
    assert f"f: NEES ({len(m.nees_states)} states), 95 % band [-]" in tabs["NEES / NIS"]
    np.testing.assert_allclose(scalars(data, "/f/error/theta")[:, 0], 1e-3 / DEG, rtol=1e-9)
    assert "theta error [deg] (f)" in tabs["Sensor errors"]


def test_ensemble_view_colours_tabs_and_bands(tmp_path):
    from navreplay.metrics import EnsembleStats, run_metrics
    from navreplay.viz.ensemble import SIGMA_SHADE, log_ensemble, log_runs
    from navreplay.viz.style import lighter

    truth = make_truth(duration=30.0)
    stats = {"ins": EnsembleStats("ins"), "gps-ins": EnsembleStats("gps-ins")}
    per_run = {}
    for k in range(3):
        per_run[k + 1] = {}
        for label, st in stats.items():
            m = run_metrics(make_result(label, 10 + k, truth, m=300), truth)
            st.add(m)
            per_run[k + 1][label] = m
    path = tmp_path / "ens.rrd"
    with open_sink(path, drawn_rate=None) as sink:
        for label, st in stats.items():
            log_ensemble(sink, label, st.result(), STATES)
        log_runs(sink, per_run)
    data = read_rrd(path)
    pages, _ = read_blueprint(path)
    tabs: dict[str, list[str]] = {}  # a tab of more than four rows is in pages "(k/n)"
    for title, views in pages.items():
        tabs.setdefault(title.split(" (")[0], []).extend(views)
    assert all(len(v) <= 3 * 4 for v in pages.values())
    assert {"Ensemble position", "Ensemble velocity", "Ensemble attitude",
            "Ensemble NEES / NIS", "Ensemble runs"} <= set(tabs)
    # navigation-error states (scored: dlat, dv_N, phi_N..) are not repeated as states; their
    # ratio RMS/sigma has its own tab
    assert not any("dlat" in v or "dv_N" in v for tab, vs in tabs.items() for v in vs
                   if tab != "Ensemble RMS/σ")
    assert any(v.startswith("ins: RMS/σ of dlat (") for v in tabs["Ensemble RMS/σ"])
    for i, label in enumerate(("ins", "gps-ins")):
        root = naming.entity_path("ensemble", f"{label}: position error N, RMS and σ")
        rms = first_color(data, f"{root}/{label}\\ RMS")
        sigma = first_color(data, f"{root}/{label}\\ σ")
        c = PALETTE[color_index(label)]
        assert rms == c and sigma == lighter(c, SIGMA_SHADE)
        nees = naming.entity_path("ensemble", f"{label}: NEES (9 states, 3 runs), 95 % band")
        band = scalars(data, f"{nees}/bounds")
        assert band.shape[1] == BAND_LINES and np.all(band[:, -1] > band[:, 0])
    assert "ins: horizontal position error, every run [m]" in tabs["Ensemble runs"]


def test_live_sink_sends_the_blueprint_before_the_data(tmp_path, monkeypatch):
    from navreplay.viz.sink import Sink

    events: list[tuple[str, str]] = []
    rec = rr.RecordingStream("navreplay", recording_id="live-test")
    rec.save(tmp_path / "live.rrd")
    sink = Sink(rec, Connect("rerun+http://127.0.0.1:1/proxy"), url="test")
    real_send = rec.send_columns
    monkeypatch.setattr(rec, "send_columns",
                        lambda path, **kw: (events.append(("data", str(path))),
                                            real_send(path, **kw))[1])
    real_bp = sink._rec.send_blueprint
    planned: list[set[str]] = []

    def send_blueprint(bp, **kw):
        events.append(("blueprint", ""))
        planned.append(set(sink.catalog.paths()))
        return real_bp(bp, **kw)

    monkeypatch.setattr(rec, "send_blueprint", send_blueprint)
    truth = make_truth(duration=20.0)
    r = make_result("live", 5, truth, m=200)
    log_runs(sink, [r.rows(0, 0)], truth)
    for a, b in ((0, 50), (50, 200)):
        sink.rows(dataclasses.replace(r.rows(a, b), extras={}), None, truth[StreamKind.TRUTH])
    assert events[0][0] == "blueprint"
    # every plotted entity's first data comes after a blueprint that already shows it (but the
    # truth columns states are scored against: logged with the truth, they join their state's
    # plot with its first estimates)
    plotted = {p for p in sink.catalog.paths() if not p.startswith("/truth/extra/")}
    sent = 0
    checked = 0
    for kind, path in events:
        if kind == "blueprint":
            sent += 1
        elif path in plotted:
            assert any(path in p for p in planned[:sent]), path
            checked += 1
    assert checked > 20 and "/live/error/p_N" in plotted
    sink.abort()


def test_sweep_on_its_own_axis_and_one_colour_per_variant(tmp_path):
    from navreplay.viz.style import SIGMA_SHADE, lighter

    a_mg = np.arange(-1500.0, 1501.0, 100.0)
    path = tmp_path / "sweep.rrd"
    with open_sink(path, drawn_rate=None) as sink:
        for k in range(2):
            sink.log_ensemble(f"sweep {k}", a_mg, {"gravity": a_mg * 0 + k, "specific-force": a_mg},
                              unit="deg", timeline="acceleration_mg")
        sink.log_ensemble("azimuth", np.arange(5.0), {"full RMS": np.ones(5),
                                                      "full sigma": np.ones(5)}, unit="mrad")
    store = rr.chunk.RrdReader(path).stream().collect()
    timelines = {}
    for chunk in store.stream().to_chunks():
        if not chunk.is_static:
            names = set(chunk.to_record_batch().schema.names)
            timelines[chunk.entity_path] = {"acceleration_mg", "time"} & names
    assert timelines["/ensemble/sweep\\ 0/gravity"] == {"acceleration_mg"}
    assert timelines["/ensemble/azimuth/full\\ RMS"] == {"time"}
    data = read_rrd_any(path, "acceleration_mg")
    np.testing.assert_array_equal(data["/ensemble/sweep\\ 1/gravity"]["acceleration_mg"], a_mg)
    full = read_rrd(path)
    # a variant keeps its colour across plots; its sigma is a lighter shade of it
    c0 = first_color(full, "/ensemble/sweep\\ 0/gravity")
    assert c0 == first_color(full, "/ensemble/sweep\\ 1/gravity")
    assert c0 != first_color(full, "/ensemble/sweep\\ 0/specific-force")
    rms = first_color(full, "/ensemble/azimuth/full\\ RMS")
    assert first_color(full, "/ensemble/azimuth/full\\ sigma") == lighter(rms, SIGMA_SHADE)
    tabs, _ = read_blueprint(path)
    assert tabs["Ensemble"][0] == "sweep 0 [deg]"


def read_rrd_any(path, timeline: str) -> dict[str, dict[str, np.ndarray]]:
    """Index values of ``timeline`` per entity."""
    out: dict[str, dict[str, np.ndarray]] = {}
    for chunk in rr.chunk.RrdReader(path).stream().collect().stream().to_chunks():
        rb = chunk.to_record_batch()
        if timeline in rb.schema.names:
            out[chunk.entity_path] = {timeline: rb.column(timeline).to_numpy()}
    return out


def test_compare_tab_first_overlays_every_filter_with_cdfs_and_the_table(saved):
    path, truth, a, b, *_, data = saved
    tabs, views = read_blueprint(path)
    assert list(tabs)[0] == "Compare"
    assert tabs["Compare"][:4] == ["horizontal position error [m]", "vertical position error [m]",
                                   "velocity error [m/s]", "heading error [deg]"]
    assert "CDF of the horizontal position error [%] vs [m]" in tabs["Compare"]
    assert tabs["Compare"][-1] == "headline metrics"
    assert views["headline metrics"][0] == "TextDocument"
    assert views["CDF of the heading error [%] vs [deg]"][0] == "BarChart"
    # both filters overlaid in one plot, each its own entity
    assert set(views["horizontal position error [m]"][1]) == {
        "+ /compare/pos_h/gps-ins", "+ " + naming.entity_path("compare", "pos_h", "gps-ins[q=2]")}
    # the magnitudes are those of the per-filter error panes
    e_n = scalars(data, "/gps-ins/error/p_N")[:, 0]
    e_e = scalars(data, "/gps-ins/error/p_E")[:, 0]
    np.testing.assert_allclose(scalars(data, "/compare/pos_h/gps-ins")[:, 0], np.hypot(e_n, e_e),
                               rtol=1e-9, atol=1e-12)
    phi_d = scalars(data, "/gps-ins/error/phi_D")[:, 0]
    np.testing.assert_allclose(scalars(data, "/compare/heading/gps-ins")[:, 0], np.abs(phi_d),
                               rtol=1e-9, atol=1e-12)
    # the CDF: a bar per percentile, at rising errors (its accuracy: tests/metrics/test_compare)
    cdf = data["static"]["/compare/cdf/heading/gps-ins"].to_pydict()
    x = np.asarray(cdf["BarChart:abscissa"][0][0]["buffer"], dtype=float)
    assert x.shape == (200,) and np.all(np.diff(x) >= 0)
    # the table: metrics as rows, filters as columns, the best in bold
    text = data["static"]["/compare/summary"].to_pydict()["TextDocument:text"][0][0]
    assert "| metric | gps-ins | gps-ins\\[q=2\\] |" in text
    assert "| horizontal position RMS [m] | 1.5 | **0.5** |" in text
    assert "| heading RMS [mrad] | 2 | - |" in text


def test_filter_colours_follow_their_names_not_their_order(tmp_path):
    truth = make_truth(duration=20.0)
    runs = [make_result(label, k, truth, m=200) for k, label in enumerate(("ins", "gps-ins"))]
    colours = []
    for name, order in (("a", runs), ("b", runs[::-1]), ("c", runs[1:])):
        path = tmp_path / f"{name}.rrd"
        with open_sink(path, drawn_rate=None) as sink:
            log_runs(sink, order, truth)
        data = read_rrd(path)
        colours.append({r.label: first_color(data, naming.entity_path(r.label, "nav", "roll"))
                        for r in order})
    assert colours[0] == colours[1] and colours[2]["gps-ins"] == colours[0]["gps-ins"]
    assert colours[0]["ins"] != colours[0]["gps-ins"]


def test_a_frozen_state_gets_no_pane(tmp_path):
    """A state with zero sigma all run (disabled, or frozen by its filter) is logged but gets
    no plot; one with a sigma does, in its filter's column."""
    from navreplay.filters.base import Quantity, State

    t = np.arange(50) * 0.1
    states = (State("b_g_x", "rad/s", Quantity.GYRO_BIAS),
              State("b_a_x", "m/s^2", Quantity.ACCEL_BIAS))
    P = np.zeros((50, 2, 2))
    P[:, 0, 0] = 1e-10  # b_a_x frozen: zero variance
    r = RunResult("f", "f", "demo", 0, t, states, np.full((50, 2), 1e-6), P)
    with open_sink(tmp_path / "f.rrd") as sink:
        sink.rows(r)
    plots = sink.catalog.plots["states"]
    assert "sigma:b_g@f" in plots and plots["sigma:b_g@f"].column == "f"
    assert not any("/f/sigma/b_a_x" in p.paths for p in plots.values())
