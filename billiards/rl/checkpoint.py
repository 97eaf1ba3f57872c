"""Checkpoints of a training run: one file, ``<run dir>/checkpoint.pt``, replaced atomically.

Contents (a dict saved with ``torch.save``):

* ``config``: the resolved training config (plain containers);
* ``agent``: the agent's ``state_dict`` (actor, critics, target critics / target actor,
  SAC's log-temperature) and ``agent_extra`` (optimizer states, update counter);
* ``buffer``: the filled part of the replay buffer and its write cursor (off-policy, unless
  ``checkpoint.save_buffer=false``), or None;
* ``counters``: env frames, fractional update debt, next log/eval/checkpoint steps,
  accumulated training seconds;
* ``eval_history``: every periodic evaluation so far;
* ``rng``: torch, numpy, python and the training env's rack generator states;
* ``wandb_id``: to continue the same wandb run.

Written to ``checkpoint.pt.tmp``, flushed and fsynced, then ``os.replace``d over the old one,
so a kill at any moment leaves either the previous or the new checkpoint, never half of one.
"""

from __future__ import annotations

import os
import pickle
import zipfile
from pathlib import Path
from typing import Any

import torch

from .config import CHECKPOINT_FILE

FORMAT_VERSION = 1


class CheckpointError(RuntimeError):
    """A missing, unreadable or incompatible checkpoint; the message says what to do."""


def save_checkpoint(run_dir: Path, state: dict[str, Any]) -> Path:
    path = Path(run_dir) / CHECKPOINT_FILE
    tmp = path.with_name(path.name + ".tmp")
    state = {"format_version": FORMAT_VERSION, **state}
    with tmp.open("wb") as f:
        torch.save(state, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    return path


def load_checkpoint(run_dir: str | Path) -> dict[str, Any]:
    run_dir = Path(run_dir)
    path = run_dir / CHECKPOINT_FILE
    if not run_dir.is_dir():
        raise CheckpointError(f"cannot resume: {run_dir} is not a directory")
    if not path.is_file():
        raise CheckpointError(
            f"cannot resume: {path} does not exist (the run was killed before its first checkpoint, "
            f"every budget.checkpoint_every steps); start a new run instead"
        )
    try:
        # Our own file: it holds numpy/python RNG states, hence weights_only=False.
        state = torch.load(path, map_location="cpu", weights_only=False)
    except (RuntimeError, EOFError, OSError, pickle.UnpicklingError, zipfile.BadZipFile, ValueError) as err:
        raise CheckpointError(
            f"cannot resume: {path} is corrupt or truncated ({type(err).__name__}: {err}); "
            f"delete it to start over, or start a new run"
        ) from None
    if not isinstance(state, dict) or state.get("format_version") != FORMAT_VERSION:
        version = state.get("format_version") if isinstance(state, dict) else None
        raise CheckpointError(
            f"cannot resume: {path} is not a billiards training checkpoint of format {FORMAT_VERSION} (found {version!r})"
        )
    missing = [k for k in ("config", "agent", "agent_extra", "counters", "rng") if k not in state]
    if missing:
        raise CheckpointError(f"cannot resume: {path} lacks {missing}; it is corrupt, start a new run")
    return state
