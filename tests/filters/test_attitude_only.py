"""A filter that outputs only part of the navigation solution (an AHRS: attitude only) declares
it (``Filter.navigation``) and is scored, shown and exported like any other: attitude errors,
attitude RMS and NEES; no position or velocity anywhere."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from navreplay.cli import cli
from navreplay.filters.base import (
    Filter,
    Nav,
    NavError,
    Quantity,
    State,
    navigation_parts,
)
from navreplay.metrics import consistency
from navreplay.viz.naming import display_unit

PLUGINS = '''
import numpy as np

from navreplay.filters.base import (
    Estimate, Filter, Nav, NavError, NavSolution, Quantity, State,
)
from navreplay.geo.rotations import quat_mult, quat_normalize, quat_to_dcm
from navreplay.core.streams import StreamKind

KP = 0.5                    # accelerometer levelling gain [rad/s per unit of misalignment]
LEVEL_SIGMA = 1e-3          # the loop's steady level error, 1-sigma [rad]
HEADING_SIGMA0 = 1e-3       # initial heading, 1-sigma [rad]
HEADING_RATE_SIGMA = 5e-5   # unaided heading drift, 1-sigma [rad/s]


class Complementary(Filter):
    """Mahony-style complementary filter: the gyros integrated, levelled towards the
    accelerometer's up direction (a vehicle at rest); no position, no velocity."""

    name = "complementary"
    requires = (StreamKind.IMU,)
    initial = ("q_nb",)
    navigation = ("q_nb",)
    states = tuple(State(f"phi_{a}", "rad", Quantity.ATTITUDE, NavError(q), nees=True)
                   for a, q in (("N", Nav.PHI_N), ("E", Nav.PHI_E), ("D", Nav.PHI_D)))
    measurements = ()

    def __init__(self, params, context):
        super().__init__(params, context)
        self.q = np.asarray(context.metadata.initial_nav["q_nb"], dtype=float)
        self.t = 0.0

    def propagate(self, t, imu):
        for tk, w, f in zip(t, imu["omega_ib_b"], imu["f_b"], strict=True):
            dt, self.t = tk - self.t, tk
            up_b = quat_to_dcm(self.q).T @ np.array([0.0, 0.0, -1.0])  # estimated, body
            w = w + KP * np.cross(f / np.linalg.norm(f), up_b)
            self.q = quat_normalize(quat_mult(self.q, np.r_[1.0, 0.5 * w * dt]))

    def update(self, kind, t, sample):
        return None

    def estimate(self):
        s_h2 = HEADING_SIGMA0**2 + (HEADING_RATE_SIGMA * self.t) ** 2
        P = np.diag([LEVEL_SIGMA**2, LEVEL_SIGMA**2, s_h2])
        nav = NavSolution(np.full(3, np.nan), np.full(3, np.nan), self.q.copy())
        return Estimate(self.t, np.zeros(3), P, nav)


class UnknownPart(Complementary):
    name = "unknown-part"
    navigation = ("q_nb", "heading")


class PositionStateWithoutPosition(Complementary):
    name = "position-state-without-position"
    states = Complementary.states + (State("dlat", "rad", Quantity.POSITION, NavError(Nav.LAT)),)

    def estimate(self):
        est = super().estimate()
        P = np.eye(4) * 1e-6
        P[:3, :3] = est.P
        return Estimate(est.t, np.zeros(4), P, est.nav)


class NanAttitude(Complementary):
    name = "nan-attitude"

    def estimate(self):
        est = super().estimate()
        q = est.nav.q_nb if est.t < 20.0 else np.full(4, np.nan)
        return Estimate(est.t, est.x, est.P, NavSolution(est.nav.pos, est.nav.v_n, q))
'''

POSITION_KEYS = ("pos_rms_h", "pos_rms_v", "pos_err_final_h", "pos_err_final_dt", "vel_rms")


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """An IMU at rest with its truth."""
    from navreplay.io import write_recording
    from navreplay.sim.scenario import simulate

    path = tmp_path_factory.mktemp("rec") / "still.mcap"
    write_recording(path, simulate("stationary", {"duration": 40.0}, seed=4))
    return path


@pytest.fixture()
def plugins(plugin_module):
    return plugin_module("ahrs_plugins", PLUGINS)


def test_a_plug_in_ahrs_is_scored_and_shown_for_its_attitude_only(plugins, drive, tmp_path):
    from rrd import read_rrd

    rrd, summary, export = tmp_path / "v.rrd", tmp_path / "s.json", tmp_path / "exp"
    res = CliRunner().invoke(cli, ["run", "--filter", f"{plugins}:Complementary", str(drive),
                                   "--save", str(rrd), "--full-rate", "--summary", str(summary),
                                   "--export", str(export)])
    assert res.exit_code == 0, res.output
    s = json.loads(summary.read_text())["filters"]["complementary"]
    # scored: attitude RMS and a 3-dof NEES; position and velocity absent, not NaN
    # levelled by the accelerometer: 0.47 mrad (1.2 mrad without the levelling, the gyros'
    # errors and the earth rate integrated; 220 mrad levelled the wrong way)
    assert 0.0 < s["att_rms_level"] < 1e-3 and 0.0 < s["att_rms_heading"] < 3e-3
    assert s["nees_dof"] == 3 and np.isfinite(s["nees_mean"]) and s["nees_mean"] > 0.0
    assert not set(POSITION_KEYS) & set(s)
    assert "pos_rms_h" not in res.output and "att_rms_level" in res.output

    data = read_rrd(rrd)
    deg = display_unit("rad").scale

    def series(path):
        cols = data[path]
        (key,) = [k for k in cols if k not in ("time", "timestamp")]
        return cols[key]

    # the Attitude tab: the estimate, its error against the truth and the error's 3-sigma
    for name in ("roll", "pitch", "yaw"):
        assert np.isfinite(series(f"/complementary/nav/{name}")).all()
    err = {a: series(f"/complementary/error/phi_{a}") for a in "NED"}
    for a in "NED":
        assert err[a].shape[1] >= 2  # the error and its bounds
    level = np.concatenate([err["N"][:, 0], err["E"][:, 0]]) / deg
    assert np.sqrt(np.mean(level**2)) == pytest.approx(s["att_rms_level"], rel=1e-6)
    assert np.sqrt(np.mean((err["D"][:, 0] / deg) ** 2)) == pytest.approx(
        s["att_rms_heading"], rel=1e-6)
    # nothing of a position or velocity it does not output
    paths = set(data)
    assert not [p for p in paths if p.startswith("/complementary/") and any(
        f"/{k}" in p for k in ("p_N", "p_E", "p_D", "v_N", "v_E", "v_D"))]
    assert not [p for p in paths if p.startswith("/world/complementary")]

    # exports: the attitude columns in the CSV, no pose (TUM) without a position
    header = (export / "complementary.csv").read_text().splitlines()[0]
    assert "roll [deg]" in header and "error_phi_N [deg]" in header and "nees [-]" in header
    assert "lat [deg]" not in header and "v_N [m/s]" not in header
    assert "error_p_N [m]" not in header and "sigma_v_N [m/s]" not in header
    assert not (export / "complementary.tum").exists()
    assert (export / "reference.tum").exists()


def test_vector_matching_is_scored_on_its_attitude_with_a_consistent_nees(tmp_path):
    """An ensemble of a few short runs at rest: attitude RMS per run and for the ensemble, and
    the ensemble's attitude NEES (3 dof) in its chi-square band (false alarm 0.001). The
    filter's covariance declared 4 times too large or too small lands outside it."""
    runner = CliRunner()
    runs = 8
    res = runner.invoke(cli, ["simulate", "gimpo-accel-sweep", "-p", "accel_g=0", "--runs",
                              str(runs), "--seed", "3100", "-o", str(tmp_path / "rest")])
    assert res.exit_code == 0, res.output
    summary = tmp_path / "s.json"
    recs = sorted(str(p) for p in (tmp_path / "rest").glob("*.mcap"))
    res = runner.invoke(cli, ["run", "vector-matching", *recs, "--no-viz",
                              "--summary", str(summary)])
    assert res.exit_code == 0, res.output
    out = json.loads(summary.read_text())
    for run in out["runs"]:
        s = run["filters"]["vector-matching"]
        assert s["nees_dof"] == 3 and s["att_rms_level"] > 0.0 and s["att_rms_heading"] > 0.0
        assert not set(POSITION_KEYS) & set(s)
    ens = out["ensemble"]["vector-matching"]
    assert ens["runs"] == runs and ens["nees_dof"] == 3
    assert ens["att_rms_level"] < np.radians(0.5) and ens["att_rms_heading"] < np.radians(2.0)
    assert consistency.inside(ens["nees_mean"], 3, runs), ens["nees_mean"]
    assert not consistency.inside(4.0 * ens["nees_mean"], 3, runs)
    assert not consistency.inside(0.25 * ens["nees_mean"], 3, runs)


@pytest.mark.parametrize(("cls", "what"), [
    ("UnknownPart", "filter 'unknown-part': navigation names unknown parts ['heading']"),
    ("PositionStateWithoutPosition", "filter 'position-state-without-position': states dlat "
                                     "are errors of parts of the navigation solution it does "
                                     "not declare"),
    ("NanAttitude", "at t = 20.000 s: non-finite attitude estimate"),
])
def test_a_wrong_navigation_declaration_or_output_stops_with_one_line(plugins, drive, cls,
                                                                     what):
    res = CliRunner().invoke(cli, ["run", "--filter", f"{plugins}:{cls}", str(drive),
                                   "--no-viz"])
    assert res.exit_code != 0
    assert "Traceback" not in res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1, res.output
    assert what in errors[0]


def test_navigation_parts_in_order_and_checked():
    def make(parts, states=()):
        return type("F", (Filter,), {"name": "f", "navigation": parts, "states": states,
                                     "propagate": None, "update": None, "estimate": None})

    assert navigation_parts(make(("q_nb", "pos"))) == ("pos", "q_nb")
    assert navigation_parts(Filter) == ("pos", "v_n", "q_nb")  # the default: all three
    for bad in ((), ("q_nb", "q_nb"), ("attitude",)):
        with pytest.raises(ValueError, match="filter 'f': navigation names"):
            navigation_parts(make(bad))
    with pytest.raises(TypeError, match="filter 'f': navigation must be a tuple"):
        navigation_parts(make("q_nb"))
    vel = (State("dv_N", "m/s", Quantity.VELOCITY, NavError(Nav.V_N)),)
    with pytest.raises(ValueError, match="states dv_N are errors of parts"):
        navigation_parts(make(("q_nb",)), vel)
    assert navigation_parts(make(("v_n",)), vel) == ("v_n",)
