"""Golden recordings in recordings/golden/ with their expected summary.

Each golden file was written by ``navreplay simulate`` and its summary by ``navreplay run``
(recordings/golden/README.md lists the commands). The tests check that replaying the filters
over the file reproduces the summary, that re-simulating with the same command gives the same
streams (unintended changes in sim/, sensors/ or io/), and that the file opens with rosbags.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from navreplay import metrics
from navreplay.filters.registry import load_filter
from navreplay.filters.settings import summary_entries
from navreplay.io import TOPICS, read_recording
from navreplay.jobs import scenario_values
from navreplay.replay import replay
from navreplay.sim.scenario import simulate

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "recordings" / "golden"
README = GOLDEN / "README.md"


@dataclasses.dataclass(frozen=True)
class Case:
    name: str
    scenario: str
    seed: int
    params: tuple[str, ...]  # the -p KEY=VALUE items of the simulate command
    filters: tuple[str, ...]
    topics: dict[str, str]  # topic -> message type

    @property
    def mcap(self) -> Path:
        return GOLDEN / f"{self.name}.mcap"

    @property
    def summary(self) -> Path:
        return GOLDEN / f"{self.name}.summary.json"

    @property
    def rel(self) -> str:
        return f"recordings/golden/{self.name}.mcap"

    @property
    def simulate_command(self) -> str:
        ps = "".join(f" -p {p}" for p in self.params)
        return f"navreplay simulate {self.scenario} -o {self.rel} --seed {self.seed}{ps}"

    @property
    def run_command(self) -> str:
        return (f"navreplay run {','.join(self.filters)} {self.rel} --no-viz "
                f"--summary recordings/golden/{self.name}.summary.json")

    def regenerate(self) -> str:
        return (f"if the change is intended, regenerate the golden files with the commands in "
                f"recordings/golden/README.md:\n  {self.simulate_command} --force\n"
                f"  {self.run_command}")


CASES = [
    Case("vehicle-drive", "vehicle-drive", 1, ("duration=60",), ("ins", "gps-ins"), {
        "/imu": "sensor_msgs/msg/Imu",
        "/gps/fix": "sensor_msgs/msg/NavSatFix",
        "/gps/vel": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "/mag": "sensor_msgs/msg/MagneticField",
        "/truth": "navreplay_msgs/msg/Truth",
    }),
    Case("underwater-rpm", "underwater-rpm", 1, ("duration=60",), ("ins", "rpm-aided-ins"), {
        "/imu": "sensor_msgs/msg/Imu",
        "/speed_log": "navreplay_msgs/msg/SpeedLog",
        "/depth": "navreplay_msgs/msg/Depth",
        "/truth": "navreplay_msgs/msg/Truth",
    }),
]
IDS = [c.name for c in CASES]

# Every summary entry comes from deterministic code (no wall-clock timings), so none is
# excluded; a timing-dependent entry added later would belong here, with the reason.
EXCLUDED_SUMMARY_KEYS: frozenset[str] = frozenset()


@pytest.fixture(scope="module", params=CASES, ids=IDS)
def case(request: pytest.FixtureRequest) -> Case:
    c: Case = request.param
    assert c.mcap.is_file(), f"{c.mcap.relative_to(ROOT)} is missing; {c.regenerate()}"
    assert c.summary.is_file(), f"{c.summary.relative_to(ROOT)} is missing; {c.regenerate()}"
    return c


@pytest.fixture(scope="module")
def golden(case: Case) -> Any:
    return read_recording(case.mcap)


def test_files_are_small_and_documented() -> None:
    text = README.read_text()
    total = 0
    for c in CASES:
        size = c.mcap.stat().st_size
        total += size
        assert size < 1_500_000, f"{c.mcap.name} is {size} bytes; keep golden files < 1.5 MB"
        assert c.simulate_command in text, f"README.md lacks `{c.simulate_command}`"
        assert c.run_command in text, f"README.md lacks `{c.run_command}`"
    assert total < 4_000_000, f"golden recordings total {total} bytes; keep them < 4 MB"


def _compare(got: Any, want: Any, where: str, problems: list[str]) -> None:
    if isinstance(want, dict) and isinstance(got, dict):
        for key in sorted(set(want) | set(got)):
            if key in EXCLUDED_SUMMARY_KEYS:
                continue
            if key not in got or key not in want:
                side = "missing from the replay" if key not in got else "not in the golden file"
                problems.append(f"{where}{key}: {side}")
                continue
            _compare(got[key], want[key], f"{where}{key}.", problems)
    elif isinstance(want, (int, float)) and isinstance(got, (int, float)):
        if not (math.isclose(got, want, rel_tol=1e-6, abs_tol=0.0) or (got == want)):
            problems.append(f"{where[:-1]}: replay {got!r}, golden {want!r}")
    elif got != want:
        problems.append(f"{where[:-1]}: replay {got!r}, golden {want!r}")


def test_replay_reproduces_the_summary(case: Case, golden: Any) -> None:
    """The filters over the golden file give the committed summary (rtol 1e-6), with the
    settings each filter derived from the file's sensor specifications."""
    expected = json.loads(case.summary.read_text())
    assert expected["recording"] == case.rel, case.regenerate()
    assert list(expected["filters"]) == list(case.filters), case.regenerate()
    summaries = {}
    for label in case.filters:
        cls = load_filter(label)
        result = replay(golden, cls, None, label=label, source=case.rel, validate=False)
        summaries[label] = {**metrics.run_metrics(result, golden).summary(),
                            **summary_entries(result.settings)}
    problems: list[str] = []
    _compare(summaries, expected["filters"], "", problems)
    assert not problems, (
        f"replaying {', '.join(case.filters)} over {case.rel} no longer gives "
        f"{case.summary.name}:\n  " + "\n  ".join(problems) + "\n" + case.regenerate()
    )


def _metadata(rec: Any) -> dict[str, Any]:
    meta = dataclasses.asdict(rec.metadata)
    meta.pop("navreplay_version")
    return json.loads(json.dumps(meta))  # tuples and lists alike


def test_resimulation_gives_the_golden_streams(case: Case, golden: Any) -> None:
    """The documented command (scenario, -p items, seed) reproduces the file's streams."""
    fresh = simulate(case.scenario, scenario_values(case.params), case.seed)
    hint = (f"re-simulating {case.scenario} (seed {case.seed}, {' '.join(case.params)}) no "
            f"longer gives {case.rel}: sim/, sensors/ or io/ changed; {case.regenerate()}")
    assert sorted(fresh.streams) == sorted(golden.streams), hint
    for kind, want in golden.streams.items():
        got = fresh[kind]
        assert got.frame_id == want.frame_id, f"{kind}: frame_id; {hint}"
        np.testing.assert_array_equal(got.t_ns, want.t_ns, err_msg=f"{kind}.t_ns; {hint}")
        assert sorted(got.columns) == sorted(want.columns), f"{kind}: columns; {hint}"
        for name, col in want.columns.items():
            # atol: 1e-12 of the column's scale, for entries that are zero up to rounding
            scale = float(np.max(np.abs(col))) if col.size else 0.0
            np.testing.assert_allclose(
                got[name], col, rtol=1e-12, atol=1e-12 * scale,
                err_msg=f"{kind}.{name}; {hint}",
            )
    assert _metadata(fresh) == _metadata(golden), f"metadata; {hint}"


def test_opens_with_rosbags(case: Case, golden: Any) -> None:
    """The independent rosbags reader opens the file and lists the expected topics."""
    with AnyReader([case.mcap]) as reader:
        topics = {t: info.msgtype for t, info in reader.topics.items()}
        counts = {t: info.msgcount for t, info in reader.topics.items()}
    assert topics == case.topics, f"{case.rel}: topics {topics}; {case.regenerate()}"
    assert counts == {TOPICS[k]: len(s) for k, s in golden.streams.items()}
