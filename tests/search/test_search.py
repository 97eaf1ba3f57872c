"""Search: the lookahead's choice, budgets counted at the simulator, determinism, exact replay."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

import billiards.search.lookahead as lookahead_mod
import billiards.search.puct as puct_mod
import billiards.search.puct_reference as puct_reference_mod
from billiards.physics import random_racks, simulate_batch
from billiards.search import (GeometricProposer, H2Config, LookaheadActor, PolicyProposer, PUCTActor, PUCTConfig, h2_search,
                              puct_search, verifier_reward)
from billiards.search.config import SHIPPED_PROPOSERS
from billiards.search.protocols import run_chain, run_p1

ROOT = Path(__file__).resolve().parents[2]


class Recording:
    """Wraps a proposer and keeps every batch of candidates it emitted."""

    def __init__(self, inner):
        self.inner, self.calls, self.name = inner, [], "recording"

    def propose(self, positions, k, rng):
        out = self.inner.propose(positions, k, rng)
        self.calls.append((positions.copy(), out.copy()))
        return out


class ScoringFirst:
    """A strong prior for PUCT tests: 4k geometric candidates, the k first after ordering those
    that score first (stable). Most children are then live, so the trees grow deep and every
    descent chooses among several children by the PUCT rule."""

    name = "scoring-first"

    def propose(self, positions, k, rng):
        cand = GeometricProposer().propose(positions, 4 * k, rng)
        score = simulate_batch(np.repeat(positions, 4 * k, 0), cand.reshape(-1, 4)).score.reshape(len(positions), 4 * k)
        order = np.argsort(~score, axis=1, kind="stable")[:, :k]
        return np.take_along_axis(cand, order[..., None], axis=1)


@pytest.fixture
def count_sims(monkeypatch):
    """Counts the shots that reach the simulator from the search modules."""
    counter = {"shots": 0}

    def counting(positions, actions, params=None):
        counter["shots"] += len(actions)
        return simulate_batch(positions, actions) if params is None else simulate_batch(positions, actions, params)

    monkeypatch.setattr(lookahead_mod, "simulate_batch", counting)
    monkeypatch.setattr(puct_mod, "simulate_batch", counting)
    monkeypatch.setattr(puct_reference_mod, "simulate_batch", counting)
    return counter


@pytest.fixture(scope="module")
def base_policies():
    """The three shipped policies of the Table 5 "base" proposer, as torch modules."""
    from billiards.rl.policy import load_policy

    return [load_policy(ROOT / "results" / "policies" / "base" / f"seed{s}.pt")[0] for s in range(3)]


def test_lookahead_choice_maximises_r1_plus_gamma_max_r2():
    racks = random_racks(np.random.default_rng(0), 6)
    cfg = H2Config(budget=80, k1=40, m1=5, gamma=0.99)
    prop = Recording(GeometricProposer())
    res = h2_search(racks, prop, cfg, np.random.default_rng(1))
    (pos1, a1), (pos2, a2) = prop.calls
    r1 = verifier_reward(simulate_batch(np.repeat(pos1, cfg.k1, 0), a1.reshape(-1, 4))).reshape(6, cfg.k1)
    after1 = simulate_batch(np.repeat(pos1, cfg.k1, 0), a1.reshape(-1, 4)).positions.reshape(6, cfg.k1, 4, 2)
    r2 = verifier_reward(simulate_batch(np.repeat(pos2, cfg.k2, 0), a2.reshape(-1, 4))).reshape(6, cfg.m1, cfg.k2)
    for s in range(6):
        # the expanded candidates are the top m1 by r1, in proposer order among ties
        top = np.argsort(-r1[s], kind="stable")[: cfg.m1]
        np.testing.assert_array_equal(pos2[s * cfg.m1:(s + 1) * cfg.m1], after1[s, top])
        values = r1[s, top] + cfg.gamma * r2[s].max(axis=1)
        chosen = [k for k in top if np.array_equal(a1[s, k], res.actions[s])]
        assert chosen, "the executed action is one of the simulated candidates"
        assert res.value[s] == pytest.approx(values.max())
        assert r1[s, chosen[0]] + cfg.gamma * r2[s][list(top).index(chosen[0])].max() == pytest.approx(values.max())


def test_one_candidate_without_expansion_plays_the_proposer_action():
    racks = random_racks(np.random.default_rng(2), 5)
    prop = GeometricProposer()
    res = h2_search(racks, prop, H2Config(budget=1, k1=1, m1=0), np.random.default_rng(3))
    expected = prop.propose(racks, 1, np.random.default_rng(3))[:, 0]
    np.testing.assert_array_equal(res.actions, expected)
    assert res.n_sims == 5


def test_search_with_another_proposer_and_stream_leaves_the_actors_own():
    """search_with decides as an actor of that proposer and stream would, and the actor's next
    decision is the one it would have made without it."""
    tables = random_racks(np.random.default_rng(5), 3)
    cfg = H2Config(budget=12, k1=12, m1=0)
    other = GeometricProposer(power_low=0.6, power_high=0.9)
    actor = LookaheadActor(GeometricProposer(), cfg, seed=1)
    got = actor.search_with(tables, other, np.random.default_rng(9))
    want = LookaheadActor(other, cfg, seed=9).search(tables)
    np.testing.assert_array_equal(got.actions, want.actions)
    assert (got.actions[:, 1] >= 0.5).all()  # candidate 0 is the geometric mode p = 0.5; the others 0.6-0.9
    np.testing.assert_array_equal(actor.search(tables).actions, LookaheadActor(GeometricProposer(), cfg, seed=1).search(tables).actions)


def test_actors_use_exactly_the_configured_number_of_simulations(count_sims):
    from tensordict import TensorDict
    import torch

    racks = random_racks(np.random.default_rng(4), 3)
    td = TensorDict({"positions": torch.from_numpy(racks)}, batch_size=[3])
    cfg = H2Config.from_budget(400, 200, 10)
    LookaheadActor(GeometricProposer(), cfg)(td.clone())
    assert count_sims["shots"] == 3 * 400 == 3 * cfg.sims_per_decision
    count_sims["shots"] = 0
    actor = PUCTActor(GeometricProposer(), PUCTConfig(budget=60))
    with pytest.MonkeyPatch.context() as mp:  # every round through simulate_batch, where it is counted
        mp.setattr(puct_mod, "_max_serial", lambda S: 0)
        actor(td.clone())
    assert count_sims["shots"] == 3 * 60 == actor.n_sims
    count_sims["shots"] = 0
    puct_search(racks, GeometricProposer(), PUCTConfig(budget=60), np.random.default_rng(0), impl="reference")
    assert count_sims["shots"] == 3 * 60


@pytest.mark.parametrize("cfg, prior", [
    (PUCTConfig(budget=150), ScoringFirst),  # deep trees, walks often end at max_depth
    (PUCTConfig(budget=100, pool=4, max_depth=4, c_puct=2.0), ScoringFirst),  # samples used up and refilled
    (PUCTConfig(budget=150), GeometricProposer),  # mostly terminal children: the root widens
    (PUCTConfig(budget=60, c_puct=0.0, pw_c=0.5, pw_alpha=1.0, max_depth=1), GeometricProposer),  # flat, no bonus
])
def test_compiled_puct_makes_the_reference_decisions(cfg, prior):
    """The compiled tree and the pure-Python one, from the same generator state, choose the same
    actions with the same values and predictions, and leave the generator in the same state
    (the same proposer calls, in the same order)."""
    racks = random_racks(np.random.default_rng(11), 4)
    rng_ref, rng_new = np.random.default_rng(3), np.random.default_rng(3)
    prop_ref, prop_new = Recording(prior()), Recording(prior())
    ref = puct_search(racks, prop_ref, cfg, rng_ref, impl="reference")
    new = puct_search(racks, prop_new, cfg, rng_new)
    for field in ("actions", "value", "r1", "positions"):
        np.testing.assert_array_equal(getattr(new, field), getattr(ref, field), err_msg=field)
    assert new.n_sims == ref.n_sims == 4 * cfg.budget
    assert rng_new.bit_generator.state == rng_ref.bit_generator.state
    # the same nodes were widened in the same order: the trees grew alike, not just the choice
    assert len(prop_new.calls) == len(prop_ref.calls) > 4
    for (pos_new, _), (pos_ref, _) in zip(prop_new.calls, prop_ref.calls):
        np.testing.assert_array_equal(pos_new, pos_ref)
    # the predicted table and reward are those of the chosen shot
    check = simulate_batch(racks, new.actions)
    np.testing.assert_array_equal(check.positions, new.positions)
    np.testing.assert_array_equal(verifier_reward(check), new.r1)


@pytest.mark.slow
@pytest.mark.parametrize("S", [1, 3, 70])
def test_puct_rounds_simulated_inside_the_tree_equal_simulate_batchs(monkeypatch, S):
    """The compiled rounds simulate their own shots (kernel, carom rule, verifier reward); routed
    instead through simulate_batch, round by round, the search makes the same decisions to the
    bit. 70 states: simulate_batch's threads take rounds of 64 or more when numba has threads."""
    racks = random_racks(np.random.default_rng(21), S)
    cfg = PUCTConfig(budget=80, foul_penalty=0.7)
    inside = puct_search(racks, ScoringFirst(), cfg, np.random.default_rng(5))
    monkeypatch.setattr(puct_mod, "_max_serial", lambda S: 0)
    outside = puct_search(racks, ScoringFirst(), cfg, np.random.default_rng(5))
    for field in ("actions", "value", "r1", "positions"):
        np.testing.assert_array_equal(getattr(inside, field), getattr(outside, field), err_msg=field)
    assert inside.n_sims == outside.n_sims == S * 80


def test_puct_rejects_a_proposers_invalid_shot_with_the_simulators_message():
    class TooHard:
        name = "too-hard"

        def propose(self, positions, k, rng):
            cand = GeometricProposer().propose(positions, k, rng)
            cand[:, -1, 1] = 1.5  # the last sample of every pool: power outside [0, 1]
            return cand

    racks = random_racks(np.random.default_rng(2), 2)
    for impl in ("compiled", "reference"):
        with pytest.raises(ValueError, match=r"power p = 1.5 is outside \[0, 1\]"):
            puct_search(racks, TooHard(), PUCTConfig(budget=200, pool=4), np.random.default_rng(0), impl=impl)


def test_compiled_puct_with_a_trained_ensemble_and_a_stall(base_policies):
    prop = PolicyProposer(base_policies, constrain_aim=True, extra_features=True)
    racks = random_racks(np.random.default_rng(12), 2)
    cfg = PUCTConfig(budget=100, pool=5)
    ref = puct_search(racks, prop, cfg, np.random.default_rng(4), impl="reference")
    new = puct_search(racks, prop, cfg, np.random.default_rng(4))
    np.testing.assert_array_equal(new.actions, ref.actions)
    np.testing.assert_array_equal(new.value, ref.value)
    # a configuration whose walks keep ending at max_depth stops the same way in both
    stall = PUCTConfig(budget=100, pool=3, max_depth=2)
    for impl in ("compiled", "reference"):
        with pytest.raises(RuntimeError, match="PUCT made no progress"):
            puct_search(random_racks(np.random.default_rng(0), 1), GeometricProposer(), stall, np.random.default_rng(7), impl=impl)
    with pytest.raises(ValueError, match="impl must be one of compiled, reference"):
        puct_search(racks, prop, cfg, np.random.default_rng(4), impl="python")
    with pytest.raises(ValueError, match=r"positions of shape \(S, 4, 2\); got \(4, 2\)"):
        puct_search(racks[0], prop, cfg, np.random.default_rng(4))


@pytest.mark.parametrize("S, k", [(1, 16), (5, 7), (3, 1), (2, 200)])
def test_batched_proposer_gives_the_per_policy_candidates(base_policies, S, k):
    """Same generator state in, same candidates out, same generator state after. Equal to float32
    rounding, not bit for bit: both evaluate the networks in float32, but NumPy's and torch's
    matmul kernels sum the 256 products in different orders (and tanh/softplus come from
    different math libraries), so a coordinate can differ in its last float32 bits; the draws,
    their order and every step after the network are the same."""
    kw = dict(constrain_aim=True, extra_features=True)
    batched, reference = PolicyProposer(base_policies, **kw), PolicyProposer(base_policies, impl="reference", **kw)
    assert (batched.impl, reference.impl) == ("batched", "reference")
    racks = random_racks(np.random.default_rng(S), S)
    rng_b, rng_r = np.random.default_rng(9), np.random.default_rng(9)
    a, b = batched.propose(racks, k, rng_b), reference.propose(racks, k, rng_r)
    assert a.shape == b.shape == (S, k, 4) and a.dtype == b.dtype == np.float64
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
    assert rng_b.bit_generator.state == rng_r.bit_generator.state
    if k > 3:  # policy 0's first sample (candidate 3) differs from its mode (candidate 0)
        assert (a[:, 3] != a[:, 0]).any()


def test_policy_proposer_impl_choice_fails_clearly(base_policies):
    import torch

    not_a_policy = torch.nn.Identity()
    assert PolicyProposer([not_a_policy], constrain_aim=False, extra_features=False).impl == "reference"
    with pytest.raises(ValueError, match="proposer 'odd' cannot be batched: not an \\(actor, ScaleAction\\) policy"):
        PolicyProposer([not_a_policy], constrain_aim=False, extra_features=False, name="odd", impl="batched")
    with pytest.raises(ValueError, match="impl must be one of auto, batched, reference; got 'numpy'"):
        PolicyProposer(base_policies, constrain_aim=True, extra_features=True, impl="numpy")


def test_a_fixed_seed_gives_the_same_chain():
    actor = LookaheadActor(GeometricProposer(), H2Config(budget=90, k1=60, m1=3))  # 30 candidates never score the opening shot
    n1, h1 = run_chain(actor, seed=5, cap=25)
    n2, h2 = run_chain(actor, seed=5, cap=25)
    assert n1 == n2 and len(h1) == len(h2)
    for (p1, a1, s1), (p2, a2, s2) in zip(h1, h2):
        np.testing.assert_array_equal(p1, p2)
        np.testing.assert_array_equal(a1, a2)
        assert s1 == s2
    _, h3 = run_chain(actor, seed=6, cap=25)
    assert not all(np.array_equal(x[1], y[1]) for x, y in zip(h1, h3))  # another seed, another chain


@pytest.mark.parametrize("search, proposer", [("h2", "geometric"), ("h2", "base"), ("puct", "geometric"), ("puct", "base")])
def test_search_collector_plays_exactly_the_verified_shot(search, proposer, base_policies):
    prop = GeometricProposer() if proposer == "geometric" else PolicyProposer(base_policies, constrain_aim=True, extra_features=True)
    if search == "h2":
        actor = LookaheadActor(prop, H2Config(budget=100, k1=60, m1=4))
    else:
        actor = PUCTActor(prop, PUCTConfig(budget=100))
    res = run_p1(actor, n_innings=6, shots=4, seed=0, progress=False)
    assert len(res.values) == 6 and res.sims_per_decision == 100
    # the predicted immediate reward of every executed shot came true in the environment
    assert res.extra["mispredicted_shots"] == 0
    assert res.extra["success_per_shot"] > 0.5


def run_search(*args, cwd=ROOT):
    """``python search.py <args>`` in ``cwd`` (conftest.app_here: in this process, a multirun in a process of its own)."""
    from conftest import app_here

    return app_here("search.py", *args, cwd=cwd)


@pytest.mark.slow
def test_search_entry_point_writes_results(tmp_path):
    out = tmp_path / "run"
    proc = run_search("protocol=p3", "protocol.seeds=2", "protocol.cap=4", "search.k1=40", "search.m1=4",
                      "search.budget=80", "progress=false", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-2000:]
    data = json.loads((out / "results.json").read_text())
    assert data["protocol"] == "p3" and data["search"] == "h2" and data["proposer"] == "geometric"
    assert len(data["values"]) == 2 and data["sims_per_decision"] == 80
    assert (out / "longest_chain.png").stat().st_size > 1000
    # the report command lays search results out as the paper's Table 6
    from billiards.report import report

    text = report([tmp_path])
    line = next(line for line in text.splitlines() if line.startswith("| geometric"))
    row = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]  # cells "ours \| paper"
    # P1 h=2 and PUCT not run, P3 h=2 this run (2 chains capped at 4), P3 PUCT not run; no paper figures
    assert row[1:5] == ["— \\| —", "— \\| —", f"{data['mean']:.1f} ({data['max']:.0f}, cap 4, 2 chains) \\| —", "— \\| —"], row


SEARCH_BAD = [
    ("search.kind=bfs", "search.kind must be one of h2, puct"),
    ("search.k1=175", "not a non-negative multiple of m1"),
    ("protocol=p9", "protocol"),
    ("search.budgett=3", "budgett"),
]


@pytest.mark.slow
@pytest.mark.parametrize("override, message", SEARCH_BAD)
def test_each_bad_search_knob_is_refused_with_its_message(tmp_path, override, message):
    from conftest import refusal

    out = tmp_path / "never"
    assert message in refusal("search.py", override, f"hydra.run.dir={out}")
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.parametrize("override, message", SEARCH_BAD[1:2])
def test_bad_search_overrides_fail_fast_and_write_nothing(tmp_path, override, message):
    out = tmp_path / "never"
    proc = run_search(override, f"hydra.run.dir={out}")
    assert proc.returncode != 0
    assert message in proc.stderr + proc.stdout
    assert not out.exists()


@pytest.mark.slow
def test_policy_proposer_from_a_training_run(tmp_path):
    """A trained run (here a smoke run) becomes a proposer: candidate 0 is the policy's
    deterministic action through the aim constraint, sampling follows the caller's rng only."""
    import torch
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from billiards import domain
    from billiards.rl.policy import load_policy
    from billiards.search.proposers import load_policy_proposer

    run = tmp_path / "run"
    from conftest import app_here

    proc = app_here("train.py", "budget=smoke", "env=aim_features", "progress=false", f"hydra.run.dir={run}", cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    prop = load_policy_proposer([run], name="smoke")
    assert prop.constrain_aim and prop.extra_features
    racks = random_racks(np.random.default_rng(8), 4)
    torch.manual_seed(123)
    before = torch.rand(1)
    torch.manual_seed(123)
    a = prop.propose(racks, 6, np.random.default_rng(0))
    assert torch.equal(torch.rand(1), before)  # torch's global generator untouched
    np.testing.assert_array_equal(a, prop.propose(racks, 6, np.random.default_rng(0)))
    assert a.shape == (4, 6, 4) and np.isfinite(a).all()
    assert ((a[..., 1] >= 0) & (a[..., 1] <= 1)).all() and (np.abs(a[..., 2:]) <= 1).all()
    policy, _ = load_policy(run / "checkpoint.pt")
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        mode = policy(TensorDict({"observation": prop.observation(racks)}, batch_size=[4]))["action"].detach().double().numpy()
    # to float32 rounding: the proposer evaluates the network with NumPy (see the batched test)
    np.testing.assert_allclose(a[:, 0, 1:], np.clip(mode[:, 1:], [0, -1, -1], [1, 1, 1]), rtol=0, atol=1e-6)
    np.testing.assert_allclose(a[:, 0, 0], domain.constrained_theta(racks, np.clip(mode[:, 0], -1, 1)), rtol=0, atol=1e-6)
    res = h2_search(racks, prop, H2Config(budget=16, k1=8, m1=2), np.random.default_rng(1))
    assert res.actions.shape == (4, 4) and res.n_sims == 4 * 16

    # the small exported policy file proposes exactly what the full checkpoint does
    from billiards.rl.policy import export_policy

    small = export_policy(run, tmp_path / "policies" / "seed0.pt")
    assert small.stat().st_size < (run / "checkpoint.pt").stat().st_size / 5
    exported = load_policy_proposer([small], name="smoke")
    np.testing.assert_array_equal(exported.propose(racks, 6, np.random.default_rng(0)), a)
    (tmp_path / "bad.pt").write_bytes(b"nope")
    with pytest.raises(Exception, match="corrupt or not a torch file"):
        load_policy(tmp_path / "bad.pt")


SHIPPED = sorted(SHIPPED_PROPOSERS)


@pytest.mark.slow
def test_shipped_proposers_work_out_of_the_box(tmp_path):
    """`python search.py proposer=<name>` runs from a fresh checkout: the exported policies
    of every conf/proposer/<name>.yaml are in the repository and load as one ensemble."""
    from billiards.search.config import shipped_proposer
    from billiards.search.proposers import load_policy_proposer

    racks = random_racks(np.random.default_rng(5), 2)
    for name in SHIPPED:
        cfg = shipped_proposer(name)
        assert cfg.kind == "policy" and len(cfg.checkpoints) == 3
        prop = load_policy_proposer([ROOT / c for c in cfg.checkpoints], name=name)
        res = h2_search(racks, prop, H2Config(budget=16, k1=8, m1=2), np.random.default_rng(1))
        assert res.actions.shape == (2, 4) and np.isfinite(res.actions).all()
    if SHIPPED:  # one through the entry point
        out = tmp_path / "run"
        proc = run_search(f"proposer={SHIPPED[0]}", "protocol=p3", "protocol.seeds=1", "protocol.cap=3", "search.k1=40",
                          "search.m1=4", "search.budget=80", "progress=false", "picture=false", f"hydra.run.dir={out}")
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert json.loads((out / "results.json").read_text())["proposer"] == SHIPPED[0]


@pytest.mark.slow
def test_a_missing_proposer_checkpoint_fails_fast(tmp_path):
    out = tmp_path / "never"
    proc = run_search("proposer=policy", "proposer.checkpoints=[results/policies/none/seed0.pt]",
                      f"hydra.run.dir={out}")
    assert proc.returncode != 0 and "no checkpoint at results/policies/none/seed0.pt" in proc.stderr
    assert not out.exists()
