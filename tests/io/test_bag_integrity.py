"""rosbag2 folders are checked like MCAP files: the data files against metadata.yaml (counts,
duration) in `info` (DAMAGED, exit 1) and `run` (SALVAGED, coverage below 1); a garbled
metadata.yaml or a missing data file is one line."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pytest
from click.testing import CliRunner
from commands import one_line_error
from rosbag_maker import T0_NS, write_bag

from navreplay.cli import cli
from navreplay.io.rosbag import check_bag

RUN = ("--init", "reference", "--reference", "/ground_truth/odom", "--no-viz")


def invoke(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bags")
    return {"sqlite3": write_bag(root / "sq", storage="sqlite3", duration=20.0),
            "mcap": write_bag(root / "mc", duration=20.0)}


@pytest.fixture
def copy(bags, tmp_path):
    def make(storage: str) -> Path:
        return Path(shutil.copytree(bags[storage], tmp_path / storage))
    return make


def _summary(bag: Path, tmp_path: Path) -> tuple[dict, str]:
    s = tmp_path / "s.json"
    res = invoke("run", "ins", bag, *RUN, "--summary", s, "--force")
    assert res.exit_code == 0, res.output
    return json.loads(s.read_text()), res.output


def test_an_intact_bag_is_intact(bags, tmp_path):
    for bag in bags.values():
        check = check_bag(bag)
        assert check.problems == () and not check.lost
        assert check.found == check.declared == {"/imu/data": 1000, "/gnss/fix": 21,
                                                 "/ground_truth/odom": 201}
        assert check.start_ns == T0_NS and check.declared_duration_s == 20.0
        res = invoke("info", bag)
        assert res.exit_code == 0 and "DAMAGED" not in res.output, res.output
        got, out = _summary(bag, tmp_path)
        assert got["salvaged"] is False and got["coverage"] == 1.0 and "SALVAGED" not in out


def test_a_data_file_that_lost_its_last_quarter(copy, tmp_path):
    """The issue's case: the data file holds 15 s of the 20 s metadata.yaml declares. info
    says DAMAGED with the counts the data hold (50 Hz, not the 66.7 Hz of metadata's count over
    the data's span) and exits 1; run replays it, SALVAGED, coverage 0.75."""
    bag = copy("sqlite3")
    db = sqlite3.connect(bag / "sq.db3")
    db.execute("DELETE FROM messages WHERE timestamp > ?", (T0_NS + 15_000_000_000,))
    db.commit()
    db.close()
    res = invoke("info", bag)
    assert res.exit_code == 1 and res.stderr.strip() == f"Error: {bag}: DAMAGED (see above)"
    assert "topic /imu/data: metadata.yaml counts 1000 messages, the data files hold 750" in \
        res.output
    assert "the data end at 15.000 s of the 20.000 s metadata.yaml declares" in res.output
    imu_row = next(line for line in res.output.splitlines() if line.startswith("/imu/data"))
    assert " 750 " in imu_row and "50.000" in imu_row
    got, out = _summary(bag, tmp_path)
    assert got["salvaged"] is True and got["coverage"] == pytest.approx(0.75, abs=1e-6)
    assert f"SALVAGED: {bag} is damaged; replayed 75.0 % of it" in out


def test_fewer_messages_than_counted_over_the_whole_span(copy, tmp_path):
    """Every other IMU message gone (the span intact): coverage is the fraction of messages
    kept, not 1."""
    bag = copy("sqlite3")
    db = sqlite3.connect(bag / "sq.db3")
    imu = db.execute("SELECT id FROM topics WHERE name = '/imu/data'").fetchone()[0]
    db.execute("DELETE FROM messages WHERE topic_id = ? AND id % 2 = 0", (imu,))
    db.commit()
    db.close()
    check = check_bag(bag)
    assert check.lost and check.found["/imu/data"] == 500
    got, _ = _summary(bag, tmp_path)
    assert got["salvaged"] is True
    assert got["coverage"] == pytest.approx((1222 - 500) / 1222, abs=1e-9)


def test_more_messages_than_counted_is_damage_but_nothing_lost(copy, tmp_path):
    bag = copy("mcap")
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("message_count: 1000", "message_count: 900"))
    res = invoke("info", bag)
    assert res.exit_code == 1 and "metadata.yaml counts 900 messages" in res.output
    got, out = _summary(bag, tmp_path)
    assert got["salvaged"] is False and "disagree with metadata.yaml" in out


@pytest.mark.parametrize("edit, fragment", [
    (lambda t: t.replace("  duration:", "  duration: [[", 1), "not valid YAML at line"),
    (lambda t: "just: a mapping\n", "no rosbag2_bagfile_information"),
    (lambda t: "\x00\x01 garbage: [", "not valid YAML"),
    (lambda t: t.replace("relative_file_paths:\n  - ", "relative_file_paths:\n  - x"),
     "data file xmc.mcap named in metadata.yaml is missing"),
    (lambda t: t.replace("message_count: 1000", "message_count: lots"),
     "lacks its name or count"),
])
def test_a_garbled_metadata_yaml_is_one_line(copy, edit, fragment):
    bag = copy("mcap")
    meta = bag / "metadata.yaml"
    meta.write_text(edit(meta.read_text()))
    for args in (("info", bag), ("run", "ins", bag, *RUN)):
        err = one_line_error(invoke(*args), fragment)
        assert str(bag) in err


def test_sqlite_damage_is_damage(copy, tmp_path):
    """A page of the sqlite file overwritten: sqlite's own check says so (or it cannot be
    opened at all); either way one line, never a silent answer."""
    bag = copy("sqlite3")
    data = bytearray((bag / "sq.db3").read_bytes())
    page = 4096
    data[3 * page: 3 * page + 64] = b"\xff" * 64
    (bag / "sq.db3").write_bytes(bytes(data))
    res = invoke("info", bag)
    assert res.exit_code == 1 and "Traceback" not in res.output
    res = invoke("run", "ins", bag, *RUN, "--summary", tmp_path / "s.json")
    if res.exit_code == 0:
        assert "SALVAGED" in res.output
        assert json.loads((tmp_path / "s.json").read_text())["salvaged"] is True
    else:
        one_line_error(res, str(bag))
