"""The command line through click's CliRunner: every command, and bad input giving one specific
line on stderr, a non-zero exit, no traceback and no file under the target name."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from navreplay.cli import cli
from navreplay.io import write_recording
from navreplay.sim.scenario import simulate


def invoke(*args: str):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ok(res) -> None:
    assert res.exit_code == 0, f"exit {res.exit_code}\n{res.output}\n{res.stderr}"


def fails(res, *fragments: str) -> str:
    """Exit status 1, one 'Error: ...' line on stderr naming every fragment, no traceback."""
    assert res.exit_code == 1, f"exit {res.exit_code}\n{res.output}"
    err = res.stderr.strip()
    assert err.startswith("Error: "), err
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in res.output
    for f in fragments:
        assert f in err, (f, err)
    return err


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    d = tmp_path_factory.mktemp("recs")
    drive = simulate("vehicle-drive", {"duration": 40.0}, seed=5)
    write_recording(d / "drive.mcap", drive)
    write_recording(d / "still.mcap", simulate("stationary", {"duration": 10.0}, seed=1))
    drive["gps"]["pos"][7, 1] = float("nan")
    write_recording(d / "nan.mcap", drive, validate=False)
    drive = simulate("vehicle-drive", {"duration": 40.0}, seed=5)
    drive["gps"].t_ns[12] = drive["gps"].t_ns[10]
    write_recording(d / "back.mcap", drive, validate=False)
    return d


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --------------------------------------------------------------------------------------------
# listing and simulating


def test_help_and_module_entry_point():
    res = invoke("--help")
    ok(res)
    for cmd in ("scenarios", "simulate", "info", "filters", "run", "montecarlo", "reproduce",
                "demo"):
        assert cmd in res.output
    out = subprocess.run([sys.executable, "-m", "navreplay", "--version"], capture_output=True,
                         text=True, check=True)
    assert out.stdout.startswith("navreplay, version")


def test_scenarios_lists_the_built_ins():
    res = invoke("scenarios")
    ok(res)
    assert "vehicle-drive" in res.output and "stationary" in res.output
    res = invoke("scenarios", "-v")
    ok(res)
    assert "duration" in res.output and "[s]" in res.output


def test_filters_lists_streams_and_parameters_with_units():
    res = invoke("filters")
    ok(res)
    assert "gps-ins:" in res.output and "ins:" in res.output
    assert "requires: imu, gps" in res.output
    res = invoke("filters", "gps-ins")
    ok(res)
    assert "optional: gps_vel" in res.output and "[m" in res.output


def test_simulate_info_and_no_overwrite(in_tmp):
    res = invoke("simulate", "stationary", "-o", "r/still.mcap", "--duration", "5", "--seed", "3")
    ok(res)
    assert "wrote r/still.mcap" in res.output
    before = (in_tmp / "r/still.mcap").read_bytes()
    fails(invoke("simulate", "stationary", "-o", "r/still.mcap", "--duration", "5"),
          "r/still.mcap exists", "--force")
    assert (in_tmp / "r/still.mcap").read_bytes() == before
    ok(invoke("simulate", "stationary", "-o", "r/still.mcap", "--duration", "5", "--seed", "3",
              "--force"))
    assert (in_tmp / "r/still.mcap").read_bytes() == before  # same inputs, same bytes
    res = invoke("info", "r/still.mcap")
    ok(res)
    assert "stationary" in res.output and "/imu" in res.output


def test_simulate_runs_with_suffixes_or_into_a_directory(in_tmp):
    ok(invoke("simulate", "stationary", "-o", "mc.mcap", "--runs", "2", "--duration", "2"))
    assert sorted(p.name for p in in_tmp.glob("mc_*.mcap")) == ["mc_0001.mcap", "mc_0002.mcap"]
    ok(invoke("simulate", "stationary", "-o", "set/", "--runs", "2", "--duration", "2",
              "--seed", "10"))
    assert sorted(p.name for p in (in_tmp / "set").iterdir()) == [
        "stationary_0001.mcap", "stationary_0002.mcap"]


def test_simulate_with_toml_config(in_tmp):
    (in_tmp / "c.toml").write_text("[scenario]\nduration = 3.0\nlat_deg = 10.0\n")
    ok(invoke("simulate", "stationary", "-o", "c.mcap", "--config", "c.toml"))
    res = invoke("info", "c.mcap")
    assert "3.0" in res.output
    fails(invoke("simulate", "stationary", "-o", "d.mcap", "--config", "nope.toml"),
          "nope.toml: no such config file")


def test_simulate_bad_input(in_tmp):
    fails(invoke("simulate", "nowhere", "-o", "x.mcap"), "unknown scenario 'nowhere'",
          "vehicle-drive")
    fails(invoke("simulate", "stationary", "-o", "x.mcap", "-p", "duration=long"),
          "duration", "'long' is not a number")
    fails(invoke("simulate", "stationary", "-o", "x.mcap", "-p", "speed=1"),
          "unknown parameter(s) speed", "valid:")
    fails(invoke("simulate", "stationary", "-o", "x.mcap", "-p", "oops"),
          "'oops' is not of the form key=value")
    assert not (in_tmp / "x.mcap").exists()


# --------------------------------------------------------------------------------------------
# run


def test_run_two_filters_saves_rrd_and_summary(recs, in_tmp):
    res = invoke("run", "ins,gps-ins", recs / "drive.mcap", "--save", "v/drive.rrd",
                 "--summary", "s.json", "-p", "gps-ins.gps_pos_sigma_scale=1.5")
    ok(res)
    assert "pos_rms_h" in res.output and "gps-ins NIS gps_pos" in res.output
    assert "rerun v/drive.rrd" in res.output
    data = json.loads((in_tmp / "s.json").read_text())
    assert set(data["filters"]) == {"ins", "gps-ins"}
    assert data["filters"]["gps-ins"]["pos_rms_h"] < data["filters"]["ins"]["pos_rms_h"]
    import rerun as rr

    paths = {c.entity_path for c in rr.chunk.RrdReader(in_tmp / "v/drive.rrd").stream()
             .collect().stream().to_chunks()}
    assert any(p.startswith("/gps-ins/") for p in paths)
    assert any(p.startswith("/ins/") for p in paths)
    assert any(p.startswith("/truth/") for p in paths)


def test_run_default_rrd_under_out(recs, in_tmp):
    res = invoke("run", "gps-ins", recs / "drive.mcap")
    ok(res)
    assert (in_tmp / "out" / "drive.rrd").is_file()
    assert "rerun out/drive.rrd" in res.output


def test_paced_replay_logs_live_and_keeps_real_time_ratio(recs, in_tmp):
    import time

    t = time.perf_counter()
    res = invoke("run", "gps-ins", recs / "drive.mcap", "--rate", "100", "--save", "p.rrd")
    ok(res)
    assert time.perf_counter() - t > 0.35  # 40 s of data at 100x real time
    assert (in_tmp / "p.rrd").stat().st_size > 0
    fails(invoke("run", "gps-ins", recs / "drive.mcap", "--rate", "0"), "--rate must be positive")


def test_run_variants_of_one_filter(recs, in_tmp):
    res = invoke("run", "gps-ins[gps_pos_sigma_scale=1],gps-ins[gps_pos_sigma_scale=4]",
                 recs / "drive.mcap", "--no-viz", "--summary", "s.json")
    ok(res)
    data = json.loads((in_tmp / "s.json").read_text())
    assert set(data["filters"]) == {"gps-ins[gps_pos_sigma_scale=1]",
                                    "gps-ins[gps_pos_sigma_scale=4]"}
    a, b = data["filters"].values()
    assert a["nis_mean_gps_pos"] > b["nis_mean_gps_pos"]


@pytest.mark.parametrize("command", ["run", "montecarlo"])
def test_help_shows_the_variant_syntax_with_an_example_that_parses(command):
    """--help states the variant grammar (',' between pairs, not ';') and its example is a
    filter list the commands accept: two labelled variants, the vector read whole; ';'
    between pairs is one line showing the comma form."""
    import re

    from navreplay.jobs import filter_specs

    res = invoke(command, "--help")
    ok(res)
    text = " ".join(res.output.split())
    assert "Pairs are separated by ',' (not ';')" in text
    after = res.output.split("(not ';')")[1]
    example = re.search(rf"navreplay {command} .*'([^']+\[[^']+\])'", after).group(1)
    plain, variant = (spec.resolve() for spec in filter_specs(example))
    assert plain.label == "gps-ins" and variant.label == example.split(",", 1)[1]
    assert variant.values["use_gps_vel"] is False and len(variant.values["lever_arm_b"]) == 3
    assert "use_gps_vel" not in plain.values
    err = fails(invoke(command, *(["vehicle-drive"] if command == "montecarlo" else []),
                       "gps-ins[use_gps_vel=false;gps_pos_sigma_scale=2]",
                       *(["--runs", "1"] if command == "montecarlo" else ["r.mcap"])))
    assert err == ("Error: filter 'gps-ins[use_gps_vel=false;gps_pos_sigma_scale=2]': separate "
                   "KEY=VALUE pairs with ',' (not ';'): "
                   "'gps-ins[use_gps_vel=false,gps_pos_sigma_scale=2]'")


@pytest.mark.parametrize("scenario, duration, name", [
    ("gimpo-accel-sweep", 10.0, "vector-matching"),
    ("ship-transfer-alignment", 5.0, "transfer-alignment"),
    ("underwater-rpm", 10.0, "rpm-aided-ins"),
])
def test_each_built_in_filter_runs_on_its_scenario_from_the_command_line(
        in_tmp, scenario, duration, name):
    """The run asks a recording only for the parts of the initial solution the filter declares
    (``Filter.initial``): vector matching starts from TRIAD and needs only the site, transfer
    alignment starts from the master INS and needs nothing."""
    ok(invoke("simulate", scenario, "-o", "r.mcap", "--duration", str(duration)))
    ok(invoke("run", name, "r.mcap", "--no-viz", "--summary", "s.json"))
    summary = json.loads((in_tmp / "s.json").read_text())["filters"][name]
    assert any(k.startswith("nis_mean_") for k in summary)


def test_initial_parts_are_declared_data():
    from navreplay.filters import registry
    from navreplay.filters.base import initial_parts

    get = registry.load_filter
    assert initial_parts([get("vector-matching")]) == ("pos",)
    assert initial_parts([get("transfer-alignment")]) == ()
    assert initial_parts([get("transfer-alignment"), get("gps-ins")]) == ("pos", "v_n", "q_nb")

    class Odd(get("ins")):
        name = "odd"
        initial = ("pos", "heading")

    with pytest.raises(ValueError, match="'odd'.*heading"):
        initial_parts([Odd])


def test_run_filter_params_from_toml(recs, in_tmp):
    (in_tmp / "f.toml").write_text('[filter.gps-ins]\ngps_pos_sigma_scale = "x"\n')
    fails(invoke("run", "gps-ins", recs / "drive.mcap", "--config", "f.toml", "--no-viz"),
          "gps_pos_sigma_scale", "'x' is not a number")


def test_run_over_several_recordings_gives_ensemble_statistics(recs, in_tmp):
    ok(invoke("simulate", "vehicle-drive", "-o", "set/", "--runs", "2", "--duration", "20"))
    files = sorted(str(p) for p in (in_tmp / "set").iterdir())
    res = invoke("run", "gps-ins", *files, "--workers", "2", "--summary", "e.json",
                 "--save", "e.rrd")
    ok(res)
    assert "Per recording:" in res.output and "Ensemble over 2 runs" in res.output
    data = json.loads((in_tmp / "e.json").read_text())
    assert [r["recording"] for r in data["runs"]] == files
    assert data["ensemble"]["gps-ins"]["runs"] == 2
    assert (in_tmp / "e.rrd").is_file()


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["gps-ins", "still.mcap"],
         ["filter 'gps-ins' needs stream(s) gps", "still.mcap", "it has: imu, truth"]),
        (["nofilter", "drive.mcap"], ["unknown filter 'nofilter'", "available:", "gps-ins"]),
        (["gps-ins", "drive.mcap", "-p", "gps_pos_sigma_scale=abc"],
         ["gps_pos_sigma_scale", "'abc' is not a number"]),
        (["gps-ins", "drive.mcap", "-p", "gps_pos_sigma_scale=-1"], ["gps_pos_sigma_scale"]),
        (["ins,gps-ins", "drive.mcap", "-p", "nope=1"],
         ["none of the filters ins, gps-ins has a parameter 'nope'"]),
        (["gps-ins", "nan.mcap"], ["nan.mcap", "/gps/fix", "non-finite", "t = 7.0"]),
        (["gps-ins", "back.mcap"], ["back.mcap", "/gps/fix", "timestamp", "t = 10.0"]),
        (["gps-ins", "missing.mcap"], ["missing.mcap: no such recording"]),
        (["--filter", "no.such.module:Cls", "drive.mcap"], ["cannot import filter module"]),
    ],
)
def test_run_bad_input(recs, in_tmp, args, fragments):
    args = [str(recs / a) if a.endswith(".mcap") and a != "missing.mcap" else a for a in args]
    fails(invoke("run", *args, "--save", "t.rrd", "--summary", "t.json"), *fragments)
    assert not (in_tmp / "t.rrd").exists() and not (in_tmp / "t.json").exists()
    assert not (in_tmp / "out").exists()
    assert not list(in_tmp.glob(".t.rrd*"))


def test_run_unreachable_viewer(recs, in_tmp):
    port = closed_port()
    fails(invoke("run", "gps-ins", recs / "drive.mcap", "--connect",
                 f"rerun+http://127.0.0.1:{port}/proxy", "--summary", "t.json"),
          f"no Rerun viewer reachable at rerun+http://127.0.0.1:{port}/proxy")
    assert not (in_tmp / "t.json").exists() and not (in_tmp / "out").exists()


def test_truncated_recording_is_salvaged_with_a_one_line_warning(recs, in_tmp):
    data = (recs / "drive.mcap").read_bytes()
    (in_tmp / "cut.mcap").write_bytes(data[: int(len(data) * 0.7)])
    res = invoke("run", "gps-ins", "cut.mcap", "--no-viz")
    ok(res)
    warning = [line for line in res.stderr.splitlines() if line.startswith("warning: ")]
    assert len(warning) == 1 and "cut.mcap" in warning[0] and "salvaged" in warning[0]
    assert "gps-ins" in res.output


def test_viewer_options_exclude_each_other(recs):
    res = invoke("run", "gps-ins", recs / "drive.mcap", "--spawn", "--no-viz")
    assert res.exit_code == 2 and "--spawn and --no-viz exclude each other" in res.stderr


def test_debug_shows_the_traceback(recs):
    res = CliRunner().invoke(cli, ["--debug", "run", "nofilter", str(recs / "drive.mcap")])
    assert res.exit_code == 1 and res.exception is not None
    assert "unknown filter" in str(res.exception)


# --------------------------------------------------------------------------------------------
# montecarlo, reproduce, demo


def test_montecarlo_keeps_recordings_and_reports_ensemble(in_tmp):
    res = invoke("montecarlo", "vehicle-drive", "ins,gps-ins", "--runs", "2", "--seed", "4",
                 "-p", "scenario.duration=20", "--keep", "kept", "--save", "mc.rrd",
                 "--summary", "mc.json")
    ok(res)
    assert "Ensemble over 2 runs" in res.output and "ins NEES" in res.output
    kept = sorted(p.name for p in (in_tmp / "kept").iterdir())
    assert kept == ["vehicle-drive_0001.mcap", "vehicle-drive_0002.mcap"]
    data = json.loads((in_tmp / "mc.json").read_text())
    assert [r["seed"] for r in data["runs"]] == [4, 5]
    # run i is `simulate --seed 4+i`: the kept file equals a fresh simulation
    ok(invoke("simulate", "vehicle-drive", "-o", "again.mcap", "--seed", "5", "--duration", "20"))
    assert (in_tmp / "again.mcap").read_bytes() == (in_tmp / "kept" / kept[1]).read_bytes()
    import rerun as rr

    paths = {c.entity_path for c in rr.chunk.RrdReader(in_tmp / "mc.rrd").stream()
             .collect().stream().to_chunks()}
    assert any(p.startswith("/ensemble/") for p in paths)


def test_montecarlo_bad_input(in_tmp):
    fails(invoke("montecarlo", "stationary", "gps-ins", "--runs", "2"),
          "filter 'gps-ins' needs stream(s) gps", "scenario stationary")
    fails(invoke("montecarlo", "vehicle-drive", "gps-ins", "--runs", "2", "-p",
                 "scenario.duration=-5"), "duration")
    assert not (in_tmp / "out").exists()


def test_reproduce_lists_and_rejects_unknown_names():
    res = invoke("reproduce")
    ok(res)
    assert "transfer-alignment" in res.output
    fails(invoke("reproduce", "nope"), "unknown reproduction 'nope'")


# --------------------------------------------------------------------------------------------
# the README


README = Path(__file__).resolve().parents[2] / "README.md"


def test_readme_opens_with_the_two_make_commands():
    head = README.read_text().split("## Quick start")[0]
    assert "make demo" in head and "make test" in head


def test_readme_python_example_runs(in_tmp):
    import re

    code = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)[0]
    exec(compile(code, "README.md", "exec"), {})
    assert (in_tmp / "recordings" / "drive.mcap").is_file()


def test_readme_commands_exist_and_their_options_parse():
    import re
    import shlex

    for line in README.read_text().splitlines():
        m = re.match(r"\s+navreplay (\w+) ", line)
        if m is None or "[" in line or "..." in line:
            continue
        command = re.split(r"\s{2,}", line.split("#")[0].strip())[0]  # drop descriptions
        args = shlex.split(command)[1:]
        cmd = cli.commands[args[0]]
        ctx = cmd.make_context(args[0], args[1:], resilient_parsing=False)
        assert ctx.params is not None, line


def test_warm_up_covers_every_built_in_filter_and_rejects_others():
    """`navreplay warm-up` has a recording for each built-in filter, and an unknown name is
    one line and exit 1 (nothing compiled)."""
    from navreplay.cli import cli
    from navreplay.filters.registry import filters
    from navreplay.jobs import warmup

    builtin = {n for n, c in filters().items() if c.__module__.startswith("navreplay.")}
    assert set(warmup.PLAN) == builtin
    res = CliRunner().invoke(cli, ["warm-up", "no-such-filter"])
    assert res.exit_code == 1
    assert "no warm-up for no-such-filter" in res.output
