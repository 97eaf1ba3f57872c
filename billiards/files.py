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


SEAL_KEY = "sha256"  # the checksum entry of a sealed (tagged) file


def payload_digest(payload) -> str:
    """SHA-256 over a payload's content in a canonical order: every key (sorted), tensor (dtype,
    shape, bytes), array and plain value, except the top-level :data:`SEAL_KEY` itself. The same
    content gives the same digest however ``torch.save`` lays it out."""
    import hashlib
    import json

    import numpy as np
    import torch

    h = hashlib.sha256()

    def feed(x) -> None:
        if isinstance(x, dict):
            h.update(b"d%d" % len(x))
            for k in sorted(x, key=str):
                feed(str(k))
                feed(x[k])
        elif isinstance(x, (list, tuple)):
            h.update(b"l%d" % len(x))
            for v in x:
                feed(v)
        elif torch.is_tensor(x):
            t = x.detach().cpu().contiguous()
            h.update(f"t{t.dtype}{tuple(t.shape)}".encode())
            h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
        elif isinstance(x, np.ndarray):
            a = np.ascontiguousarray(x)
            h.update(f"a{a.dtype}{a.shape}".encode() + a.tobytes())
        else:
            h.update(("v" + json.dumps(x, sort_keys=True, default=repr)).encode())

    feed({k: v for k, v in payload.items() if k != SEAL_KEY})
    return h.hexdigest()


def _non_finite(payload, prefix: str = "") -> str | None:
    """The first entry of ``payload`` holding a NaN or an infinity (floating tensors and arrays)."""
    import numpy as np
    import torch

    items = payload.items() if isinstance(payload, dict) else enumerate(payload) if isinstance(payload, (list, tuple)) else ()
    for k, v in items:
        name = f"{prefix}{k}"
        if torch.is_tensor(v) and v.is_floating_point() and v.numel() and not bool(torch.isfinite(v).all()):
            return name
        if isinstance(v, np.ndarray) and v.dtype.kind == "f" and not np.isfinite(v).all():
            return name
        if isinstance(v, (dict, list, tuple)) and (bad := _non_finite(v, f"{name}.")):
            return bad
    return None


def record_digest(record: dict) -> str:
    """SHA-256 of a JSON record (its keys sorted), without its own :data:`SEAL_KEY` entry: the
    checksum each line of an append-only ledger and each whole JSON ledger carries."""
    import hashlib
    import json

    body = {k: v for k, v in record.items() if k != SEAL_KEY}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def sealed_record(record: dict) -> dict:
    """The record with its checksum (:func:`record_digest`) under :data:`SEAL_KEY`."""
    return {**{k: v for k, v in record.items() if k != SEAL_KEY}, SEAL_KEY: record_digest(record)}


def record_intact(record: dict) -> bool:
    """True unless the record carries a checksum that its content does not match (records
    written before ledgers were sealed carry none and pass on their shape alone)."""
    return SEAL_KEY not in record or record[SEAL_KEY] == record_digest(record)


def save_tagged(path, payload: dict) -> Path:
    """Write a tagged payload (``"format"`` set by the caller) with its checksum
    (:func:`payload_digest`), atomically; :func:`load_tagged` checks both."""
    import io

    import torch

    buf = io.BytesIO()
    torch.save({**payload, SEAL_KEY: payload_digest(payload)}, buf)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_bytes(path, buf.getvalue())


def load_tagged(path, tag: str, error: type[Exception], what: str) -> dict:
    """``torch.load`` (tensors and plain containers only: nothing in the file is executed) of a
    dict whose ``"format"`` is ``tag``, sealed by :func:`save_tagged`; raises ``error`` naming
    the path and ``what`` was expected if the file is missing, empty, unreadable, of another
    format, without its checksum or not matching it (a flipped bit), or holds a NaN or an
    infinity. The loaders check the shapes their layout declares."""
    payload = _load_tagged_unchecked(path, tag, error, what)
    if SEAL_KEY not in payload:
        raise error(f"{what} file {path} carries no checksum (written before files were sealed): "
                    f"python -m billiards.files seal {path} checks its contents and seals it")
    if payload[SEAL_KEY] != payload_digest(payload):
        raise error(f"{what} file {path} is damaged: its contents do not match its sha256 checksum")
    if (bad := _non_finite(payload)) is not None:
        raise error(f"{what} file {path} holds non-finite values (NaN or inf) in {bad}")
    return payload


def _load_tagged_unchecked(path, tag: str, error: type[Exception], what: str) -> dict:
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


def seal(path) -> str:
    """Add the checksum to a tagged file written before files were sealed, after checking that
    it loads as tensors and plain values and holds only finite numbers; returns the digest."""
    import torch

    payload = torch.load(Path(path), map_location="cpu", weights_only=True)
    if not isinstance(payload, dict) or not isinstance(payload.get("format"), str):
        raise ValueError(f"{path} is not a tagged file (no format entry)")
    if (bad := _non_finite(payload)) is not None:
        raise ValueError(f"{path} holds non-finite values (NaN or inf) in {bad}: not sealed")
    payload.pop(SEAL_KEY, None)
    save_tagged(path, payload)
    return payload_digest(payload)


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m billiards.files", description="Seal tagged files (policies, rankers, "
                                 "reward models) written before checksums: check their contents, add the checksum.")
    sub = ap.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("seal", help="seal each file in place")
    sp.add_argument("paths", nargs="+", type=Path)
    args = ap.parse_args(argv)
    for p in args.paths:
        try:
            print(f"{p}: sealed, sha256 {seal(p)[:16]}...")
        except (OSError, ValueError, RuntimeError) as err:
            print(f"Error: {p}: {err}")
            return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
