"""Say when the simulator compiles, before it does: what numba's cache holds, and the notice
each entry kernel's first call in a process gives when it would compile (the simulator's API
calls :func:`before_first_call`). The expected times and the measurements behind them:
:mod:`billiards.physics.warmup`, which also compiles every kernel ahead of a run."""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path
from typing import Callable

from . import core

# the expected times (seconds) the notices state, measured as billiards.physics.warmup's docstring says
FIRST_SECONDS = 12
MORE_SECONDS = 3

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


__all__ = ["CACHE_DIR", "CHECKED", "ENTRY_KERNELS", "FIRST_SECONDS", "MORE_SECONDS", "before_first_call", "kernels_cached",
           "notice", "ready", "will_compile"]
