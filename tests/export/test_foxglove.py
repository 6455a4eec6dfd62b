"""The estimates MCAP for Foxglove: a NavSatFix per filter, /tf (map -> <filter>/base_link),
the Odometry topics, decoded by two independent decoders (rosbags' CDR deserialiser and
mcap-ros2-support's), their bytes equal to mcap-ros2-support's encoder's; a plain
(uncompressed) option with the same messages; the Foxglove layout beside it names topics the
file holds."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer
from rosbags.highlevel import AnyReader
from test_export import _as_dict
from whole_runs import export_runs

from navreplay.core.colors import PALETTE, color_index
from navreplay.export.foxglove import NAVSATFIX_SCHEMA, TF_SCHEMA
from navreplay.filters.registry import load_filter
from navreplay.geo import earth
from navreplay.io import read_recording, write_recording
from navreplay.replay import replay
from navreplay.sim.scenario import simulate

FILTERS = ("ins", "gps-ins")
T = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # NED <-> ENU


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    d = tmp_path_factory.mktemp("foxglove")
    write_recording(d / "drive.mcap", simulate("vehicle-drive", {"duration": 20.0}, seed=3))
    rec = read_recording(d / "drive.mcap")
    results = {name: replay(rec, load_filter(name), {}, label=name) for name in FILTERS}
    export_runs(d / "zstd", list(results.values()), rec, source="drive.mcap")
    export_runs(d / "plain", list(results.values()), rec, source="drive.mcap",
                compression="none")
    return d, rec, results


def _rosbags(path) -> dict[str, list]:
    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for conn, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            out.setdefault(conn.topic, []).append((stamp, msg))
    return out


def test_navsatfix_per_filter_decodes_in_rosbags(exported) -> None:
    d, rec, results = exported
    msgs = _rosbags(d / "zstd" / "estimates.mcap")
    assert {"/estimates/ins/fix", "/estimates/gps_ins/fix", "/reference/fix", "/tf"} <= set(msgs)
    r = results["gps-ins"]
    fixes = msgs["/estimates/gps_ins/fix"]
    assert len(fixes) == r.t.shape[0]
    lat = np.array([m.latitude for _, m in fixes])
    lon = np.array([m.longitude for _, m in fixes])
    alt = np.array([m.altitude for _, m in fixes])
    np.testing.assert_allclose(lat, np.degrees(r.nav_pos[:, 0]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(lon, np.degrees(r.nav_pos[:, 1]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(alt, r.nav_pos[:, 2], rtol=0, atol=1e-9)
    stamp, m = fixes[-1]
    assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == stamp
    assert m.header.frame_id == "gps_ins/base_link"
    assert m.position_covariance_type == 3  # known
    cov = np.reshape(m.position_covariance, (3, 3))
    # the ENU covariance at the vehicle: the Odometry pose's position block, in the map frame
    # about the origin a few hundred metres away (the frames differ by ~3e-5 rad)
    odom = [o for s, o in msgs["/estimates/gps_ins/odom"] if s == stamp][0]
    np.testing.assert_allclose(cov, np.reshape(odom.pose.covariance, (6, 6))[:3, :3],
                               rtol=0, atol=1e-4 * cov.max())
    assert np.all(np.linalg.eigvalsh(cov) > 0.0)
    # the truth's fixes: zero covariance, known
    ref = msgs["/reference/fix"]
    assert len(ref) == len(rec["truth"])
    assert ref[0][1].latitude == pytest.approx(math.degrees(rec["truth"]["pos"][0][0]), abs=1e-12)


def test_tf_transforms_equal_the_odometry_poses(exported) -> None:
    d, _, results = exported
    msgs = _rosbags(d / "zstd" / "estimates.mcap")
    per_child: dict[str, list] = {}
    for stamp, m in msgs["/tf"]:
        assert len(m.transforms) == 1
        tf = m.transforms[0]
        assert tf.header.frame_id == "map"
        assert tf.header.stamp.sec * 10**9 + tf.header.stamp.nanosec == stamp
        per_child.setdefault(tf.child_frame_id, []).append(tf)
    assert set(per_child) == {"ins/base_link", "gps_ins/base_link", "reference/base_link"}
    for topic, child in (("/estimates/ins/odom", "ins/base_link"),
                         ("/estimates/gps_ins/odom", "gps_ins/base_link")):
        odom = [o for _, o in msgs[topic]]
        tfs = per_child[child]
        assert len(tfs) == len(odom)
        for o, tf in zip(odom[::50], tfs[::50], strict=True):
            p, q = o.pose.pose.position, o.pose.pose.orientation
            assert (tf.transform.translation.x, tf.transform.translation.y,
                    tf.transform.translation.z) == (p.x, p.y, p.z)
            assert (tf.transform.rotation.x, tf.transform.rotation.y, tf.transform.rotation.z,
                    tf.transform.rotation.w) == (q.x, q.y, q.z, q.w)
    # the transform's translation is the filter's position in ENU about the origin (the
    # reference's first sample): its distance from the origin is that of the ECEF points
    r = results["ins"]
    last = per_child["ins/base_link"][-1].transform.translation
    truth0 = _rosbags_first_reference(msgs)
    dr = earth.lla_to_ecef(*r.nav_pos[-1]) - earth.lla_to_ecef(*truth0)
    assert math.hypot(last.x, last.y, last.z) == pytest.approx(np.linalg.norm(dr), rel=1e-9)


def _rosbags_first_reference(msgs) -> np.ndarray:
    m = msgs["/reference/fix"][0][1]
    return np.array([math.radians(m.latitude), math.radians(m.longitude), m.altitude])


def test_bytes_equal_mcap_ros2_supports_encoder(exported, tmp_path) -> None:
    """The bulk CDR records equal an independent encoder's (mcap-ros2-support) of the same
    messages, for NavSatFix and TFMessage."""
    d, *_ = exported
    path = d / "zstd" / "estimates.mcap"
    ours: dict[str, list[bytes]] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(
                topics=["/estimates/gps_ins/fix", "/tf"]):
            if len(ours.get(channel.topic, [])) < 5:
                ours.setdefault(channel.topic, []).append(message.data)
    msgs = _rosbags(path)
    for topic, kind, schema_text in (("/estimates/gps_ins/fix", "sensor_msgs/msg/NavSatFix",
                                      NAVSATFIX_SCHEMA),
                                     ("/tf", "tf2_msgs/msg/TFMessage", TF_SCHEMA)):
        with open(tmp_path / "g.mcap", "wb") as f:
            w = Ros2Writer(f)
            schema = w.register_msgdef(kind, schema_text)
            for _, m in msgs[topic][:5]:
                w.write_message("/x", schema, _as_dict(m), 0)
            w.finish()
        with open(tmp_path / "g.mcap", "rb") as f:
            generic = [m.data for _, _, m in make_reader(f).iter_messages()]
        assert ours[topic] == generic, topic


def test_plain_option_holds_the_same_messages_uncompressed(exported) -> None:
    d, *_ = exported

    def decoded(path):
        out = []
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            chunks = {c.compression for c in reader.get_summary().chunk_indexes}
            for _, channel, message, ros in reader.iter_decoded_messages():
                out.append((channel.topic, message.log_time, message.data))
                assert ros is not None
        return chunks, out

    plain_chunks, plain = decoded(d / "plain" / "estimates.mcap")
    zstd_chunks, packed = decoded(d / "zstd" / "estimates.mcap")
    assert plain_chunks == {""} and zstd_chunks == {"zstd"}
    assert plain == packed and len(plain) > 1000
    manifest = json.loads((d / "plain" / "manifest.json").read_text())
    assert manifest["odometry"]["compression"] == "none"


def test_foxglove_layout_names_the_files_topics(exported) -> None:
    d, *_ = exported
    layout = json.loads((d / "zstd" / "estimates.foxglove-layout.json").read_text())
    manifest = json.loads((d / "zstd" / "manifest.json").read_text())
    assert manifest["odometry"]["foxglove_layout"] == "estimates.foxglove-layout.json"
    with open(d / "zstd" / "estimates.mcap", "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    panels = layout["configById"]
    assert {k.split("!")[0] for k in panels} == {"3D", "map", "Plot"}
    assert set(panels["3D!estimates"]["topics"]) <= topics
    assert set(panels["map!estimates"]["topicColors"]) == {
        "/estimates/ins/fix", "/estimates/gps_ins/fix", "/reference/fix"}
    color = PALETTE[color_index("gps-ins")]
    assert panels["map!estimates"]["topicColors"]["/estimates/gps_ins/fix"] == \
        "#{:02x}{:02x}{:02x}".format(*color)
    for key in ("Plot!east", "Plot!north"):
        for path in panels[key]["paths"]:
            assert path["value"].split(".")[0] in topics
    assert set(_leaves(layout["layout"])) == set(panels)


def _leaves(node):
    if isinstance(node, str):
        return [node]
    return _leaves(node["first"]) + _leaves(node["second"])


CHECK = Path(__file__).resolve().parent.parent / "foxglove"


@pytest.mark.skipif(shutil.which("node") is None or not (CHECK / "node_modules").is_dir(),
                    reason="Foxglove's npm decoders not installed (cd tests/foxglove && npm ci)")
@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_foxglove_npm_decoders_read_every_message(exported, compression, tmp_path) -> None:
    d, rec, results = exported
    if compression == "lz4":
        export_runs(tmp_path / "lz4", list(results.values()), rec, compression="lz4")
        path = tmp_path / "lz4" / "estimates.mcap"
    else:
        path = d / ("zstd" if compression == "zstd" else "plain") / "estimates.mcap"
    done = subprocess.run(["node", str(CHECK / "check_exports.mjs"), str(path)],
                          capture_output=True, text=True, timeout=120, cwd=CHECK)
    assert done.returncode == 0, done.stderr or done.stdout
    summary = json.loads(done.stdout)
    with open(path, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    assert summary["messages"] == stats.message_count and not summary["problems"]
    assert summary["tf"] == ["map->gps_ins/base_link", "map->ins/base_link",
                             "map->reference/base_link"]
