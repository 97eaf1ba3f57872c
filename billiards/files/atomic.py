"""One atomic writer for every result file (:func:`atomic_open`, :func:`atomic_write_bytes`,
:func:`atomic_write_text`).

Atomic means a reader (or a kill at any moment) sees either the old file or the new one,
never half of one: the content goes to a temporary file in the same directory, is flushed and
fsynced, and then replaces the old file by :func:`os.replace` (an atomic rename on POSIX and
Windows); the directory is fsynced too, so the rename survives a power loss.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import IO, Iterator

TMP_SUFFIX = ".tmp"


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open ``path + ".tmp"`` for writing (``mode`` "w" or "wb", ``kwargs`` as for
    :func:`open`); when the block ends normally the file is flushed, fsynced and renamed over
    ``path``. If the block raises, the temporary file is removed and ``path`` is untouched."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes whole files: mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    tmp = path.with_name(path.name + TMP_SUFFIX)
    tmp.unlink(missing_ok=True)  # a stale temporary file, or a link planted there: never written through
    try:
        with open(tmp, mode.replace("w", "x"), **kwargs) as f:  # created afresh (O_EXCL: no link is followed)
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def _fsync_dir(directory: Path) -> None:
    """Make a rename in ``directory`` durable (POSIX; a no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring); returns the path."""
    with atomic_open(path, "wb") as f:
        f.write(data)
    return Path(path)


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (see the module docstring); returns the path."""
    with atomic_open(path, "w", encoding="utf-8", newline="") as f:
        f.write(text)
    return Path(path)
