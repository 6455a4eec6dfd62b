"""Sensor specifications as data: [sensors.*] TOML tables in datasheet units, the writer that
produces them, the round trip through a recording's metadata, and the simulator's use of them."""

from __future__ import annotations

import dataclasses
import math
import tomllib

import numpy as np
import pytest
from click.testing import CliRunner

from navreplay.cli import cli
from navreplay.core.params import ParamError
from navreplay.core.units import (
    DEG,
    DEG_PER_HOUR,
    DEG_PER_HOUR_PER_G,
    DEG_PER_SQRT_HOUR,
    MICRO_G_PER_SQRT_HZ,
    MILLI_G,
    PPM,
)
from navreplay.io import read_recording, write_recording
from navreplay.logs.options import LogOptions
from navreplay.logs.prepare import read_log
from navreplay.sensors.gps import GpsModel
from navreplay.sensors.imu import ImuGrade, ImuModel, imu_grade
from navreplay.sensors.specs import (
    SPEC_KINDS,
    SensorSpecs,
    spec_fields,
    spec_table,
    specs_from_tables,
    specs_toml,
)
from navreplay.sim.scenario import get_scenario, scenario_inputs, scenarios, simulate

CONTRACT = {
    "gyro_arw": ("0.15 deg/sqrt(h)", 0.15 * DEG_PER_SQRT_HOUR),
    "accel_vrw": ("60 ug/sqrt(Hz)", 60 * MICRO_G_PER_SQRT_HZ),
    "gyro_bias_instability": ("3 deg/h", 3 * DEG_PER_HOUR),
    "gyro_bias_tau": ("600 s", 600.0),
    "gyro_rrw": ("0.02 deg/h/sqrt(h)", 0.02 * DEG_PER_HOUR / 60.0),
    "accel_rw": ("1e-5 m/s^2/sqrt(s)", 1e-5),
    "accel_bias": ("2 mg", 2 * MILLI_G),
    "gyro_scale_factor": ("300 ppm", 300 * PPM),
    "gyro_misalignment": ("0.5 mrad", 0.5e-3),
    "gyro_g_sensitivity": ("10 deg/h/g", 10 * DEG_PER_HOUR_PER_G),
}
"""The [sensors.imu] key contract: SI field name = "NUMBER UNIT"."""


def test_the_key_contract():
    specs = specs_from_tables({"imu": {k: text for k, (text, _) in CONTRACT.items()}})
    imu = specs.imu
    for name, (_, si) in CONTRACT.items():
        assert getattr(imu, name) == pytest.approx(si, rel=1e-12), name
    # a table without grade states only its keys; the others stay unknown
    assert specs.known_fields("imu") == frozenset(CONTRACT)
    assert not specs.has("imu", "gyro_bias")
    # numbers are SI, and the unit may end the key instead
    numbers = specs_from_tables({"imu": {"gyro_arw": 4.36e-5, "accel_vrw_ug_per_sqrt_hz": 60,
                                         "gyro_bias_instability_deg_per_h": 3}})
    assert numbers.imu.gyro_arw == 4.36e-5
    assert numbers.imu.accel_vrw == pytest.approx(60 * MICRO_G_PER_SQRT_HZ)
    assert numbers.imu.gyro_bias_instability == pytest.approx(3 * DEG_PER_HOUR)


def test_grade_is_the_start_the_keys_override():
    specs = specs_from_tables({"imu": {"grade": "mems", "gyro_arw": "0.15 deg/sqrt(h)"}})
    assert specs.imu == dataclasses.replace(imu_grade("mems"),
                                            gyro_arw=0.15 * DEG_PER_SQRT_HOUR)
    assert specs.known_fields("imu") == frozenset(spec_fields(ImuModel))
    assert specs.source("imu") == "[sensors.imu]: grade mems, with gyro_arw"


def test_per_axis_values():
    specs = specs_from_tables({"gps": {"pos_sigma": ["1.5 m", "1.5 m", "300 cm"],
                                       "vel_sigma": "0.1 m/s", "pos_gm_sigma": 0.5}})
    assert specs.gps.pos_sigma == (1.5, 1.5, 3.0)
    assert specs.gps.vel_sigma == (0.1, 0.1, 0.1)
    assert specs.gps.pos_gm_sigma == (0.5, 0.5, 0.5)
    np.testing.assert_allclose(specs.gps.total_pos_sigma(), np.hypot([1.5, 1.5, 3.0], 0.5))


@pytest.mark.parametrize(
    ("kind", "table", "message"),
    [
        ("imu", {"gyro_arw": "3 deg/h"},
         'cfg.toml: [sensors.imu] gyro_arw: "3 deg/h" is in rad/s, not in rad/s^(1/2) '
         '(gyro_arw is in rad/s^(1/2), e.g. "1 deg/sqrt(h)")'),
        ("imu", {"accel_vrw": "60 ug"}, "[sensors.imu] accel_vrw: \"60 ug\" is in m/s^2, not"),
        ("imu", {"gyro_scale_factor": "0.1 deg"}, "is in rad, not dimensionless"),
        ("imu", {"gyro_awr": "0.1 deg/sqrt(h)"}, "[sensors.imu] gyro_awr: no such key; did you "
                                                  "mean gyro_arw?"),
        ("imu", {"grade": "cheap"}, "[sensors.imu] grade = 'cheap': no such grade (grades: "),
        ("imu", {"gyro_arw": "-0.1 deg/sqrt(h)"}, "[sensors.imu]: ImuModel.gyro_arw must be "
                                                  "finite and >= 0"),
        ("imu", {"gyro_arw_deg_per_sqrt_h": "0.1 deg/sqrt(h)"}, "the key gives the unit"),
        ("imu", {"gyro_arw": "0.1 deg/sqrt(h)", "gyro_arw_deg_per_sqrt_h": 0.1},
         "gyro_arw is given twice"),
        ("imu", {"gyro_arw": [1, 2, 3]}, "expected one value"),
        ("gps", {"pos_sigma": ["1 m", "2 m"]}, "expected one value or three"),
        ("gps", {"pos_sigma": "1 deg"}, "[sensors.gps] pos_sigma: \"1 deg\" is in rad, not in m"),
        ("gyro", {"arw": 1}, "[sensors.gyro]: no such sensor kind"),
    ],
)
def test_mistakes_are_one_line_naming_file_table_and_key(kind, table, message):
    with pytest.raises(ParamError) as e:
        specs_from_tables({kind: table}, where="cfg.toml")
    text = str(e.value)
    assert message in text and "\n" not in text
    assert text.startswith("cfg.toml: ")


@pytest.mark.parametrize("grade", [g for g in ImuGrade if g is not ImuGrade.IDEAL])
def test_the_writer_reads_back(grade):
    """specs_toml writes datasheet units that specs_from_tables reads back (6 digits)."""
    specs = SensorSpecs({"imu": imu_grade(grade),
                         "gps": GpsModel(pos_sigma=(1.0, 1.2, 2.5), vel_gm_sigma=0.02)},
                        sources={"imu": f"grade {grade}"})
    text = specs_toml(specs)
    assert f"# grade {grade}" in text and "[sensors.imu]" in text and "[sensors.gps]" in text
    back = specs_from_tables(tomllib.loads(text)["sensors"])
    for kind in ("imu", "gps"):
        for name in spec_fields(SPEC_KINDS[kind]):
            np.testing.assert_allclose(getattr(back.get(kind), name),
                                       getattr(specs.get(kind), name), rtol=1e-5, atol=0.0,
                                       err_msg=f"{kind}.{name}")
    assert spec_table(imu_grade(grade))["gyro_arw"].endswith(" deg/sqrt(h)")


def test_partial_specs_write_only_what_they_state():
    specs = specs_from_tables({"imu": {"gyro_arw": "0.2 deg/sqrt(h)",
                                       "gyro_bias_instability": "5 deg/h"}})
    table = tomllib.loads(specs_toml(specs))["sensors"]["imu"]
    assert table == {"gyro_arw": "0.2 deg/sqrt(h)", "gyro_bias_instability": "5 deg/h"}
    # written over complete specs, the stated fields win and the rest stays
    over = SensorSpecs({"imu": imu_grade("tactical")},
                       sources={"imu": "grade tactical"}).overridden_by(specs)
    assert over.imu == dataclasses.replace(imu_grade("tactical"), gyro_arw=0.2 * DEG_PER_SQRT_HOUR,
                                           gyro_bias_instability=5 * DEG_PER_HOUR)
    assert over.has("imu", *spec_fields(ImuModel))
    assert over.source("imu") == ("grade tactical, with [sensors.imu]: gyro_arw, "
                                  "gyro_bias_instability")
    # a table over partial specs states its fields and the base's, no more
    more = specs_from_tables({"imu": {"accel_vrw": "80 ug/sqrt(Hz)"}}, base=specs)
    assert more.known_fields("imu") == {"gyro_arw", "gyro_bias_instability", "accel_vrw"}
    assert more.imu.gyro_arw == specs.imu.gyro_arw


@pytest.mark.parametrize("name", sorted(scenarios()))
def test_every_scenario_records_its_sensors(name, tmp_path):
    """A simulated recording carries its sensor specifications (SI) and reading the file gives
    back the very records the scenario simulated."""
    cls = get_scenario(name)
    values = {} if name.startswith("gimpo") else {"duration": 4.0}
    p, sensors = scenario_inputs(cls, values)
    assert sensors.models and set(sensors.models) <= set(SPEC_KINDS)
    rec = simulate(name, values, seed=2)
    path = tmp_path / "r.mcap"
    write_recording(path, rec)
    back = SensorSpecs.from_metadata(read_recording(path).metadata.sensors, str(path))
    assert back.models == sensors.models
    assert back.sources == sensors.sources
    assert all(back.has(k, *spec_fields(SPEC_KINDS[k])) for k in back.models)


def test_a_sensors_table_is_what_the_simulator_draws_from():
    """[sensors.imu] grade = "mems" over vehicle-drive gives the streams of -p imu_grade=mems;
    a field written over the grade changes exactly that field."""
    values = {"duration": 20.0}
    by_param = simulate("vehicle-drive", {**values, "imu_grade": "mems"}, seed=5)
    by_table = simulate("vehicle-drive", {**values, "sensors": {"imu": {"grade": "mems"}}},
                        seed=5)
    for kind, stream in by_param.streams.items():
        for col, arr in stream.columns.items():
            np.testing.assert_array_equal(by_table[kind][col], arr, err_msg=f"{kind}.{col}")
    assert by_table.metadata.sensors["imu"]["gyro_bias"] == imu_grade("mems").gyro_bias
    noisy = simulate("vehicle-drive", {**values, "sensors": {
        "imu": {"grade": "mems", "gyro_arw": "3 deg/sqrt(h)"}, "gps": {"rate": "2 Hz"}}}, seed=5)
    assert noisy.metadata.sensors["imu"]["gyro_arw"] == pytest.approx(3 * DEG_PER_SQRT_HOUR)
    assert len(noisy["gps"]) == 2 * len(by_param["gps"]) - 1
    diff = noisy["imu"]["omega_ib_b"] - by_param["imu"]["omega_ib_b"]
    assert 0.5 < np.std(diff) / (3 * DEG_PER_SQRT_HOUR / math.sqrt(0.01)) < 1.5


def test_scenarios_refuse_sensors_they_do_not_simulate():
    with pytest.raises(ParamError, match=r"scenario vehicle-drive simulates no speed_log .*"
                                         r"remove \[sensors.speed_log\]"):
        simulate("vehicle-drive", {"duration": 4.0, "sensors": {"speed_log": {"noise": 1}}})
    with pytest.raises(ValueError, match="the gps rate .3 Hz. must divide imu_rate"):
        simulate("vehicle-drive", {"duration": 4.0, "sensors": {"gps": {"rate": "3 Hz"}}})


def test_simulate_and_info_through_the_command_line(tmp_path):
    cfg = tmp_path / "imu.toml"
    cfg.write_text('[sensors.imu]\ngrade = "consumer"\naccel_vrw = "120 ug/sqrt(Hz)"\n')
    out = tmp_path / "d.mcap"
    res = CliRunner().invoke(cli, ["simulate", "vehicle-drive", "-o", str(out), "--duration",
                                   "5", "--config", str(cfg), "-p",
                                   "sensors.imu.gyro_arw=0.5 deg/sqrt(h)"])
    assert res.exit_code == 0, res.output
    meta = read_recording(out).metadata.sensors["imu"]
    assert meta["accel_vrw"] == pytest.approx(120 * MICRO_G_PER_SQRT_HZ)
    assert meta["gyro_arw"] == pytest.approx(0.5 * DEG_PER_SQRT_HOUR)
    assert meta["gyro_bias"] == pytest.approx(0.1 * DEG)
    res = CliRunner().invoke(cli, ["info", str(out)])
    assert res.exit_code == 0, res.output
    assert "sensors (datasheet units" in res.output
    assert "gyro_arw                0.5 deg/sqrt(h)" in res.output
    assert "accel_vrw               120 ug/sqrt(Hz)" in res.output
    bad = tmp_path / "bad.toml"
    bad.write_text('[sensors.imu]\ngyro_arw = "0.3 deg/h"\n')
    res = CliRunner().invoke(cli, ["simulate", "vehicle-drive", "-o", str(tmp_path / "x.mcap"),
                                   "--config", str(bad)])
    assert res.exit_code == 1
    assert res.output.strip().splitlines()[-1] == (
        f'Error: {bad}: [sensors.imu] gyro_arw: "0.3 deg/h" is in rad/s, not in rad/s^(1/2) '
        '(gyro_arw is in rad/s^(1/2), e.g. "1 deg/sqrt(h)")')
    res = CliRunner().invoke(cli, ["simulate", "vehicle-drive", "-o", str(tmp_path / "x.mcap"),
                                   "-p", "sensors.imu=3"])
    assert res.exit_code == 1 and "write sensors.KIND.FIELD=VALUE" in res.output


def test_a_config_writes_over_the_recording_specs(tmp_path):
    """run --config [sensors.imu] changes the specs the filters see, field by field."""
    path = tmp_path / "d.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 4.0}, seed=1))
    over = specs_from_tables({"imu": {"gyro_arw": "0.3 deg/sqrt(h)"}}, where="my.toml")
    recording, _ = read_log(path, LogOptions(sensors=over))
    specs = SensorSpecs.from_metadata(recording.metadata.sensors)
    assert specs.imu == dataclasses.replace(imu_grade("tactical"),
                                            gyro_arw=0.3 * DEG_PER_SQRT_HOUR)
    assert specs.source("imu") == "grade tactical, with [sensors.imu] of my.toml: gyro_arw"
    assert specs.gps == GpsModel(pos_sigma=(2.5, 2.5, 5.0))
    # a log without specs takes the table as it is: only the stated fields are known
    bare = read_recording(path)
    bare.metadata.sensors = {}
    bare_path = tmp_path / "bare.mcap"
    write_recording(bare_path, bare)
    specs = SensorSpecs.from_metadata(
        read_log(bare_path, LogOptions(sensors=over))[0].metadata.sensors)
    assert list(specs.models) == ["imu"] and specs.known_fields("imu") == {"gyro_arw"}


def test_malformed_metadata_is_one_line():
    with pytest.raises(ValueError, match=r"f.mcap: metadata sensors.imu: unknown field\(s\) foo"):
        SensorSpecs.from_metadata({"imu": {"foo": 1.0}}, "f.mcap")
    with pytest.raises(ValueError, match="unknown kind 'lidar'"):
        SensorSpecs.from_metadata({"lidar": {}}, "f.mcap")
    with pytest.raises(ValueError, match="ImuModel.gyro_arw must be finite and >= 0"):
        SensorSpecs.from_metadata({"imu": {"gyro_arw": -1.0}}, "f.mcap")
