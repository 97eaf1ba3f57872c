"""Compile the simulator's kernels before a run starts, and say so.

numba compiles each kernel on its first call (about 30-60 s for the whole simulator on this
machine) and caches the machine code in ``billiards/physics/__pycache__`` (``cache=True``; under
``$NUMBA_CACHE_DIR`` where that is set), so
only the first run on a machine, or after the kernels changed, pays it. :func:`warm_up` makes
that cost visible: entry points call it before their progress bars start, instead of sitting
at 0 % in silence.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np

from . import core
from .api import PARALLEL_MIN_BATCH, canonical_rack, simulate_batch, simulate_shot
from .params import DEFAULT_PARAMS, PhysicsParams


def _numba_cache_dir() -> Path:
    """Where numba caches the kernels of ``core``: the folder its own cache locator chose (the
    package's ``__pycache__``, ``$NUMBA_CACHE_DIR/...`` where that is set, or a user-wide folder
    where the package's is read-only)."""
    located = getattr(getattr(core.run_batch, "_cache", None), "_cache_path", None)
    return Path(located) if located else Path(core.__file__).resolve().parent / "__pycache__"


CACHE_DIR = _numba_cache_dir()
SLOW = 3.0  # seconds: a warm-up longer than this compiled something


def kernels_cached() -> bool:
    """Whether numba's cache holds the entry kernels (index files of run_batch, its serial
    twin and checked_shot); stale entries of edited kernels are recompiled all the same."""
    return all(any(CACHE_DIR.glob(f"core.{name}-*.nbi")) for name in ("run_batch", "run_batch_serial", "checked_shot"))


def warm_up(params: PhysicsParams = DEFAULT_PARAMS, log: Callable[[str], None] = print) -> float:
    """Run one tiny shot through every entry kernel (single shot, serial and parallel batch);
    returns the seconds it took. Says beforehand when the kernels are not cached yet, and
    afterwards how long the compilation took when it did."""
    cached = kernels_cached()
    if not cached:
        log("compiling the simulator (first run on this machine: about a minute; cached for every later run) ...")
    t0 = time.perf_counter()
    rack = canonical_rack(params)
    action = np.array([0.3, 0.5, 0.0, 0.0])
    simulate_shot(rack, action, params)
    for n in (1, PARALLEL_MIN_BATCH):
        simulate_batch(np.repeat(rack[None], n, axis=0), np.repeat(action[None], n, axis=0), params)
    seconds = time.perf_counter() - t0
    if not cached or seconds > SLOW:
        log(f"simulator ready: compiled in {seconds:.0f} s (cached in {CACHE_DIR})")
    return seconds


__all__ = ["kernels_cached", "warm_up"]
