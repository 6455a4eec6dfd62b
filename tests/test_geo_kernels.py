"""navreplay.geo.kernels: each single-value numba kernel against its numpy counterpart in
navreplay.geo (and the gravity derivatives against finite differences)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navreplay.geo import earth, kernels
from navreplay.geo import rotations as rot

PI = np.pi

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
lat_st = st.floats(-1.5, 1.5, **finite)  # the transport rate is singular at the poles
h_st = st.floats(-1e4, 1e5, **finite)


# --------------------------------------------------------------------------------------------
# earth model


@given(lat_st, h_st, vec3)
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


# --------------------------------------------------------------------------------------------
# rotations


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
