"""Built-in vehicle scenarios: determinism, stream contract, metadata, parameter validation."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from navreplay.core.params import ParamError, describe
from navreplay.core.streams import FIELDS, Recording, StreamKind, seconds
from navreplay.geo import strapdown
from navreplay.geo.earth import gravity, lla_to_ned_offset, radii
from navreplay.geo.rotations import dcm_to_rotvec, quat_conj, quat_rotate, quat_to_dcm
from navreplay.sim.scenario import get_scenario, scenarios, simulate

DRIVE = {"duration": 40.0}


@pytest.fixture(scope="module")
def drive() -> Recording:
    return simulate("vehicle-drive", DRIVE, seed=7)


def assert_recordings_equal(a: Recording, b: Recording) -> None:
    assert a.t0_ns == b.t0_ns
    assert a.kinds() == b.kinds()
    for kind in a.kinds():
        sa, sb = a[kind], b[kind]
        np.testing.assert_array_equal(sa.t_ns, sb.t_ns)
        assert sa.columns.keys() == sb.columns.keys()
        for name in sa.columns:
            np.testing.assert_array_equal(sa[name], sb[name])
    assert dataclasses.asdict(a.metadata) == dataclasses.asdict(b.metadata)


def test_registered():
    table = scenarios()
    assert {"vehicle-drive", "stationary"} <= set(table)
    assert get_scenario("vehicle-drive").summary


def test_determinism(drive):
    assert_recordings_equal(drive, simulate("vehicle-drive", DRIVE, seed=7))
    other = simulate("vehicle-drive", DRIVE, seed=8)
    assert not np.array_equal(drive["imu"]["omega_ib_b"], other["imu"]["omega_ib_b"])
    assert not np.array_equal(drive["gps"]["pos"], other["gps"]["pos"])
    assert drive.metadata.true_errors != other.metadata.true_errors
    # the route does not depend on the seed
    for name in ("pos", "v_n", "q_nb"):
        np.testing.assert_array_equal(drive["truth"][name], other["truth"][name])


@pytest.mark.parametrize("name", ["vehicle-drive", "stationary"])
def test_stream_contract(name, drive):
    rec = drive if name == "vehicle-drive" else simulate("stationary", {"duration": 20.0}, seed=1)
    assert set(rec.kinds()) == set(get_scenario(name).streams)
    for kind in rec.kinds():
        stream = rec[kind]
        assert stream.t_ns.dtype == np.int64
        assert np.all(np.diff(stream.t_ns) > 0)
        assert stream.t_ns[0] >= rec.t0_ns
        assert stream.missing_fields() == []
        for col, field in FIELDS[kind].items():
            assert stream[col].shape == (len(stream),) + field.shape, (kind, col)
            assert np.all(np.isfinite(stream[col]))
    truth = rec["truth"]
    assert set(truth.columns) == set(rec.metadata.extra["truth_columns"])
    assert len(rec["imu"]) == len(truth) - 1
    np.testing.assert_array_equal(rec["imu"].t_ns, truth.t_ns[1:])


def test_rates_and_timing(drive):
    rates = drive.metadata.extra["rates"]
    for kind in (StreamKind.IMU, StreamKind.GPS, StreamKind.MAG):
        dt = np.diff(drive[kind].t_ns)
        assert np.all(dt == round(1e9 / rates[kind.value]))
    # 2017-01-01T00:00:00Z
    assert drive.t0_ns == 1_483_228_800 * 10**9
    assert drive["truth"].t_ns[0] == drive.t0_ns


def test_metadata(drive):
    meta = drive.metadata
    json.dumps(dataclasses.asdict(meta))
    assert meta.scenario == "vehicle-drive" and meta.seed == 7 and meta.navreplay_version
    assert meta.params["duration"] == 40.0 and meta.params["imu_grade"] == "tactical"
    assert {"imu", "gps", "mag", "initial_nav"} <= set(meta.true_errors)
    nav = meta.initial_nav
    assert set(nav) == {"t_ns", "pos", "v_n", "q_nb", "sigma"}
    assert set(nav["sigma"]) == {"pos_ned", "v_n", "phi"}
    assert nav["t_ns"] == drive.t0_ns
    # initial errors: the handed-over attitude differs from the truth by the recorded phi
    C_hat = quat_to_dcm(np.array(nav["q_nb"]))
    C = quat_to_dcm(drive["truth"]["q_nb"][0])
    np.testing.assert_allclose(-dcm_to_rotvec(C_hat @ C.T), meta.true_errors["initial_nav"]["phi"],
                               atol=1e-12)
    assert meta.extra["wmm"] == "WMM2015" and meta.extra["decimal_year"] == 2017.0


def test_magnetometer_sees_the_recorded_field():
    rec = simulate("vehicle-drive", {"duration": 20.0, "mag_noise": 0.0, "mag_bias": 0.0,
                                     "mag_scale_factor": 0.0}, seed=3)
    h_n = np.array(rec.metadata.extra["mag_field_n"])
    np.testing.assert_allclose(h_n * 1e9, [29419, -4307, 41627], atol=1.0)
    step = round(rec.metadata.extra["rates"]["truth"] / rec.metadata.extra["rates"]["mag"])
    q = rec["truth"]["q_nb"][::step]
    np.testing.assert_allclose(rec["mag"]["m_b"], quat_rotate(quat_conj(q), h_n), atol=1e-15)


def test_imu_errors_match_truth_columns():
    rec = simulate("vehicle-drive", {"duration": 10.0, "imu_grade": "ideal", "gps_rate": 2.0},
                   seed=0)
    assert not rec["truth"]["gyro_bias"].any()
    assert len(rec["gps"]) == 21
    rec = simulate("stationary", {"duration": 10.0}, seed=0)
    b = np.array(rec.metadata.true_errors["imu"]["gyro_bias"])
    # the truth bias column is the constant plus the (small) Gauss-Markov instability
    assert np.abs(rec["truth"]["gyro_bias"] - b).max() < 0.5 * np.abs(b).max()


@pytest.mark.parametrize("outages", ["100:30,200:60", [[100, 30], [200, 60]], ["100:30", "200:60"]])
def test_gnss_outages_drop_every_epoch_inside_and_are_recorded(outages):
    """``-p gps_outages=START:LEN,...`` or a TOML list: no fix and no velocity in [start,
    start + length); the schedule in the parameters and, as [start, end], in
    ``extra["gnss_outages"]``; the Gauss-Markov error wanders on underneath."""
    values = {"duration": 300.0, "gps_pos_gm_sigma": 2.0, "gps_pos_gm_tau": 60.0}
    full = simulate("vehicle-drive", values, seed=5)
    rec = simulate("vehicle-drive", {**values, "gps_outages": outages}, seed=5)
    assert rec.metadata.params["gps_outages"] == [[100.0, 30.0], [200.0, 60.0]]
    assert rec.metadata.extra["gnss_outages"] == [[100.0, 130.0], [200.0, 260.0]]
    assert full.metadata.extra["gnss_outages"] == []
    for kind in ("gps", "gps_vel"):
        t = (rec[kind].t_ns - rec.t0_ns) * 1e-9
        t_full = (full[kind].t_ns - full.t0_ns) * 1e-9
        gone = ((t_full >= 100.0) & (t_full < 130.0)) | ((t_full >= 200.0) & (t_full < 260.0))
        assert gone.sum() == 90 and np.array_equal(t, t_full[~gone])
        for name, column in rec[kind].columns.items():  # the others are the same samples
            assert np.array_equal(column, full[kind][name][~gone])
    for name in rec["truth"].columns:
        assert np.array_equal(rec["truth"][name], full["truth"][name])
    assert np.abs(np.diff(rec["truth"]["gps_pos_gm"][::100], axis=0)).max() > 0.0


def test_gnss_outages_of_the_gimpo_scenarios():
    from navreplay.sim.scenarios import gimpo

    rec = simulate("gimpo-accel-yaw", {"gps_outages": "12:4"}, seed=2)
    t = (rec["gps_vel"].t_ns - rec.t0_ns) * 1e-9
    assert len(t) == len(rec["imu"]) - 16 and not ((t >= 12.0) & (t < 16.0)).any()
    assert rec.metadata.extra["gnss_outages"] == [[12.0, 16.0]]
    p = gimpo.GimpoAccelYawParams(gps_outages=((12.0, 4.0),))
    with pytest.raises(ValueError, match="outages"):
        gimpo.simulate_runs(p, gimpo.GimpoAccelYaw().truth(p), [1, 2])


def test_the_gps_pos_gm_truth_column_is_the_gnss_error_s_correlated_part():
    """At the GNSS epochs the truth column is the Gauss-Markov part of the fix's error: the
    rest, fix minus truth minus that column, is the white noise of the specification."""
    rec = simulate("vehicle-drive", {"duration": 600.0, "gps_pos_gm_sigma": 3.0,
                                     "gps_pos_sigma_h": 1.0, "gps_pos_sigma_v": 1.5}, seed=8)
    truth, gps = rec["truth"], rec["gps"]
    idx = np.searchsorted(truth.t_ns, gps.t_ns)
    assert np.array_equal(truth.t_ns[idx], gps.t_ns)
    err = lla_to_ned_offset(*truth["pos"][idx].T, *gps["pos"].T)
    white = err - truth["gps_pos_gm"][idx]
    np.testing.assert_allclose(np.std(white, axis=0), [1.0, 1.0, 1.5], rtol=0.1)
    assert 1.5 < np.std(truth["gps_pos_gm"][idx]) < 4.5
    lag1 = [np.corrcoef(white[:-1, k], white[1:, k])[0, 1] for k in range(3)]
    assert np.abs(lag1).max() < 0.15


def test_stationary_initial_tilt():
    rec = simulate("stationary", {"duration": 5.0, "init_attitude_error": "1e-3, -2e-3, 0"}, seed=0)
    assert rec.metadata.true_errors["initial_nav"]["phi"] == [1e-3, -2e-3, 0.0]
    truth = rec["truth"]
    assert np.array_equal(truth["pos"], np.tile(truth["pos"][0], (len(truth), 1)))
    assert not truth["v_n"].any()


@pytest.mark.parametrize(
    ("name", "values", "match"),
    [
        ("vehicle-drive", {"gps_rate": 3.0}, "gps_rate"),
        ("vehicle-drive", {"date": "2031-01-01"}, "date"),
        ("vehicle-drive", {"date": "yesterday"}, "date"),
        ("vehicle-drive", {"duration": 10.005}, "duration"),
        ("vehicle-drive", {"turn_mode": "sideways"}, "turn_mode"),
        ("vehicle-drive", {"warp": 1}, "unknown"),
        ("vehicle-drive", {"duration": 60.0, "gps_outages": "50:20"}, "ends after"),
        ("vehicle-drive", {"gps_outages": "100:30,120:10"}, "before the previous"),
        ("vehicle-drive", {"gps_outages": "100"}, "2 values separated by .:."),
        ("vehicle-drive", {"gps_outages": "100:0"}, "more than 0 s"),
        ("vehicle-drive", {"max_bank_deg": 90.0}, "max_bank_deg"),
        ("gimpo-accel-yaw", {"gps_outages": "28:5"}, "ends after"),
        ("stationary", {"lat_deg": 91.0}, "lat_deg"),
        ("stationary", {"init_tilt_sigma": -1.0}, "init_tilt_sigma"),
    ],
)
def test_bad_parameters(name, values, match):
    with pytest.raises(ParamError, match=match):
        simulate(name, values, seed=0)


SHORT = {
    "vehicle-drive": {"duration": 10.0},
    "stationary": {"duration": 5.0, "init_tilt_sigma": 1e-3},
    "underwater-rpm": {"duration": 5.0},
    "ship-transfer-alignment": {"duration": 2.0},
    "gimpo-accel-sweep": {},
    "gimpo-accel-yaw": {},
}


def test_every_scenario_is_covered_below():
    assert set(SHORT) == set(scenarios())


@pytest.mark.parametrize("name", sorted(SHORT))
def test_metadata_contract(name):
    """Every parameter recorded; metadata plain JSON in memory as on file; every truth column
    described; true errors present; a handed-over initial solution is not the truth."""
    rec = simulate(name, SHORT[name], seed=3)
    meta = rec.metadata
    assert {f.name for f in dataclasses.fields(get_scenario(name).Params)} <= set(meta.params)
    for field in ("params", "true_errors", "initial_nav", "extra"):
        value = getattr(meta, field)
        assert json.loads(json.dumps(value, allow_nan=False)) == value, field
    assert meta.true_errors
    assert set(rec["truth"].columns) == set(meta.extra["truth_columns"])
    nav = meta.initial_nav
    if "q_nb" in nav:
        truth = rec["truth"]
        assert nav["t_ns"] == truth.t_ns[0]
        assert any(np.any(s) for s in nav["sigma"].values())
        assert not np.array_equal(nav["q_nb"], truth["q_nb"][0])


@pytest.mark.parametrize("name", sorted(SHORT))
def test_every_parameter_is_documented(name):
    rows = describe(get_scenario(name).Params)
    assert [row[0] for row in rows if not row[3]] == []


def test_stationary_free_inertial_shows_the_schuler_oscillation():
    """A perfect IMU at rest, a 1 mrad initial tilt: v_N returns to 0 after half a Schuler period
    (pi sqrt(R/g), about 42 min) with the north error at its peak, 2 R phi."""
    tilt = 1e-3
    rec = simulate("stationary", {"duration": 2700.0, "imu_rate": 5.0, "imu_grade": "ideal",
                                  "init_attitude_error": f"0, {tilt}, 0"}, seed=0)
    nav = rec.metadata.initial_nav
    imu = rec["imu"]
    hist = strapdown.integrate(strapdown.nav_vector(nav["pos"], nav["v_n"], nav["q_nb"]),
                               imu["omega_ib_b"], imu["f_b"], np.full(len(imu), 0.2))
    t = seconds(rec["truth"].t_ns, rec.t0_ns)
    lat = rec["truth"]["pos"][0, 0]
    R_M, R_N = radii(lat)
    R = math.sqrt(R_M * R_N)
    half_period = math.pi * math.sqrt(R / gravity(lat, 0.0))
    v_n = hist[:, 3]
    k = np.flatnonzero((v_n[1:] < 0.0) & (v_n[:-1] >= 0.0) & (t[1:] > 100.0))[0] + 1
    assert t[k] == pytest.approx(half_period, rel=0.01)
    north = lla_to_ned_offset(*rec["truth"]["pos"][k], *hist[k, :3])[0]
    assert north == pytest.approx(2 * R * tilt, rel=0.03)
