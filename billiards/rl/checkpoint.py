"""Checkpoints of a training run: one file, ``<run dir>/checkpoint.pt``, replaced atomically.

Contents (a dict of tensors and plain Python types only: dict, list, tuple, str, int, float,
bool, None, so that it loads with ``torch.load(..., weights_only=True)`` and loading never
runs code from the file):

* ``config``: the resolved training config (plain containers);
* ``agent``: the agent's ``state_dict`` (actor, critics, target critics / target actor,
  SAC's log-temperature) and ``agent_extra`` (optimizer states, update counter);
* ``buffer``: the filled part of the replay buffer as a nested dict of tensors, its row
  count and its write cursor (off-policy, unless ``checkpoint.save_buffer=false``), or None;
* ``counters``: env frames, fractional update debt, next log/eval/checkpoint steps,
  accumulated training seconds;
* ``eval_history``: every periodic evaluation so far;
* ``rng``: torch, numpy, python and the training env's rack generator states
  (:func:`rng_state`: numpy arrays as lists of ints);
* ``wandb_id``: to continue the same wandb run.

File layout (format 2)::

    billiards-checkpoint 2\\n
    sha256 <64 hex digits>\\n
    <torch.save of the dict above>

The digest is the SHA-256 of the first line and the payload, so a changed byte anywhere in the
file (header, digest or payload) is detected on load and the file refused instead of resumed
on damaged weights. Written with :func:`billiards.files.atomic_open` (temporary file, fsync,
``os.replace``), so a kill at any moment leaves either the previous or the new checkpoint.
Format 1 (before the checksum) was a plain ``torch.save`` pickle holding numpy objects; it is
refused, since loading it would need the unsafe unpickler.
"""

from __future__ import annotations

import hashlib
import io
import pickle
import random
import re
from pathlib import Path
from typing import Any

import numpy as np
import torch

from billiards.files import atomic_open

from .config import CHECKPOINT_FILE

FORMAT_VERSION = 2
MAGIC = b"billiards-checkpoint"
_HEADER = re.compile(rb"(billiards-checkpoint (\d{1,6})\n)sha256 ([0-9a-f]{64})\n")
_HEADER_MAX = 128  # bytes: the header is about 94
_ZIP = b"PK\x03\x04"  # what format 1 (a bare torch.save) starts with
_PLAIN = (str, int, float, bool, type(None), bytes, torch.Tensor)
REQUIRED = ("config", "agent", "agent_extra", "counters", "rng")


class CheckpointError(RuntimeError):
    """A missing, unreadable or incompatible checkpoint; the message says what to do."""


# ----------------------------------------------------------------------------- rng states


def _plain_array(value: Any) -> Any:
    """A numpy bit-generator state with its arrays as lists of ints (plain, loadable safely)."""
    if isinstance(value, dict):
        return {k: _plain_array(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def rng_state(env_rng: np.random.Generator) -> dict[str, Any]:
    """Every random state a training run draws from, as tensors and plain types: torch's,
    numpy's global one, Python's ``random`` and the training env's rack generator."""
    version, internal, gauss_next = random.getstate()
    return {
        "torch": torch.get_rng_state(),
        "numpy": _plain_array(np.random.get_state(legacy=False)),
        "python": {"version": version, "internal": list(internal), "gauss_next": gauss_next},
        "env": _plain_array(env_rng.bit_generator.state),
    }


def set_rng_state(state: dict[str, Any], env_rng: np.random.Generator) -> None:
    """Restore what :func:`rng_state` saved (numpy accepts its states with lists for arrays)."""
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    py = state["python"]
    random.setstate((py["version"], tuple(py["internal"]), py["gauss_next"]))
    env_rng.bit_generator.state = state["env"]


# ----------------------------------------------------------------------------- the file


def _check_plain(value: Any, where: str) -> None:
    """Raise TypeError naming the entry unless ``value`` is tensors and plain types only."""
    if isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, (str, int)):
                raise TypeError(f"{where} has a key of type {type(k).__name__}; checkpoints store str/int keys only")
            _check_plain(v, f"{where}[{k!r}]")
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _check_plain(v, f"{where}[{i}]")
    elif not isinstance(value, _PLAIN):
        raise TypeError(f"{where} is a {type(value).__module__}.{type(value).__name__}; "
                        f"checkpoints store tensors and plain Python types only")


def save_checkpoint(run_dir: Path, state: dict[str, Any]) -> Path:
    """Write ``state`` (tensors and plain types only, else TypeError naming the entry) as
    ``run_dir/checkpoint.pt`` in format 2 (see the module docstring); returns the path."""
    state = {"format_version": FORMAT_VERSION, **state}
    _check_plain(state, "checkpoint")
    buf = io.BytesIO()
    torch.save(state, buf)
    payload = buf.getbuffer()
    first = MAGIC + b" %d\n" % FORMAT_VERSION
    digest = hashlib.sha256(first)
    digest.update(payload)
    path = Path(run_dir) / CHECKPOINT_FILE
    with atomic_open(path, "wb") as f:
        f.write(first + b"sha256 " + digest.hexdigest().encode() + b"\n")
        f.write(payload)
    return path


def _corrupt(path: Path, why: str) -> CheckpointError:
    return CheckpointError(
        f"cannot resume: {path} is corrupt or truncated ({why}); it is refused rather than resumed "
        f"on damaged data: restore it from a copy, or start a new run"
    )


def _payload(path: Path) -> bytes:
    """The verified payload of a format-2 checkpoint file; CheckpointError if it is not one
    or its checksum does not match."""
    with path.open("rb") as f:
        head = f.read(_HEADER_MAX)
        if head.startswith(_ZIP):
            raise CheckpointError(
                f"cannot resume: {path} was written by an older version of billiards in an unsafe format "
                f"(checkpoint format 1, a pickle that can run code when loaded); this version loads only "
                f"format {FORMAT_VERSION}. Finish that run with the commit that wrote it, or start a new run"
            )
        m = _HEADER.match(head)
        if m is None:
            raise _corrupt(path, "no billiards checkpoint header")
        f.seek(m.end())
        payload = f.read()
    digest = hashlib.sha256(m.group(1))
    digest.update(payload)
    if digest.hexdigest() != m.group(3).decode():
        raise _corrupt(path, f"content checksum mismatch: sha256 {digest.hexdigest()[:12]}..., "
                             f"the file says {m.group(3).decode()[:12]}...")
    version = int(m.group(2))
    if version != FORMAT_VERSION:
        raise CheckpointError(
            f"cannot resume: {path} is a checkpoint of format {version}; this version of billiards reads "
            f"format {FORMAT_VERSION}"
        )
    return payload


def load_checkpoint(run_dir: str | Path) -> dict[str, Any]:
    """The state saved by :func:`save_checkpoint` in ``run_dir``. Loads tensors and plain
    types only (``weights_only=True``): nothing in the file is executed. Raises
    :class:`CheckpointError` naming the file if it is missing, of another format, corrupt
    (checksum) or holds anything else."""
    run_dir = Path(run_dir)
    path = run_dir / CHECKPOINT_FILE
    if not run_dir.is_dir():
        raise CheckpointError(f"cannot resume: {run_dir} is not a directory")
    if not path.is_file():
        raise CheckpointError(
            f"cannot resume: {path} does not exist (the run was killed before its first checkpoint, "
            f"every budget.checkpoint_every steps); start a new run instead"
        )
    payload = _payload(path)
    try:
        state = torch.load(io.BytesIO(payload), map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise CheckpointError(
            f"cannot resume: {path} holds objects other than tensors and plain data ({first}); "
            f"refusing to load it, since unpickling them could run code"
        ) from None
    except Exception as err:  # torch raises many types for a malformed archive
        raise _corrupt(path, f"{type(err).__name__}: {err}") from None
    if not isinstance(state, dict) or state.get("format_version") != FORMAT_VERSION:
        version = state.get("format_version") if isinstance(state, dict) else None
        raise CheckpointError(
            f"cannot resume: {path} is not a billiards training checkpoint of format {FORMAT_VERSION} (found {version!r})"
        )
    missing = [k for k in REQUIRED if k not in state]
    if missing:
        raise CheckpointError(f"cannot resume: {path} lacks {missing}; it is corrupt, start a new run")
    return state
