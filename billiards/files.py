"""Files the package writes and reads back: one atomic writer for every result file, and one
loader for the small ``torch.save`` files with a format tag (exported policies, reward models)
that turns every way such a file can be bad into one clear error.

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
    try:
        with open(tmp, mode, **kwargs) as f:
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


def load_tagged(path, tag: str, error: type[Exception], what: str) -> dict:
    """``torch.load`` (tensors and plain containers only) of a dict whose ``"format"`` is
    ``tag``; raises ``error`` naming the path and ``what`` was expected if the file is missing,
    empty, unreadable or of another format."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise error(f"{what} file {path} does not exist")
    if path.stat().st_size == 0:
        raise error(f"{what} file {path} is empty")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for a corrupt file
        raise error(f"{what} file {path} is corrupt or not a torch file ({type(err).__name__}: {err})") from None
    if not isinstance(payload, dict) or payload.get("format") != tag:
        raise error(f"{path} is not a {what} file (expected format tag {tag!r})")
    return payload
