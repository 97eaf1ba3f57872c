"""The reward model's offline data set: uniformly random shots from uniformly random racks.

Layout of a data directory (all arrays memory-mapped ``.npy``, row k = shot k):

* ``positions.npy`` (n, 4, 2) float32 ball centres before the shot (white, yellow, red1, red2);
* ``actions.npy``   (n, 4) float32 raw actions (theta, p, a, b);
* ``score.npy``, ``foul.npy`` (n,) uint8 carom outcome of the shot;
* ``meta.json``: n, seed, chunk, chunks_done, generation rate, git commit, physics params.

Rows come in chunks of ``chunk`` rows; chunk i is drawn from its own generator
``default_rng(SeedSequence([seed, i]))`` (:func:`draw_chunk`: racks, then uniform actions)
and simulated in float64 exactly as drawn, then stored as float32. The data set is therefore a
pure function of (n, seed, chunk), however many runs or resumes produced it.

Generation is resumable: after each chunk is written and flushed, ``meta.json``'s
``chunks_done`` is updated atomically, and re-running :func:`generate` on the same directory
with the same (n, seed, chunk) continues from there. An array file found shorter than the
chunks done (truncated, e.g. by a disk full or an interrupted copy) is never zero-filled:
generation goes back to the last chunk every file holds and redraws the rest, and
:func:`load_dataset` refuses it.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from datetime import datetime, timezone
from pathlib import Path

import numba
import numpy as np
from tqdm import tqdm

from billiards import compat
from billiards.device import start_numba_threads
from billiards.domain import ACTION_HIGH, ACTION_LOW
from billiards.files import atomic_write_text
from billiards.physics import DEFAULT_PARAMS, PhysicsParams, get_params, random_racks, simulate_batch
from billiards.physics.config import physics_record, recorded_physics
from billiards.provenance import git_commit

META_FILE = "meta.json"
DEFAULT_N = 10_000_000
DEFAULT_CHUNK = 65_536
# name -> (per-row shape, dtype) of each array file
ARRAYS = {
    "positions": ((4, 2), np.float32),
    "actions": ((4,), np.float32),
    "score": ((), np.uint8),
    "foul": ((), np.uint8),
}


class DatasetError(ValueError):
    """A data directory that is unfinished, inconsistent or was made with other parameters."""


# ----------------------------------------------------------------------------- drawing


def n_chunks(n: int, chunk: int) -> int:
    """Number of chunks covering n rows."""
    return -(-n // chunk)


def chunk_rows(i: int, n: int, chunk: int) -> tuple[int, int]:
    """Row range [start, stop) of chunk i."""
    return i * chunk, min(n, (i + 1) * chunk)


def draw_chunk(seed: int, i: int, size: int, params: PhysicsParams = DEFAULT_PARAMS) -> tuple[np.ndarray, np.ndarray]:
    """The float64 (positions (size, 4, 2), actions (size, 4)) of chunk i of a data set with
    this seed: ``random_racks`` of ``params``'s table then actions uniform in [ACTION_LOW,
    ACTION_HIGH), both from ``default_rng(SeedSequence([seed, i]))``. ``size`` is the chunk's
    row count."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, i]))
    positions = random_racks(rng, size, params)
    actions = rng.uniform(ACTION_LOW, ACTION_HIGH, size=(size, 4))
    return positions, actions


# ----------------------------------------------------------------------------- files


def read_meta(out_dir) -> dict:
    """The data set's ``meta.json`` as a dict, in today's form (:func:`billiards.compat.upgrade_artefact_meta`);
    DatasetError if missing or unreadable."""
    path = Path(out_dir) / META_FILE
    try:
        return compat.upgrade_artefact_meta(json.loads(path.read_text()))
    except FileNotFoundError:
        raise DatasetError(f"{path} not found: {out_dir} is not a reward-model data set") from None
    except (OSError, json.JSONDecodeError) as err:
        raise DatasetError(f"{path} is unreadable: {err}") from None


def _write_meta(out_dir: Path, meta: dict) -> None:
    atomic_write_text(out_dir / META_FILE, json.dumps(meta, indent=2) + "\n")


def _layout(path: Path, name: str, n: int) -> tuple[int, int]:
    """``(header bytes, rows stored)`` of the array file ``path`` of a data set of n rows, from
    its header and its size. DatasetError if it is unreadable, of another shape or dtype, or
    longer than n rows. Fewer rows than n means the file was truncated."""
    shape, dtype = ARRAYS[name]
    try:
        with path.open("rb") as f:
            version = np.lib.format.read_magic(f)
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            found_shape, fortran, found_dtype = read_header(f)
            header = f.tell()
        size = path.stat().st_size
    except (OSError, ValueError) as err:
        raise DatasetError(f"cannot open {path}: {err}") from None
    if found_shape != (n, *shape) or found_dtype != dtype or fortran:
        raise DatasetError(f"{path} has shape {found_shape} {found_dtype}, expected {(n, *shape)} {np.dtype(dtype)}")
    row_bytes = math.prod(shape) * np.dtype(dtype).itemsize
    if size - header > n * row_bytes:
        raise DatasetError(f"{path} is {size:,} bytes, longer than its {n:,} rows ({header + n * row_bytes:,} bytes)")
    return header, (size - header) // row_bytes


def _open_array(out_dir: Path, name: str, n: int, mode: str) -> np.memmap:
    """Open ``name.npy`` as a memmap in ``mode`` ("r" or "r+"), checking shape, dtype and that
    the file holds all n rows (numpy would silently zero-fill a truncated file opened "r+")."""
    path = out_dir / f"{name}.npy"
    _, rows = _layout(path, name, n)
    if rows < n:
        raise DatasetError(f"{path} is truncated: it holds {rows:,} of {n:,} rows")
    try:
        return np.lib.format.open_memmap(path, mode=mode)
    except (OSError, ValueError) as err:
        raise DatasetError(f"cannot open {path}: {err}") from None


def _regenerate_truncated(out_dir: Path, meta: dict) -> None:
    """If an array file holds fewer rows than the chunks done, set ``chunks_done`` back to the
    chunks every file holds in full (meta.json first), then restore the files' length, so that
    generation redraws and rewrites the lost chunks -- the data are a pure function of
    (n, seed, chunk) -- instead of keeping zeros."""
    n, chunk, done = meta["n"], meta["chunk"], meta["chunks_done"]
    layouts = {name: _layout(out_dir / f"{name}.npy", name, n) for name in ARRAYS}
    held = min(rows for _, rows in layouts.values())
    needed = chunk_rows(done - 1, n, chunk)[1]
    if held >= needed:
        return
    keep = held // chunk
    short = [f"{name}.npy ({rows:,} rows)" for name, (_, rows) in layouts.items() if rows < needed]
    warnings.warn(f"{out_dir}: {', '.join(short)} truncated below the {needed:,} rows generated; "
                  f"regenerating from chunk {keep} of {meta['n_chunks']}", stacklevel=3)
    meta.update(chunks_done=keep, rows_done=chunk_rows(keep, n, chunk)[0], finished=False)
    _write_meta(out_dir, meta)  # first: a kill after it leaves a directory that resumes correctly
    for name, (header, _) in layouts.items():
        shape, dtype = ARRAYS[name]
        with (out_dir / f"{name}.npy").open("r+b") as f:
            f.truncate(header + n * math.prod(shape) * np.dtype(dtype).itemsize)


def _create_array(out_dir: Path, name: str, n: int) -> np.memmap:
    shape, dtype = ARRAYS[name]
    return np.lib.format.open_memmap(out_dir / f"{name}.npy", mode="w+", dtype=dtype, shape=(n, *shape))


def _start(out_dir: Path, n: int, seed: int, chunk: int, params: PhysicsParams) -> tuple[dict, dict[str, np.memmap]]:
    """Meta and writable arrays of a new or partly generated data set in out_dir."""
    if (out_dir / META_FILE).exists():
        meta = read_meta(out_dir)
        found = {k: meta.get(k) for k in ("n", "seed", "chunk")}
        if found != {"n": n, "seed": seed, "chunk": chunk}:
            raise DatasetError(
                f"{out_dir} already holds a data set with n={found['n']}, seed={found['seed']}, "
                f"chunk={found['chunk']}; asked for n={n}, seed={seed}, chunk={chunk}. "
                f"Use another directory or delete this one."
            )
        made_on = recorded_physics(meta["physics_params"])
        if made_on != params:
            raise DatasetError(
                f"{out_dir} holds a data set on physics {made_on.describe()!r}; asked for {params.describe()!r}. "
                f"Use another directory or pass --physics {made_on.describe()}."
            )
        if meta.get("chunks_done") == 0:  # nothing stored yet (killed while creating the arrays)
            return meta, {name: _create_array(out_dir, name, n) for name in ARRAYS}
        _regenerate_truncated(out_dir, meta)
        return meta, {name: _open_array(out_dir, name, n, "r+") for name in ARRAYS}
    stale = [f"{name}.npy" for name in ARRAYS if (out_dir / f"{name}.npy").exists()]
    if stale:
        raise DatasetError(f"{out_dir} has {', '.join(stale)} but no {META_FILE}; refusing to overwrite them")
    out_dir.mkdir(parents=True, exist_ok=True)
    meta = {
        "n": n,
        "seed": seed,
        "chunk": chunk,
        "n_chunks": n_chunks(n, chunk),
        "chunks_done": 0,
        "finished": False,
        "rows_done": 0,
        "wall_seconds": 0.0,
        "shots_per_s": None,
        "git_commit": git_commit(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        **physics_record(params),
        "action_low": ACTION_LOW.tolist(),
        "action_high": ACTION_HIGH.tolist(),
        "sessions": [],
    }
    _write_meta(out_dir, meta)  # meta first: a crash right after leaves a resumable dir
    return meta, {name: _create_array(out_dir, name, n) for name in ARRAYS}


# ----------------------------------------------------------------------------- generation


def generate(
    out_dir,
    n: int = DEFAULT_N,
    seed: int = 0,
    chunk: int = DEFAULT_CHUNK,
    progress: bool = True,
    threads: int | None = None,
    max_chunks: int | None = None,
    physics: PhysicsParams | str | dict | None = None,
) -> dict:
    """Generate (or resume generating) n random shots into out_dir; returns the meta dict.

    threads: numba threads for the simulator during this call (default: numba's current
    setting; restored afterwards). max_chunks: stop after this many chunks in this call
    (for tests and time-boxed runs; the directory stays resumable). The returned dict is
    ``meta.json`` plus ``session_rows``, ``session_seconds`` and ``session_shots_per_s``
    for this call. A finished data set with the same parameters is a no-op.
    ``physics`` is the table (a preset name, PhysicsParams or dict; default korean_medium).
    Raises DatasetError if out_dir holds a data set with other (n, seed, chunk, physics).
    """
    params = get_params(physics)
    for name, value, low in (("n", n, 1), ("seed", seed, 0), ("chunk", chunk, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    if max_chunks is not None and max_chunks < 0:
        raise ValueError(f"max_chunks must be >= 0, got {max_chunks!r}")
    if threads is not None and not 1 <= threads <= numba.config.NUMBA_NUM_THREADS:
        raise ValueError(f"threads must lie in [1, {numba.config.NUMBA_NUM_THREADS}], got {threads!r}")
    n, seed, chunk = int(n), int(seed), int(chunk)
    out_dir = Path(out_dir)
    meta, arrays = _start(out_dir, n, seed, chunk, params)
    total = meta["n_chunks"]
    first = meta["chunks_done"]
    last = total if max_chunks is None else min(total, first + max_chunks)

    start_numba_threads()  # before numba's first thread query, which would reset torch's count
    previous_threads = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(threads)
    session = {
        "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "git_commit": git_commit(),
        "threads": numba.get_num_threads(),
        "chunks": [first, first],
        "rows": 0,
        "seconds": 0.0,
    }
    rows_before = chunk_rows(first, n, chunk)[0]
    bar = tqdm(total=n, initial=rows_before, unit="shot", unit_scale=True, dynamic_ncols=True,
               disable=not progress or first >= last, desc="generate")
    t0 = time.perf_counter()
    try:
        for i in range(first, last):
            start, stop = chunk_rows(i, n, chunk)
            positions, actions = draw_chunk(seed, i, stop - start, params)
            result = simulate_batch(positions, actions, params)
            arrays["positions"][start:stop] = positions
            arrays["actions"][start:stop] = actions
            arrays["score"][start:stop] = result.score
            arrays["foul"][start:stop] = result.foul
            for arr in arrays.values():
                arr.flush()
            elapsed = time.perf_counter() - t0
            session.update(chunks=[first, i + 1], rows=stop - rows_before, seconds=elapsed)
            meta.update(
                chunks_done=i + 1,
                rows_done=stop,
                finished=i + 1 == total,
                wall_seconds=sum(s["seconds"] for s in meta["sessions"]) + elapsed,
            )
            meta["shots_per_s"] = meta["rows_done"] / meta["wall_seconds"] if meta["wall_seconds"] > 0 else None
            _write_meta(out_dir, {**meta, "sessions": meta["sessions"] + [session]})
            bar.update(stop - start)
    finally:
        bar.close()
        if threads is not None:
            numba.set_num_threads(previous_threads)
        del arrays
    if session["rows"]:
        meta["sessions"].append(session)
    seconds = session["seconds"]
    return {
        **meta,
        "session_rows": session["rows"],
        "session_seconds": seconds,
        "session_shots_per_s": session["rows"] / seconds if seconds > 0 else None,
    }


def load_dataset(out_dir) -> dict[str, np.memmap]:
    """The finished data set in out_dir as read-only memmaps ``positions``, ``actions``,
    ``score``, ``foul`` (see the module docstring). Raises DatasetError for a missing,
    unfinished or inconsistent directory."""
    out_dir = Path(out_dir)
    meta = read_meta(out_dir)
    n, done, total = meta.get("n"), meta.get("chunks_done"), meta.get("n_chunks")
    if not isinstance(n, int) or done != total or not meta.get("finished"):
        raise DatasetError(
            f"data set {out_dir} is unfinished ({done} of {total} chunks); resume it with "
            f"`python -m billiards.rm generate --out {out_dir} --n {n} --seed {meta.get('seed')} --chunk {meta.get('chunk')}`"
        )
    for name in ARRAYS:
        path = out_dir / f"{name}.npy"
        rows = _layout(path, name, n)[1]
        if rows < n:
            raise DatasetError(
                f"{path} is truncated: it holds {rows:,} of {n:,} rows; `python -m billiards.rm generate --out {out_dir} "
                f"--n {n} --seed {meta.get('seed')} --chunk {meta.get('chunk')}` regenerates the missing rows"
            )
    return {name: _open_array(out_dir, name, n, "r") for name in ARRAYS}
