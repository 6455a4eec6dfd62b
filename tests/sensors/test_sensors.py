"""Sensor error models: statistics on large seeded samples, analytic cases, validation."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from navreplay.core.units import (
    ARCMIN,
    DEG,
    DEG_PER_HOUR,
    DEG_PER_HOUR_PER_G,
    MICRO_G,
    NANOTESLA,
    PPM,
)
from navreplay.geo.earth import lla_to_ned_offset
from navreplay.geo.rotations import euler_to_quat, quat_conj, quat_rotate, quat_to_dcm
from navreplay.sensors import (
    DepthModel,
    GpsModel,
    ImuGrade,
    ImuModel,
    MagnetometerModel,
    MasterInsModel,
    SpeedLogModel,
    WmmEpoch,
    earth_field_n,
    ground_velocity,
    imu_grade,
    water_speed_along_axis,
)
from navreplay.sensors.magnetometer import decimal_year
from navreplay.sensors.noise import (
    density_from_average_sigma,
    gauss_markov,
    nyquist_sample_sigma,
    random_walk,
    sample_sigma,
)


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


# --------------------------------------------------------------------------------------------
# noise processes and conversions
# --------------------------------------------------------------------------------------------


def test_noise_conversions():
    assert sample_sigma(1e-3, 0.01) == pytest.approx(1e-2)
    assert sample_sigma(2e-4, 0.005) == pytest.approx(2e-4 / np.sqrt(0.005))
    # "80 ug/sqrt(Hz)" read at Nyquist for 4 Hz instantaneous samples: 113.1 ug
    # (docs/methods/vector-matching.md §3.1)
    assert nyquist_sample_sigma(80 * MICRO_G, 0.25) / MICRO_G == pytest.approx(113.137, abs=1e-3)
    # transfer-alignment reading: 20 ug as the 1-sigma of a 1-s average, at 100 Hz
    assert (sample_sigma(density_from_average_sigma(20 * MICRO_G), 0.01) / MICRO_G
            == pytest.approx(200.0))


def test_one_second_average_reading_reproduces_the_specified_value():
    """White noise specified as the 1-sigma of a 1-s average really has that 1-s average."""
    dt = 0.01
    model = ImuModel(gyro_arw=density_from_average_sigma(0.1 * DEG_PER_HOUR),
                     accel_vrw=density_from_average_sigma(20 * MICRO_G))
    n = 100 * 2000
    out = model.measure(model.draw(rng(1)), np.zeros((n, 3)), np.zeros((n, 3)), dt, rng(2))
    avg_g = out.omega_ib_b.reshape(-1, 100, 3).mean(axis=1)
    avg_a = out.f_b.reshape(-1, 100, 3).mean(axis=1)
    # 6000 averages: relative standard error of the sigma ~ 0.9 %
    assert avg_g.std() / (0.1 * DEG_PER_HOUR) == pytest.approx(1.0, abs=0.04)
    assert avg_a.std() / (20 * MICRO_G) == pytest.approx(1.0, abs=0.04)


def test_gauss_markov_variance_and_autocorrelation():
    dt, tau, sigma = 0.1, 5.0, 2.0
    x = gauss_markov(400_000, dt, sigma, tau, rng(3), dims=3)
    assert x.std() == pytest.approx(sigma, rel=0.05)
    lag = round(tau / dt)
    r = np.mean([np.corrcoef(x[:-lag, i], x[lag:, i])[0, 1] for i in range(3)])
    assert r == pytest.approx(math.exp(-1.0), abs=0.03)
    # the first sample is the given initial state
    x0 = np.array([1.0, -2.0, 3.0])
    assert np.array_equal(gauss_markov(10, dt, sigma, tau, rng(4), x0=x0)[0], x0)
    assert not gauss_markov(10, dt, 0.0, tau, rng(4)).any()


def test_random_walk_variance_grows_linearly():
    dt, q, n = 0.5, 0.3, 201
    r = random_walk(n, dt, q, rng(5), dims=4000)
    assert not r[0].any()
    assert r[-1].var() == pytest.approx(q**2 * (n - 1) * dt, rel=0.06)
    assert r[50].var() == pytest.approx(q**2 * 50 * dt, rel=0.06)


# --------------------------------------------------------------------------------------------
# IMU
# --------------------------------------------------------------------------------------------


def ta_imu() -> ImuModel:
    """Table 2 of the transfer-alignment paper (1 sigma; docs/methods/transfer-alignment.md
    §3.1)."""
    return ImuModel(
        gyro_bias=0.6 * DEG_PER_HOUR, gyro_scale_factor=300 * PPM, gyro_misalignment=ARCMIN,
        gyro_g_sensitivity=0.3 * DEG_PER_HOUR_PER_G,
        gyro_arw=density_from_average_sigma(0.1 * DEG_PER_HOUR),
        accel_bias=250 * MICRO_G, accel_scale_factor=300 * PPM, accel_misalignment=ARCMIN,
        accel_vrw=density_from_average_sigma(20 * MICRO_G),
    )


def test_imu_error_draws_have_the_specified_sigmas():
    model = ta_imu()
    g = rng(6)
    draws = [model.draw(g) for _ in range(3000)]
    gb = np.array([d.gyro_bias for d in draws])
    ab = np.array([d.accel_bias for d in draws])
    sf = np.array([d.gyro_scale_factor for d in draws])
    mis = np.array([d.gyro_misalignment for d in draws])
    kg = np.array([d.gyro_g_sensitivity for d in draws])
    assert gb.std() / model.gyro_bias == pytest.approx(1.0, abs=0.03)
    assert ab.std() / model.accel_bias == pytest.approx(1.0, abs=0.03)
    assert sf.std() / model.gyro_scale_factor == pytest.approx(1.0, abs=0.03)
    off = ~np.eye(3, dtype=bool)
    assert not mis[:, ~off].any()
    assert mis[:, off].std() / model.gyro_misalignment == pytest.approx(1.0, abs=0.03)
    assert kg.std() / model.gyro_g_sensitivity == pytest.approx(1.0, abs=0.03)


def test_imu_regression_recovers_errors():
    """Least squares of the measurements on the ideal inputs recovers (I + S + M), K_g, bias."""
    model = ImuModel(
        gyro_bias=1e-3, gyro_scale_factor=1e-2, gyro_misalignment=1e-2,
        gyro_g_sensitivity=1e-3, gyro_arw=1e-3,
        accel_bias=1e-2, accel_scale_factor=1e-2, accel_misalignment=1e-2, accel_vrw=1e-3,
    )
    errors = model.draw(rng(7))
    n, dt = 100_000, 0.01
    g = rng(8)
    omega = g.uniform(-1.0, 1.0, (n, 3))
    f = g.uniform(-10.0, 10.0, (n, 3))
    out = model.measure(errors, omega, f, dt, rng(9))

    X = np.hstack([omega, f, np.ones((n, 1))])
    coef, *_ = np.linalg.lstsq(X, out.omega_ib_b, rcond=None)
    sig = sample_sigma(model.gyro_arw, dt)
    # tolerances: 5 standard errors, sig / (std(x) sqrt(n))
    se_w, se_f, se_1 = (sig / (s * math.sqrt(n)) for s in (1 / math.sqrt(3), 10 / math.sqrt(3), 1))
    np.testing.assert_allclose(coef[:3].T, errors.gyro_matrix(), atol=5 * se_w)
    np.testing.assert_allclose(coef[3:6].T, errors.gyro_g_sensitivity, atol=5 * se_f)
    np.testing.assert_allclose(coef[6], errors.gyro_bias, atol=5 * se_1)
    resid = out.omega_ib_b - X @ coef
    assert resid.std() == pytest.approx(sig, rel=0.01)

    Xa = np.hstack([f, np.ones((n, 1))])
    coef_a, *_ = np.linalg.lstsq(Xa, out.f_b, rcond=None)
    sig_a = sample_sigma(model.accel_vrw, dt)
    np.testing.assert_allclose(coef_a[:3].T, errors.accel_matrix(), atol=5 * se_f * sig_a / sig)
    np.testing.assert_allclose(coef_a[3], errors.accel_bias, atol=5 * se_1 * sig_a / sig)
    assert (out.f_b - Xa @ coef_a).std() == pytest.approx(sig_a, rel=0.01)
    # constant biases: the bias columns are the constants
    assert np.array_equal(out.gyro_bias, np.broadcast_to(errors.gyro_bias, (n + 1, 3)))


def test_imu_gauss_markov_bias_is_in_the_truth_series():
    model = ImuModel(gyro_bias_instability=1e-4, gyro_bias_tau=20.0,
                     accel_bias_instability=1e-3, accel_bias_tau=20.0, accel_rw=1e-4)
    errors = model.draw(rng(10))
    n, dt = 20_000, 0.1
    out = model.measure(errors, np.zeros((n, 3)), np.zeros((n, 3)), dt, rng(11))
    assert out.gyro_bias.shape == (n + 1, 3)
    # no white noise: the measurement is exactly the bias applied to sample k (rows 1..n)
    np.testing.assert_array_equal(out.omega_ib_b, out.gyro_bias[1:])
    np.testing.assert_array_equal(out.f_b, out.accel_bias[1:])
    assert out.gyro_bias.std() == pytest.approx(1e-4, rel=0.2)


def test_imu_ideal_grade_is_exact_and_measure_is_pure():
    g = rng(12)
    omega, f = g.normal(size=(50, 3)), g.normal(size=(50, 3))
    ideal = imu_grade(ImuGrade.IDEAL)
    out = ideal.measure(ideal.draw(rng(0)), omega, f, 0.01, rng(1))
    assert np.array_equal(out.omega_ib_b, omega) and np.array_equal(out.f_b, f)
    model = imu_grade("mems")
    a = model.measure(model.draw(rng(2)), omega, f, 0.01, rng(3))
    b = model.measure(model.draw(rng(2)), omega, f, 0.01, rng(3))
    assert np.array_equal(a.omega_ib_b, b.omega_ib_b) and np.array_equal(a.f_b, b.f_b)
    json.dumps(model.draw(rng(4)).as_dict())


def test_effective_biases_at_the_true_or_the_level_attitude():
    """At rest the errors ``(S + M) f`` and ``K_g f`` of the gravity reaction add to the bias: at
    the true attitude ``f_0 = -C_bn g_n``; in the level attitude of the same heading
    ``(0, 0, -g)`` whatever the roll and pitch (the 1-g bias of a banked coordinated turn)."""
    from navreplay.geo.earth import gravity, omega_ie_n
    from navreplay.sensors.imu import effective_biases

    model = imu_grade("mems")
    errors = model.draw(rng(21))
    euler = np.array([[0.6, 0.1, 1.2], [-0.7, 0.0, -2.0], [0.0, 0.0, 0.4]])
    q = euler_to_quat(euler)
    pos = np.tile([0.65, 2.2, 100.0], (3, 1))
    meas = model.measure(errors, np.zeros((2, 3)), np.zeros((2, 3)), 0.01, rng(22))
    g = gravity(0.65, 100.0)
    eye = np.eye(3)
    for level in (False, True):
        gyro, accel = effective_biases(errors, meas, q, pos, level=level)
        rest = euler.copy()
        if level:
            rest[:, :2] = 0.0
        C_bn = np.swapaxes(quat_to_dcm(euler_to_quat(rest)), 1, 2)
        f0 = -C_bn @ [0.0, 0.0, g]
        w_ie = C_bn @ omega_ie_n(0.65)
        np.testing.assert_allclose(
            accel, meas.accel_bias + f0 @ (errors.accel_matrix() - eye).T, rtol=0, atol=1e-15)
        np.testing.assert_allclose(
            gyro, meas.gyro_bias + w_ie @ (errors.gyro_matrix() - eye).T
            + f0 @ errors.gyro_g_sensitivity.T, rtol=0, atol=1e-18)
        if level:
            np.testing.assert_allclose(f0, np.tile([0.0, 0.0, -g], (3, 1)), atol=1e-12)


@pytest.mark.parametrize(
    ("cls", "kwargs", "field"),
    [
        (ImuModel, {"gyro_bias": -1.0}, "gyro_bias"),
        (ImuModel, {"accel_vrw": float("nan")}, "accel_vrw"),
        (ImuModel, {"gyro_bias_tau": 0.0}, "gyro_bias_tau"),
        (GpsModel, {"pos_sigma": (1.0, 2.0)}, "pos_sigma"),
        (GpsModel, {"vel_sigma": (1.0, -2.0, 0.0)}, "vel_sigma"),
        (GpsModel, {"rate": 0.0}, "rate"),
        (MagnetometerModel, {"bias": -1e-9}, "bias"),
        (MasterInsModel, {"tilt": (1.0, float("inf"), 0.0)}, "tilt"),
        (SpeedLogModel, {"speed_per_rpm": 0.0}, "speed_per_rpm"),
        (DepthModel, {"noise": -0.1}, "noise"),
    ],
)
def test_invalid_specs_name_the_field(cls, kwargs, field):
    with pytest.raises(ValueError, match=field):
        cls(**kwargs)


def test_specs_are_keyword_only_and_frozen():
    with pytest.raises(TypeError):
        ImuModel(1.0)  # type: ignore[misc]
    model = GpsModel(pos_sigma=3.0)
    assert model.pos_sigma == (3.0, 3.0, 3.0)
    with pytest.raises(AttributeError):
        model.rate = 5.0  # type: ignore[misc]


# --------------------------------------------------------------------------------------------
# GPS
# --------------------------------------------------------------------------------------------


def test_gps_noise_statistics_and_true_errors():
    model = GpsModel(pos_sigma=(2.0, 3.0, 5.0), pos_gm_sigma=(1.0, 1.0, 2.0), pos_gm_tau=5.0,
                     vel_sigma=(0.05, 0.05, 0.1), rate=1.0)
    m = 50_000
    lat, h = 0.6, 100.0
    pos = np.tile([lat, 2.2, h], (m, 1))
    v = np.tile([10.0, -5.0, 0.5], (m, 1))
    errors = model.draw(rng(13))
    out = model.measure(errors, pos, v, rng(14))
    ned = lla_to_ned_offset(lat, 2.2, h, out.pos[:, 0], out.pos[:, 1], out.pos[:, 2])
    np.testing.assert_allclose(ned, out.pos_error_ned, atol=1e-4)
    total = np.hypot([2.0, 3.0, 5.0], [1.0, 1.0, 2.0])
    np.testing.assert_allclose(out.pos_error_ned.std(axis=0) / total, 1.0, atol=0.03)
    np.testing.assert_allclose(out.pos_sigma[0], total)
    np.testing.assert_allclose((out.v_n - v).std(axis=0) / [0.05, 0.05, 0.1], 1.0, atol=0.02)
    np.testing.assert_allclose(out.vel_sigma[0], [0.05, 0.05, 0.1])
    assert set(out.fix_columns()) == {"pos", "pos_sigma"}
    assert set(out.velocity_columns()) == {"v_n", "vel_sigma"}


def test_gps_velocity_gauss_markov_error():
    """The time-correlated velocity error has its stationary sigma and correlation time, and
    the reported sigma is the total; without it the draws are those of the white model."""
    model = GpsModel(pos_sigma=1.0, vel_sigma=0.02, vel_gm_sigma=(0.1, 0.1, 0.2), vel_gm_tau=20.0,
                     rate=1.0)
    m = 200_000
    pos, v = np.tile([0.6, 2.2, 10.0], (m, 1)), np.zeros((m, 3))
    out = model.measure(model.draw(rng(3)), pos, v, rng(4))
    err = out.vel_error_n
    total = np.hypot(0.02, [0.1, 0.1, 0.2])
    np.testing.assert_allclose(err.std(axis=0) / total, 1.0, atol=0.02)
    np.testing.assert_allclose(out.vel_sigma[0], total)
    lag = 20  # one correlation time: the GM part correlates exp(-1), the white part not at all
    corr = np.mean(err[:-lag] * err[lag:], axis=0) / err.var(axis=0)
    np.testing.assert_allclose(corr, np.exp(-1.0) * (1.0 - 0.02 ** 2 / total ** 2), atol=0.03)
    white = GpsModel(pos_sigma=1.0, vel_sigma=0.02, rate=1.0)
    a = white.measure(white.draw(rng(3)), pos[:100], v[:100], rng(4))
    b = dataclasses.replace(model, vel_gm_sigma=0.0)
    b = b.measure(b.draw(rng(3)), pos[:100], v[:100], rng(4))
    np.testing.assert_array_equal(a.v_n, b.v_n)


# --------------------------------------------------------------------------------------------
# magnetometer
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("year", "expected_nt"),
    [
        (2017.0, (29419.0, -4307.0, 41627.0)),  # pygeomag WMM2015, libraries.md
        (2026.9, (29394.0, -4657.0, 41994.0)),  # pygeomag WMM2025, libraries.md
    ],
)
def test_wmm_field_matches_library_notes(year, expected_nt):
    h = earth_field_n(37.55 * DEG, 126.80 * DEG, 0.0, year) / NANOTESLA
    np.testing.assert_allclose(h, expected_nt, atol=1.0)


def test_wmm_agrees_with_igrf_within_model_differences():
    # ppigrf IGRF at 2017.0 (libraries.md): N 29467, E -4330, D 41594 nT
    h = earth_field_n(37.55 * DEG, 126.80 * DEG, 0.0, 2017.0) / NANOTESLA
    np.testing.assert_allclose(h, [29467.0, -4330.0, 41594.0], atol=60.0)


def test_wmm_epoch_selection_and_range():
    assert WmmEpoch.for_year(2015.0) is WmmEpoch.WMM2015
    assert WmmEpoch.for_year(2019.999) is WmmEpoch.WMM2015
    assert WmmEpoch.for_year(2020.0) is WmmEpoch.WMM2020
    assert WmmEpoch.for_year(2027.3) is WmmEpoch.WMM2025
    for year in (2014.99, 2030.0):
        with pytest.raises(ValueError, match="World Magnetic Model"):
            earth_field_n(0.6, 2.2, 0.0, year)
    import datetime

    assert decimal_year(datetime.datetime(2017, 7, 2, 12)) == pytest.approx(2017.5)


def test_magnetometer_model():
    h_n = np.array([29e-6, -4e-6, 41e-6])
    q = euler_to_quat(rng(15).uniform(-1.0, 1.0, (2000, 3)))
    perfect = MagnetometerModel()
    m_b = perfect.measure(perfect.draw(rng(0)), q, h_n, rng(1))["m_b"]
    np.testing.assert_allclose(m_b, quat_rotate(quat_conj(q), h_n), atol=1e-18)
    # (I + S + M) C_bn h_n + bias recovered by regression
    model = MagnetometerModel(scale_factor=0.01, misalignment=0.01, bias=300e-9, noise=10e-9)
    errors = model.draw(rng(16))
    m_b = model.measure(errors, q, h_n, rng(17))["m_b"]
    h_b = quat_rotate(quat_conj(q), h_n)
    X = np.hstack([h_b, np.ones((len(q), 1))])
    coef, *_ = np.linalg.lstsq(X, m_b, rcond=None)
    np.testing.assert_allclose(coef[:3].T, errors.matrix(), atol=2e-3)
    np.testing.assert_allclose(coef[3], errors.bias, atol=3e-9)
    assert (m_b - X @ coef).std() == pytest.approx(10e-9, rel=0.05)


# --------------------------------------------------------------------------------------------
# master INS
# --------------------------------------------------------------------------------------------


def test_master_ins_without_errors_is_the_truth():
    g = rng(18)
    euler = np.column_stack([g.uniform(-0.5, 0.5, 500), g.uniform(-1.2, 1.2, 500),
                             g.uniform(-math.pi, math.pi, 500)])
    v = g.normal(size=(500, 3))
    pos = np.tile([0.6, 2.2, 0.0], (500, 1))
    model = MasterInsModel()
    out = model.measure(model.draw(rng(0)), euler_to_quat(euler), v, pos, rng(1))
    np.testing.assert_allclose(out["euler"], euler, atol=1e-12)
    np.testing.assert_array_equal(out["v_n"], v)
    np.testing.assert_array_equal(out["pos"], pos)


def paper_eqs_20_22(euler: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """Transfer-alignment paper eqs. (20)-(22), with psi_tilde = psi - eps_d (erratum E14 in
    docs/methods/transfer-alignment.md)."""
    phi, theta, psi = euler.T
    en, ee, ed = eps
    pt = psi - ed
    roll = np.arctan((-en * np.cos(pt) - ee * np.sin(pt))
                     / (np.cos(theta) - np.sin(theta) * (en * np.sin(pt) - ee * np.cos(pt)))) + phi
    pitch = np.arcsin(np.sin(theta) + np.cos(theta) * (en * np.sin(pt) - ee * np.cos(pt)))
    yaw = np.arctan2(np.cos(theta) * np.sin(pt) - en * np.sin(theta),
                     np.cos(theta) * np.cos(pt) + ee * np.sin(theta))
    return np.column_stack([roll, pitch, yaw])


def test_master_ins_tilt_sign_matches_paper_to_first_order():
    g = rng(19)
    euler = np.column_stack([g.uniform(-0.2, 0.2, 200), g.uniform(-0.3, 0.3, 200),
                             g.uniform(-3.0, 3.0, 200)])
    eps = np.array([3.0, -3.0, 5.0]) * ARCMIN  # the paper's 1-sigma sizes
    model = MasterInsModel(tilt=1.0)  # draws are replaced below
    errors = model.draw(rng(0))
    errors = type(errors)(tilt=eps, synchro_bias=np.zeros(3), vel_bias=np.zeros(3))
    out = model.measure(errors, euler_to_quat(euler), np.zeros((200, 3)),
                        np.zeros((200, 3)), rng(1))["euler"]
    expected = paper_eqs_20_22(euler, eps)
    diff = out - expected
    diff[:, 2] = (diff[:, 2] + math.pi) % (2 * math.pi) - math.pi
    effect = np.abs(out - euler)
    effect[:, 2] = np.abs((effect[:, 2] + math.pi) % (2 * math.pi) - math.pi)
    assert effect.max() > 5e-4  # the tilt shows ...
    # ... and agrees with (20)-(22) up to second order (eps^2 ~ 2e-6)
    assert np.abs(diff).max() < 3e-6
    # the opposite tilt sign would be off by twice the effect
    flipped = paper_eqs_20_22(euler, -eps) - out
    assert np.abs(flipped[:, :2]).max() > 5e-4


def test_master_ins_synchro_and_velocity_errors():
    model = MasterInsModel(synchro_bias=3 * ARCMIN, synchro_noise=ARCMIN, vel_bias=0.2,
                           vel_noise=(0.1, 0.1, 0.05))
    errors = model.draw(rng(20))
    m = 20_000
    q = np.tile([1.0, 0.0, 0.0, 0.0], (m, 1))
    out = model.measure(errors, q, np.zeros((m, 3)), np.zeros((m, 3)), rng(21))
    np.testing.assert_allclose(out["euler"].mean(axis=0), errors.synchro_bias, atol=5e-5)
    np.testing.assert_allclose(out["euler"].std(axis=0) / ARCMIN, 1.0, atol=0.03)
    np.testing.assert_allclose(out["v_n"].mean(axis=0), errors.vel_bias, atol=3e-3)
    np.testing.assert_allclose(out["v_n"].std(axis=0) / [0.1, 0.1, 0.05], 1.0, atol=0.03)
    json.dumps(errors.as_dict())


# --------------------------------------------------------------------------------------------
# speed log and depth
# --------------------------------------------------------------------------------------------


def test_speed_log_model_and_current_kinematics():
    model = SpeedLogModel()
    errors = model.draw(rng(22))
    assert errors.misalignment[0] == 0.0
    u = np.linspace(12.0, 16.0, 50_000)
    quiet = SpeedLogModel(noise=0.0)
    rpm = quiet.measure(errors, u, rng(1))["rpm"]
    np.testing.assert_allclose(rpm, (1 + errors.scale_factor) * u / 0.01, rtol=1e-14)
    noisy = model.measure(errors, u, rng(2))["rpm"] - rpm
    assert noisy.std() == pytest.approx(5.0, rel=0.02)
    # ground velocity = C_nb C_bv [u, 0, 0] + v_c, and back
    g = rng(23)
    q = euler_to_quat(g.uniform(-0.3, 0.3, (100, 3)))
    v_c = np.array([0.2, -0.15, 0.0])
    m = np.array([0.0, 0.01, -0.02])
    v_n = ground_velocity(q, u[:100], m, v_c)
    v_w_b = np.einsum("kji,kj->ki", quat_to_dcm(q), v_n - v_c)
    np.testing.assert_allclose(np.linalg.norm(v_w_b, axis=1), u[:100], rtol=1e-12)
    np.testing.assert_allclose(water_speed_along_axis(q, v_n, m, v_c), u[:100], rtol=1e-12)
    # C_bv = exp([m x]) tilts the velocity axis to [1, m_z, -m_y] to first order
    np.testing.assert_allclose(v_w_b / u[:100, None], np.tile([1.0, m[2], -m[1]], (100, 1)),
                               atol=5e-4)


def test_depth_model():
    model = DepthModel(bias=2.0, noise=0.1)
    errors = model.draw(rng(24))
    d = np.full(40_000, 50.0)
    out = model.measure(errors, d, rng(25))["depth"]
    assert out.mean() - 50.0 == pytest.approx(errors.bias, abs=3e-3)
    assert out.std() == pytest.approx(0.1, rel=0.02)
    json.dumps(errors.as_dict())
