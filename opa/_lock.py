"""Advisory locks on output folders and files: two runs never write the same output.

A run that writes a folder (the trust map's OUTDIR, a resume store such as ``F.nc.parts``)
or a file first takes its lock, :class:`OutputLock`: a small JSON file created atomically
(``os.open`` with ``O_CREAT | O_EXCL``) that names the process holding it::

    <folder>/.opa-mc.lock          the lock of a folder
    <file>.lock                    the lock of a file

    {"pid": 4242, "host": "node7", "command": "opa-mc validate --outdir DIR",
     "started": "2025-01-01T12:00:00+00:00", "ticks": 123456, "token": "..."}

A second process that asks for the lock is refused at once with a ValueError (the CLI:
one line, exit status 2) that names the path, the holder's pid, host, command line and
start, and the lock file. A lock whose process no longer runs on this host (its pid is
gone, a zombie, or now another process: ``ticks`` is the process's start time, read from
``/proc``) is stale: it is taken over, said in one ``log`` line. A lock held on another
host cannot be judged from here: it is refused, and the message says which file to remove
once that process has stopped. A lock file that stays unreadable for a few seconds (its
writer died between creating and filling it) is stale too.

The lock is advisory (only opa-mc looks at it) and per process: the process that holds a
lock may take it again (a nested ``with``), and it is released when the last holder
releases it, on leaving the ``with`` (an exception or KeyboardInterrupt included), and at
interpreter exit; a forked child does not inherit it. A process killed without cleanup
(SIGKILL, a power cut) leaves its lock file, which the next run takes over.
"""

from __future__ import annotations

import atexit
import datetime as _dt
import json
import logging
import os
import socket
import sys
import threading
import time
import uuid
from collections.abc import Callable

#: the lock file of a folder, inside it
LOCK_NAME = ".opa-mc.lock"
#: the lock file of a file, beside it (``<file>.lock``)
LOCK_SUFFIX = ".lock"
# a lock file that is still empty or unreadable after this many seconds is stale: its
# writer died between O_EXCL and the write (which take microseconds)
_UNREADABLE_GRACE = 3.0
# the guard of a takeover (``<lock>.break``): older than this, its holder died mid-takeover
_BREAK_GRACE = 10.0
_ATTEMPTS = 200

_logger = logging.getLogger("opa_mc")


class OutputInUse(ValueError):
    """The output asked for is locked by another running process (exit status 2)."""


# lock file (real path) -> [pid of the holding process, holds, token]
_HELD: dict[str, list] = {}
_GUARD = threading.Lock()
_TAKING = threading.Lock()


def _forget_in_child() -> None:
    global _GUARD, _TAKING
    _HELD.clear()
    _GUARD, _TAKING = threading.Lock(), threading.Lock()  # a thread may have held them


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_in_child)


def lock_file(path: str | os.PathLike, folder: bool) -> str:
    """The lock file of ``path``: ``<folder>/.opa-mc.lock`` or ``<file>.lock``."""
    path = os.path.abspath(os.fspath(path))
    return os.path.join(path, LOCK_NAME) if folder else path + LOCK_SUFFIX


def command_line(pid: int | None = None) -> str | None:
    """The command line of process ``pid`` (default: this one) as a lock records it
    (``opa-mc validate --outdir DIR``: the program's base name, white space collapsed, at
    most 200 characters: its start and end), read from ``/proc``; for this process, from
    sys.argv where ``/proc`` cannot be read. None where it cannot be read."""
    try:
        with open(f"/proc/{'self' if pid is None else pid}/cmdline", "rb") as file:
            argv = [a.decode(errors="replace") for a in file.read().split(b"\0") if a]
    except OSError:
        argv = list(sys.argv) if pid is None else []
    if not argv:
        return None
    text = " ".join(" ".join(os.path.basename(a) if i == 0 else a for i, a in
                             enumerate(argv)).split())
    return text if len(text) <= 200 else f"{text[:120]} ... {text[-75:]}"


def process_ticks(pid: int) -> int | None:
    """The start time of process ``pid`` in clock ticks after boot (``/proc/PID/stat``),
    or None where it cannot be read; with the pid it names one process for good."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as file:
            fields = file.read().rsplit(")", 1)[1].split()
        return int(fields[19])  # field 22 of proc(5); fields[0] is field 3
    except (OSError, IndexError, ValueError):
        return None


def _zombie(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as file:
            return file.read().rsplit(")", 1)[1].split()[0] == "Z"
    except (OSError, IndexError):
        return False


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this host (a zombie does not run; another user's
    process is taken as running)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True  # another user's process, or not ours to judge
    return not _zombie(pid)


def _read(lockfile: str) -> tuple[dict | None, bytes | None, float]:
    """(holder, raw bytes, age in seconds) of a lock file; (None, None, 0) when it is gone,
    holder None when it does not read as a lock. OSError when it cannot be opened."""
    try:
        with open(lockfile, "rb") as file:
            raw = file.read()
            age = time.time() - os.fstat(file.fileno()).st_mtime
    except FileNotFoundError:
        return None, None, 0.0
    try:
        holder = json.loads(raw.decode())
        pid = holder.get("pid") if isinstance(holder, dict) else None
        if not (type(pid) is int and pid > 0):
            holder = None
    except (UnicodeDecodeError, ValueError):
        holder = None
    return holder, raw, age


def _try_read(lockfile: str) -> tuple[dict | None, bytes | None, float]:
    """:func:`_read`, with a file that cannot be opened taken as unreadable."""
    try:
        return _read(lockfile)
    except OSError:
        return None, b"", 0.0


def _why_stale(holder: dict, lockfile: str) -> str | None:
    """Why the lock of ``holder`` no longer holds, or None while its process runs (or
    runs on another host, where it cannot be judged)."""
    if holder.get("host") != socket.gethostname():
        return None
    pid = holder["pid"]
    if pid == os.getpid():
        with _GUARD:
            entry = _HELD.get(lockfile)
        if entry is not None and entry[0] == pid and entry[2] == holder.get("token"):
            return None
        return "left by an earlier process with this process's pid"
    if not pid_alive(pid):
        return "which is no longer running"
    ticks = holder.get("ticks")
    if isinstance(ticks, int) and process_ticks(pid) not in (None, ticks):
        return "which is no longer running (its pid now names another process)"
    return None


def _describe(holder: dict) -> str:
    pid = holder["pid"]
    host = holder.get("host") or "an unknown host"
    where = "" if host == socket.gethostname() else f" on host {host}"
    command = (holder.get("command") or (command_line(pid) if not where else None)
               or "command line unknown")
    since = f", started {holder['started']}" if holder.get("started") else ""
    return f"process {pid}{where} ({command}{since})"


class OutputLock:
    """The lock of an output folder or file (module docstring).

    Parameters
    ----------
    path : the folder or the file.
    what : what ``path`` is, for messages ("output folder", "Monte Carlo checkpoint").
    folder : True: a folder (created if missing; the lock file inside it); False: a file
        (the lock file beside it).
    log : callable taking one line (a stale lock taken over); default: a warning of the
        ``opa_mc`` logger (printed to stderr when logging is not configured).

    Raises
    ------
    OutputInUse (a ValueError)
        On :meth:`acquire`, when another running process holds the lock: one line naming
        ``path``, that process (pid, host, command line) and the lock file.

    Examples
    --------
    >>> import os, tempfile
    >>> folder = tempfile.mkdtemp()
    >>> with OutputLock(folder, "output folder", folder=True):
    ...     os.path.exists(os.path.join(folder, LOCK_NAME))
    True
    >>> os.path.exists(os.path.join(folder, LOCK_NAME))
    False
    """

    def __init__(self, path: str | os.PathLike, what: str, *, folder: bool,
                 log: Callable[[str], object] | None = None):
        self.path = os.fspath(path)
        self.what = what
        self.folder = folder
        self.lockfile = lock_file(path, folder)
        self.log = log if log is not None else _logger.warning
        self.held = False
        self._created: str | None = None  # the folder this lock created, if any

    def __repr__(self) -> str:
        return f"OutputLock({self.path!r}, {self.what!r}, held={self.held})"

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()

    def acquire(self) -> OutputLock:
        """Take the lock (module docstring); returns ``self``."""
        if self.held:
            return self
        with _TAKING:  # one thread of this process at a time: none sees another's lock
            return self._acquire()  # between its creation and its registration

    def _acquire(self) -> OutputLock:
        key = os.path.realpath(self.lockfile)
        with _GUARD:
            entry = _HELD.get(key)
            if entry is not None and entry[0] == os.getpid():
                holder, _, _ = _try_read(self.lockfile)
                if holder is not None and holder.get("token") == entry[2]:
                    entry[1] += 1  # this process holds it already
                    self.held = True
                    return self
                del _HELD[key]  # its file went: take it again below
        directory = self.path if self.folder else os.path.dirname(os.path.abspath(self.path))
        if os.path.exists(directory) and not os.path.isdir(directory):
            raise ValueError(f"{self.what} {self.path!r}: {directory!r} is not a directory")
        created = not os.path.isdir(directory)
        try:
            os.makedirs(directory, exist_ok=True)
        except OSError as err:
            raise ValueError(f"{self.what} {self.path!r} cannot be created: "
                             f"{err.strerror or err}") from None
        token = uuid.uuid4().hex
        self._take(key, token)
        with _GUARD:
            _HELD[key] = [os.getpid(), 1, token]
        self.held = True
        self._created = directory if created and self.folder else None
        return self

    def _take(self, key: str, token: str) -> None:
        record = json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                             "command": command_line(),
                             "started": _dt.datetime.now(_dt.timezone.utc).isoformat(
                                 timespec="seconds"),
                             "ticks": process_ticks(os.getpid()), "token": token})
        for _ in range(_ATTEMPTS):
            try:
                fd = os.open(self.lockfile, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
            except FileExistsError:
                pass
            except OSError as err:
                raise ValueError(f"{self.what} {self.path!r}: its lock {self.lockfile} "
                                 f"cannot be created ({err.strerror or err})") from None
            else:
                try:
                    os.write(fd, record.encode())
                    os.fsync(fd)
                finally:
                    os.close(fd)
                return
            try:
                holder, raw, age = _read(self.lockfile)
            except OSError as err:
                raise ValueError(f"{self.what} {self.path!r}: its lock {self.lockfile} "
                                 f"cannot be read ({err.strerror or err})") from None
            if raw is None:
                continue  # released meanwhile: try again
            if holder is None:
                if age < _UNREADABLE_GRACE:
                    time.sleep(0.05)  # being written
                    continue
                why = "an unreadable lock file"
            else:
                why = _why_stale(holder, key)
                if why is None:
                    raise OutputInUse(self._refusal(holder))
                why = f"the lock of {_describe(holder)}, {why}"
            if self._break(raw):
                self.log(f"{self.what} {self.path!r}: took over {why} ({self.lockfile})")
        raise ValueError(f"{self.what} {self.path!r}: could not take its lock "
                         f"{self.lockfile} (other processes keep taking it); try again")

    def _refusal(self, holder: dict) -> str:
        other_host = holder.get("host") != socket.gethostname()
        hint = (f"if that process has stopped, remove {self.lockfile}" if other_host else
                f"wait for it to finish or stop it, or name another "
                f"{'folder' if self.folder else 'file'} (lock file {self.lockfile})")
        return f"{self.what} {self.path!r} is in use by {_describe(holder)}: {hint}"

    def _break(self, raw: bytes) -> bool:
        """Remove the stale lock file that read ``raw``, under a guard so that a lock
        another process has just taken in its place is never removed. True when done."""
        guard = self.lockfile + ".break"
        try:
            fd = os.open(guard, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        except FileExistsError:
            try:
                if time.time() - os.stat(guard).st_mtime > _BREAK_GRACE:
                    os.remove(guard)  # its taker died mid-takeover
            except OSError:
                pass
            time.sleep(0.02)
            return False
        except OSError as err:
            raise ValueError(f"{self.what} {self.path!r}: its stale lock {self.lockfile} "
                             f"cannot be taken over ({err.strerror or err})") from None
        os.close(fd)
        try:
            _, now, _ = _try_read(self.lockfile)
            if now != raw:
                return False  # released, or taken by another process meanwhile
            try:
                os.remove(self.lockfile)
            except FileNotFoundError:
                return False
            except OSError as err:
                raise ValueError(f"{self.what} {self.path!r}: its stale lock "
                                 f"{self.lockfile} cannot be removed "
                                 f"({err.strerror or err})") from None
            return True
        finally:
            try:
                os.remove(guard)
            except OSError:
                pass

    def release(self) -> None:
        """Give the lock up (the file goes when the last holder in this process releases
        it); a folder the lock created is removed again if it is left empty."""
        if not self.held:
            return
        self.held = False
        key = os.path.realpath(self.lockfile)
        with _GUARD:
            entry = _HELD.get(key)
            if entry is None or entry[0] != os.getpid():
                return
            entry[1] -= 1
            if entry[1] > 0:
                return
            del _HELD[key]
        _remove_own(self.lockfile, entry[2])
        if self._created is not None:
            try:
                os.rmdir(self._created)  # only when empty
            except OSError:
                pass


def _remove_own(lockfile: str, token: str) -> None:
    holder, _, _ = _try_read(lockfile)
    if holder is not None and holder.get("token") == token:
        try:
            os.remove(lockfile)
        except OSError:
            pass


def holder_elsewhere(path: str | os.PathLike, folder: bool) -> dict | None:
    """The holder of the lock of ``path`` when another running process holds it (as its
    lock file records it), else None: free, stale, or held by this process."""
    lockfile = lock_file(path, folder)
    holder, _, _ = _try_read(lockfile)
    if holder is None or _why_stale(holder, os.path.realpath(lockfile)) is not None:
        return None
    if holder["pid"] == os.getpid() and holder.get("host") == socket.gethostname():
        return None
    return holder


def forget(path: str | os.PathLike, folder: bool) -> None:
    """Drop this process's lock of ``path`` whatever the holds (its folder is being
    removed): the lock file goes, later releases do nothing."""
    lockfile = lock_file(path, folder)
    key = os.path.realpath(lockfile)
    with _GUARD:
        entry = _HELD.pop(key, None)
    if entry is not None and entry[0] == os.getpid():
        _remove_own(lockfile, entry[2])


@atexit.register
def _release_all() -> None:
    with _GUARD:
        held = [(path, entry) for path, entry in _HELD.items() if entry[0] == os.getpid()]
        _HELD.clear()
    for path, entry in held:
        _remove_own(path, entry[2])
