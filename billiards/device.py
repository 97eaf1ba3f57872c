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

Importing this module costs nothing: torch is imported inside the functions, and only when a
spelling needs it (``cpu`` and ``auto`` are checked without it).
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


__all__ = ["DEVICES", "device_error", "resolve_device"]
