"""The exports of one run written as its blocks are scored (``--export DIR``):
:class:`RunExport`, a stage of the pipeline."""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.core.streams import Stream
from navreplay.export.columns import (
    Column,
    csv_blocks,
    csv_header,
    innovation_columns,
    innovation_rows,
    no_updates,
    run_columns,
)
from navreplay.export.files import (
    FOXGLOVE_LAYOUT,
    MANIFEST,
    ODOMETRY_FILE,
    REFERENCE_LABEL,
    check_targets,
    file_stem,
    file_stems,
    innovation_file,
    run_targets,
    topic_name,
    write_text,
)
from navreplay.export.foxglove import (
    NAVSATFIX_TYPE,
    TF_TOPIC,
    TF_TYPE,
    Topic,
    body_frame,
    topics_of,
)
from navreplay.export.foxglove import layout as foxglove_layout
from navreplay.export.frames import BODY_FRAME, WORLD_FRAME, LocalFrame, reference_poses, ros_poses
from navreplay.export.odometry import COMPRESSIONS, ODOMETRY_TYPE, OdometryWriter
from navreplay.export.output import FilterOutput
from navreplay.export.tum import TUM_HEADER, tum_blocks
from navreplay.filters.base import MeasurementKind
from navreplay.filters.result import InnovationSeries
from navreplay.io.background import Background


class RunExport:
    """``--export DIR`` of one run, written as the estimates come (see the module docstring
    for the files).

    Feed it the truth window by window (:meth:`add_reference`), each filter's estimates
    block by block (:meth:`add`, blocks of one label in time order) and its updates
    (:meth:`add_innovations`, or with the estimates), then :meth:`close`; or :meth:`abort`.
    Every file goes to a temporary beside its target, renamed when complete, so an interrupted
    run leaves the directory as it was. The files are those of one call with the whole run:
    what is written depends on the rows, not on how they were split into blocks.

    With ``background`` (the default) the blocks are written by a thread of their own
    (:class:`~navreplay.io.background.Background`), in the order they came, while the caller
    goes on: the caller must not change the arrays it hands over. An error met there (a full
    disk) is raised by the next call or by :meth:`close`.

    The first rows are held until the export frame's origin (``origin`` when given, else the
    reference's first sample, else the first filter's first navigation estimate) and which
    filters have a navigation solution are known (usually the first window).

    Parameters
    ----------
    out_dir : Path
    labels : sequence of str
        The filters' labels, in the command's order.
    has_reference : bool
        A truth / reference stream follows.
    source : str
        The recording, for the manifest.
    force : bool
        Overwrite existing files (checked here, before anything is written).
    late : mapping, optional
        Labels whose rows come after every other's, with the label they follow.
    origin : mapping, optional
        The frame's origin the user gave (``metadata.extra[LOCAL_ORIGIN]``: ``pos`` [rad, rad,
        m] and ``source``).
    reference_rate : float, optional
        The reference written at this rate [Hz] (the run's output rate): of each interval
        ``[k, k + 1) / reference_rate`` after ``t0_ns``, its first sample (the truth's own
        samples, none moved or interpolated; on the output grid when the truth's clock is the
        IMU's). None: every sample.
    t0_ns : int
        The recording start [ns]: the origin of the intervals.
    background : bool
        Write in a thread of its own (False: in the caller's, each call returning when its
        rows are written).
    """

    def __init__(self, out_dir: Path, labels: Sequence[str], *, has_reference: bool,
                 source: str = "", force: bool = False,
                 late: Mapping[str, str] | None = None,
                 origin: Mapping[str, Any] | None = None, compression: str = "zstd",
                 reference_rate: float | None = None, t0_ns: int = 0,
                 background: bool = True) -> None:
        self.out_dir = Path(out_dir)
        if compression not in COMPRESSIONS:
            raise ValueError(f"MCAP compression {compression!r}: one of {', '.join(COMPRESSIONS)}")
        self.compression = compression
        """Chunk compression of ``estimates.mcap`` (:data:`COMPRESSIONS`)."""
        self.labels = tuple(labels)
        self.late = dict(late or {})
        """Labels whose rows come after every other's (smoothed runs), each with the label whose
        solution parts it shares: nothing waits for them."""
        self.has_reference = has_reference
        self.reference_rate = reference_rate
        self._t0_ns = int(t0_ns)
        self._ref_interval = -np.inf  # the last interval a reference sample was kept of
        self.source = source
        self.force = force
        check_targets(run_targets(self.out_dir, self.labels, has_reference), force)
        self.file_stems = file_stems(self.labels)
        self._frame: LocalFrame | None = None
        if origin is not None:  # given (Metadata.extra[LOCAL_ORIGIN]): before any sample
            lat, lon, h = (float(x) for x in origin["pos"])
            self._frame = LocalFrame(lat, lon, h, str(origin["source"]))
        self._started = False
        self._held: list[tuple[str, Any]] = []  # ("ref", Stream) / ("out", FilterOutput)
        self._nav: dict[str, bool] = {}  # label -> has a navigation solution (from its rows)
        self._empty: dict[str, FilterOutput] = {}  # a block without rows per label
        self._tmp: dict[Path, tuple[Path, Any]] = {}  # target -> (temporary, open file)
        self._entries: dict[str, dict[str, Any]] = {}
        self._odometry: OdometryWriter | None = None
        self._topics: dict[str, str] = {}  # label (or the reference) -> odometry topic
        self._streams: dict[str, list[Topic]] = {}  # label (or the reference) -> its streams
        # label -> measurement -> its file's manifest entry; the rows and units of its columns
        self._innovations: dict[str, dict[str, dict[str, Any]]] = {}
        self._rows: dict[tuple[str, str], tuple[tuple[str, ...], tuple[str, ...]]] = {}
        self._declared: dict[str, dict[str, MeasurementKind]] = {}
        self._done = False
        self._work = Background("navreplay export") if background else None

    # -- feeding -------------------------------------------------------------------------

    def _call(self, fn: Any, *args: Any) -> None:
        """``fn(*args)`` in the writing thread (or here, without one)."""
        if self._done:
            raise ValueError("the export is already closed")
        if self._work is None:
            fn(*args)
        else:
            self._work.submit(fn, *args)

    def add_reference(self, truth: Stream) -> None:
        """A window of the truth stream (``pos``, ``v_n``, ``q_nb``), later than before."""
        self._call(self._add_reference, truth)

    def _add_reference(self, truth: Stream) -> None:
        if not len(truth):
            return
        if "pos" not in truth.columns:
            # no pose to write (its velocity or attitude scores the CSV's errors): the frame
            # is the first filter's, as without a reference
            self.has_reference = False
            self._feed("ref", None)
            return
        if self.reference_rate is not None:
            truth = self._decimated(truth)
            if not len(truth):
                return
        if self._frame is None:
            p = truth["pos"][0]
            self._frame = LocalFrame(float(p[0]), float(p[1]), float(p[2]),
                                     "first reference sample")
        self._feed("ref", truth)

    def _decimated(self, truth: Stream) -> Stream:
        """The first sample of each interval of ``1 / reference_rate`` (not kept before)."""
        assert self.reference_rate is not None
        k = np.floor((truth.t_ns - self._t0_ns) * (self.reference_rate * 1e-9) + 1e-6)
        first = np.flatnonzero(k > np.r_[self._ref_interval, k[:-1]])
        self._ref_interval = max(self._ref_interval, float(k[-1]))
        if len(first) == len(truth):
            return truth
        return Stream(truth.kind, truth.t_ns[first],
                      {name: v[first] for name, v in truth.columns.items()}, truth.frame_id)

    def add(self, out: FilterOutput) -> None:
        """A block of one filter's estimates (:func:`filter_output` of its rows) and the
        innovations it carries."""
        if out.label not in self.file_stems:
            raise ValueError(f"{out.label!r} is not one of the exported filters")
        self._call(self._add, out)

    def _add(self, out: FilterOutput) -> None:
        self._add_innovations(out.label, out.t0_ns, out.innovations, out.measurements)
        if not len(out.t):
            self._empty.setdefault(out.label, out)
            return
        self._nav.setdefault(out.label, out.has_nav)
        for late, follows in self.late.items():
            if follows == out.label:
                self._nav.setdefault(late, out.has_nav)
        if (self._frame is None and not self.has_reference and out.has_nav
                and self._first_nav() == out.label):
            assert out.nav_pos is not None  # has_nav
            p = out.nav_pos[0]
            self._frame = LocalFrame(float(p[0]), float(p[1]), float(p[2]),
                                     f"first navigation estimate of {out.label}")
        self._feed("out", out)

    def add_innovations(self, label: str, t0_ns: int,
                        innovations: Mapping[str, InnovationSeries],
                        measurements: Sequence[MeasurementKind] = ()) -> None:
        """A block of one filter's updates (later than its updates before), per measurement;
        ``measurements``: the filter's declarations (each gets a file, updates or not)."""
        if label not in self.file_stems:
            raise ValueError(f"{label!r} is not one of the exported filters")
        self._call(self._add_innovations, label, t0_ns, dict(innovations), tuple(measurements))

    def _add_innovations(self, label: str, t0_ns: int,
                         innovations: Mapping[str, InnovationSeries],
                         measurements: Sequence[MeasurementKind]) -> None:
        if label not in self._declared:
            self._declared[label] = {m.name: m for m in measurements}
            self._innovations[label] = {}
            for m in measurements:
                self._innovation_file(label, m.name, m.dim)
        for name, series in innovations.items():
            f = self._innovation_file(label, name, int(series.nu.shape[1]))
            if len(series.t):
                f.writelines(csv_blocks(innovation_columns(t0_ns, series,
                                                           *self._rows[label, name])))

    def _innovation_file(self, label: str, name: str, dim: int) -> Any:
        """The open file of a measurement's innovations (opened with its header at first)."""
        entry = self._innovations[label].get(name)
        if entry is not None:
            return self._file(entry["csv"])
        rows, units = self._rows[label, name] = innovation_rows(
            self._declared[label].get(name), dim)
        taken = {e["csv"] for e in self._innovations[label].values()}
        stem = base = file_stem(name)
        k = 2
        while innovation_file(self.file_stems[label], stem) in taken:
            stem, k = f"{base}_{k}", k + 1
        csv_name = innovation_file(self.file_stems[label], stem)
        check_targets([self.out_dir / csv_name], self.force)  # a name known only now
        cols = innovation_columns(0, no_updates(dim), rows, units)
        self._innovations[label][name] = {"csv": csv_name, "dof": dim,
                                          "columns": [c.to_json() for c in cols]}
        f = self._open(csv_name)
        f.write(csv_header(cols).encode())
        return f

    def _first_nav(self) -> str | None:
        """The first label (in order) whose rows may carry a navigation solution."""
        for label in self.labels:
            if self._nav.get(label, True):
                return label
        return None

    def _held_frame(self) -> LocalFrame | None:
        """At the end, before anything is written: the frame of the first filter (in order)
        with a navigation solution, when the filters before it never had an estimate."""
        firsts = {out.label: out for kind, out in reversed(self._held) if kind == "out"}
        for label in self.labels:
            out = firsts.get(label)
            if out is not None and out.has_nav:
                p = out.nav_pos[0]
                return LocalFrame(float(p[0]), float(p[1]), float(p[2]),
                                  f"first navigation estimate of {label}")
        return None

    def _feed(self, kind: str, item: Any) -> None:
        if item is None and self._started:
            return
        if not self._started:
            if item is not None:
                self._held.append((kind, item))
            # the frame comes from the reference when there is one (else from the first
            # filter with a position): wait for it, whatever the filters output
            if len(self._nav) == len(self.labels) and (
                    self._frame is not None
                    or (self._first_nav() is None and not self.has_reference)):
                self._start()
            return
        self._write(kind, item)

    # -- writing -------------------------------------------------------------------------

    def _open(self, name: str) -> Any:
        from navreplay.io.outputs import temporary_path

        target = self.out_dir / name
        tmp = temporary_path(target)
        # binary: the rows come as ASCII bytes (headers encoded as UTF-8)
        f = open(tmp, "wb")  # noqa: SIM115 (closed on close/abort)
        self._tmp[target] = (tmp, f)
        return f

    def _start(self) -> None:
        """The frame and the filters' solutions are known: open the files, write the rows held."""
        from navreplay.io.outputs import temporary_path

        self._started = True
        topics = []
        for label in self.labels:
            entry: dict[str, Any] = {"csv": f"{self.file_stems[label]}.csv"}
            if self._nav.get(label) and self._frame is not None:
                entry["tum"] = f"{self.file_stems[label]}.tum"
                root = f"/estimates/{topic_name(label)}"
                entry["odometry_topic"] = f"{root}/odom"
                entry["navsatfix_topic"] = f"{root}/fix"
                entry["tf_child_frame_id"] = body_frame(topic_name(label))
                self._open(entry["tum"]).write(TUM_HEADER.encode())
                self._streams[label] = topics_of(topic_name(label), root)
                topics += self._streams[label]
                self._topics[label] = entry["odometry_topic"]
            self._entries[label] = entry
        if self.has_reference and self._frame is not None:
            self._open(f"{REFERENCE_LABEL}.tum").write(TUM_HEADER.encode())
            self._streams[REFERENCE_LABEL] = topics_of(REFERENCE_LABEL, f"/{REFERENCE_LABEL}")
            topics += self._streams[REFERENCE_LABEL]
            self._topics[REFERENCE_LABEL] = "/reference/odom"
        if topics:
            target = self.out_dir / ODOMETRY_FILE
            tmp = temporary_path(target)
            self._odometry = OdometryWriter(
                tmp, topics, late=[t.key for x in self.late for t in self._streams.get(x, [])],
                compression=self.compression)
            self._tmp[target] = (tmp, self._odometry)
        held, self._held = self._held, []
        # estimates first: the reference then goes out piece by piece instead of queueing
        # behind them (the files do not depend on the order of the topics' pieces)
        for kind, item in sorted(held, key=lambda h: h[0] == "ref"):
            self._write(kind, item)

    def _write(self, kind: str, item: Any) -> None:
        frame = self._frame
        if kind == "ref":
            if frame is None:
                return
            for a in range(0, len(item), _POSE_ROWS):  # bounded temporaries
                truth = item.slice(a, min(a + _POSE_ROWS, len(item)))
                poses = reference_poses(frame, truth)
                self._file(f"{REFERENCE_LABEL}.tum").writelines(tum_blocks(poses))
                assert self._odometry is not None  # opened with the first rows
                for stream in self._streams[REFERENCE_LABEL]:
                    self._odometry.add(stream.key, poses)
            return
        out: FilterOutput = item
        entry = self._entries[out.label]
        cols = run_columns(out, frame)
        if "columns" not in entry:
            entry["columns"] = [c.to_json() for c in cols]
            self._open(entry["csv"]).write(csv_header(cols).encode())
        self._file(entry["csv"]).writelines(csv_blocks(cols))
        if "tum" in entry and out.has_nav:
            assert frame is not None and self._odometry is not None  # the first navigation rows
            assert out.nav_pos is not None and out.nav_v_n is not None and out.nav_q_nb is not None
            stamps = out.stamps_ns
            for a in range(0, len(stamps), _POSE_ROWS):  # bounded temporaries
                k = slice(a, a + _POSE_ROWS)
                poses = ros_poses(frame, stamps[k], out.nav_pos[k], out.nav_v_n[k],
                                  out.nav_q_nb[k], None if out.nav_cov is None else out.nav_cov[k])
                self._file(entry["tum"]).writelines(tum_blocks(poses))
                for stream in self._streams[out.label]:
                    self._odometry.add(stream.key, poses)

    def _file(self, name: str) -> Any:
        return self._tmp[self.out_dir / name][1]

    # -- finishing -----------------------------------------------------------------------

    def close(self) -> list[Path]:
        """Write what is held, finish every file and rename it onto its target; returns the
        files written (the manifest last)."""
        from navreplay.io.outputs import fsync_path, release

        if self._done:
            raise ValueError("the export is already closed")
        try:
            if self._work is not None:  # every block written, then the thread stopped
                self._work.drain()
                self._work.close()
            if not self._started:
                if self._frame is None and not self.has_reference:
                    self._frame = self._held_frame()
                self._start()
            for label in self.labels:  # filters without a single estimate: a header
                entry = self._entries[label]
                if "columns" not in entry:
                    empty = self._empty.get(label)
                    cols = run_columns(empty, self._frame) if empty is not None else [
                        Column("stamp", "ns", "absolute estimate time", np.zeros(0, np.int64),
                               "%d"),
                        Column("t", "s", "time since the recording start", np.zeros(0))]
                    entry["columns"] = [c.to_json() for c in cols]
                    self._open(entry["csv"]).write(csv_header(cols).encode())
            if self._odometry is not None:
                self._odometry.finish()
            for _, f in self._tmp.values():
                f.close()
        except BaseException:
            self.abort()
            raise
        self._done = True
        written = []
        order = [self.out_dir / e[k] for e in self._entries.values() for k in ("csv", "tum")
                 if k in e]
        order += [self.out_dir / e["csv"] for files in self._innovations.values()
                  for e in files.values()]
        order += [p for p in self._tmp if p not in order]
        for target in order:
            tmp, _ = self._tmp[target]
            fsync_path(tmp)
            os.replace(tmp, target)
            release(tmp, remove=False)
            written.append(target)
        if self._topics:  # the Foxglove layout of the estimates MCAP
            write_text(self.out_dir / FOXGLOVE_LAYOUT, json.dumps(self._layout(), indent=2) + "\n")
            written.append(self.out_dir / FOXGLOVE_LAYOUT)
        manifest = self._manifest()
        write_text(self.out_dir / MANIFEST, json.dumps(manifest, indent=2) + "\n")
        written.append(self.out_dir / MANIFEST)
        return written

    def _manifest(self) -> dict[str, Any]:
        manifest: dict[str, Any] = {
            "recording": self.source,
            "frames": {
                "map": "local ENU (east, north, up) about the origin, metres (REP-103/105); "
                       "TUM positions and Odometry poses",
                "base_link": "vehicle body FLU (forward, left, up); Odometry twist",
                "nav": "navreplay's NED / FRD: CSV velocities, attitudes and errors",
            },
            "origin": self._frame.to_json() if self._frame is not None else None,
            "filters": {label: {k: e[k] for k in ("csv", "columns", "tum", "odometry_topic",
                                                  "navsatfix_topic", "tf_child_frame_id")
                                if k in e}
                        for label, e in self._entries.items()},
        }
        for label, files in self._innovations.items():
            if files:  # the declared measurements in order, then the others by name
                declared = list(self._declared[label])
                names = declared + sorted(set(files) - set(declared))
                manifest["filters"][label]["innovations"] = {n: files[n] for n in names}
        if REFERENCE_LABEL in self._topics:
            manifest["reference"] = {"tum": f"{REFERENCE_LABEL}.tum",
                                     "odometry_topic": "/reference/odom",
                                     "navsatfix_topic": "/reference/fix",
                                     "tf_child_frame_id": body_frame(REFERENCE_LABEL)}
        if self._topics:
            manifest["odometry"] = {"file": ODOMETRY_FILE, "type": ODOMETRY_TYPE,
                                    "frame_id": WORLD_FRAME, "child_frame_id": BODY_FRAME,
                                    "topics": sorted(self._topics.values()),
                                    "compression": self.compression,
                                    "navsatfix": {"type": NAVSATFIX_TYPE, "topics": sorted(
                                        f"{t[:-len('/odom')]}/fix"
                                        for t in self._topics.values())},
                                    "tf": {"type": TF_TYPE, "topic": TF_TOPIC,
                                           "frame_id": WORLD_FRAME},
                                    "foxglove_layout": FOXGLOVE_LAYOUT}
        return manifest

    def _layout(self) -> dict[str, Any]:
        from navreplay.core.colors import TRUTH_COLOR, LabelColors

        colors = LabelColors()
        sources = [(label, topic[:-len("/odom")],
                    TRUTH_COLOR if label == REFERENCE_LABEL else colors.rgb(label))
                   for label, topic in self._topics.items()]
        return foxglove_layout(ODOMETRY_FILE, sources)

    def abort(self) -> None:
        """Stop without publishing: the temporaries are deleted, the targets untouched."""
        from navreplay.io.outputs import release

        self._done = True
        if self._work is not None:  # the blocks queued dropped, the one in hand finished
            self._work.cancel()
        for tmp, f in self._tmp.values():
            with contextlib.suppress(OSError):
                f.close()
            release(tmp)
        self._tmp.clear()


_POSE_ROWS = 2_000
"""Rows converted to poses and queued at once (a window's 9x9 covariances, their products and
messages are not all held)."""
