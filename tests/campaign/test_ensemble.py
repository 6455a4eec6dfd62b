"""Ensemble runner: order, determinism across worker counts, the executor seam, failures."""

from __future__ import annotations

import concurrent.futures as cf
import time

import numpy as np
import pytest

from navreplay.campaign.ensemble import RunFailedError, run_ensemble
from navreplay.campaign.executors import InlineExecutor
from navreplay.campaign.tasks import file_tasks, monte_carlo_tasks
from navreplay.replay.spec import FilterSpec


def final_velocity_error(recording, results, task):
    """A user extractor: final horizontal velocity error per filter [m/s] (module level, so
    worker processes can unpickle it)."""
    out = {}
    truth = recording["truth"]
    for label, res in results.items():
        out[label] = float(np.linalg.norm(res.nav_v_n[-1, :2] - truth["v_n"][-1, :2]))
    return out


def slow_for_even_seeds(recording, results, task):
    time.sleep(0.2 if task.seed % 2 == 0 else 0.0)
    return task.seed


SPECS = (FilterSpec("gps-ins"),)
VALUES = {"duration": 15.0}


def collect(into):
    return lambda out: into.append(out)


def test_tasks_and_seeds(tmp_path):
    tasks = monte_carlo_tasks("vehicle-drive", 3, values=VALUES, seed=7, keep_dir=tmp_path)
    assert [t.seed for t in tasks] == [7, 8, 9]
    assert [t.index for t in tasks] == [0, 1, 2]
    assert tasks[2].keep == str(tmp_path / "vehicle-drive_0003.mcap")
    assert tasks[0].source.endswith("vehicle-drive_0001.mcap")
    assert monte_carlo_tasks("x", 1)[0].source == "x#seed=0"
    assert [t.path for t in file_tasks(["a.mcap", "b.mcap"])] == ["a.mcap", "b.mcap"]
    with pytest.raises(ValueError, match="runs must be at least 1"):
        monte_carlo_tasks("x", 0)


def test_user_extractor_in_order_and_same_with_two_workers():
    tasks = monte_carlo_tasks("vehicle-drive", 4, values=VALUES, seed=0)
    one, two = [], []
    progress = []
    r1 = run_ensemble(tasks, SPECS, collect(one), extract=final_velocity_error, workers=1,
                      progress=lambda d, n: progress.append((d, n)))
    r2 = run_ensemble(tasks, SPECS, collect(two), extract=final_velocity_error, workers=2)
    assert r1.runs == r2.runs == 4 and not r1.failed
    assert [o.index for o in one] == [o.index for o in two] == [0, 1, 2, 3]
    assert [o.seed for o in two] == [0, 1, 2, 3]
    assert [o.metrics for o in one] == [o.metrics for o in two]  # bit-identical runs
    assert all(o.metrics["gps-ins"] < 1.0 for o in one)
    assert progress == [(1, 4), (2, 4), (3, 4), (4, 4)]


def test_outputs_reach_the_sink_in_task_order_whatever_finishes_first():
    tasks = monte_carlo_tasks("stationary", 4, values={"duration": 1.0}, seed=0)
    seen = []
    with cf.ThreadPoolExecutor(max_workers=4) as ex:  # any concurrent.futures executor plugs in
        run_ensemble(tasks, (FilterSpec("ins"),), lambda o: seen.append(o.metrics),
                     extract=slow_for_even_seeds, executor=ex)
    assert seen == [0, 1, 2, 3]


class CountingExecutor(InlineExecutor):
    """A stand-in for another engine: the seam is ``submit`` + ``shutdown``."""

    def __init__(self):
        self.submitted = 0

    def submit(self, fn, /, *args, **kwargs):
        self.submitted += 1
        return super().submit(fn, *args, **kwargs)


def test_custom_executor_is_used_and_left_running():
    ex = CountingExecutor()
    out = []
    run_ensemble(monte_carlo_tasks("stationary", 3, values={"duration": 1.0}),
                 (FilterSpec("ins"),), collect(out), extract=slow_for_even_seeds, executor=ex)
    assert ex.submitted == 3 and len(out) == 3


def test_failed_run_names_run_seed_and_cause():
    tasks = monte_carlo_tasks("stationary", 2, values={"duration": 1.0}, seed=3)
    with pytest.raises(RunFailedError, match=r"run 1 \(stationary#seed=3\): .*needs "
                                             r"stream\(s\) gps"):
        run_ensemble(tasks, SPECS, collect([]), extract=final_velocity_error)


def test_keep_going_collects_failures(tmp_path):
    good = tmp_path / "good.mcap"
    from navreplay.io import write_recording
    from navreplay.sim.scenario import simulate

    write_recording(good, simulate("vehicle-drive", VALUES, seed=1))
    tasks = file_tasks([good, tmp_path / "missing.mcap", good])
    out = []
    res = run_ensemble(tasks, SPECS, collect(out), extract=final_velocity_error, workers=2,
                       keep_going=True)
    assert res.runs == 2 and [o.index for o in out] == [0, 2]
    assert len(res.failed) == 1 and res.failed[0][0] == 1
    assert "missing.mcap" in res.failed[0][1]


def test_bad_filter_fails_before_any_work():
    with pytest.raises(Exception, match="unknown filter 'nope'"):
        run_ensemble(monte_carlo_tasks("stationary", 100), (FilterSpec("nope"),), collect([]))
    with pytest.raises(Exception, match="gps_pos_sigma_scale"):
        run_ensemble(monte_carlo_tasks("stationary", 100),
                     (FilterSpec("gps-ins", {"gps_pos_sigma_scale": "x"}),), collect([]))
    with pytest.raises(ValueError, match="labels must be unique"):
        run_ensemble(monte_carlo_tasks("stationary", 1), (FilterSpec("ins"), FilterSpec("ins")),
                     collect([]))


def test_kept_recordings_are_written(tmp_path):
    tasks = monte_carlo_tasks("stationary", 2, values={"duration": 1.0}, keep_dir=tmp_path)
    run_ensemble(tasks, (FilterSpec("ins"),), collect([]), extract=slow_for_even_seeds,
                 workers=2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stationary_0001.mcap",
                                                          "stationary_0002.mcap"]


def test_default_extractor_feeds_ensemble_statistics():
    from navreplay import metrics

    stats = metrics.EnsembleStats()
    run_ensemble(monte_carlo_tasks("vehicle-drive", 2, values=VALUES), SPECS,
                 lambda o: stats.add(o.metrics["gps-ins"]), workers=1)
    res = stats.result()
    assert res.runs == 2 and res.t.shape[0] > 100
    assert np.isfinite(res.nees_mean).any()
