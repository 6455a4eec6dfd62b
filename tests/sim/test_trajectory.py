"""Truth trajectory generator: profiles, kinematic consistency, strapdown round trip."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from navreplay.core.units import DEG
from navreplay.geo import strapdown
from navreplay.geo.earth import gravity, lla_to_ned_offset, omega_ie_n, radii
from navreplay.geo.rotations import (
    attitude_error,
    dcm_to_rotvec,
    quat_rotate,
    quat_to_dcm,
    quat_to_euler,
)
from navreplay.sensors.speed_log import ground_velocity
from navreplay.sim.scenarios.vehicle import drive_manoeuvres
from navreplay.sim.trajectory import (
    Channel,
    Manoeuvre,
    Ramp,
    Route,
    Segment,
    TurnMode,
    bank_limited,
    channel_profile,
    generate,
    initial_nav,
    sample_indices,
    segments_to_manoeuvres,
    time_grid,
)

LAT, LON, H = 37.55 * DEG, 126.80 * DEG, 40.0


@pytest.fixture(scope="module")
def drive() -> dict:
    """Truth of the vehicle-drive route (one 150-s block), flat and coordinated, at 100 Hz."""
    out = {}
    for mode in TurnMode:
        route = Route(lat=LAT, lon=LON, h=H, heading=0.3,
                      manoeuvres=drive_manoeuvres(150.0, 15.0), turn_mode=mode)
        out[mode] = generate(route, 150.0, 100.0)
    return out


def test_channel_profile_ramps():
    t = np.linspace(0.0, 30.0, 3001)
    ms = [Manoeuvre(channel=Channel.HEADING, start=5.0, duration=5.0, change=1.0,
                    ramp=Ramp.LINEAR),
          Manoeuvre(channel=Channel.HEADING, start=10.0, duration=10.0, change=-0.5)]
    value, rate = channel_profile(t, 0.2, ms)
    assert value[0] == 0.2 and value[-1] == pytest.approx(0.7, abs=1e-15)
    inside = (t > 5.0) & (t < 10.0)
    np.testing.assert_allclose(rate[inside], 0.2)  # linear: constant rate
    # smooth: rate starts and ends at 0, peaks at twice the mean mid-window
    at = {x: int(np.argmin(np.abs(t - x))) for x in (15.0, 20.0)}
    assert rate[at[20.0]] == pytest.approx(0.0, abs=1e-12)
    assert rate[at[15.0]] == pytest.approx(-0.1, abs=1e-12)
    # the rate is the derivative of the value (away from the linear ramp's rate steps)
    ok = np.abs(t - 5.0) > 0.011
    ok &= np.abs(t - 10.0) > 0.011
    np.testing.assert_allclose(np.gradient(value, t)[ok], rate[ok], atol=2e-5)


def test_segments_to_manoeuvres():
    ms = segments_to_manoeuvres([Segment(duration=10.0, speed_change=5.0),
                                 Segment(duration=20.0, heading_change=1.0, pitch_change=0.1),
                                 Segment(duration=5.0)], start=2.0)
    assert [(m.channel, m.start, m.duration) for m in ms] == [
        (Channel.SPEED, 2.0, 10.0), (Channel.HEADING, 12.0, 20.0), (Channel.PITCH, 12.0, 20.0)]


def test_profile_is_continuous(drive):
    for traj in drive.values():
        d_euler = np.diff(traj.euler, axis=0)
        d_euler[:, 2] = (d_euler[:, 2] + math.pi) % (2 * math.pi) - math.pi
        assert np.abs(d_euler).max() < 0.2 * DEG  # <= 20 deg/s at 100 Hz: no jumps
        assert np.abs(np.diff(traj.speed)).max() < 0.03  # <= 3 m/s^2
        # smooth ramps: the rates are continuous, so the IMU has no steps
        assert np.abs(np.diff(traj.omega_ib_b, axis=0)).max() < 2e-3
        assert np.abs(np.diff(traj.f_b, axis=0)).max() < 0.05


def test_velocity_is_the_derivative_of_position(drive):
    traj = drive[TurnMode.COORDINATED]
    dt = traj.t[1] - traj.t[0]
    lat, h = traj.pos[1:-1, 0], traj.pos[1:-1, 2]
    R_M, R_N = radii(lat)
    d = traj.pos[2:] - traj.pos[:-2]
    v_fd = np.column_stack([d[:, 0] * (R_M + h), d[:, 1] * (R_N + h) * np.cos(lat), -d[:, 2]])
    v_fd /= 2 * dt
    np.testing.assert_allclose(v_fd, traj.v_n[1:-1], atol=2e-4)


def test_velocity_is_along_body_x_and_euler_matches_quaternion(drive):
    traj = drive[TurnMode.FLAT]
    v_b = quat_rotate(traj.q_nb * [1, -1, -1, -1], traj.v_n)
    np.testing.assert_allclose(v_b[:, 1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(v_b[:, 0], traj.speed, atol=1e-12)
    e = quat_to_euler(traj.q_nb)
    np.testing.assert_allclose(e, traj.euler, atol=1e-12)
    assert not traj.euler[:, 0].any()  # flat turns: no roll


def test_coordinated_turns_bank_without_lateral_force(drive):
    flat, coord = drive[TurnMode.FLAT], drive[TurnMode.COORDINATED]
    assert np.abs(flat.f_b[:, 1]).max() > 2.0  # ~0.3 g sideways in a flat turn
    assert np.abs(coord.euler[:, 0]).max() > 10 * DEG
    # bank atan(u psi_dot / g) cancels the centripetal force up to earth-rate / slope effects
    assert np.abs(coord.f_b[:, 1]).max() < 0.05


@pytest.mark.parametrize("speed", [40.0, 60.0, 80.0])
def test_coordinated_turns_bank_at_most_the_limit(speed):
    """A turn that would bank beyond the limit is flown longer (same change, same start) and
    peaks at the limit; the turns within it, and flat turns, are left as they are."""
    limit = 45.0 * DEG
    route = Route(lat=LAT, lon=LON, h=H, manoeuvres=drive_manoeuvres(150.0, speed),
                  turn_mode=TurnMode.COORDINATED)
    limited = bank_limited(route, limit)
    roll = generate(limited, 150.0, 50.0, ideal_imu=False).euler[:, 0]
    free = generate(route, 150.0, 50.0, ideal_imu=False).euler[:, 0]
    assert np.abs(roll).max() <= limit + 1e-9
    g = gravity(LAT, H)
    for before, after in zip(route.manoeuvres, limited.manoeuvres, strict=True):
        assert (before.start, before.change, before.channel) == (
            after.start, after.change, after.channel)
        if before.channel is not Channel.HEADING:
            assert after == before
            continue
        # the peak bank of a smooth turn at the window's top speed u: atan(2 u |dpsi| / (T g))
        grid = np.linspace(after.start, after.end, 401)
        u = channel_profile(grid, 0.0, [m for m in route.manoeuvres
                                         if m.channel is Channel.SPEED])[0].max()
        peak = math.atan(2.0 * u * abs(before.change) / (before.duration * g))
        if peak <= limit:
            assert after == before
        else:
            assert after.duration > before.duration
            assert math.atan(2.0 * u * abs(after.change) / (after.duration * g)) == (
                pytest.approx(limit, abs=1e-9))
    if speed == 40.0:
        assert limited == route and np.abs(free).max() < limit  # 38.7 deg: nothing to do
    else:
        assert np.abs(free).max() > limit + 3.0 * DEG and np.abs(roll).max() > limit - 1.0 * DEG
    flat = dataclasses.replace(route, turn_mode=TurnMode.FLAT)
    assert bank_limited(flat, limit) is flat
    with pytest.raises(ValueError, match="max_bank"):
        bank_limited(route, 0.5 * math.pi)


def test_perfect_imu_reproduces_truth_through_strapdown(drive):
    for traj in drive.values():
        nav0 = strapdown.nav_vector(traj.pos[0], traj.v_n[0], traj.q_nb[0])
        dt = np.diff(traj.t)
        hist = strapdown.integrate(nav0, traj.omega_ib_b, traj.f_b, dt)
        dp = lla_to_ned_offset(*traj.pos.T, *hist[:, :3].T)
        assert np.abs(dp).max() < 1e-6
        assert np.abs(hist[:, 3:6] - traj.v_n).max() < 1e-8
        phi = attitude_error(quat_to_dcm(hist[:, 6:]), quat_to_dcm(traj.q_nb))
        assert np.abs(phi).max() < 1e-10


def test_stationary_truth_reads_earth_rate_and_gravity():
    heading = 0.7
    traj = generate(Route(lat=LAT, lon=LON, h=H, heading=heading), 10.0, 50.0)
    assert np.array_equal(traj.pos, np.tile(traj.pos[0], (len(traj.t), 1)))
    assert not traj.v_n.any()
    w_b = quat_rotate(traj.q_nb[0] * [1, -1, -1, -1], omega_ie_n(LAT))
    np.testing.assert_allclose(traj.omega_ib_b, np.tile(w_b, (len(traj.f_b), 1)), atol=1e-15)
    np.testing.assert_allclose(traj.f_b, np.tile([0.0, 0.0, -gravity(LAT, H)], (len(traj.f_b), 1)),
                               atol=1e-11)


def test_current_and_velocity_misalignment():
    m = (0.0, 0.002, -0.003)
    v_c = (0.2, -0.1, 0.0)
    route = Route(lat=0.6, lon=2.2, h=-50.0, speed=12.0, velocity_misalignment=m, current_n=v_c,
                  manoeuvres=(Manoeuvre(channel=Channel.HEADING, start=2.0, duration=10.0,
                                        change=1.0),
                              Manoeuvre(channel=Channel.PITCH, start=3.0, duration=5.0,
                                        change=-0.1, ramp=Ramp.LINEAR)))
    traj = generate(route, 15.0, 20.0, ideal_imu=False)
    assert traj.omega_ib_b is None
    np.testing.assert_allclose(traj.v_n, ground_velocity(traj.q_nb, traj.speed, m, v_c),
                               atol=1e-12)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="negative"):
        generate(Route(lat=0.1, lon=0.1, speed=1.0, manoeuvres=(
            Manoeuvre(channel=Channel.SPEED, start=0.0, duration=1.0, change=-2.0),)), 2.0, 10.0)
    with pytest.raises(ValueError, match="whole number"):
        time_grid(1.05, 10.0)
    with pytest.raises(ValueError, match="divide"):
        sample_indices(101, 100.0, 3.0)
    with pytest.raises(ValueError, match="duration"):
        Manoeuvre(channel=Channel.ROLL, start=0.0, duration=0.0, change=0.1)
    with pytest.raises(ValueError, match="Manoeuvre.channel"):
        Manoeuvre(channel="speeed", start=0.0, duration=1.0, change=0.1)
    with pytest.raises(ValueError, match="lat"):
        Route(lat=2.0, lon=0.0)
    np.testing.assert_array_equal(sample_indices(101, 100.0, 10.0), np.arange(0, 101, 10))


def test_initial_nav_errors_have_the_documented_sign():
    traj = generate(Route(lat=LAT, lon=LON, h=H, heading=1.0), 1.0, 10.0)
    phi0 = np.array([1e-3, -2e-3, 5e-3])
    nav, err = initial_nav(traj, 10**18, np.random.default_rng(0), pos_sigma_ned=(1.0, 2.0, 3.0),
                           vel_sigma_n=(0.1, 0.1, 0.1), phi_offset=phi0)
    assert nav["t_ns"] == 10**18
    np.testing.assert_array_equal(err["phi"], phi0)
    # C_nb_hat = exp(-[phi x]) C_nb exactly, and attitude_error() agrees to first order
    C_hat, C = quat_to_dcm(np.array(nav["q_nb"])), quat_to_dcm(traj.q_nb[0])
    np.testing.assert_allclose(-dcm_to_rotvec(C_hat @ C.T), phi0, atol=1e-12)
    np.testing.assert_allclose(attitude_error(C_hat, C), phi0, atol=1e-7)
    dp = lla_to_ned_offset(*traj.pos[0], *nav["pos"])
    np.testing.assert_allclose(dp, err["pos_ned"], atol=1e-6)
    np.testing.assert_allclose(np.array(nav["v_n"]) - traj.v_n[0], err["v_n"])
    assert nav["sigma"] == {"pos_ned": [1.0, 2.0, 3.0], "v_n": [0.1] * 3, "phi": [0.0] * 3}
