"""A filter spec is resolved once: its class loaded once (the registry scans the installed
plug-ins once per process), its ``-p`` values parsed once into typed values; the filter's
parameters are built once per recording, in one place."""

from __future__ import annotations

import importlib
import pickle

import pytest
from click.testing import CliRunner

from navreplay.cli import cli
from navreplay.core.params import ParamError
from navreplay.filters import registry
from navreplay.filters.gps_ins import GpsInsFilter
from navreplay.filters.settings import Source, build_params
from navreplay.io import write_recording
from navreplay.replay import FilterSpec
from navreplay.sim.scenario import simulate


def test_values_are_typed_once_and_checked() -> None:
    spec = FilterSpec("gps-ins", {"gps_pos_sigma_scale": "2", "lever_arm_b": "0.1,0,0"})
    assert spec.resolve() is spec and spec.filter_cls is GpsInsFilter
    assert spec.values == {"gps_pos_sigma_scale": 2.0, "lever_arm_b": (0.1, 0.0, 0.0)}
    p = build_params(spec.filter_cls, spec.values).params
    assert p.gps_pos_sigma_scale == 2.0 and p.lever_arm_b == (0.1, 0.0, 0.0)
    with pytest.raises(ParamError, match="unknown parameter.*no_such"):
        FilterSpec("gps-ins", {"no_such": "1"}).resolve()
    with pytest.raises(ParamError, match="gps_pos_sigma_scale"):
        FilterSpec("gps-ins", {"gps_pos_sigma_scale": "-1"}).resolve()
    # pickled to a campaign's workers with its class and values
    again = pickle.loads(pickle.dumps(spec))
    assert again.filter_cls is GpsInsFilter and again.values == spec.values


def test_the_values_keep_their_sources() -> None:
    from navreplay.jobs import filter_specs

    (spec,) = filter_specs("gps-ins[gps_pos_sigma_scale=2]", assignments=["gps_vel_sigma_scale=3"],
                           config={"filter": {"gps-ins": {"cov_step": 0.5}}})
    assert spec.values == {"gps_pos_sigma_scale": 2.0, "gps_vel_sigma_scale": 3.0,
                           "cov_step": 0.5}
    assert spec.values.sources == {"gps_pos_sigma_scale": Source.INLINE,
                                   "gps_vel_sigma_scale": Source.OPTION,
                                   "cov_step": Source.TOML}
    # a parameter instance is used as it is
    p = GpsInsFilter.Params(gps_pos_sigma_scale=3.0)
    assert FilterSpec.of(GpsInsFilter, p).values is p


def test_the_class_is_loaded_once(monkeypatch) -> None:
    calls = []
    real = registry.load_filter
    spec_module = importlib.import_module("navreplay.replay.spec")
    monkeypatch.setattr(spec_module, "load_filter", lambda ref: calls.append(ref) or real(ref))
    spec = FilterSpec("ins")
    for _ in range(3):
        assert spec.filter_cls.name == "ins" and spec.values == {}
    assert calls == ["ins"]


def test_the_registry_scans_the_plug_ins_once(monkeypatch) -> None:
    scans = []
    real = registry._md.entry_points
    monkeypatch.setattr(registry._md, "entry_points",
                        lambda **kw: scans.append(kw) or real(**kw))
    registry.refresh()
    try:
        for name in ("ins", "gps-ins", "ins"):
            registry.load_filter(name)
        assert scans == []  # a built-in name needs no scan (a built-in wins over a plug-in)
        registry.filters()
        with pytest.raises(registry.FilterLoadError, match="unknown filter 'no-such'"):
            registry.load_filter("no-such")
        assert len(scans) == 1
        registry.refresh()
        registry.filters()
        assert len(scans) == 2
    finally:
        registry.refresh()


def test_a_run_builds_each_filters_parameters_once(tmp_path, monkeypatch) -> None:
    """``navreplay run`` with -p: one class lookup per filter (from the command line), one
    parameter instance per filter and recording."""
    path = tmp_path / "drive.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 20.0}, seed=3))
    session = importlib.import_module("navreplay.replay.session")
    config = importlib.import_module("navreplay.jobs.config")
    built, loaded = [], []
    real_build, real_load = session.build_params, config.load_filter
    monkeypatch.setattr(session, "build_params",
                        lambda cls, values, sensors, label: built.append((cls.name, values))
                        or real_build(cls, values, sensors, label=label))
    monkeypatch.setattr(config, "load_filter", lambda ref: loaded.append(ref) or real_load(ref))
    res = CliRunner().invoke(cli, ["run", "ins,gps-ins", str(path), "--no-viz",
                                   "-p", "gps-ins.gps_pos_sigma_scale=2"])
    assert res.exit_code == 0, res.output
    assert loaded == ["ins", "gps-ins"]
    assert built == [("ins", {}), ("gps-ins", {"gps_pos_sigma_scale": 2.0})]
