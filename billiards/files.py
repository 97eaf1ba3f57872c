"""Files the package writes and reads back: the repository root and paths relative to it, the
names of the files a run directory holds, one atomic writer for every result file, and one
loader for the small ``torch.save`` files with a format tag (exported policies, reward models)
that turns every way such a file can be bad into one clear error.

The lowest layer of the package: standard library only (torch lazily, in :func:`load_tagged`),
so anything may import it.

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

ROOT = Path(__file__).resolve().parent.parent  # the repository (a checkout; billiards/ is in it)

# What a training run directory holds (billiards.rl) ...
CONFIG_FILE = "config.yaml"  # the resolved config, written at start (training and search runs)
CHECKPOINT_FILE = "checkpoint.pt"
EVAL_FILE = "eval.json"
EVAL_HISTORY_FILE = "eval_history.jsonl"
METRICS_FILE = "metrics.csv"
SUMMARY_FILE = "summary.json"
# ... and a search run directory (billiards.search)
RESULTS_FILE = "results.json"


def repo_path(path) -> Path:
    """A path a config or a command line gives: itself if it is absolute or exists (relative to
    the working directory), else the same path under the repository root, so the shipped
    ``results/...`` files are found from any working directory."""
    p = Path(path)
    if p.is_absolute() or p.exists():
        return p
    return ROOT / p


def display_path(path) -> str:
    """How a path is written into logs and records: relative to the repository when it lies
    inside it, so no committed file names a folder of the machine that wrote it."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(ROOT.resolve()))
    except ValueError:
        return str(path)


def recorded_command(cmd) -> list[str]:
    """A command line as recorded: the interpreter as ``python`` and paths inside the repository
    relative to it (``hydra.run.dir=/abs/repo/x`` -> ``hydra.run.dir=x``)."""
    import sys

    root = str(ROOT.resolve()) + "/"
    return ["python" if c == sys.executable else c.replace(root, "") for c in cmd]


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
