"""One API test every search actor passes (as tests/envs/test_api.py is for the envs): each
method search.py composes (``search=h2|puct|robust``, :data:`billiards.search.config.OPTIONS`),
exact and under execution noise, over the training-free proposer.

The contract, checked the same way for all of them:

* the actor reads ``positions`` (B, 4, 2) from a TensorDict and writes ``action`` (B, 4)
  float64 -- power and spin inside the raw action box, the angle within one turn either way
  (the proposers' angles come from ``atan2``, in (-pi, pi]; the simulator plays any angle, and
  wrapping them would change the bits of every recorded search) -- and ``search_r1`` (B, 1),
  the verified reward of its choice;
* it never spends more than its budget per decision, counted at the simulator;
* the same seed replays the same decisions bit for bit (``reseed``), another seed may differ;
* run by a TorchRL collector on the bare env in place of a policy, the env plays exactly the
  shot the actor verified: an exact actor's ``search_r1`` is the env's reward.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from billiards import domain
from billiards.physics import DEFAULT_PARAMS, random_racks
from billiards.physics.noise import get_noise
from billiards.search.actors import build_actor
from billiards.search.config import OPTIONS
from billiards.search.proposers import GeometricProposer

BUDGET = 60
CASES = {  # kind -> (overrides that fit BUDGET, execution noise)
    "h2": ({"k1": 30, "m1": 3}, None),
    "puct": ({"pool": 8, "max_depth": 3}, None),
    "puct-fastfiz": ({"pool": 8, "max_depth": 3}, "fastfiz"),
    "robust-fastfiz": ({"k1": 20, "target": 0, "m1": 0}, "fastfiz"),
}


def make_actor(case: str, seed: int = 0):
    overrides, noise = CASES[case]
    kind = case.split("-")[0]
    schema = OPTIONS["search"][1][kind]
    settings = schema(budget=BUDGET, **overrides).settings()
    noise_model = get_noise(noise) if noise else None
    return build_actor(settings, GeometricProposer(), seed, DEFAULT_PARAMS, noise=noise_model), noise_model


def racks(n: int, seed: int = 11) -> np.ndarray:
    return random_racks(np.random.default_rng(seed), n)


def test_every_method_search_py_composes_has_a_case_here():
    assert {case.split("-")[0] for case in CASES} == set(OPTIONS["search"][1])


@pytest.mark.parametrize("case", list(CASES))
def test_every_search_actor_keeps_the_contract(case):
    actor, _ = make_actor(case)
    positions = racks(3)
    td = TensorDict({"positions": torch.from_numpy(positions)}, batch_size=[3])
    out = actor(td)
    action, r1 = out["action"], out["search_r1"]
    assert action.dtype == torch.float64 and action.shape == (3, 4) and r1.shape == (3, 1)
    low, high = domain.ACTION_LOW, domain.ACTION_HIGH  # the angle: any real one within a turn either way
    a = action.numpy()
    assert np.all(np.abs(a[:, 0]) <= high[0]) and np.all(a[:, 1:] >= low[1:]) and np.all(a[:, 1:] <= high[1:]), a
    assert actor.n_decisions == 3 and 0 < actor.n_sims <= 3 * BUDGET

    again, _ = make_actor(case)
    td2 = TensorDict({"positions": torch.from_numpy(positions)}, batch_size=[3])
    np.testing.assert_array_equal(again(td2)["action"].numpy(), action.numpy())
    actor.reseed(0)
    td3 = TensorDict({"positions": torch.from_numpy(positions)}, batch_size=[3])
    np.testing.assert_array_equal(actor(td3)["action"].numpy(), action.numpy())


@pytest.mark.parametrize("case", list(CASES))
def test_every_search_actor_runs_in_a_collector_and_the_env_plays_its_shot(case):
    from billiards.envs import BilliardsEnv
    from billiards.search.actors import make_search_collector

    actor, noise = make_actor(case)
    env = BilliardsEnv(2, seed=5, noise=noise) if noise else BilliardsEnv(2, seed=5)
    collector = make_search_collector(env, actor, frames_per_batch=4, total_frames=4)
    (batch,) = list(collector)
    collector.shutdown()
    assert batch["action"].shape[-1] == 4 and torch.isfinite(batch["action"]).all()
    if noise is None:
        torch.testing.assert_close(batch["next", "reward"].to(torch.float64), batch["search_r1"].to(torch.float64))
