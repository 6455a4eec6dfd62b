"""What a command imports, checked in fresh interpreters: each module below costs start-up CPU
and resident memory that a command not using it should not pay (benchmarks/bench_realdrive.py
measures both)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent.parent
GOLDEN = ROOT / "recordings" / "golden" / "vehicle-drive.mcap"

NEVER_ON_A_RUN = {
    "scipy.linalg", "scipy.stats", "scipy.signal", "scipy.optimize", "scipy.interpolate",
    "pandas",
    "matplotlib", "dask", "distributed", "optuna", "allantools", "pyulog",
    "navreplay.sim", "navreplay.report", "navreplay.campaign.dask_executor",
    "navreplay.filters.transfer_alignment", "navreplay.filters.vector_matching",
    "navreplay.filters.rpm_aided_ins",
}
"""Never imported by ``navreplay run gps-ins REC`` (with or without the view): scipy's linear
algebra (numba's BLAS check would import it: ``navreplay.core.jit``), the statistics and
plotting libraries, the simulator, the report, the campaign executors and the filters not
run."""
VIEWER = {"rerun", "pyarrow", "navreplay.viz.sink"}
"""Imported only to draw."""


def _modules(args: list[str], cwd: Path) -> set[str]:
    """The modules a fresh interpreter holds after ``navreplay ARGS`` (as ``python -m
    navreplay``), the command having succeeded."""
    code = ("import json, runpy, sys\n"
            "sys.argv = ['navreplay', *json.loads(sys.argv[1])]\n"
            "try:\n"
            "    runpy.run_module('navreplay', run_name='__main__')\n"
            "except SystemExit as e:\n"
            "    assert not e.code, e.code\n"
            "print(json.dumps(sorted(sys.modules)))\n")
    out = subprocess.run([sys.executable, "-c", code, json.dumps(args)], cwd=cwd,
                         capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_the_command_line_starts_without_the_numerical_libraries(tmp_path) -> None:
    mods = _modules(["--help"], tmp_path)
    heavy = {"numpy", "numba", "scipy", "rerun", "mcap", "rosbags", "pandas", "matplotlib"}
    assert "navreplay.cli.runs" in mods  # the commands were built
    assert not mods & heavy


@pytest.mark.parametrize("view", [False, True], ids=["no-viz", "default"])
def test_a_run_imports_only_what_it_uses(tmp_path, view) -> None:
    args = ["run", "gps-ins", str(GOLDEN), *([] if view else ["--no-viz"])]
    mods = _modules(args, tmp_path)
    assert {"navreplay.filters.gps_ins", "numba"} <= mods  # it ran
    assert not mods & NEVER_ON_A_RUN, sorted(mods & NEVER_ON_A_RUN)
    if view:
        assert (tmp_path / "out" / "vehicle-drive.rrd").is_file()
        assert VIEWER <= mods
    else:
        assert not mods & VIEWER, sorted(mods & VIEWER)


def test_a_filter_by_name_imports_its_module_only(tmp_path) -> None:
    """load_filter of a built-in name, and a config file's [filter.NAME] tables checked
    against the filter names, leave the other filters' modules unimported; the whole table
    imports them all."""
    code = ("import json, sys\n"
            "from navreplay.filters import registry\n"
            "from navreplay.filters.builtins import MODULES\n"
            "assert registry.load_filter('ins').name == 'ins'\n"
            "names = registry.names()\n"
            "before = sorted(m for m in MODULES.values() if m in sys.modules)\n"
            "table = registry.filters()\n"
            "print(json.dumps([before, names, sorted(table), "
            "sorted(m for m in MODULES.values() if m in sys.modules)]))\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, check=True)
    before, names, table, after = json.loads(out.stdout.strip().splitlines()[-1])
    assert before == ["navreplay.filters.ins"]
    assert set(table) <= set(names)  # every loadable filter is named without loading
    from navreplay.filters.builtins import MODULES

    assert set(MODULES) <= set(table)  # each built-in module registers the name it is under
    assert after == sorted(MODULES.values())
