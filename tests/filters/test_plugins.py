"""The example plug-in package (examples/navreplay-example-filter) end to end.

The package is made importable by putting its source directory on sys.path, and discoverable
by writing a minimal ``.dist-info`` with its ``entry_points.txt`` into a temporary directory on
sys.path — what ``pip install`` would leave behind — so the test needs no network and no build.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from navreplay.cli import cli
from navreplay.filters.registry import ENTRY_POINT_GROUP, filters, load_filter, refresh

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "navreplay-example-filter"
CLASS_REF = "navreplay_example_filter.gps_cv:GpsConstantVelocity"


def _entry_points_from_pyproject() -> str:
    import tomllib

    meta = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())
    eps = meta["project"]["entry-points"][ENTRY_POINT_GROUP]
    lines = [f"[{ENTRY_POINT_GROUP}]"] + [f"{k} = {v}" for k, v in eps.items()]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    """Install the example package into sys.path the way pip would (source + dist-info)."""
    site = tmp_path_factory.mktemp("site")
    info = site / "navreplay_example_filter-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: navreplay-example-filter\nVersion: 0.1.0\n"
    )
    (info / "entry_points.txt").write_text(_entry_points_from_pyproject())
    added = [str(EXAMPLE / "src"), str(site)]
    sys.path[:0] = added
    import importlib

    importlib.invalidate_caches()
    refresh()  # the registry scans the entry points once per process: again, with the plug-in
    yield
    for p in added:
        sys.path.remove(p)
    for name in [m for m in sys.modules if m.startswith("navreplay_example_filter")]:
        del sys.modules[name]
    importlib.invalidate_caches()
    refresh()


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    from navreplay.io import write_recording
    from navreplay.sim.scenario import simulate

    path = tmp_path_factory.mktemp("rec") / "drive.mcap"
    write_recording(path, simulate("vehicle-drive", {"duration": 60.0}, seed=3))
    return path


def test_entry_point_is_discovered(plugin):
    table = filters()
    assert "gps-cv" in table
    assert table["gps-cv"] is load_filter(CLASS_REF)


def test_listed_by_the_filters_command(plugin):
    res = CliRunner().invoke(cli, ["filters"])
    assert res.exit_code == 0, res.output
    assert "gps-cv: GNSS-only constant-velocity KF" in res.output
    assert "[plug-in: navreplay_example_filter.gps_cv]" in res.output
    assert "accel_psd" in res.output and "[m^2/s^3]" in res.output


def _check_summary(path: Path, label: str) -> None:
    data = json.loads(path.read_text())
    assert label in data["filters"]
    assert data["filters"][label]  # figures against the truth


def test_run_by_entry_point_name(plugin, drive, tmp_path):
    summary = tmp_path / "s.json"
    rrd = tmp_path / "v.rrd"
    res = CliRunner().invoke(cli, ["run", "gps-cv", str(drive), "--save", str(rrd),
                                   "--summary", str(summary), "-p", "accel_psd=0.2"])
    assert res.exit_code == 0, res.output + res.stderr
    assert "gps-cv" in res.output and f"rerun {rrd}" in res.output
    assert rrd.stat().st_size > 0
    _check_summary(summary, "gps-cv")


def test_run_by_module_class_reference(plugin, drive, tmp_path):
    summary = tmp_path / "s.json"
    res = CliRunner().invoke(cli, ["run", "--filter", CLASS_REF, "gps-ins", str(drive),
                                   "--no-viz", "--summary", str(summary),
                                   "-p", "gps-cv.pos_sigma_scale=1.5"])
    assert res.exit_code == 0, res.output + res.stderr
    data = json.loads(summary.read_text())
    assert set(data["filters"]) == {"gps-ins", "gps-cv"}


def test_module_class_reference_alone(plugin, drive, tmp_path):
    res = CliRunner().invoke(cli, ["run", "--filter", CLASS_REF, str(drive), "--no-viz"])
    assert res.exit_code == 0, res.output + res.stderr


def test_library_replay_tracks_the_truth(plugin):
    from navreplay_example_filter import GpsConstantVelocity

    from navreplay.replay import replay
    from navreplay.sim.scenario import simulate

    rec = simulate("vehicle-drive", {"duration": 120.0}, seed=1)
    res = replay(rec, GpsConstantVelocity, {"accel_psd": "0.5"})
    truth = rec["truth"]
    idx = np.searchsorted(truth.t_ns, rec.t0_ns + np.rint(res.t * 1e9).astype(np.int64))
    idx = np.clip(idx, 0, len(truth) - 1)
    v_err = res.nav_v_n[20:] - truth["v_n"][idx[20:]]
    assert np.sqrt(np.mean(v_err**2)) < 3.0  # m/s, from 2.5 m position fixes only
    assert 0.5 < res.innovations["gps_pos"].nis.mean() / 3.0 < 3.0


def test_monte_carlo_with_the_plugin_in_worker_processes(plugin, tmp_path):
    res = CliRunner().invoke(cli, ["montecarlo", "vehicle-drive", "gps-cv", "--runs", "2",
                                   "--workers", "2", "-p", "scenario.duration=30",
                                   "--no-viz", "--summary", str(tmp_path / "mc.json")])
    assert res.exit_code == 0, res.output + res.stderr
    data = json.loads((tmp_path / "mc.json").read_text())
    assert [r["seed"] for r in data["runs"]] == [0, 1]


def test_a_broken_plugin_does_not_hide_the_others(tmp_path):
    """A plug-in whose module is missing is reported by name; the rest still load."""
    import importlib
    import warnings

    from navreplay.filters.registry import FilterLoadError, FilterPluginWarning

    info = tmp_path / "navreplay_broken_plugin-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: navreplay-broken-plugin\nVersion: 0.1.0\n"
    )
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nbroken-kf = navreplay_no_such_module:Missing\n"
    )
    sys.path.insert(0, str(tmp_path))
    importlib.invalidate_caches()
    refresh()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            table = filters()
        assert "gps-ins" in table and "broken-kf" not in table
        messages = [str(w.message) for w in caught if issubclass(w.category, FilterPluginWarning)]
        assert any("broken-kf" in m and "navreplay_no_such_module" in m for m in messages)
        with pytest.raises(FilterLoadError, match="broken-kf.*failed to load"):
            load_filter("broken-kf")
        assert load_filter("gps-ins").name == "gps-ins"
    finally:
        sys.path.remove(str(tmp_path))
        importlib.invalidate_caches()
        refresh()
