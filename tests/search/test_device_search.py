"""The device option on the search side: a policy proposer's networks on a device.

This machine has no GPU, so the transfer path (modules moved with ``.to``, the observation sent
once per decision, candidates brought back with ``.cpu()``) is exercised with ``device=cpu``
and the torch implementation, against the default proposer; a GPU must fail clearly where
there is none.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from billiards.physics import random_racks
from billiards.search.proposers import PolicyProposer, load_policy_proposer

ROOT = Path(__file__).resolve().parents[2]
BASE = [ROOT / "results" / "policies" / "base" / f"seed{s}.pt" for s in range(3)]


def test_the_device_path_gives_the_cpu_candidates():
    """``device=cpu`` through the torch path equals the default torch path bit for bit and the
    batched NumPy path to float32 rounding; the generator advances identically."""
    default = load_policy_proposer(BASE, name="base")
    on_device = load_policy_proposer(BASE, name="base", device="cpu")
    reference = PolicyProposer(on_device.policies, constrain_aim=True, extra_features=True, impl="reference",
                               device=torch.device("cpu"))
    assert (default.impl, reference.impl, str(reference.device)) == ("batched", "reference", "cpu")
    racks = random_racks(np.random.default_rng(3), 4)
    rngs = [np.random.default_rng(11) for _ in range(3)]
    plain = PolicyProposer(on_device.policies, constrain_aim=True, extra_features=True, impl="reference")
    a, b, c = default.propose(racks, 30, rngs[0]), reference.propose(racks, 30, rngs[1]), plain.propose(racks, 30, rngs[2])
    np.testing.assert_array_equal(b, c)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
    assert rngs[0].bit_generator.state == rngs[1].bit_generator.state == rngs[2].bit_generator.state
    assert reference.observation(racks).device.type == "cpu"


def test_a_gpu_proposer_needs_the_torch_implementation_and_a_gpu():
    prop = load_policy_proposer(BASE, name="base")
    with pytest.raises(ValueError, match="the batched implementation runs in NumPy on the CPU"):
        PolicyProposer(prop.policies, constrain_aim=True, extra_features=True, impl="batched", device="cuda")
    if not torch.cuda.is_available():
        with pytest.raises((RuntimeError, AssertionError)):
            PolicyProposer(prop.policies, constrain_aim=True, extra_features=True, device="cuda")


def _search(tmp_path, *overrides: str, timeout: float = 900):
    """``python search.py <overrides>`` in ``tmp_path``, in this process (conftest.app_here)."""
    from conftest import app_here

    return app_here("search.py", *overrides, cwd=tmp_path)


@pytest.mark.slow
def test_search_app_device_cpu_end_to_end(tmp_path):
    """``python search.py device=cpu`` with a trained ensemble plays through the device path and
    records the device; its decisions equal the default's (``auto``, the CPU here)."""
    common = ["proposer=base", "protocol=p1", "protocol.n_innings=1", "protocol.shots=3",
              "search.budget=60", "search.k1=20", "search.m1=4", "picture=false", "progress=false", "threads=1"]
    results = {}
    for device in ("cpu", "auto"):
        proc = _search(tmp_path, *common, f"device={device}", f"hydra.run.dir={tmp_path / device}")
        assert proc.returncode == 0, proc.stderr
        import json

        results[device] = json.loads((tmp_path / device / "results.json").read_text())
    assert results["cpu"]["device"] == "cpu"
    assert results["auto"]["device"] == ("cuda:0" if torch.cuda.is_available() else "cpu")
    if not torch.cuda.is_available():
        assert results["cpu"]["values"] == results["auto"]["values"]


@pytest.mark.slow
@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
@pytest.mark.parametrize("device", ["cuda", "cuda:1", "gpu"])
def test_search_app_refuses_a_device_it_cannot_use_and_writes_nothing(tmp_path, device):
    proc = _search(tmp_path, f"device={device}", timeout=900)
    expected = "is not a device" if device == "gpu" else "this machine has no CUDA GPU that torch can use"
    assert proc.returncode != 0 and expected in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []
