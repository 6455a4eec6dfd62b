"""The GNSS/INS text format of KF-GINS and its datasets: an IMU file of increments and a GNSS
position file, as columns of numbers separated by spaces (or commas).

``IMU`` file (a ``.txt`` file with ``imu`` in its name), 7 columns, one row per IMU sample:
time [s, GPS seconds of week, the end of the interval], gyro increments x, y, z [rad] and
velocity increments x, y, z [m/s] over the interval since the previous row, in the body's
front-right-down axes. navreplay's IMU stream is the mean rate and specific force over the
preceding interval: the increments divided by the interval (the first row by the second's).

``GNSS`` file (``gnss`` or ``gps`` in its name), 7 columns: time [s of week], latitude,
longitude [deg], ellipsoidal height [m], and the 1-sigma of north, east, up [m]; further
columns are ignored.

A reference (``truth`` in its name or a ``.nav`` file), 11 columns: GPS week, time [s of
week], latitude, longitude [deg], height [m], velocity north, east, down [m/s], roll, pitch,
yaw [deg]; ``info`` lists it and ``--reference FILE.nav`` scores against it
(:mod:`navreplay.logs.reference`).

The recording is the folder of these files (or the IMU file, the others next to it); the
files are its topics, named by file name (``--topic gps=GNSS-RTK.txt`` picks one of several).
Times are seconds of the GPS week, as the files have them (``t_ns`` = s x 1e9): a reference
file in the same time base lines up. Lines starting with ``#`` or ``%`` are comments; a row
that is not numbers, has too few columns, or a time that does not increase stops the read
with one line naming the file and the line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from navreplay.core.streams import StreamKind
from navreplay.io.convert import Convention
from navreplay.io.direct import Columns, DirectSource, Topic, body_axes
from navreplay.io.errors import RecordingError

IMU_TYPE = "gins/ImuIncrements"
GNSS_TYPE = "gins/GnssPosition"
NAV_TYPE = "gins/Navigation"
WIDTH = {IMU_TYPE: 7, GNSS_TYPE: 7, NAV_TYPE: 11}
"""Columns each file type needs at least."""
SUFFIXES = (".txt", ".imu", ".gnss", ".nav", ".pos")
COMMENTS = ("#", "%")


def file_type(path: Path) -> str | None:
    """The type of a text file by its name (module docstring), or None."""
    name = path.name.lower()
    if path.suffix.lower() not in SUFFIXES:
        return None
    if "imu" in name:
        return IMU_TYPE
    if "gnss" in name or "gps" in name:
        return GNSS_TYPE
    if "truth" in name or path.suffix.lower() == ".nav":
        return NAV_TYPE
    return None


def _first_row(path: Path) -> list[str] | None:
    try:
        with open(path, encoding="ascii", errors="replace") as f:
            for _ in range(50):
                line = f.readline()
                if not line:
                    return None
                if line.strip() and not line.lstrip().startswith(COMMENTS):
                    return line.replace(",", " ").split()
    except OSError:
        return None
    return None


def _numeric(fields: list[str] | None, width: int) -> bool:
    if not fields or len(fields) < width:
        return False
    try:
        [float(f) for f in fields]
    except ValueError:
        return False
    return True


def _imu_file(path: Path) -> bool:
    return (path.is_file() and file_type(path) == IMU_TYPE
            and _numeric(_first_row(path), WIDTH[IMU_TYPE]))


def accepts(path: Path) -> bool:
    """Whether ``path`` is an IMU increment file, or a folder (not a rosbag2 one) with one."""
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            return False
        return any(_imu_file(p) for p in sorted(path.iterdir()))
    return _imu_file(path)


def read_table(path: Path, width: int) -> np.ndarray:
    """The rows of numbers of a text file (at least ``width`` columns; comments skipped); a
    bad row is one :class:`RecordingError` naming the file and line."""
    try:
        with open(path, encoding="ascii", errors="replace") as f:
            text = f.read()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    rows: list[list[float]] = []
    ti = 1 if width == WIDTH[NAV_TYPE] else 0  # the time column (a .nav file: after the week)
    for n, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith(COMMENTS):
            continue
        fields = s.replace(",", " ").split()
        if len(fields) < width:
            raise RecordingError(f"{path}, line {n}: {len(fields)} columns; this file needs "
                                 f"{width}")
        try:
            values = [float(v) for v in fields[:width]]
        except ValueError:
            raise RecordingError(f"{path}, line {n}: not a number in {s[:60]!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise RecordingError(f"{path}, line {n}: non-finite value")
        if rows and values[ti] <= rows[-1][ti]:
            raise RecordingError(f"{path}, line {n}: time {fields[ti]} does not increase")
        rows.append(values)
    if not rows:
        raise RecordingError(f"{path}: no rows of numbers")
    return np.array(rows)


def seconds_to_ns(t: np.ndarray) -> np.ndarray:
    """Seconds of the week -> int64 ns (rounded to the microsecond the files resolve)."""
    return np.rint(np.asarray(t) * 1e6).astype(np.int64) * 1000


class GinsSource(DirectSource):
    """A folder of GINS text files (module docstring) as one window."""

    kind = "gins"
    what = "folder"

    def _folder(self) -> Path:
        return self.path if self.path.is_dir() else self.path.parent

    def topics(self) -> list[Topic]:
        folder = self._folder()
        if not folder.is_dir():
            raise RecordingError(f"{self.path}: no such file or folder")
        files = sorted(p for p in folder.iterdir() if p.is_file() and file_type(p))
        if not self.path.is_dir():  # the IMU file given: it first among its kind
            files.sort(key=lambda p: p != self.path)
        out = []
        kinds = {IMU_TYPE: (StreamKind.IMU,), GNSS_TYPE: (StreamKind.GPS,), NAV_TYPE: ()}
        for p in files:
            ty = file_type(p)
            assert ty is not None
            if not _numeric(_first_row(p), WIDTH[ty]):
                continue
            out.append(Topic(p.name, ty, _count_rows(p), kinds[ty]))
        return out

    def read(self, topic: Topic, kind: StreamKind, declared: Convention | None) -> Columns:
        path = self._folder() / topic.name
        data = read_table(path, WIDTH[topic.type_name])
        t_ns = seconds_to_ns(data[:, 0])
        if kind is StreamKind.IMU:
            if len(t_ns) < 2:
                raise RecordingError(f"{path}: fewer than 2 IMU rows")
            dt = np.diff(data[:, 0])
            dt = np.concatenate([dt[:1], dt])
            w, conv, reason = body_axes(data[:, 1:4] / dt[:, None], Convention.FRD, declared,
                                        "the GINS text format")
            f, _, _ = body_axes(data[:, 4:7] / dt[:, None], Convention.FRD, declared,
                                "the GINS text format")
            return Columns(t_ns, {"omega_ib_b": w, "f_b": f}, f"imu_{conv.value}", conv,
                           reason)
        pos = np.column_stack([np.radians(data[:, 1]), np.radians(data[:, 2]), data[:, 3]])
        return Columns(t_ns, {"pos": pos, "pos_sigma": data[:, 4:7].copy()}, "gnss")


def _count_rows(path: Path) -> int:
    n = 0
    with open(path, "rb") as f:
        for line in f:
            s = line.strip()
            if s and not s.startswith((b"#", b"%")):
                n += 1
    return n
