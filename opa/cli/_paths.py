"""Output paths checked before any computing, so a typo never costs a long run.

Each check names the flag and the path in a ``ValueError`` (the CLI prints it as one line
with exit status 2). Writability is probed by creating and removing a file in the nearest
existing folder, which also holds for root, for whom ``os.access`` always says yes.
"""

from __future__ import annotations

import os
import tempfile

# What matplotlib's savefig writes (a name without a suffix is written as PNG).
# (.pgf is left out: it needs a LaTeX installation, which only the write would find missing)
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".eps", ".ps", ".jpg", ".jpeg", ".tif",
                   ".tiff", ".webp", ".raw", ".rgba")
NAME_MAX = 200  # longest file name: the temporary beside it adds a prefix and a pid


def _nearest_folder(path: str) -> str:
    folder = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(folder):
        folder = os.path.dirname(folder)
    return folder


def _probe(flag: str, path: str, folder: str) -> None:
    if not os.path.isdir(folder):
        raise ValueError(f"{flag} {path}: {folder} is not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".opa-mc-probe-", dir=folder)
    except OSError as err:
        raise ValueError(f"{flag} {path}: cannot write in {folder} ({err.strerror})") from None
    os.close(fd)
    os.remove(probe)


def _nonempty(flag: str, path) -> str:
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"{flag} must be a path, got {path!r}")
    path = os.fspath(path)
    if not path.strip():
        raise ValueError(f"{flag} must name a file or folder, got an empty string")
    return path


def check_output_file(flag: str, path, *, suffixes: tuple[str, ...] | None = None) -> None:
    """Refuse an output file that could not be written: empty, a folder, in a folder that
    cannot be created or written, an existing read-only file, or a suffix not in
    ``suffixes``. ``None`` (no output asked for) passes."""
    if path is None:
        return
    path = _nonempty(flag, path)
    if path.endswith(os.sep) or os.path.isdir(path):
        raise ValueError(f"{flag} {path}: is a folder, expected a file name")
    if len(os.path.basename(path)) > NAME_MAX:
        raise ValueError(f"{flag} {path[:40]}...: the file name is longer than {NAME_MAX} "
                         f"characters")
    suffix = os.path.splitext(path)[1].lower()
    if suffixes is not None and suffix and suffix not in suffixes:
        raise ValueError(f"{flag} {path}: cannot write {suffix} files; use one of "
                         f"{', '.join(suffixes)}")
    _probe(flag, path, _nearest_folder(path))
    if os.path.exists(path):
        if not os.path.isfile(path):
            raise ValueError(f"{flag} {path}: exists and is not a regular file")
        try:
            with open(path, "ab"):
                pass
        except OSError as err:
            raise ValueError(f"{flag} {path}: cannot be overwritten ({err.strerror})") from None


def check_output_dir(flag: str, path) -> None:
    """Refuse an output folder that is empty, a file, or cannot be created or written."""
    path = _nonempty(flag, path)
    if os.path.exists(path) and not os.path.isdir(path):
        raise ValueError(f"{flag} {path}: exists and is not a folder")
    _probe(flag, path, path if os.path.isdir(path) else _nearest_folder(path))


__all__ = ["FIGURE_SUFFIXES", "check_output_dir", "check_output_file"]
