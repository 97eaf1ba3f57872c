"""Reproducible anywhere: nothing committed names a folder of the machine that wrote it, the
committed report regenerates byte for byte from the committed run directories, and the
project's own arithmetic (networks, elementary functions) gives the same bits whatever BLAS
kernel, NumPy loops or numba target the processor picks, and the simulator's kernels free every
array they allocate. Each check under another setting runs in a fresh interpreter: OpenBLAS,
NumPy and numba read the setting (OPENBLAS_CORETYPE, NPY_DISABLE_CPU_FEATURES, NUMBA_CPU_NAME,
NUMBA_NRT_STATS) once, when a process starts."""

from __future__ import annotations

import functools
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]

# absolute paths that belong to one machine: home and work folders, mounted volumes, Windows
# user folders (generic scratch examples such as /tmp/x and shebangs such as /usr/bin/env are not)
MACHINE_PATH = re.compile("|".join([r"(?<![\w.])/" + d + "/" for d in ("work", "root", "home", "Users", "mnt", "scratch")]
                                   + [r"[A-Z]:\\\\Users\\\\"]))


def _tracked_text_files() -> list[Path]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, text=True)
    if out.returncode != 0:
        pytest.skip("not a git checkout")
    files = []
    for name in out.stdout.split("\0"):
        path = REPO / name
        if name and path.is_file() and b"\0" not in path.read_bytes()[:8192]:
            files.append(path)
    return files


@pytest.mark.slow
def test_no_tracked_text_file_names_a_machines_folder():
    offenders = []
    for path in _tracked_text_files():
        for n, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if MACHINE_PATH.search(line):
                offenders.append(f"{path.relative_to(REPO)}:{n}: {line.strip()[:120]}")
    assert not offenders, "absolute paths of a machine in tracked files:\n" + "\n".join(offenders[:20])


def test_the_path_scan_catches_what_it_looks_for():
    assert MACHINE_PATH.search('"command": ["' + "/ro" + 'ot/.pyenv/bin/python"]')
    assert MACHINE_PATH.search("hydra.run.dir=" + "/wo" + "rk/campaign/outputs")
    assert not MACHINE_PATH.search("#!/usr/bin/env bash") and not MACHINE_PATH.search("--out /tmp/t")
    assert not MACHINE_PATH.search("results/training/paper/table1/sac/seed0")


@pytest.mark.slow
def test_the_committed_report_regenerates_byte_for_byte(tmp_path):
    """results/reproduction.json names its command; run with --out, it rewrites the committed
    reproduction.json and .md from the committed run directories, to the byte."""
    committed = json.loads((REPO / "results" / "reproduction.json").read_text())
    command = committed["regenerate"].split()
    assert command[:3] == ["python", "-m", "billiards.campaign"]
    from conftest import app_here

    # python -m <module> <args>, as recorded, in this process (conftest.app_here)
    proc = app_here(command[2], *command[3:], "--out", str(tmp_path), cwd=tmp_path, env={"MPLBACKEND": "Agg"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("reproduction.json", "reproduction.md"):
        assert (tmp_path / name).read_bytes() == (REPO / "results" / name).read_bytes(), name
    assert sorted(p.name for p in (tmp_path / "img").iterdir()) == sorted(
        Path(f).name for f in committed["figures"].values())


# ----------------------------------------------------------------------------- same bits on every CPU

def _cross_cpu():
    """benchmarks/cross_cpu.py: its settings and its probe of the networks and functions (one
    definition, the script's)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("cross_cpu", REPO / "benchmarks" / "cross_cpu.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


CROSS_CPU = _cross_cpu()
KERNELS = {name: env for name, (env, promised) in CROSS_CPU.SETTINGS.items() if promised}


@functools.lru_cache(maxsize=None)
def _probe_of(setting: str) -> str:
    return _probe(KERNELS[setting])


def _probe(extra_env: dict) -> str:
    proc = subprocess.run([sys.executable, "-c", CROSS_CPU.PROBE], cwd=REPO, env=CROSS_CPU._env(extra_env),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout.strip().splitlines()[-1]


@pytest.mark.slow
@pytest.mark.parametrize("kernel", ["openblas_prescott", "openblas_haswell", "numba_generic", "numpy_no_avx2"])
def test_networks_and_functions_give_the_same_bits_under_another_kernel(kernel):
    """The proposer ensemble, the shot ranker, the elementary functions and the observation of
    the same tables hash the same under another OpenBLAS kernel, numba's generic target and
    NumPy's baseline loops as under this machine's defaults."""
    assert _probe_of(kernel) == _probe_of("default")


# (rows, outputs): a few outputs (lanes across rows), and many with rows in several blocks and a remainder
@pytest.mark.parametrize("S,O", [(5, 6), (19, 11), (3, 1)])
def test_dense_sums_in_index_order_in_float32(S, O):
    """numerics.dense is the documented arithmetic, not merely close to it: each output sums
    x_i * w_io in float32 in index order, then adds the bias (checked against a Python loop),
    whichever loop order the layer's shape takes."""
    from billiards import numerics

    rng = np.random.default_rng(3)
    x = rng.standard_normal((2, S, 37)).astype(np.float32) * 100
    w = rng.standard_normal((2, 37, O)).astype(np.float32)
    b = rng.standard_normal((2, O)).astype(np.float32)
    out = numerics.dense(x, w, b, relu=True)
    for e in range(2):
        for s in range(S):
            for o in range(O):
                acc = np.float32(0)
                for i in range(37):
                    acc = np.float32(acc + np.float32(x[e, s, i] * w[e, i, o]))
                v = np.float32(acc + b[e, o])
                assert out[e, s, o] == (v if v > 0 else 0)
    shared = numerics.dense(x[:1], w, b)  # one input for every layer of the stack
    assert shared.shape == (2, S, O) and np.array_equal(shared[0], numerics.dense(x[:1], w[:1], b[:1])[0])
    with pytest.raises(ValueError, match="do not chain"):
        numerics.dense(x, w[:, :36], b)


def test_starting_a_process_on_a_loaded_machine_is_retried(monkeypatch):
    """The suite's patient Popen (tests/conftest.py): a fork refused for a moment (EAGAIN) is
    tried again with a back-off instead of failing the test that started it."""
    import conftest

    real, calls = conftest._popen_init, []

    def flaky(self, *args, **kwargs):
        calls.append(1)
        if len(calls) <= 2:
            raise BlockingIOError(11, "Resource temporarily unavailable")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(conftest, "_popen_init", flaky)
    monkeypatch.setattr(conftest.time, "sleep", lambda s: None)
    out = subprocess.run([sys.executable, "-c", "print('started')"], capture_output=True, text=True, timeout=900)
    assert out.stdout.strip() == "started" and len(calls) == 3


# ----------------------------------------------------------------------------- every array freed

LEAK_CHECK = """
import dataclasses
import numpy as np
from numba.core.runtime import rtsys
from billiards.physics import PRESETS, random_racks, simulate_batch, simulate_shot
# lively balls and cloth: long shots, event logs that grow past their first 64 rows
P = dataclasses.replace(PRESETS["international"], u_roll=0.0002, e_ball=1.0, e_cushion=0.98)
rng = np.random.default_rng(0)
racks = random_racks(rng, 300, P)
acts = np.column_stack([rng.uniform(0, 2 * np.pi, 300), np.ones(300), rng.uniform(-1, 1, (300, 2))])
simulate_batch(racks[:2], acts[:2], P), simulate_shot(racks[0], acts[0], P)  # compile or load
before = rtsys.get_allocation_stats()
batch = simulate_batch(racks, acts, P)
logs = [simulate_shot(r, a, P).event_time.size for r, a in zip(racks, acts)]
del batch
after = rtsys.get_allocation_stats()
print(after.alloc - before.alloc, after.free - before.free, after.mi_alloc - before.mi_alloc,
      after.mi_free - before.mi_free, max(logs))
"""


@pytest.mark.slow
def test_the_kernel_frees_every_array_it_allocates():
    """The event loop's helpers run without numba's reference counting (see core's
    docstring); every array a shot allocates (state, caches, outcome vectors, an event log
    grown past its first 64 rows) is freed all the same, on the batch and the single path."""
    env = {**os.environ, "NUMBA_NRT_STATS": "1"}
    out = subprocess.run([sys.executable, "-c", LEAK_CHECK], env=env, capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[2])
    alloc, free, mi_alloc, mi_free, longest_log = map(int, out.stdout.split())
    assert alloc > 1000 and alloc == free and mi_alloc == mi_free
    assert longest_log > 64
