"""Filter settings from the recording's sensor specifications: the derivation of every
built-in filter, the precedence of -p / TOML / inline values, the provenance in the summary and
report, and the note of a run on a recording without specifications."""

from __future__ import annotations

import dataclasses
import json
import math
import pickle

import numpy as np
import pytest
from click.testing import CliRunner

from navreplay import metrics
from navreplay.cli import cli
from navreplay.core.params import ParamError
from navreplay.core.streams import Stream, StreamKind
from navreplay.core.units import DEG_PER_HOUR, DEG_PER_SQRT_HOUR, MICRO_G_PER_SQRT_HZ, MILLI_G
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.ins import InsFilter, imu_settings
from navreplay.filters.registry import filters, load_filter
from navreplay.filters.settings import ParamValues, Source, build_params, field_units
from navreplay.io import write_recording
from navreplay.jobs import filter_specs
from navreplay.replay import FilterSpec, replay
from navreplay.sensors.imu import imu_grade
from navreplay.sensors.specs import SensorSpecs, specs_from_tables
from navreplay.sim.scenario import get_scenario, scenario_inputs, simulate

BUILT_IN = sorted(n for n, c in filters().items() if c.__module__.startswith("navreplay."))
SCENARIO_OF = {"ins": "vehicle-drive", "gps-ins": "vehicle-drive",
               "rpm-aided-ins": "underwater-rpm", "transfer-alignment": "ship-transfer-alignment",
               "vector-matching": "gimpo-accel-sweep"}
"""The scenario each filter's defaults were chosen for (its paper's, or the tactical drive)."""


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-12)
    return a == b


@pytest.mark.parametrize("name", BUILT_IN)
def test_the_defaults_are_the_derivation_of_the_default_sensors(name):
    """Every built-in filter's defaults are what its settings_from_sensors gives for the
    sensors it says they stand for, so a recording of those sensors runs with the defaults."""
    cls = load_filter(name)
    reference = cls.default_sensors()
    assert reference, f"{name} declares no default sensors"
    derived = cls.settings_from_sensors(reference)
    assert derived, name
    defaults = cls.Params()
    for key, value in derived.items():
        default = getattr(defaults, key)
        if default is None:  # taken from the recording's metadata instead
            continue
        assert _same(value, default), (key, value, default)


@pytest.mark.parametrize("name", BUILT_IN)
def test_the_scenarios_of_the_reproductions_give_the_defaults(name):
    """The sensors of each filter's own scenario give its defaults (rpm-aided-ins,
    transfer-alignment and vector-matching keep their published numbers; ins and gps-ins on
    the tactical drive get the tactical derivation); rpm-aided-ins's speed_per_rpm, None by
    default (the recording's), is the scenario's."""
    cls = load_filter(name)
    p, sensors = scenario_inputs(get_scenario(SCENARIO_OF[name]), {})
    defaults = cls.Params()
    for key, value in cls.settings_from_sensors(sensors).items():
        default = getattr(defaults, key)
        if default is None:
            expected = {"speed_per_rpm": getattr(p, "speed_per_rpm", None)}.get(key)
            if key in ("gps_pos_sigma", "gps_vel_sigma"):
                continue  # only for fixes without their own sigma
            assert _same(value, expected), (key, value, expected)
        elif isinstance(default, tuple):
            assert value == default, (key, value, default)
        else:
            assert math.isclose(value, default, rel_tol=1e-15), (key, value, default)


def test_ins_derivation_by_grade():
    """The effective bias sigmas of a level IMU at rest, from the grade's terms."""
    g = 9.80665
    mems = imu_settings(SensorSpecs({"imu": imu_grade("mems")}))
    assert mems["gyro_arw"] == pytest.approx(0.3 * DEG_PER_SQRT_HOUR)
    assert mems["accel_vrw"] == pytest.approx(100 * MICRO_G_PER_SQRT_HZ)
    # 3 mg turn-on, 1 mrad x g, 0.1 mg instability
    assert mems["accel_bias_sigma"] == pytest.approx(
        math.sqrt((3 * MILLI_G) ** 2 + (1e-3 * g) ** 2 + (0.1 * MILLI_G) ** 2), rel=1e-12)
    # z: 1000 ppm x g instead of the misalignment
    assert mems["accel_bias_sigma_z"] == pytest.approx(
        math.sqrt((3 * MILLI_G) ** 2 + (1e-3 * g) ** 2 + (0.1 * MILLI_G) ** 2), rel=1e-12)
    # 10 deg/h turn-on, 10 deg/h/g x g, 3 deg/h instability, earth rate through 1e-3
    expected = math.sqrt(10**2 + 10**2 + 3**2) * DEG_PER_HOUR
    assert mems["gyro_bias_sigma"] == pytest.approx(expected, rel=1e-4)
    assert mems["gyro_bias_rw"] == pytest.approx(3 * DEG_PER_HOUR * math.sqrt(2 / 300))
    consumer = imu_settings(SensorSpecs({"imu": imu_grade("consumer")}))
    assert consumer["gyro_misalignment_sigma"] == pytest.approx(math.radians(0.5))
    assert consumer["gyro_bias_sigma"] > 0.1 * math.pi / 180
    # only the stated fields: an Allan fit without turn-on bias gives the noise only
    allan = specs_from_tables({"imu": {"gyro_arw": "0.2 deg/sqrt(h)",
                                       "gyro_bias_instability": "4 deg/h",
                                       "gyro_bias_tau": "200 s"}})
    assert imu_settings(allan) == pytest.approx({
        "gyro_arw": 0.2 * DEG_PER_SQRT_HOUR,
        "gyro_bias_rw": 4 * DEG_PER_HOUR * math.sqrt(2 / 200)})


def test_precedence_and_sources():
    """inline > -p > [filter] TOML > the sensor specifications > the defaults."""
    config = {"filter": {"gps-ins": {"gyro_arw": 3e-5, "accel_vrw": 5e-4,
                                     "gps_pos_sigma_scale": 2.0}}}
    spec, = filter_specs("gps-ins[accel_vrw=6e-4]", (), ["gyro_arw=4e-5"], config)
    sensors = SensorSpecs({"imu": imu_grade("mems")}, sources={"imu": "grade mems"})
    settings = build_params(load_filter("gps-ins"), spec.params, sensors)
    p, src = settings.params, settings.sources
    assert (p.accel_vrw, src["accel_vrw"]) == (6e-4, Source.INLINE)
    assert (p.gyro_arw, src["gyro_arw"]) == (4e-5, Source.OPTION)
    assert (p.gps_pos_sigma_scale, src["gps_pos_sigma_scale"]) == (2.0, Source.TOML)
    assert (p.gyro_bias_sigma, src["gyro_bias_sigma"]) == (
        imu_settings(sensors)["gyro_bias_sigma"], Source.SPEC)
    assert (p.cov_step, src["cov_step"]) == (0.1, Source.DEFAULT)
    assert settings.sensors == "imu: grade mems" and settings.note == ""
    summary = settings.summary()
    assert summary["gyro_arw"] == {"value": 4e-5, "source": "-p", "unit": "rad/sqrt(s)"}
    assert summary["gyro_bias_sigma"]["source"] == "spec"
    assert set(summary) == {f.name for f in dataclasses.fields(p)}
    # a program's plain values are "given"; a ready Params instance is used as it is
    given = build_params(InsFilter, {"gyro_arw": 1e-5}, sensors)
    assert given.sources["gyro_arw"] is Source.GIVEN
    assert given.sources["accel_vrw"] is Source.SPEC
    ready = build_params(InsFilter, InsFilter.Params(), sensors)
    assert ready.params == InsFilter.Params() and set(ready.sources.values()) == {Source.GIVEN}
    assert field_units(InsFilter.Params)["accel_bias_sigma"] == "m/s^2"


def test_sources_travel_with_the_filter_spec():
    spec, = filter_specs("ins", (), ["gyro_arw=4e-5"], None)
    back = pickle.loads(pickle.dumps(spec))
    assert isinstance(back.params, ParamValues) and back.params.sources == {"gyro_arw": "-p"}
    assert FilterSpec("ins", spec.params).params.sources == {"gyro_arw": Source.OPTION}


def test_a_run_without_specifications_says_so_once():
    rec = simulate("vehicle-drive", {"duration": 20.0}, seed=3)
    rec.metadata.sensors = {}
    settings = replay(rec, GpsInsFilter).settings
    assert set(settings.sources.values()) == {Source.DEFAULT}
    assert settings.note == (
        "gps-ins: no imu specification in the recording ([sensors.imu] of --config gives it): "
        "accel_vrw, gyro_arw, accel_bias_sigma, accel_bias_sigma_z and 7 more keep the "
        "defaults, which are for imu: grade tactical")
    # the same values as a tactical recording's: the defaults are the tactical derivation
    tactical = replay(simulate("vehicle-drive", {"duration": 20.0}, seed=3), GpsInsFilter)
    assert dataclasses.replace(tactical.settings.params, gps_pos_sigma=None,
                               gps_vel_sigma=None) == settings.params
    assert tactical.settings.note == ""


def test_an_ideal_sensor_keeps_positive_noises_at_their_defaults():
    """A zero noise cannot be a measurement noise: the setting keeps its default and the
    note says why; zero process noise and bias sigmas are taken as stated."""
    sensors = specs_from_tables({"speed_log": {"noise": 0.0, "speed_per_rpm": 0.01},
                                 "imu": {"grade": "ideal"}})
    settings = build_params(load_filter("rpm-aided-ins"), None, sensors)
    assert settings.sources["rpm_sigma"] is Source.DEFAULT
    assert "rpm_sigma must be finite and > 0, got 0.0" in settings.note
    assert settings.params.accel_bias_sigma == 0.0
    assert settings.sources["accel_bias_sigma"] is Source.SPEC


def test_gnss_noise_from_the_specification_for_fixes_without_covariance():
    """Fixes without their own sigma take it from the GNSS specification: the run equals the
    one on the same fixes with the sigma in the message, in the compiled batch path and in the
    per-event path alike; without either, one line."""
    rec = simulate("vehicle-drive", {"duration": 40.0, "gps_pos_sigma_h": 2.0}, seed=2)
    full = replay(rec, GpsInsFilter)
    bare = dataclasses.replace(rec, streams=dict(rec.streams))
    for kind, col in ((StreamKind.GPS, "pos_sigma"), (StreamKind.GPS_VEL, "vel_sigma")):
        s = rec[kind]
        bare.streams[kind] = Stream(kind, s.t_ns, {k: v for k, v in s.columns.items()
                                                    if k != col}, s.frame_id)
    got = replay(bare, GpsInsFilter)
    assert got.settings.params.gps_pos_sigma == (2.0, 2.0, 5.0)
    np.testing.assert_array_equal(got.x, full.x)
    np.testing.assert_array_equal(got.nav_pos, full.nav_pos)
    paced = replay(bare, GpsInsFilter, pacing=1e9)  # the per-event path
    np.testing.assert_allclose(paced.nav_pos, full.nav_pos, rtol=0, atol=1e-9)
    bare.metadata.sensors = {}
    with pytest.raises(Exception, match="carry no pos_sigma .* set gps_pos_sigma, or give "
                                        r"\[sensors.gps\]"):
        replay(bare, GpsInsFilter)


def test_summary_report_and_notes_through_the_command_line(tmp_path):
    path = tmp_path / "d.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 20.0, "imu_grade": "mems"},
                                   seed=1))
    cfg = tmp_path / "c.toml"
    cfg.write_text('[filter.ins]\naccel_vrw = 5e-4\n\n'
                   '[sensors.imu]\ngyro_arw = "0.5 deg/sqrt(h)"\n')
    res = CliRunner().invoke(cli, ["run", "ins,gps-ins", str(path), "--no-viz", "--config",
                                   str(cfg), "-p", "gps-ins.gyro_bias_sigma=1e-5", "--summary",
                                   str(tmp_path / "s.json"), "--report", str(tmp_path / "r.html")])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "s.json").read_text())["filters"]
    ins, gps = s["ins"]["settings"], s["gps-ins"]["settings"]
    assert ins["accel_vrw"] == {"value": 5e-4, "source": "toml", "unit": "(m/s)/sqrt(s)"}
    assert ins["gyro_arw"]["value"] == pytest.approx(0.5 * DEG_PER_SQRT_HOUR)
    assert ins["gyro_arw"]["source"] == "spec"
    assert ins["gyro_bias_sigma"]["source"] == "spec"
    assert gps["gyro_bias_sigma"] == {"value": 1e-5, "source": "-p", "unit": "rad/s"}
    assert s["ins"]["settings_sensors"] == "imu: grade mems, with [sensors.imu] of c.toml: gyro_arw"
    assert "settings_note" not in s["ins"]
    html = (tmp_path / "r.html").read_text()
    assert "<details><summary>Settings (" in html and "<td>gyro_bias_sigma</td>" in html
    # a recording without specifications: one note per filter, once
    bare = tmp_path / "bare.mcap"
    rec = simulate("vehicle-drive", {"duration": 20.0}, seed=1)
    rec.metadata.sensors = {}
    write_recording(bare, rec)
    res = CliRunner().invoke(cli, ["run", "ins,gps-ins", str(bare), str(bare), "--no-viz"])
    assert res.exit_code == 0, res.output
    notes = [line for line in res.output.splitlines() if "keep the defaults" in line]
    assert [n.split(":")[0] for n in notes] == ["ins", "gps-ins"], res.output


def test_the_issue_case_has_power():
    """The mismatch the derivation removes: tactical settings on a MEMS recording are far
    over-confident, the derived ones are not (one 150 s run; the ensembles are in
    tests/filters/test_grade_consistency.py)."""
    rec = simulate("vehicle-drive", {"duration": 150.0, "imu_grade": "mems"}, seed=6101)
    derived = metrics.run_metrics(replay(rec, InsFilter, output_rate=1.0), rec)
    tactical = metrics.run_metrics(replay(rec, InsFilter, InsFilter.Params(), output_rate=1.0),
                                   rec)
    assert np.mean(tactical.nees[10:]) > 5 * np.mean(derived.nees[10:])


def test_a_bad_derivation_is_one_line(plugin_module):
    name = plugin_module("bad_settings", """
        from navreplay.filters.ins import InsFilter

        class Bad(InsFilter):
            name = "bad-settings"

            @classmethod
            def settings_from_sensors(cls, sensors):
                return {"no_such_setting": 1.0}
        """)
    cls = load_filter(f"{name}:Bad")
    with pytest.raises(ParamError, match="filter bad-settings: settings_from_sensors gives "
                                         "unknown parameter.s. no_such_setting"):
        build_params(cls, None, SensorSpecs({"imu": imu_grade("mems")}))


def test_a_term_the_specification_states_and_the_filter_does_not_model_is_said_once(tmp_path):
    """A filter declares the error terms it models (``modelled_terms``); a run whose recording
    states another term, not zero, of a sensor whose stream the filter consumes says so once,
    in the summary's ``settings_note`` and at the end of the run."""
    values = {"duration": 20.0, "sensors": {"gps": {"vel_gm_sigma": "0.03 m/s"}}}
    rec = simulate("vehicle-drive", values, seed=1)
    sensors = SensorSpecs.from_metadata(rec.metadata.sensors)
    note = build_params(GpsInsFilter, None, sensors).note
    assert note == ("gps-ins does not model the gps time-correlated (Gauss-Markov) velocity "
                    "error (vel_gm_sigma) that the sensor specifications state")
    assert build_params(GpsInsFilter, {"use_gps_vel": False}, sensors).note == ""  # not used
    assert build_params(InsFilter, None, sensors).note == ""  # ins consumes no GNSS
    clean = SensorSpecs.from_metadata(simulate("vehicle-drive", {"duration": 20.0},
                                               seed=1).metadata.sensors)
    assert build_params(GpsInsFilter, None, clean).note == ""  # its gps terms: white, modelled
    path = tmp_path / "d.mcap"
    write_recording(path, rec)
    res = CliRunner().invoke(cli, ["run", "ins,gps-ins", str(path), str(path), "--no-viz",
                                   "--summary", str(tmp_path / "s.json")])
    assert res.exit_code == 0, res.output
    assert [line for line in res.output.splitlines() if "does not model" in line] == [note]
    s = json.loads((tmp_path / "s.json").read_text())["runs"]
    assert {r["filters"]["gps-ins"]["settings_note"] for r in s} == {note}


def test_the_declaration_is_data_any_filter_can_give(plugin_module):
    """The note comes from the declaration and the records' ``error_terms``, whatever the
    filter: a plug-in consuming the magnetometer that models only its noise hears of the rest;
    one that declares nothing hears nothing."""
    name = plugin_module("mag_terms", """
        from navreplay.filters.ins import InsFilter
        from navreplay.core.streams import StreamKind

        class MagTerms(InsFilter):
            name = "mag-terms"
            optional = (StreamKind.MAG,)

            @classmethod
            def modelled_terms(cls, params):
                return {**super().modelled_terms(params), "mag": {"noise"}}

        class Silent(MagTerms):
            name = "silent"

            @classmethod
            def modelled_terms(cls, params):
                return None
        """)
    sensors = SensorSpecs.from_metadata(simulate("vehicle-drive", {"duration": 10.0},
                                                 seed=1).metadata.sensors)
    note = build_params(load_filter(f"{name}:MagTerms"), None, sensors).note
    assert note == ("mag-terms does not model the mag magnetometer scale factor (scale_factor) "
                    "and the mag magnetometer hard-iron bias (bias) that the sensor "
                    "specifications state")
    assert build_params(load_filter(f"{name}:Silent"), None, sensors).note == ""
