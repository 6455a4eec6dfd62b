"""navreplay.geo: WGS84 earth model and rotation algebra.

Analytic values, identities (round trips, composition, finite differences of the earth model),
edge cases (poles, antimeridian, gimbal lock), an independent implementation
(scipy.spatial.transform.Rotation, converted to scalar-last only at the boundary), and the
single-value numba kernels of navreplay.geo.kernels against the numpy functions.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.spatial.transform import Rotation

from navreplay.geo import earth, kernels
from navreplay.geo import rotations as rot

PI = np.pi
DEG = PI / 180.0

settings.register_profile("navreplay", max_examples=60, deadline=None, derandomize=True)
settings.load_profile("navreplay")

finite = {"allow_nan": False, "allow_infinity": False}
vec3 = st.lists(st.floats(-1.0, 1.0, **finite), min_size=3, max_size=3).map(np.array)
quat = (
    st.lists(st.floats(-1.0, 1.0, **finite), min_size=4, max_size=4)
    .map(np.array)
    .filter(lambda q: np.linalg.norm(q) > 0.1)
    .map(lambda q: q / np.linalg.norm(q))
)
lat_st = st.floats(-PI / 2, PI / 2, **finite)
lon_st = st.floats(-PI, PI, **finite)
h_st = st.floats(-1e5, 1e7, **finite)


def same_rotation_quat(p, q, atol=1e-12):
    """Quaternions equal up to sign."""
    return min(np.abs(p - q).max(), np.abs(p + q).max()) < atol


# --------------------------------------------------------------------------------------------
# earth: analytic values
# --------------------------------------------------------------------------------------------


def test_normal_gravity_equator_and_pole():
    assert earth.gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert earth.gravity(PI / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-10)
    assert earth.gravity(-PI / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-10)


def test_normal_gravity_mid_latitude_and_height():
    # Somigliana closed form with the published WGS84 constants (NIMA TR8350.2, eq. 4-1):
    # k = 0.00193185265241, e^2 = 0.00669437999013
    for lat in np.deg2rad([10.0, 37.0, 45.0, 80.0]):
        s2 = np.sin(lat) ** 2
        g = 9.7803253359 * (1 + 0.00193185265241 * s2) / np.sqrt(1 - 0.00669437999013 * s2)
        assert earth.gravity(lat, 0.0) == pytest.approx(g, abs=1e-10)
    # free-air gradient ~ -3.086e-6 s^-2 near the surface
    grad = (earth.gravity(45 * DEG, 100.0) - earth.gravity(45 * DEG, 0.0)) / 100.0
    assert grad == pytest.approx(-3.086e-6, rel=2e-3)
    # gravity_n points down
    np.testing.assert_array_equal(earth.gravity_n(0.3, 10.0)[:2], [0.0, 0.0])
    assert earth.gravity_n(0.3, 10.0)[2] == earth.gravity(0.3, 10.0)


def test_radii_equator_and_pole():
    R_M, R_N = earth.radii(0.0)
    assert R_N == pytest.approx(earth.A, abs=1e-6)
    assert R_M == pytest.approx(earth.A * (1 - earth.E2), abs=1e-6)
    R_M, R_N = earth.radii(PI / 2)
    polar = earth.A**2 / earth.B  # polar radius of curvature a^2/b
    assert R_M == pytest.approx(polar, abs=1e-6)
    assert R_N == pytest.approx(polar, abs=1e-6)
    assert polar == pytest.approx(6399593.626, abs=1e-3)


def test_radii_derivatives_match_finite_differences():
    lat = np.linspace(-1.5, 1.5, 13)
    d = 1e-5
    dR_M, dR_N = earth.radii_derivatives(lat)
    (Mp, Np), (Mm, Nm) = earth.radii(lat + d), earth.radii(lat - d)
    np.testing.assert_allclose(dR_M, (Mp - Mm) / (2 * d), atol=1e-3)
    np.testing.assert_allclose(dR_N, (Np - Nm) / (2 * d), atol=1e-3)


def test_meridian_arc_is_integral_of_R_M():
    # equator to pole: 10 001 965.729 m on WGS84
    arc, _ = quad(lambda p: earth.radii(p)[0], 0.0, PI / 2, epsabs=1e-6)
    assert arc == pytest.approx(10001965.729, abs=1e-3)


@pytest.mark.parametrize("lat_deg", [-90.0, -37.0, 0.0, 37.0, 60.0, 90.0])
def test_earth_rate_components(lat_deg):
    lat = lat_deg * DEG
    w = earth.omega_ie_n(lat)
    np.testing.assert_allclose(
        w, [earth.OMEGA_IE * np.cos(lat), 0.0, -earth.OMEGA_IE * np.sin(lat)], atol=1e-20
    )
    assert np.linalg.norm(w) == pytest.approx(earth.OMEGA_IE, rel=1e-15)
    # the same vector is the earth's spin axis [0, 0, W] in ECEF, for any longitude
    for lon in (-PI, -1.0, 0.0, 2.5):
        np.testing.assert_allclose(earth.C_en(lat, lon) @ w, [0, 0, earth.OMEGA_IE], atol=1e-19)


def test_transport_rate_known_velocity():
    lat, h = 45 * DEG, 1000.0
    R_M, R_N = earth.radii(lat)
    w = earth.omega_en_n(lat, h, [30.0, 100.0, -2.0])
    np.testing.assert_allclose(
        w, [100.0 / (R_N + h), -30.0 / (R_M + h), -100.0 / (R_N + h)], rtol=1e-14
    )
    # ~1.57e-5 rad/s for 100 m/s east: one earth circumference in ~4.6 days
    assert w[0] == pytest.approx(1.565e-5, rel=1e-3)


def test_transport_rate_is_rotation_rate_of_the_navigation_frame():
    # d/dt C_en = C_en [w_en x] along a path with lat' = v_N/(R_M+h), lon' = v_E/((R_N+h) cos lat)
    lat, lon, h = 0.7, -2.0, 500.0
    v = np.array([40.0, -70.0, 3.0])
    R_M, R_N = earth.radii(lat)
    rates = np.array([v[0] / (R_M + h), v[1] / ((R_N + h) * np.cos(lat)), -v[2]])
    dt = 1e-2
    C = [earth.C_en(*((lat, lon, h) + s * dt * rates)[:2]) for s in (-1, 1)]
    W = C[0].T @ C[1] / (2 * dt)  # ~ I/(2dt) + [w_en x]
    np.testing.assert_allclose(rot.vee(W), earth.omega_en_n(lat, h, v), rtol=1e-6, atol=1e-15)


def test_transport_rate_broadcasts_height():
    w = earth.omega_en_n(0.5, np.array([0.0, 100.0, 1e4]), [10.0, 5.0, 0.0])
    assert w.shape == (3, 3)
    for i, h in enumerate([0.0, 100.0, 1e4]):
        np.testing.assert_array_equal(w[i], earth.omega_en_n(0.5, h, [10.0, 5.0, 0.0]))


# --------------------------------------------------------------------------------------------
# earth: ECEF
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("lla", "ecef"),
    [
        ((0.0, 0.0, 0.0), (earth.A, 0.0, 0.0)),
        ((0.0, PI / 2, 100.0), (0.0, earth.A + 100.0, 0.0)),
        ((0.0, PI, 0.0), (-earth.A, 0.0, 0.0)),
        ((PI / 2, 0.0, 0.0), (0.0, 0.0, earth.B)),
        ((-PI / 2, 1.0, 50.0), (0.0, 0.0, -earth.B - 50.0)),
    ],
)
def test_lla_to_ecef_known_points(lla, ecef):
    np.testing.assert_allclose(earth.lla_to_ecef(*lla), ecef, atol=1e-8)


@given(lat_st, lon_st, h_st)
def test_lla_ecef_round_trip(lat, lon, h):
    r = earth.lla_to_ecef(lat, lon, h)
    lat2, lon2, h2 = earth.ecef_to_lla(r)
    assert np.linalg.norm(earth.lla_to_ecef(lat2, lon2, h2) - r) < 1e-6
    assert abs(h2 - h) < 1e-6
    assert abs(lat2 - lat) < 1e-13
    if abs(lat) < PI / 2 - 1e-9:  # longitude is undefined at the poles
        assert abs(rot.wrap_angle(lon2 - lon)) * np.cos(lat) < 1e-13


@pytest.mark.parametrize("h", [-1e5, 0.0, 1e3, 2e7])
@pytest.mark.parametrize("lat", [PI / 2, -PI / 2])
def test_ecef_to_lla_at_the_poles(lat, h):
    lat2, lon2, h2 = earth.ecef_to_lla(earth.lla_to_ecef(lat, 0.7, h))
    assert lat2 == pytest.approx(lat, abs=1e-15)
    assert h2 == pytest.approx(h, abs=1e-7)
    assert np.isfinite(lon2)


def test_ecef_to_lla_antimeridian():
    for lon in (PI, -PI, PI - 1e-12, -PI + 1e-12):
        _, lon2, _ = earth.ecef_to_lla(earth.lla_to_ecef(0.3, lon, 10.0))
        assert abs(rot.wrap_angle(lon2 - lon)) < 1e-14
        assert -PI <= lon2 <= PI
    # a point just west and just east of 180 deg stays on its side
    assert earth.ecef_to_lla(earth.lla_to_ecef(0.3, PI - 1e-9, 0.0))[1] > 3.0
    assert earth.ecef_to_lla(earth.lla_to_ecef(0.3, -PI + 1e-9, 0.0))[1] < -3.0


def test_lla_ecef_vectorised():
    lat = np.array([-1.2, 0.0, 0.4, PI / 2])
    lon = np.array([3.1, -PI, 0.2, 0.0])
    h = np.array([10.0, -50.0, 9e3, 0.0])
    r = earth.lla_to_ecef(lat, lon, h)
    assert r.shape == (4, 3)
    lat2, _, h2 = earth.ecef_to_lla(r)
    np.testing.assert_allclose(lat2, lat, atol=1e-14)
    np.testing.assert_allclose(h2, h, atol=1e-7)


def test_C_en_is_a_rotation_with_down_along_minus_normal():
    C = earth.C_en(0.6, -2.1)
    np.testing.assert_allclose(C @ C.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(C) == pytest.approx(1.0)
    # a height increase moves the ECEF point along -D
    dr = earth.lla_to_ecef(0.6, -2.1, 1.0) - earth.lla_to_ecef(0.6, -2.1, 0.0)
    np.testing.assert_allclose(C[:, 2], -dr, atol=1e-9)


def test_ned_offset_round_trip_and_direction():
    lat0, lon0, h0 = 37 * DEG, 127 * DEG, 50.0
    d = np.array([1200.0, -800.0, 30.0])
    lat, lon, h = earth.ned_offset_to_lla(lat0, lon0, h0, d)
    np.testing.assert_allclose(earth.lla_to_ned_offset(lat0, lon0, h0, lat, lon, h), d, atol=1e-8)
    # a small step north changes latitude by d/(R_M + h)
    R_M, _ = earth.radii(lat0)
    lat1, lon1, _ = earth.ned_offset_to_lla(lat0, lon0, h0, [1.0, 0.0, 0.0])
    assert lat1 - lat0 == pytest.approx(1.0 / (R_M + h0), rel=1e-6)
    assert lon1 == pytest.approx(lon0, abs=1e-15)


# --------------------------------------------------------------------------------------------
# rotations
# --------------------------------------------------------------------------------------------


@given(vec3, vec3)
def test_skew_vee_and_cross(a, b):
    np.testing.assert_allclose(rot.skew(a) @ b, np.cross(a, b), atol=1e-15)
    np.testing.assert_array_equal(rot.vee(rot.skew(a)), a)


@given(quat, quat)
def test_quaternion_composition_is_dcm_product(p, q):
    np.testing.assert_allclose(
        rot.quat_to_dcm(rot.quat_mult(p, q)), rot.quat_to_dcm(p) @ rot.quat_to_dcm(q), atol=1e-14
    )
    np.testing.assert_allclose(rot.quat_left_matrix(p) @ q, rot.quat_mult(p, q), atol=1e-15)
    np.testing.assert_allclose(rot.quat_right_matrix(q) @ p, rot.quat_mult(p, q), atol=1e-15)


@given(quat, vec3)
def test_quaternion_unit_norm_inverse_and_rotation(q, v):
    C = rot.quat_to_dcm(q)
    np.testing.assert_allclose(C @ C.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(C) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(rot.quat_mult(q, rot.quat_conj(q)), [1, 0, 0, 0], atol=1e-15)
    # C(q) v equals q (x) [0, v] (x) q^*
    qv = rot.quat_mult(rot.quat_mult(q, np.r_[0.0, v]), rot.quat_conj(q))
    np.testing.assert_allclose(rot.quat_rotate(q, v), qv[1:], atol=1e-15)
    assert abs(qv[0]) < 1e-15
    n = rot.quat_normalize(3.0 * q)
    assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-15)
    assert n[0] >= 0.0


@given(quat)
def test_quat_dcm_round_trip(q):
    p = rot.dcm_to_quat(rot.quat_to_dcm(q))
    assert np.linalg.norm(p) == pytest.approx(1.0, abs=1e-15)
    assert p[0] >= 0.0
    assert same_rotation_quat(p, q)


@given(st.floats(-PI, PI, **finite), st.floats(-1.5, 1.5, **finite), st.floats(-PI, PI, **finite))
def test_euler_round_trips(roll, pitch, yaw):
    e = np.array([roll, pitch, yaw])
    C = rot.euler_to_dcm(e)
    np.testing.assert_allclose(rot.quat_to_dcm(rot.euler_to_quat(e)), C, atol=1e-15)
    e2 = rot.dcm_to_euler(C)
    np.testing.assert_allclose(rot.wrap_angle(e2 - e), 0.0, atol=1e-12)
    np.testing.assert_allclose(rot.quat_to_euler(rot.euler_to_quat(e)), e2, atol=1e-12)


@given(
    vec3.filter(lambda v: np.linalg.norm(v) > 0).map(lambda v: v / np.linalg.norm(v)),
    st.floats(0.0, PI, **finite),
)
def test_rotvec_exp_log_inverse_up_to_pi(axis, angle):
    rv = axis * angle
    q = rot.rotvec_to_quat(rv)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
    rv2 = rot.quat_to_rotvec(q)
    if angle < PI - 1e-7:
        np.testing.assert_allclose(rv2, rv, atol=1e-12)
    else:  # at pi, +axis and -axis are the same rotation
        assert min(np.abs(rv2 - rv).max(), np.abs(rv2 + rv).max()) < 1e-6
    np.testing.assert_allclose(rot.rotvec_to_dcm(rv2), rot.rotvec_to_dcm(rv), atol=1e-12)
    np.testing.assert_allclose(rot.dcm_to_rotvec(rot.rotvec_to_dcm(rv)), rv2, atol=1e-7)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-8, 1e-7, 1.0000001e-7, 1e-4])
def test_rotvec_small_angles(angle):
    rv = angle * np.array([0.6, -0.8, 0.0])
    q = rot.rotvec_to_quat(rv)
    np.testing.assert_allclose(
        q,
        [np.cos(angle / 2), *(np.sin(angle / 2) * np.array([0.6, -0.8, 0.0]))],
        rtol=1e-15,
        atol=1e-22,
    )
    np.testing.assert_allclose(rot.quat_to_rotvec(q), rv, rtol=1e-12, atol=1e-22)
    # first order: exp([rv x]) = I + [rv x]
    np.testing.assert_allclose(rot.rotvec_to_dcm(rv), np.eye(3) + rot.skew(rv), atol=angle**2)


def test_rotvec_is_vectorised():
    rv = np.array([[0.0, 0.0, 0.0], [1e-9, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, PI]])
    q = rot.rotvec_to_quat(rv)
    assert q.shape == (4, 4)
    np.testing.assert_allclose(rot.quat_to_rotvec(q)[:3], rv[:3], atol=1e-15)


# gimbal lock ---------------------------------------------------------------------------------


@given(
    st.floats(-PI, PI, **finite),
    st.sampled_from([1.0, -1.0]),
    st.sampled_from([0.0, 1e-14, 1e-12, 1e-10, 1e-8, 1e-6, 1e-4]),
    st.floats(-PI, PI, **finite),
    vec3,
)
def test_dcm_to_euler_near_gimbal_lock_reproduces_the_dcm(roll, sign, eps, yaw, axis):
    e = np.array([roll, sign * (PI / 2 - eps), yaw])
    # a DCM carrying rounding errors like one from a chain of products
    a = rot.rotvec_to_quat(0.7 * axis)
    C = rot.quat_to_dcm(rot.quat_mult(rot.quat_mult(rot.euler_to_quat(e), a), rot.quat_conj(a)))
    e2 = rot.dcm_to_euler(C)
    np.testing.assert_allclose(rot.euler_to_dcm(e2), C, atol=1e-14)
    assert -PI / 2 <= e2[1] <= PI / 2
    assert abs(e2[1] - e[1]) < 1e-14


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_dcm_to_euler_exact_gimbal_lock_puts_rotation_in_yaw(sign):
    for roll, yaw in [(0.3, 1.0), (-2.0, 0.5), (1.0, -3.0)]:
        C = rot.euler_to_dcm([roll, sign * PI / 2, yaw])
        r2, p2, y2 = rot.dcm_to_euler(C)
        assert r2 == 0.0
        assert p2 == pytest.approx(sign * PI / 2, abs=1e-15)
        # only yaw - roll (pitch +90) or yaw + roll (pitch -90) is observable
        assert rot.wrap_angle(y2 - (yaw - sign * roll)) == pytest.approx(0.0, abs=1e-12)
        np.testing.assert_allclose(rot.euler_to_dcm([r2, p2, y2]), C, atol=1e-15)


# other helpers -------------------------------------------------------------------------------


def test_attitude_error_sign_convention():
    C_true = rot.euler_to_dcm([0.1, -0.2, 1.0])
    # estimate with heading 1 mrad too small: phi_D = +1 mrad
    C_hat = rot.euler_to_dcm([0.1, -0.2, 1.0 - 1e-3])
    phi = rot.attitude_error(C_hat, C_true)
    np.testing.assert_allclose(phi, [0.0, 0.0, 1e-3], atol=1e-9)
    # and in general C_hat = exp(-[phi x]) C_true
    phi0 = np.array([2e-4, -1e-4, 3e-4])
    phi = rot.attitude_error(rot.rotvec_to_dcm(-phi0) @ C_true, C_true)
    np.testing.assert_allclose(phi, phi0, atol=1e-11)


def test_wrap_angle():
    a = np.array([-PI, PI, 3 * PI, -3 * PI + 0.1, 0.5, 2 * PI])
    w = rot.wrap_angle(a)
    assert np.all((w >= -PI) & (w < PI))
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-14)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-14)


def test_quaternion_order_conversions():
    q = np.array([0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(rot.quat_wxyz_to_xyzw(q), [0.2, 0.3, 0.4, 0.1])
    np.testing.assert_array_equal(rot.quat_xyzw_to_wxyz(rot.quat_wxyz_to_xyzw(q)), q)


# scipy as an independent implementation ---------------------------------------------------------


@given(quat, vec3)
def test_against_scipy_quaternion_and_rotvec(q, rv):
    R = Rotation.from_quat(rot.quat_wxyz_to_xyzw(q))
    np.testing.assert_allclose(rot.quat_to_dcm(q), R.as_matrix(), atol=1e-14)
    assert same_rotation_quat(rot.dcm_to_quat(R.as_matrix()), q)
    rv = 3.0 * rv
    R = Rotation.from_rotvec(rv)
    assert same_rotation_quat(rot.rotvec_to_quat(rv), rot.quat_xyzw_to_wxyz(R.as_quat()))
    if np.linalg.norm(rv) < PI - 1e-6:
        np.testing.assert_allclose(
            rot.quat_to_rotvec(rot.rotvec_to_quat(rv)), R.as_rotvec(), atol=1e-12
        )


@given(st.floats(-PI, PI, **finite), st.floats(-1.55, 1.55, **finite), st.floats(-PI, PI, **finite))
def test_against_scipy_euler(roll, pitch, yaw):
    # scipy's intrinsic "ZYX" with angles [yaw, pitch, roll] is Rz(yaw) Ry(pitch) Rx(roll)
    R = Rotation.from_euler("ZYX", [yaw, pitch, roll])
    np.testing.assert_allclose(rot.euler_to_dcm([roll, pitch, yaw]), R.as_matrix(), atol=1e-15)
    assert same_rotation_quat(
        rot.euler_to_quat([roll, pitch, yaw]), rot.quat_xyzw_to_wxyz(R.as_quat())
    )
    np.testing.assert_allclose(rot.dcm_to_euler(R.as_matrix())[::-1], R.as_euler("ZYX"), atol=1e-11)


# --------------------------------------------------------------------------------------------
# kernels: each single-value numba kernel against its numpy counterpart
# --------------------------------------------------------------------------------------------

lat_inner = st.floats(-1.5, 1.5, **finite)  # the transport rate is singular at the poles


@given(lat_inner, h_st, vec3)
def test_earth_kernels_equal_geo_earth(lat, h, v):
    v = 100.0 * v
    np.testing.assert_allclose(kernels.radii(lat), earth.radii(lat), rtol=1e-15)
    np.testing.assert_allclose(kernels.radii_derivatives(lat), earth.radii_derivatives(lat),
                               rtol=1e-14, atol=1e-9)
    assert kernels.gravity(lat, h) == pytest.approx(float(earth.gravity(lat, h)), rel=1e-15)
    np.testing.assert_allclose(kernels.earth_rate(lat), earth.omega_ie_n(lat), rtol=1e-15,
                               atol=1e-20)
    np.testing.assert_allclose(kernels.transport_rate(lat, h, v[0], v[1]),
                               earth.omega_en_n(lat, h, v), rtol=1e-14, atol=1e-20)


@pytest.mark.parametrize("lat_deg", [-70.0, -20.0, 0.0, 35.0, 80.0])
@pytest.mark.parametrize("h", [-200.0, 0.0, 3000.0])
def test_gravity_derivatives_match_finite_differences(lat_deg, h):
    lat = np.deg2rad(lat_deg)
    dlat, dh = 1e-6, 1e-2
    num_lat = (earth.gravity(lat + dlat, h) - earth.gravity(lat - dlat, h)) / (2 * dlat)
    num_h = (earth.gravity(lat, h + dh) - earth.gravity(lat, h - dh)) / (2 * dh)
    dg_dlat, dg_dh = kernels.gravity_derivatives(lat, h)
    assert dg_dlat == pytest.approx(num_lat, rel=1e-6, abs=1e-9)
    assert dg_dh == pytest.approx(num_h, rel=1e-6)


@given(quat, quat, vec3, vec3)
def test_scalar_rotation_kernels_equal_geo_rotations(p, q, a, b):
    np.testing.assert_allclose(kernels.quat_mult(*p, *q), rot.quat_mult(p, q), atol=1e-15)
    np.testing.assert_allclose(kernels.cross(*a, *b), np.cross(a, b), atol=1e-15)
    C = rot.quat_to_dcm(q)
    np.testing.assert_allclose(kernels.rotate(*q, *a), C @ a, atol=1e-15)
    np.testing.assert_allclose(kernels.rotate_inverse(*q, *a), C.T @ a, atol=1e-15)
    rv = 3.0 * a
    np.testing.assert_allclose(kernels.rotvec_to_quat(*rv), rot.rotvec_to_quat(rv), atol=1e-15)
    np.testing.assert_allclose(kernels.quat_to_rotvec(*q), rot.quat_to_rotvec(q), atol=1e-12)


@given(quat)
def test_dcm_kernels_equal_geo_rotations(q):
    C = rot.quat_to_dcm(q)
    entries = kernels.dcm_entries(*q)
    np.testing.assert_allclose(np.reshape(entries, (3, 3)), C, atol=1e-15)
    np.testing.assert_allclose(kernels.dcm_to_quat(*entries), rot.dcm_to_quat(C), atol=1e-15)


@pytest.mark.parametrize("lat, lon", [(0.0, 0.0), (0.655, 2.213), (-1.2, -3.0),
                                      (np.pi / 2, 0.3)])
def test_c_en_kernel_equals_geo_earth(lat, lon):
    np.testing.assert_allclose(np.reshape(kernels.c_en_entries(lat, lon), (3, 3)),
                               earth.C_en(lat, lon), rtol=0, atol=1e-15)


@pytest.mark.parametrize("axis", [None, 0, 1, 2])
def test_dcm_to_quat_kernel_takes_each_pivot_as_numpy(axis):
    """Half turns about x, y and z make each diagonal entry the pivot; the quaternion is
    numpy's to the last bits, with the scalar part >= 0."""
    rv = np.zeros(3) if axis is None else np.eye(3)[axis] * (np.pi - 1e-3)
    C = rot.rotvec_to_dcm(rv + np.array([0.01, -0.02, 0.015]))
    got = np.array(kernels.dcm_to_quat(*C.ravel()))
    np.testing.assert_allclose(got, rot.dcm_to_quat(C), atol=1e-15)
    assert got[0] >= 0.0
    d = np.array([np.trace(C), *np.diag(C)])
    assert int(np.argmax(d)) == (0 if axis is None else axis + 1)  # the pivot meant
    nan = C.copy()
    nan[1, 1] = np.nan
    assert np.isnan(kernels.dcm_to_quat(*nan.ravel())).all()
    assert np.isnan(rot.dcm_to_quat(nan)).all()


@given(quat, quat)
def test_array_rotation_kernels_equal_geo_rotations(p, q):
    np.testing.assert_allclose(kernels.quat_to_dcm(q), rot.quat_to_dcm(q), atol=1e-15)
    np.testing.assert_allclose(kernels.quat_left_matrix(p), rot.quat_left_matrix(p), atol=0)
    np.testing.assert_allclose(kernels.quat_right_matrix(q), rot.quat_right_matrix(q), atol=0)
    np.testing.assert_allclose(kernels.quat_left_matrix(p) @ q, rot.quat_mult(p, q), atol=1e-15)
    np.testing.assert_allclose(kernels.quat_right_matrix(q) @ p, rot.quat_mult(p, q),
                               atol=1e-15)


@given(st.floats(-PI, PI, **finite), st.floats(-1.5, 1.5, **finite), st.floats(-PI, PI, **finite))
def test_euler_kernels_equal_geo_rotations_away_from_gimbal_lock(roll, pitch, yaw):
    e = np.array([roll, pitch, yaw])
    q = kernels.euler_to_quat(e)
    np.testing.assert_allclose(q * np.sign(q[0]), rot.euler_to_quat(e), atol=1e-15)  # up to sign
    np.testing.assert_allclose(kernels.quat_to_euler(q), rot.quat_to_euler(q), atol=1e-12)
