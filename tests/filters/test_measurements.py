"""Measurements are declared as data (rows, units) and travel with the result: the engine
refuses an innovation that breaks its declaration with one line, the Rerun view shows the
declared units and row names, and a filter that declares nothing falls back to the naming guess.
"""


import numpy as np
import pytest
from click.testing import CliRunner

from navreplay.cli import cli
from navreplay.filters.base import MeasurementKind, check_measurements
from navreplay.viz import naming

PLUGINS = '''
import numpy as np

from navreplay.filters.base import Innovation, MeasurementKind
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.geo import radii


class AngularFix(GpsInsFilter):
    """gps-ins that also reports its horizontal position innovation as latitude and longitude
    angles (the same update: nu_lat = nu_N / (R_M + h), nu_lon = nu_E / ((R_N + h) cos lat))."""

    name = "angular-fix"
    measurements = GpsInsFilter.measurements + (
        MeasurementKind("gps_pos_angle", ("lat", "lon"), "rad"),)

    def update(self, kind, t, sample):
        out = super().update(kind, t, sample)
        if out and out[0].name == "gps_pos":
            lat, h = self.nav[0], self.nav[2]
            R_M, R_N = radii(lat)
            d = np.array([1.0 / (R_M + h), 1.0 / ((R_N + h) * np.cos(lat))])
            i = out[0]
            out.append(Innovation("gps_pos_angle", i.t, d * i.nu[:2],
                                  d[:, None] * i.S[:2, :2] * d[None, :]))
        return out


class Undeclared(GpsInsFilter):
    name = "undeclared"

    def update(self, kind, t, sample):
        out = super().update(kind, t, sample)
        if out and t >= 20.0:
            out = [Innovation("gps_fix", i.t, i.nu, i.S) for i in out]
        return out


class WrongRows(GpsInsFilter):
    name = "wrong-rows"

    def update(self, kind, t, sample):
        out = super().update(kind, t, sample)
        if out and t >= 20.0:
            out = [Innovation(i.name, i.t, i.nu[:2], i.S[:2, :2]) for i in out]
        return out


class Silent(GpsInsFilter):
    """Declares nothing: its innovations are unchecked and their units guessed."""

    name = "silent"
    measurements = None
'''


@pytest.fixture()
def drive(drive_40s):
    return drive_40s


@pytest.fixture()
def plugins(plugin_module):
    return plugin_module("measurement_plugins", PLUGINS)


def test_declaration_checks():
    m = MeasurementKind("rpm", ("forward", "lateral", "vertical"), "m/s")
    assert m.units == ("m/s",) * 3 and m.dim == 3
    with pytest.raises(ValueError, match="one per row"):
        MeasurementKind("vector", ("g_N", "h_N"), ("m/s^2",))
    with pytest.raises(ValueError, match="each named once"):
        MeasurementKind("gps_pos", ("N", "N"), "m")
    with pytest.raises(TypeError, match="rows must be a tuple"):
        MeasurementKind("depth", "D", "m")
    with pytest.raises(ValueError, match="declared twice: gps_pos"):
        check_measurements((m, MeasurementKind("gps_pos", ("N",), "m"),
                            MeasurementKind("gps_pos", ("E",), "m")))
    assert check_measurements(None) is None


def test_declared_rows_and_units_win_over_the_name():
    declared = MeasurementKind("pos_bearing", ("bearing",), "rad")
    assert naming.innovation_rows("pos_bearing", 1) == [("0", naming.display_unit("m"))]
    (row, unit), = naming.innovation_rows("pos_bearing", 1, declared)
    assert row == "bearing" and unit.label == "deg" and unit.scale == pytest.approx(180 / np.pi)
    # a declaration of another size is not applied to the rows
    assert naming.innovation_rows("pos_bearing", 2, declared)[1][0] == "1"


@pytest.mark.parametrize(("cls", "label", "what"), [
    ("Undeclared", "undeclared", "innovation 'gps_fix' is not a declared measurement (declared: "
                   "gps_pos, gps_vel"),
    ("WrongRows", "wrong-rows", "innovation 'gps_pos' has shape (2,); the filter declares 3 rows"),
])
def test_an_innovation_against_its_declaration_stops_with_one_line(plugins, drive, cls, label,
                                                                  what):
    res = CliRunner().invoke(cli, ["run", "--filter", f"{plugins}:{cls}", str(drive),
                                   "--no-viz"])
    assert res.exit_code != 0
    assert "Traceback" not in res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1, res.output
    line = errors[0]
    assert what in line and f"filter '{label}'" in line
    assert drive.name in line
    t = float(line.split("at t = ")[1].split(" s")[0])
    assert 20.0 <= t <= 21.0


def test_the_rrd_shows_the_declared_unit_and_the_guess_only_without_one(plugins, drive,
                                                                       tmp_path):
    from rrd import read_rrd, scalars

    from navreplay.geo import radii
    from navreplay.io import read_recording

    rrd = tmp_path / "m.rrd"
    res = CliRunner().invoke(cli, ["run", "--filter", f"{plugins}:AngularFix", "--filter",
                                   f"{plugins}:Silent", str(drive), "--save", str(rrd)])
    assert res.exit_code == 0, res.output
    data = read_rrd(rrd)
    # the same update in metres (N) and in the declared radians, shown in degrees; the name
    # alone ("...pos...") would have been guessed as metres and plotted unscaled
    north = scalars(data, "/angular-fix/innovation/gps_pos/0")
    lat = scalars(data, "/angular-fix/innovation/gps_pos_angle/0")
    assert north.shape == lat.shape
    h = read_recording(drive).metadata.initial_nav["pos"]
    R_M, _ = radii(h[0])
    np.testing.assert_allclose(lat[:, 0], np.degrees(north[:, 0] / (R_M + h[2])), rtol=1e-3)
    assert np.abs(lat[:, 0]).max() < 1e-3  # degrees: metres of error are micro-degrees
    # a filter that declares nothing is drawn with the naming guess (gps_pos: metres)
    silent = scalars(data, "/silent/innovation/gps_pos/0")
    np.testing.assert_allclose(silent, north, rtol=1e-9)


def test_the_view_titles_name_declared_rows_and_units():
    from navreplay.filters.base import Quantity, State
    from navreplay.filters.result import InnovationSeries, RunResult
    from navreplay.viz import Save, open_sink

    k = 5
    t = np.arange(k, dtype=float)
    inn = InnovationSeries(t, np.ones((k, 3)), np.tile(np.eye(3), (k, 1, 1)), np.full(k, 3.0))
    decl = (MeasurementKind("rpm", ("forward", "lateral", "vertical"), "m/s"),)
    kw = dict(filter_name="f", recording="r", t0_ns=0, t=t,
              states=(State("b", "-", Quantity.OTHER),), x=np.zeros((k, 1)),
              P=np.ones((k, 1, 1)), innovations={"rpm": inn, "vector_g": inn})
    import tempfile
    with tempfile.TemporaryDirectory() as d, open_sink(Save(f"{d}/v.rrd")) as sink:
        for r in (RunResult(label="declared", measurements=decl, **kw),
                  RunResult(label="guessed", **kw)):
            sink.innovations(r)
            sink.rows(r)
        plots = sink.catalog.plots["innovation"]
    assert plots["nu:rpm:1@declared"].title == "declared: rpm innovation lateral, ±3√S [m/s]"
    # without a declaration: N/E/D by position, the unit guessed from the name ("rpm": m/s)
    assert plots["nu:rpm:1@guessed"].title == "guessed: rpm innovation E, ±3√S [m/s]"
    assert plots["nu:vector_g:2@guessed"].title == "guessed: vector_g innovation D, ±3√S [-]"


@pytest.fixture(scope="module")
def recordings():
    from navreplay.sim.scenario import simulate

    return {
        "drive": simulate("vehicle-drive", {"duration": 30.0}, seed=2),
        "rpm": simulate("underwater-rpm", {"duration": 30.0}, seed=2),
        "gimpo": simulate("gimpo-accel-yaw", {}, seed=0),
        "ship": simulate("ship-transfer-alignment", {"duration": 20.0}, seed=2),
    }


@pytest.mark.parametrize(("name", "rec", "params", "emits"), [
    ("ins", "drive", {}, {}),
    ("gps-ins", "drive", {}, {"gps_pos": ("N", "E", "D"), "gps_vel": ("N", "E", "D")}),
    ("rpm-aided-ins", "rpm", {},
     {"rpm": ("forward", "lateral", "vertical"), "depth": ("D",)}),
    ("vector-matching", "gimpo", {},
     {"vector": ("g_N", "g_E", "g_D", "h_N", "h_E", "h_D")}),
    ("transfer-alignment", "ship", {"match": "vel_quat_partial"},
     {"velocity": ("N", "E"), "quaternion": ("q1", "q3")}),
    ("transfer-alignment", "ship", {"match": "vel_quat_partial", "quat_model": "paper"},
     {"velocity": ("N", "E"), "quaternion": ("q0", "q1", "q3")}),
    ("transfer-alignment", "ship", {"match": "vel_quat_full"},
     {"velocity": ("N", "E"), "quaternion": ("q1", "q2", "q3")}),
    ("transfer-alignment", "ship", {"match": "vel_only"}, {"velocity": ("N", "E")}),
])
def test_built_in_declarations_match_what_they_emit(recordings, name, rec, params, emits):
    from navreplay.filters.registry import load_filter
    from navreplay.replay import replay

    res = replay(recordings[rec], load_filter(name), params, output_rate=1.0)
    assert {m.name: m.rows for m in res.measurements} == emits  # declared exactly these
    assert set(res.innovations) == set(emits)  # and every one of them is used on this run
    for m in res.measurements:
        s = res.innovations[m.name]
        assert s.t.size > 0 and s.nu.shape[1] == m.dim


def test_a_declaration_refused_at_class_definition_stops_with_one_line(drive, plugin_module):
    plugin_module("repeated_rows", """
        from navreplay.filters.base import MeasurementKind
        from navreplay.filters.gps_ins import GpsInsFilter

        class Repeated(GpsInsFilter):
            measurements = (MeasurementKind("gps_pos", ("N", "E", "N"), "m"),)
    """)
    res = CliRunner().invoke(cli, ["run", "--filter", "repeated_rows:Repeated", str(drive),
                                   "--no-viz"])
    assert res.exit_code == 1
    assert "Traceback" not in res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert len(errors) == 1, res.output
    assert "'repeated_rows'" in errors[0] and "each named once" in errors[0]
