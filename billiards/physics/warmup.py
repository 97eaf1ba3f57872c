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
calls :func:`before_first_call` before an entry kernel's first call in the process, which says
nothing when the kernel is loaded already or numba's cache holds it, and otherwise writes a
line with the expected time to stderr, compiles it, and says how long that took. So the
evaluation, the matches, both environments and the viewer say so on their first shot;
training and search call :func:`warm_up` before their progress bars start, which says so in
their own log, compiles all three and leaves nothing for the API to say.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path
from typing import Callable

import numpy as np

from . import core
from .params import DEFAULT_PARAMS, PhysicsParams

# the expected times (seconds) the notices state, measured as the module's docstring says
FIRST_SECONDS = 12
MORE_SECONDS = 3
WARM_UP_SECONDS = 15
SLOW = 3.0  # seconds: a warm-up longer than this compiled something

ENTRY_KERNELS = {"checked_shot": "single-shot kernel", "run_batch_serial": "batch kernel",
                 "run_batch": "parallel batch kernel"}
CHECKED: set = set()  # the entry kernels whose first call in this process was prepared for
_FIRST_CALLS = threading.Lock()


def _numba_cache_dir() -> Path:
    """Where numba caches the kernels of ``core``: the folder its own cache locator chose (the
    package's ``__pycache__``, ``$NUMBA_CACHE_DIR/...`` where that is set, or a user-wide folder
    where the package's is read-only)."""
    located = getattr(getattr(core.run_batch, "_cache", None), "_cache_path", None)
    return Path(located) if located else Path(core.__file__).resolve().parent / "__pycache__"


CACHE_DIR = _numba_cache_dir()


def _in_cache(kernel) -> bool:
    """Whether numba's cache (``CACHE_DIR``) holds ``kernel`` compiled from this source for this
    CPU: its index file, and in it (read as numba reads it) an entry for this machine; an index
    left by an edited source or another numba has none. Where numba's cache objects are not
    what this expects, any index file of the kernel counts."""
    name = kernel.py_func.__name__
    try:
        cache_file = kernel._cache._cache_file  # numba's IndexDataCacheFile
        if not (CACHE_DIR / Path(cache_file._index_path).name).exists():
            return False
        magic = kernel.targetctx.codegen().magic_tuple()
        return any(key[1] == magic for key in cache_file._load_index())
    except Exception:  # another numba: fall back on the index file's name
        return any(CACHE_DIR.glob(f"core.{name}-*.nbi"))


def will_compile(kernel) -> bool:
    """Whether the next call of ``kernel`` (a kernel of ``core``) compiles: not loaded in this
    process yet, and not in numba's cache (False under ``NUMBA_DISABLE_JIT``)."""
    if getattr(kernel, "overloads", None) is None:
        return False
    return not kernel.overloads and not _in_cache(kernel)


def kernels_cached() -> bool:
    """Whether numba's cache holds the entry kernels (single shot, serial and parallel batch)
    compiled from this source for this machine."""
    return all(_in_cache(getattr(core, name)) for name in ENTRY_KERNELS)


def _stderr(message: str) -> None:
    """One line on stderr: above the progress bars where tqdm draws some (an app's), else plain."""
    tqdm = sys.modules.get("tqdm")
    if tqdm is not None and hasattr(tqdm, "tqdm"):
        tqdm.tqdm.write(message, file=sys.stderr)
    else:
        print(message, file=sys.stderr, flush=True)


def notice(seconds: float, what: str = "the simulator", run: str = "use") -> str:
    """The line said before a compilation expected to take about ``seconds``."""
    return f"compiling {what} (first {run} on this machine: about {seconds:.0f} s on two cores; cached for every later run) ..."


def ready(seconds: float) -> str:
    """The line said after a compilation that took ``seconds``."""
    return f"simulator ready: compiled in {seconds:.0f} s (cached in {CACHE_DIR})"


def before_first_call(kernel, *args, log: Callable[[str], None] | None = None) -> None:
    """Prepare the first call in this process of an entry kernel of ``core`` with ``args``: when
    it would compile, say so with the expected time (``log``, default stderr), compile it for
    these arguments' types and say how long that took; otherwise do nothing. Each kernel once
    per process (:data:`CHECKED`; threads that come meanwhile wait for it)."""
    with _FIRST_CALLS:
        if kernel in CHECKED:
            return
        if will_compile(kernel):
            say = log or _stderr
            if will_compile(core.run_shot):  # the event loop too: the first compilation on this machine
                say(notice(FIRST_SECONDS))
            else:
                say(notice(MORE_SECONDS, f"the simulator's {ENTRY_KERNELS[kernel.py_func.__name__]}"))
            import numba

            t0 = time.perf_counter()
            kernel.compile(tuple(numba.typeof(a) for a in args))
            say(ready(time.perf_counter() - t0))
        CHECKED.add(kernel)


def warm_up(params: PhysicsParams = DEFAULT_PARAMS, log: Callable[[str], None] = print) -> float:
    """Run one tiny shot through every entry kernel (single shot, serial and parallel batch);
    returns the seconds it took. Says beforehand when the kernels are not cached yet, and
    afterwards how long the compilation took when it did; the simulator's API then has nothing
    left to say in this process."""
    from .api import PARALLEL_MIN_BATCH, canonical_rack, simulate_batch, simulate_shot

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


__all__ = ["before_first_call", "kernels_cached", "warm_up", "will_compile"]
