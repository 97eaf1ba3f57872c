"""Where the networks run: the ``device`` option (``auto``, ``cpu``, ``cuda``, ``cuda:N``).

The simulator always runs on the CPU (numba); a device option moves what learns -- networks,
losses, optimizers, the replay buffer -- onto a GPU. Two functions, shared by every app:

* :func:`device_error` checks a spelling (and, for ``cuda``, that the GPU exists) and returns
  a message, or None when the device can be used; configs call it while validating, before
  any directory is written;
* :func:`resolve_device` turns a valid spelling into a :class:`torch.device`: ``auto`` is
  the current CUDA GPU when there is one (``torch.cuda.is_available()``), else the CPU;
  ``cuda`` is the current GPU (``cuda:0`` unless ``CUDA_VISIBLE_DEVICES`` or the process chose
  another), always with its index.

And the threads a process computes with, for the networks (torch) and the simulator's batches
(numba): :func:`set_threads` sets both, :func:`start_numba_threads` starts numba's thread pool
without disturbing torch's count (see there why the order matters).

Importing this module costs nothing: torch and numba are imported inside the functions, and
only when needed (``cpu`` and ``auto`` are checked without torch).
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

DEVICES = "auto, cpu, cuda or cuda:N"
_SPELLING = re.compile(r"(auto|cpu|cuda)(?::(\d{1,3}))?")


def _parse(spec: str) -> tuple[str, int | None] | None:
    m = _SPELLING.fullmatch(str(spec).strip())
    if m is None or (m.group(2) is not None and m.group(1) != "cuda"):
        return None
    return m.group(1), None if m.group(2) is None else int(m.group(2))


def device_error(spec: str, key: str = "device") -> str | None:
    """Why ``spec`` cannot be used as a device here (a message naming ``key``), or None."""
    parsed = _parse(spec)
    if parsed is None:
        return f"{key}={spec!r} is not a device: use {DEVICES}"
    kind, index = parsed
    if kind != "cuda":
        return None
    import torch

    if not torch.cuda.is_available():
        return (f"{key}={spec}: this machine has no CUDA GPU that torch can use (torch {torch.__version__}, "
                f"CUDA build: {torch.version.cuda or 'no'}); use {key}=cpu, or {key}=auto to take a GPU only when there is one")
    count = torch.cuda.device_count()
    if index is not None and index >= count:
        return f"{key}={spec}: this machine has {count} CUDA GPU(s), cuda:0 to cuda:{count - 1}"
    return None


def resolve_device(spec: str) -> torch.device:
    """The :class:`torch.device` of a valid spelling (ValueError with :func:`device_error`'s
    message otherwise); ``auto``: ``cuda`` when torch sees a GPU, else ``cpu``."""
    import torch

    error = device_error(spec)
    if error is not None:
        raise ValueError(error)
    kind, index = _parse(spec)
    if kind == "auto":
        kind = "cuda" if torch.cuda.is_available() else "cpu"
    if kind == "cpu":
        return torch.device("cpu")
    return torch.device("cuda", torch.cuda.current_device() if index is None else index)


def start_numba_threads() -> None:
    """Start numba's thread pool now (a no-op once started), keeping torch's thread count.

    numba starts its pool on the first parallel simulator batch or thread-count call. With its
    OpenMP layer (numba's default where OpenMP is found, as here) the start sets OpenMP's
    thread count to ``NUMBA_NUM_THREADS`` (all cores by default) in the OpenMP runtime torch
    shares, silently undoing an earlier ``torch.set_num_threads``: a ``threads=1`` training run
    then computed its networks with two threads and spent about five times the CPU time on a
    busy two-core machine. Called before torch's count is set (:func:`set_threads`) or when a
    TorchRL env is made, the count a process chose stays. (Starting the pool also fixes
    multiprocessing's start method; the torch-free gymnasium env, whose single shots never
    start it, does not call this.)
    """
    import sys

    import numba

    torch = sys.modules.get("torch")
    keep = torch.get_num_threads() if torch is not None else None
    numba.get_num_threads()  # starts the pool
    if keep is not None and torch.get_num_threads() != keep:
        torch.set_num_threads(keep)


def set_threads(n: int) -> None:
    """``n`` threads for torch's operations and for the simulator's batches (numba's, at most
    ``NUMBA_NUM_THREADS``) in this process; numba's pool first (:func:`start_numba_threads`)."""
    import numba
    import torch

    if int(n) < 1:
        raise ValueError(f"threads must be >= 1, got {n!r}")
    start_numba_threads()
    numba.set_num_threads(min(int(n), numba.config.NUMBA_NUM_THREADS))
    torch.set_num_threads(int(n))


def threads_error(n, key: str = "threads") -> str | None:
    """Why ``n`` threads cannot be used here (None when they can): at least one, at most the cores
    this process may run on (more would only oversubscribe them; far more fails inside the
    thread libraries, after a run directory was written)."""
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= cores:
        return f"{key} must be an integer in [1, {cores}] (the cores this machine gives the process), got {n!r}"
    return None


__all__ = ["DEVICES", "device_error", "resolve_device", "set_threads", "start_numba_threads", "threads_error"]
