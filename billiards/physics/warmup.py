"""Say when the simulator compiles, before it does, and compile it ahead of a run.

numba compiles each kernel on its first call and caches the machine code in
``billiards/physics/__pycache__`` (``cache=True``; under ``$NUMBA_CACHE_DIR`` where that is set),
so only the first use on a machine, or the first after the kernels changed, pays it:

* the first entry kernel (a single shot, a serial or a parallel batch) with the event loop all
  of them share: about ``FIRST_SECONDS`` (10-12 s measured);
* each further entry kernel, the event loop cached: about ``MORE_SECONDS`` (1-3.5 s);
* all three (:func:`warm_up`): about ``WARM_UP_SECONDS`` (13.8-15.2 s).

Measured at commit d5c25ac with issue #56's compile-time changes (``core``'s "Compile time"),
on this two-core machine with one other process running (a training run or a test suite, load
average 1.0-2.2), from an empty cache::

    NUMBA_CACHE_DIR=$(mktemp -d) python -c "from billiards.physics.warmup import warm_up; warm_up()"

13.8-15.2 s wall, 13.1-14.2 s CPU, over six runs (the same command took 30.0-34.2 s, 29-30 s CPU,
at 83a856e, before those changes). ``benchmarks/bench_simulator.py``'s first call with an empty
cache (a shot and a batch of 4) took 11.7-12.1 s (28.8-31.5 s before).

Every path that compiles says so first, once per entry kernel and process: the simulator's
API (:func:`billiards.physics.simulate_shot`, :func:`~billiards.physics.simulate_batch`)
calls :func:`~billiards.physics.first_use.before_first_call` before an entry kernel's first call in the process, which says
nothing when the kernel is loaded already or numba's cache holds it, and otherwise writes a
line with the expected time to stderr, compiles it, and says how long that took. So the
evaluation, the matches, both environments and the viewer say so on their first shot;
training and search call :func:`warm_up` before their progress bars start, which says so in
their own log, compiles all three and leaves nothing for the API to say.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from . import core
from .api import PARALLEL_MIN_BATCH, canonical_rack, simulate_batch, simulate_shot
from .first_use import (CACHE_DIR, CHECKED, ENTRY_KERNELS, FIRST_SECONDS, MORE_SECONDS, before_first_call, kernels_cached,
                        notice, ready, will_compile)
from .params import DEFAULT_PARAMS, PhysicsParams

WARM_UP_SECONDS = 15  # the expected time of warm_up's compilation (seconds), measured as the docstring says
SLOW = 3.0  # seconds: a warm-up longer than this compiled something


def warm_up(params: PhysicsParams = DEFAULT_PARAMS, log: Callable[[str], None] = print) -> float:
    """Run one tiny shot through every entry kernel (single shot, serial and parallel batch);
    returns the seconds it took. Says beforehand when the kernels are not cached yet, and
    afterwards how long the compilation took when it did; the simulator's API then has nothing
    left to say in this process."""
    cached = kernels_cached()
    CHECKED.update(getattr(core, name) for name in ENTRY_KERNELS)  # said here, not by the API
    if not cached:
        log(notice(WARM_UP_SECONDS, run="run"))
    t0 = time.perf_counter()
    rack = canonical_rack(params)
    action = np.array([0.3, 0.5, 0.0, 0.0])
    simulate_shot(rack, action, params)
    for n in (1, PARALLEL_MIN_BATCH):
        simulate_batch(np.repeat(rack[None], n, axis=0), np.repeat(action[None], n, axis=0), params)
    seconds = time.perf_counter() - t0
    if not cached or seconds > SLOW:
        log(ready(seconds))
    return seconds


__all__ = ["CACHE_DIR", "CHECKED", "ENTRY_KERNELS", "FIRST_SECONDS", "MORE_SECONDS", "SLOW", "WARM_UP_SECONDS",
           "before_first_call", "kernels_cached", "notice", "ready", "warm_up", "will_compile"]
