"""Output files: checked before any work, written through temporaries, never lost.

Every file a command writes (a recording, an .rrd view, a JSON summary, an export, a report)
goes through this module:

* :func:`check_outputs` runs before the work starts. It refuses a target that exists (unless
  ``force``), a target that is one of the command's inputs or lies inside an input folder (a
  rosbag2 folder), a directory output that would write over an input (even with ``force``:
  resolved paths and device/inode are compared, so links and ``./x`` spellings are caught), two
  outputs on the same file, an output inside another's directory
  (``--export x --summary x/summary.json``; the default view folder ``out/`` holds only its ``.rrd``
  files), a target that is a directory, and a target whose directory cannot be created or written.
  Each refusal is one line naming the option and the file. With ``lock`` it then takes an exclusive
  lock on every explicit target (:func:`lock_outputs`), so that two commands running at once cannot
  write the same file: the second stops at once, naming the first one's PID.
* :func:`temporary_path` names the file the work writes into: ``.NAME.PID.XXXXXXXX.part`` beside
  the target, renamed onto it only when complete (:func:`atomic_path` does both). Live
  temporaries are registered so that :func:`remove_temporaries` (called by the signal handlers of
  :mod:`navreplay.io.lifecycle`) deletes them when the process is told to stop.
* :func:`writing` turns a full disk (or a quota, a read-only or failing device) met while
  writing into one :class:`OutputError` naming the output; the temporaries are removed and
  nothing incomplete is published.
* A run killed outright (``kill -9``, power loss) cannot clean up; the PID and host in the name
  let the next write into the same directory recognise the leftovers of a process of this
  machine that no longer exists and delete them (:func:`clean_stale`, reported as a warning).
  Limits (docs/architecture.md, "Files and signals"): a PID reused by a new process keeps a
  leftover until that process ends; another machine's leftovers on a shared file system are
  never removed; a target created by someone else between the check and the rename is
  replaced.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fnmatch
import os
import re
import secrets
import socket
import threading
import warnings
from collections.abc import Iterable, Iterator
from pathlib import Path


class OutputError(OSError):
    """An output that must not or cannot be written; the message is one line."""


@dataclasses.dataclass(frozen=True)
class Output:
    """A file (or, for ``directory``, a folder of files) a command will write.

    Attributes
    ----------
    path : Path
    option : str
        How the user named it, for messages: ``--save``, ``--summary``, ``-o``, ``--keep``...
    explicit : bool
        Named by the user. An existing file is then replaced only with ``force``; a default
        target (under ``out/``) is the tool's own and is regenerated.
    directory : bool
        A directory the command fills (``--keep DIR``); it may exist, its files are checked as
        outputs of their own.
    writes : tuple of str, optional
        For a directory: the names (glob patterns) of the files it receives, e.g.
        ``("manifest.json", "gps-ins.*")``; None: any name. An input at such a name inside
        the directory is refused, and so is any other output inside an explicit directory
        (an implicit one, the default ``out/``, refuses only its own names).
    """

    path: Path
    option: str
    explicit: bool = True
    directory: bool = False
    writes: tuple[str, ...] | None = None

    def receives(self, path: Path) -> bool:
        """Whether this directory output writes ``path`` (resolved paths)."""
        if not self.directory or _resolved(Path(path).parent) != _resolved(self.path):
            return False
        return self.writes is None or any(fnmatch.fnmatchcase(path.name, w)
                                          for w in self.writes)

    def holds(self, path: Path) -> bool:
        """Whether another output at ``path`` would land in this one: anywhere inside an explicit
        directory (``--export``, ``--keep``), or among the files an implicit one writes."""
        if self.directory and self.explicit:
            return _resolved(Path(path)).is_relative_to(_resolved(self.path))
        return self.receives(path)


def check_outputs(
    outputs: Iterable[Output | None],
    inputs: Iterable[str | os.PathLike[str]] = (),
    *,
    force: bool = False,
    lock: bool = False,
) -> None:
    """Refuse outputs that would lose a file or fail after the work (see the module docstring).

    Parameters
    ----------
    outputs : iterable of Output or None
    inputs : iterable of path-like
        Files and folders the command reads; nothing at or inside them is written.
    force : bool
        Replace existing explicit targets (never an input).
    lock : bool
        Then lock the explicit targets for this process (:func:`lock_outputs`).

    Raises
    ------
    OutputError
        The first problem found, naming the option and the file.
    """
    outs = [o for o in outputs if o is not None]
    ins = [Path(p) for p in inputs]
    seen: dict[str, Output] = {}
    for out in outs:
        path = Path(out.path)
        label = f"{out.option} {path}"
        key = os.path.normcase(str(_resolved(path)))
        if key in seen:
            raise OutputError(f"{label}: the same file as {seen[key].option} {seen[key].path}")
        seen[key] = out
        _check_inputs(out, label, ins)
        for other in outs:
            if other is not out and other.holds(path):
                raise OutputError(f"{label}: is inside {other.option} {other.path}, another "
                                  "output of this command; choose another name or directory")
        if out.directory:
            if path.exists() and not path.is_dir():
                raise OutputError(f"{label}: exists and is not a directory")
            _check_directory(label, path)
            continue
        if path.is_dir():
            raise OutputError(f"{label}: is a directory, not a file")
        if path.exists() and out.explicit and not force:
            raise OutputError(f"{label} exists; use --force to overwrite")
        _check_directory(label, path.parent)
    if lock:
        lock_outputs(o for o in outs if o.explicit)


def _check_inputs(out: Output, label: str, inputs: list[Path]) -> None:
    path = Path(out.path)
    target = _resolved(path)
    for src in inputs:
        if _same_file(path, src):
            raise OutputError(f"{label}: is an input of this command ({src}); choose "
                              "another file")
        if src.is_dir() and target.is_relative_to(_resolved(src)):
            raise OutputError(f"{label}: is inside {src}, an input folder of this command; "
                              "write elsewhere")
        if out.receives(src):
            raise OutputError(f"{label}: would write over {src}, an input of this command; "
                              "choose another directory")


def _resolved(path: str | os.PathLike[str]) -> Path:
    """The absolute path with the links of its existing part resolved."""
    try:
        return Path(os.path.abspath(Path(path).resolve()))
    except (OSError, RuntimeError):  # a link loop: compare as written
        return Path(os.path.abspath(path))


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.resolve() == b.resolve():
            return True
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _check_directory(label: str, directory: Path) -> None:
    """The directory exists (or can be made) and this process may create files in it."""
    d = Path(os.path.abspath(directory))
    while not d.exists():
        if d.parent == d:
            break
        d = d.parent
    if not d.is_dir():
        raise OutputError(f"{label}: {d} is not a directory")
    if not os.access(d, os.W_OK | os.X_OK):
        raise OutputError(f"{label}: directory {d} is not writable")


# --------------------------------------------------------------------------------------------
# temporaries

_PART = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)(@(?P<host>[A-Za-z0-9_-]+))?\.[0-9a-f]{8}\.part$")
"""Name of a temporary: ``.NAME.PID@HOST.XXXXXXXX.part`` (``@HOST`` absent in older ones)."""
_HOST = re.sub(r"[^A-Za-z0-9_-]", "-", socket.gethostname())[:64] or "localhost"
"""This machine, in temporary names: on a shared file system the PID of another machine's
temporary says nothing here, so only this machine's leftovers are ever judged stale."""

_LIVE: set[Path] = set()
_LOCK = threading.Lock()


def temporary_path(target: str | os.PathLike[str]) -> Path:
    """A fresh temporary beside ``target``, registered for removal on a signal.

    Creates the target's directory, removes stale temporaries in it (:func:`clean_stale`) and
    returns ``.NAME.PID@HOST.XXXXXXXX.part``; release it with :func:`release` once renamed or
    abandoned.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    clean_stale(target.parent)
    tmp = target.with_name(f".{target.name}.{os.getpid()}@{_HOST}.{secrets.token_hex(4)}.part")
    with _LOCK:
        _LIVE.add(tmp)
    return tmp


def release(tmp: Path, *, remove: bool = True) -> None:
    """Forget a temporary (and delete it unless ``remove`` is False)."""
    with _LOCK:
        _LIVE.discard(tmp)
    if remove:
        with contextlib.suppress(OSError):
            tmp.unlink()


def remove_temporaries() -> list[Path]:
    """Delete every live temporary of this process and release its locks (signal handlers
    call this); returns the temporaries."""
    with _LOCK:
        live = [p for p in _LIVE if _pid_of(p) == os.getpid()]
        _LIVE.clear()
    for p in live:
        with contextlib.suppress(OSError):
            p.unlink()
    release_locks()
    return live


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path beside ``target``, renamed onto it when the block succeeds; removed
    otherwise (an existing target is then untouched)."""
    target = Path(target)
    tmp = temporary_path(target)
    try:
        with writing(str(target)):
            yield tmp
            fsync_path(tmp)  # the data on disk before the name: a power loss leaves old or new
            os.replace(tmp, target)
    finally:
        release(tmp)


def fsync_path(path: Path) -> None:
    """Flush a file's data, or a directory's entries, to disk (best effort: file systems that
    cannot are left alone)."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _pid_of(path: Path) -> int | None:
    m = _PART.match(path.name)
    return int(m["pid"]) if m else None


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    if os.name != "posix":  # no cheap test elsewhere: keep the file
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, another user's
        return True
    return True


def stale_temporaries(directory: str | os.PathLike[str]) -> list[Path]:
    """Temporaries in ``directory`` whose writing process no longer exists."""
    try:
        names = os.listdir(directory)
    except OSError:
        return []
    out = []
    for name in names:
        m = _PART.match(name)
        if m and m["host"] in (None, _HOST) and not _alive(int(m["pid"])):
            out.append(Path(directory) / name)
    return sorted(out)


def clean_stale(directory: str | os.PathLike[str], *, warn: bool = True) -> list[Path]:
    """Delete the temporaries a killed run left in ``directory``; warn about each (unless
    ``warn`` is False: this command's own workers, killed as it stops)."""
    removed = []
    for p in stale_temporaries(directory):
        try:
            p.unlink()
        except OSError as e:
            if warn:
                warnings.warn(f"{p}: temporary file of an interrupted run; cannot remove it: "
                              f"{e.strerror}", stacklevel=2)
            continue
        removed.append(p)
        if warn:
            warnings.warn(f"removed {p}, the temporary file of an interrupted run",
                          stacklevel=2)
    return removed


# --------------------------------------------------------------------------------------------
# locks: one command at a time per target

_LOCKS: dict[Path, tuple[int, int]] = {}
"""Lock files held -> (open descriptor, PID of the process that took it: a forked worker
inherits the descriptors but never removes its parent's locks)."""


def lock_path(target: str | os.PathLike[str]) -> Path:
    """The lock file of a target: ``.NAME.lock`` beside it (beside, not inside, a directory)."""
    target = Path(os.path.abspath(target))
    return target.with_name(f".{target.name}.lock")


def lock_outputs(outputs: Iterable[Output]) -> None:
    """Take an exclusive lock on each target for the life of this process (or until
    :func:`release_locks`).

    A target that another running process has locked is refused with one line naming it
    (:class:`OutputError`), before any work: two commands writing the same ``--summary``,
    ``--save`` or ``--export`` at once would otherwise both succeed, the later rename silently
    replacing the earlier result. The lock is ``flock`` on ``.NAME.lock`` beside the target:
    the kernel drops it when its process ends, even by ``kill -9``, so a lock file left behind
    never blocks. Where the file system cannot lock (no ``flock``), the lock is skipped.
    """
    if os.name != "posix":
        return
    import fcntl

    for out in outputs:
        lock = lock_path(out.path)
        if _LOCKS.get(lock, (0, 0))[1] == os.getpid():
            continue
        lock.parent.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _holder(fd)
                os.close(fd)
                raise OutputError(f"{out.option} {out.path}: another navreplay command"
                                  f"{holder} is writing it; wait for it to end") from None
            except OSError:  # no locks on this file system
                os.close(fd)
                break
            try:  # the file we locked is still the lock file (not unlinked by its last owner)
                same = os.path.samestat(os.fstat(fd), os.stat(lock))
            except OSError:
                same = False
            if not same:
                os.close(fd)
                continue
            with contextlib.suppress(OSError):  # who holds it, for messages (a full disk
                os.ftruncate(fd, 0)              # leaves it empty)
                os.write(fd, f"{os.getpid()}@{_HOST}\n".encode())
            with _LOCK:
                _LOCKS[lock] = (fd, os.getpid())
            break


def _holder(fd: int) -> str:
    with contextlib.suppress(OSError, ValueError):
        text = os.pread(fd, 256, 0).decode().strip()
        if text:
            pid, _, host = text.partition("@")
            return f" (PID {int(pid)}{'' if host in ('', _HOST) else f' on {host}'})"
    return ""


def release_locks() -> None:
    """Remove and release every lock of this process."""
    with _LOCK:
        held = list(_LOCKS.items())
        _LOCKS.clear()
    for lock, (fd, pid) in held:
        if pid == os.getpid():
            with contextlib.suppress(OSError):
                lock.unlink()
        with contextlib.suppress(OSError):
            os.close(fd)


# --------------------------------------------------------------------------------------------
# a full disk

DISK_ERRORS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO})
"""Errors of the device, not of the program: reported in one line."""


@contextlib.contextmanager
def writing(what: str) -> Iterator[None]:
    """A block that writes ``what`` (``--export out``): a full disk, a quota, a read-only or
    failing device becomes one :class:`OutputError` naming it."""
    try:
        yield
    except OSError as e:
        if isinstance(e, OutputError) or e.errno not in DISK_ERRORS:
            raise
        raise OutputError(f"{what}: {e.strerror or e}; nothing was written") from None
