"""Thread counts: ``threads=1`` means one thread for torch and for the simulator.

numba starts its thread pool once per process, on its first parallel batch or thread-count
call, and with its OpenMP layer that start sets OpenMP's thread count to ``NUMBA_NUM_THREADS``
in the runtime torch shares, undoing an earlier ``torch.set_num_threads``. Each check runs in a
fresh interpreter (the pool of this test process has long started) with ``NUMBA_NUM_THREADS=2``,
so that a reset is visible on a one-core machine too.
"""

from __future__ import annotations

import pytest
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CHECKS = r"""
import json, sys
import numpy as np
import torch
which = sys.argv[1]
out = {}
if which == "set_threads":
    from billiards.device import set_threads
    from billiards.physics import random_racks, simulate_batch
    set_threads(1)
    racks = random_racks(np.random.default_rng(0), 128)
    simulate_batch(racks, np.tile([0.3, 0.5, 0.0, 0.0], (128, 1)))
    import numba
    out = {"torch": torch.get_num_threads(), "numba": numba.get_num_threads()}
elif which == "torchrl":
    from billiards.envs import make_env
    torch.set_num_threads(1)
    env = make_env(batch_size=128, seed=0)  # 128 >= the parallel threshold: a parallel batch per step
    env.rollout(2)
    out = {"torch": torch.get_num_threads()}
print(json.dumps(out))
"""


def _run(which: str) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS="2", PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("OMP_NUM_THREADS", None)
    proc = subprocess.run([sys.executable, "-c", CHECKS, which], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_set_threads_gives_torch_and_the_simulator_the_count_asked_for():
    """After ``set_threads(1)`` and a parallel-sized batch, torch and numba both use one thread
    (before the fix torch was left at NUMBA_NUM_THREADS: set_threads set torch first)."""
    assert _run("set_threads") == {"torch": 1, "numba": 1}


@pytest.mark.slow
def test_the_torchrl_env_keeps_the_torch_thread_count_a_user_chose():
    """A researcher's ``torch.set_num_threads(1)`` survives making and stepping a TorchRL env
    whose steps are parallel batches. (The gymnasium env steps single shots, which never start
    the pool, and leaves it alone: starting it would also fix multiprocessing's start method,
    which the torch-free gym path keeps unset; tests/envs/test_tools.py.)"""
    assert _run("torchrl") == {"torch": 1}
