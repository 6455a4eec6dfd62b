"""Campaigns on Dask (dask.distributed): the same outputs, in the same order, as one process;
the CLI's ``--executor`` reaches a running scheduler. Threaded LocalClusters keep it quick."""

from __future__ import annotations

import json

import distributed
import pytest
from click.testing import CliRunner

from navreplay.campaign.dask_executor import DaskExecutor, DaskExecutorError
from navreplay.campaign.ensemble import run_ensemble
from navreplay.campaign.executors import make_executor
from navreplay.campaign.tasks import monte_carlo_tasks
from navreplay.cli import cli
from navreplay.replay.spec import FilterSpec

SPECS = (FilterSpec("gps-ins"),)
VALUES = {"duration": 15.0}


def test_dask_runs_equal_one_process_in_task_order() -> None:
    tasks = monte_carlo_tasks("vehicle-drive", 3, values=VALUES, seed=2)
    one: list = []
    run_ensemble(tasks, SPECS, one.append, workers=1)
    ex = DaskExecutor(None, workers=2, processes=False)
    assert ex.parallelism == 2
    dask: list = []
    done = run_ensemble(tasks, SPECS, dask.append, executor=ex)
    ex.shutdown()
    assert done.runs == 3 and not done.failed
    assert [o.index for o in dask] == [0, 1, 2]
    for a, b in zip(one, dask, strict=True):  # bit-identical runs, whatever ran where
        assert a.metrics["gps-ins"].summary() == b.metrics["gps-ins"].summary()


def test_cli_montecarlo_on_a_scheduler_gives_the_statistics_of_one_worker(tmp_path) -> None:
    runner = CliRunner()
    args = ["montecarlo", "vehicle-drive", "gps-ins", "--runs", "2", "-p",
            "scenario.duration=15", "--no-viz"]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  protocol="tcp://", dashboard_address=None) as cluster:
        address = cluster.scheduler_address.replace("tcp://", "dask://")
        res = runner.invoke(cli, [*args, "--executor", address, "--summary",
                                  str(tmp_path / "dask.json")])
    assert res.exit_code == 0, res.output
    assert f"on {address}" in res.output
    res = runner.invoke(cli, [*args, "--summary", str(tmp_path / "one.json")])
    assert res.exit_code == 0, res.output
    dask = json.loads((tmp_path / "dask.json").read_text())
    one = json.loads((tmp_path / "one.json").read_text())
    assert dask["ensemble"] == one["ensemble"]
    assert [r["filters"] for r in dask["runs"]] == [r["filters"] for r in one["runs"]]


def test_bad_executor_values() -> None:
    res = CliRunner().invoke(cli, ["montecarlo", "vehicle-drive", "gps-ins", "--runs", "1",
                                   "--executor", "ray"])
    assert res.exit_code == 2 and "use process, dask or dask://HOST:PORT" in res.output
    with pytest.raises(ValueError, match="executor must be one of"):
        make_executor(1, "spark")
    with pytest.raises(DaskExecutorError, match="cannot start Dask on dask://127.0.0.1:9"):
        DaskExecutor("dask://127.0.0.1:9", timeout=1.0)
