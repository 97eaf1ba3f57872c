"""Expert iteration (``python train.py algo=exit``, billiards/exit.py): the labelling rule, runs
on a tiny budget (under noise, from a trained policy), and the config's refusals. The loop end
to end, stopped by a signal and resumed to the uninterrupted run's bits, and its exported
policy played alone and as a proposer: tests/rl/test_train.py (a signal gets a process)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from test_train import REPO, check_finished, ok, train

SAC_POLICY = "results/policies/base/seed0.pt"  # SAC with the aim constraint and the carom features
TINY = ["algo=exit", "env=aim_features", "algo.innings=10", "algo.shots_per_round=200", "algo.search_budget=60",
        "algo.k1=20", "algo.m1=2", "algo.batch_size=64", "algo.epochs=2", "budget=smoke", "budget.total_steps=600",
        "budget.eval_every=200", "budget.checkpoint_every=200", "budget.log_every=200", "budget.eval_innings=5",
        "budget.final_eval_innings=10"]


def test_the_label_is_the_best_valued_candidate_nearest_the_proposers_own_shot():
    from billiards import domain
    from billiards.envs.gym_vector import Billiards4BallVectorEnv
    from billiards.exit import nearest_best
    from billiards.physics import DEFAULT_PARAMS
    from billiards.search.lookahead import h2_values
    from billiards.search.proposers import GeometricProposer
    from billiards.search.settings import H2Config

    _, info = Billiards4BallVectorEnv(40, start="random").reset(seed=11)
    positions = info["positions"]
    for cfg in (H2Config(budget=60, k1=20, m1=2).settings(), H2Config(budget=30, k1=30, m1=0).settings()):
        raw, target, sims = nearest_best(positions, GeometricProposer(), cfg, np.random.default_rng(3), DEFAULT_PARAMS)
        v = h2_values(positions, GeometricProposer(), cfg, np.random.default_rng(3), DEFAULT_PARAMS)
        assert sims == v.n_sims == 40 * cfg.sims_per_decision
        pool = v.top if cfg.m1 else np.broadcast_to(np.arange(cfg.k1), v.r1.shape)
        value = v.value if cfg.m1 else v.r1
        x = domain.normalized_aim_action(positions[:, None], v.candidates, DEFAULT_PARAMS.ball_radius)
        for s in range(40):
            chosen = [j for j, k in enumerate(pool[s]) if np.array_equal(v.candidates[s, k], raw[s])]
            assert chosen and value[s, chosen[0]] == value[s].max()  # a best-valued candidate
            best = [k for j, k in enumerate(pool[s]) if value[s, j] == value[s].max()]
            distance = [np.linalg.norm(x[s, k] - x[s, 0]) for k in best]
            assert np.linalg.norm(target[s] - x[s, 0]) == pytest.approx(min(distance))  # nearest the proposer's own shot
        # the target is the label's own aim-constrained, normalised action: it plays the same shot
        assert np.abs(target).max() <= 1.0
        again = domain.raw_action(target, positions, constrain_aim=True, normalized=True)
        assert np.allclose(np.mod(again[:, 0] - raw[:, 0] + np.pi, 2 * np.pi) - np.pi, 0.0, atol=1e-12)
        assert np.allclose(again[:, 1:], raw[:, 1:], atol=1e-12)


def test_a_centred_label_is_a_good_shot_at_the_middle_of_its_good_neighbours_and_tolerates_error():
    """algo.centre_probes: each label moves to the mean of itself and its probes that score
    without a foul, where it and that mean do; the raw shot played is the label's; on 400 tables
    the centred labels lose less to a small error than the labels they started from."""
    from billiards import domain
    from billiards.envs.gym_vector import Billiards4BallVectorEnv
    from billiards.exit import centred, nearest_best
    from billiards.physics import DEFAULT_PARAMS, simulate_batch
    from billiards.search.proposers import GeometricProposer
    from billiards.search.settings import H2Config

    params, R = DEFAULT_PARAMS, DEFAULT_PARAMS.ball_radius
    _, info = Billiards4BallVectorEnv(400, start="random").reset(seed=12)
    positions = info["positions"]
    raw, x, _ = nearest_best(positions, GeometricProposer(), H2Config(budget=400, k1=200, m1=10).settings(),
                             np.random.default_rng(4), params)

    def good(shots):
        res = simulate_batch(positions, shots, params)
        return (res.score > 0) & ~res.foul

    moved_raw, moved, sims = centred(positions, raw, x, 16, 0.02, np.random.default_rng(5), params)
    assert sims == 400 * 18
    kept = np.any(moved != x, axis=1)
    assert 0.3 < kept.mean() and not np.any(kept & ~good(raw))  # only a good label moves
    assert np.all(good(moved_raw)[kept])  # to a good shot
    assert np.array_equal(moved_raw[~kept], raw[~kept])  # the others play as labelled
    again = domain.raw_action(moved[kept], positions[kept], R, constrain_aim=True, normalized=True)
    assert np.allclose(again, moved_raw[kept])  # the label is the shot played
    assert np.abs(moved[kept]).max() <= 1.0 and 0.0 < np.abs(moved - x)[kept].max() < 0.1
    err = np.random.default_rng(6).normal(0.0, 0.01, x.shape)

    def tolerance(labels):  # on the tables whose label is a good shot
        return good(domain.raw_action(np.clip(labels + err, -1, 1), positions, R, constrain_aim=True, normalized=True))[good(raw)].mean()

    assert tolerance(moved) > tolerance(x) + 0.02, (tolerance(moved), tolerance(x))


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_under_noise_the_label_is_the_default_noisy_searchs_own_choice():
    """The noisy labeller is search.py's default search for the noise (the position-aware robust
    search and the preset's shot ranker) at the run's budget; a label is that search's chosen
    shot for the same generator, as the policy's normalised action; a mixed proposer gives the
    policy's share of the candidates first, the rest from round 0's proposer."""
    from types import SimpleNamespace

    from omegaconf import OmegaConf

    from billiards import domain
    from billiards.envs.gym_vector import Billiards4BallVectorEnv
    from billiards.exit import noisy_labels, noisy_search
    from billiards.physics import DEFAULT_PARAMS
    from billiards.physics.noise import get_noise
    from billiards.search.proposers import GeometricProposer, MixedProposer
    from billiards.search.robust import robust_search

    cfg = OmegaConf.create({"noise": {"preset": "fastfiz"}, "physics": {"preset": "korean_medium"},
                            "algo": {"search_budget": 330}})
    noise = get_noise("fastfiz")
    actor, first = noisy_search(SimpleNamespace(cfg=cfg), DEFAULT_PARAMS, noise)
    assert actor.cfg.kind == "robust" and actor.cfg.budget == 330 and actor.cfg.position > 0 and actor.value is not None
    assert type(first).__name__ == "RankedProposer" and actor.noise == noise
    _, info = Billiards4BallVectorEnv(12, start="random").reset(seed=5)
    positions = info["positions"]
    mixed = MixedProposer(GeometricProposer(), first, 0.5)
    raw, target, sims = noisy_labels(positions, actor, mixed, np.random.default_rng(9), DEFAULT_PARAMS)
    own = robust_search(positions, mixed, actor.cfg, np.random.default_rng(9), DEFAULT_PARAMS, noise, value=actor.value)
    assert np.array_equal(raw, own.actions) and sims == own.n_sims == 12 * 330
    # with a tolerance: the proposer's own shot (candidate 0, here the ranker's best) wherever the
    # choice beats it by no more
    ranked = MixedProposer(first, GeometricProposer(), 0.5)
    own = robust_search(positions, ranked, actor.cfg, np.random.default_rng(9), DEFAULT_PARAMS, noise, value=actor.value)
    assert own.own is not None and np.array_equal(own.own, ranked.propose(positions, 1, np.random.default_rng(9))[:, 0])
    finite = own.own_margin[np.isfinite(own.own_margin)]
    assert (own.own_margin >= 0).all() and len(finite) > 2 and (finite == 0).mean() < 1  # sampled, and sometimes beaten
    tol = float(np.median(finite[finite > 0]))
    kept, _, _ = noisy_labels(positions, actor, ranked, np.random.default_rng(9), DEFAULT_PARAMS, tolerance=tol)
    near = own.own_margin <= tol
    assert near.any() and (~near).any()
    assert np.array_equal(kept[near], own.own[near]) and np.array_equal(kept[~near], own.actions[~near])
    again = domain.raw_action(target, positions, constrain_aim=True, normalized=True)
    assert np.allclose(np.mod(again[:, 0] - raw[:, 0] + np.pi, 2 * np.pi) - np.pi, 0.0, atol=1e-12)
    assert np.allclose(again[:, 1:], raw[:, 1:], atol=1e-12)
    # the mixture: ceil(share * k) of the first proposer's candidates (its mode first), then the second's
    a, b = GeometricProposer(), GeometricProposer(power_low=0.1, power_high=0.2)
    rng, check = np.random.default_rng(1), np.random.default_rng(1)
    got = MixedProposer(a, b, 0.3).propose(positions, 10, rng)
    assert np.array_equal(got, np.concatenate([a.propose(positions, 3, check), b.propose(positions, 7, check)], axis=1))
    assert np.array_equal(MixedProposer(a, b, 1.0).propose(positions, 4, np.random.default_rng(2)),
                          a.propose(positions, 4, np.random.default_rng(2)))
    with pytest.raises(ValueError, match="share must lie in"):
        MixedProposer(a, b, 1.5)


@pytest.mark.slow
def test_an_exit_run_under_noise_labels_with_the_noisy_search_and_plays_its_shots_with_noise(tmp_path):
    """algo=exit noise=fastfiz on a tiny budget: two rounds, the second over a policy sharing the
    candidates with the shot ranker; the run records its noise and evaluates under it."""
    run = tmp_path / "noisy"
    ok(train(tmp_path, "algo=exit", "env=aim_features", "noise=fastfiz", "algo.innings=10", "algo.shots_per_round=100",
             "algo.search_budget=320", "algo.batch_size=32", "algo.epochs=1", "algo.policy_share=0.5", "budget=smoke",
             "budget.total_steps=200", "budget.eval_every=100", "budget.checkpoint_every=100", "budget.log_every=100",
             "budget.eval_innings=5", "budget.final_eval_innings=5", f"hydra.run.dir={run}"))
    check_finished(run, 200, innings=5)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["algo"] == "exit" and summary["noise"] == "fastfiz" and summary["updates"] == round(100 / 32) + round(200 / 32)
    assert json.loads((run / "eval.json").read_text())["noise"] == "fastfiz"  # the policy evaluated under the run's noise
    rounds = [line for line in (run / "train.log").read_text().splitlines() if "the search scored" in line]
    assert len(rounds) == 2


@pytest.mark.parametrize("overrides, message", [
    (("algo=exit",), "algo=exit learns aim-constrained shots: it needs env.constrain_aim=true"),
    (("algo=exit", "env=aim_features", "noise=variable"), "algo=exit under variable noise is not built"),
    (("algo=exit", "env=aim_features", "algo.policy_share=0"), "algo.policy_share must lie in (0, 1], got 0.0"),
    (("algo=exit", "env=aim_features", "algo.centre_probes=-1"), "algo.centre_probes must be >= 0, got -1"),
    (("algo=exit", "env=aim_features", "noise=fastfiz", "algo.centre_probes=8"), "algo.centre_probes centres exact play's"),
    (("algo=exit", "env=aim_features", "algo.label_tolerance=0.1"), "algo.label_tolerance picks among the noisy search's"),
    (("algo=exit", "env=aim_features", "noise=fastfiz", "algo.label_tolerance=-1"), "algo.label_tolerance must be >= 0"),
    (("algo=exit", "env=aim_features", "noise=fastfiz", "algo.search_budget=300"),
     "algo=exit under noise=fastfiz labels with search.py's search for it at algo.search_budget=300 simulations: "
     "search (robust): schedule=halving leaves 0 simulations"),
    (("algo=exit", "env=aim_features", "algo.k1=395"), "algo.search_budget - algo.k1 (400 - 395) must be a multiple"),
    (("algo=exit", "env=aim_features", "algo.innings=300"), "must be whole blocks of algo.innings x 10 shots (3000)"),
    (("algo=exit", "env=aim_features", "algo.init_policy=results/policies/nowhere.pt"),
     "algo.init_policy: results/policies/nowhere.pt is not an exported policy file"),
    (("algo=exit", "env=aim_features", f"algo.init_policy={SAC_POLICY}", "algo.hidden_sizes=[64,64]"),
     f"algo.init_policy: {SAC_POLICY} cannot start this policy: hidden_sizes=[256, 256] (this run: [64, 64])"),
    (("algo=exit", "env=aim", f"algo.init_policy={SAC_POLICY}"), "extra_features=True (this run: False)"),
    (("algo=exit", "env=aim_features", "physics=international", f"algo.init_policy={SAC_POLICY}"),
     "its table is physics=korean_medium's (this run: physics=international)"),
])
def test_bad_exit_configs_are_refused_with_their_message(tmp_path, overrides, message):
    from conftest import refusal

    assert message in refusal("train.py", *overrides, cwd=tmp_path)


def test_the_trainer_alone_refuses_exit_without_its_loop(tmp_path):
    from hydra import compose, initialize_config_dir

    from billiards.rl.train import train as train_library

    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base=None):
        cfg = compose("config", TINY)
    with pytest.raises(SystemExit, match="algo=exit has no training loop here"):
        train_library(cfg, tmp_path / "run")
    assert not (tmp_path / "run").exists()


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_an_exit_run_can_start_from_a_trained_policy_which_proposes_from_round_0(tmp_path):
    """algo.init_policy: the policy starts from an exported SAC policy's actor (at a learning
    rate too small to move it, the run ends with those weights) and that policy, not the
    geometric proposer, proposes in round 0, so its labels are the search's corrections of
    the SAC shots: the round-0 search scores as the search over SAC does, above the geometric
    proposer's at the same budget."""
    import torch

    from billiards.rl.checkpoint import load_checkpoint
    from billiards.rl.policy import init_actor_state

    one_round = [*TINY, "budget.total_steps=200", "algo.lr=1e-12"]
    started, plain = tmp_path / "started", tmp_path / "plain"
    ok(train(tmp_path, *one_round, f"algo.init_policy={SAC_POLICY}", f"hydra.run.dir={started}"))
    ok(train(tmp_path, *one_round, f"hydra.run.dir={plain}"))
    actor = load_checkpoint(started)["agent"]
    for key, weight in init_actor_state(SAC_POLICY).items():
        assert torch.allclose(actor[f"actor.{key}"], weight, atol=1e-6), key
    assert "the policy starts from" in (started / "train.log").read_text()

    def round_0(run) -> float:
        line = next(x for x in (run / "train.log").read_text().splitlines() if "round 0: the search scored" in x)
        return float(line.split("scored ")[1].split(" %")[0])

    def eval_pct(run) -> float:
        return json.loads((run / "eval.json").read_text())["success_per_shot_pct"]

    assert round_0(started) > round_0(plain) + 5.0
    assert eval_pct(started) > eval_pct(plain) + 20.0  # SAC's ~65 % against an untrained network

    # the learning curve starts a run from a trained policy at that policy's training CPU time
    from billiards.exit import learning_curve
    from billiards.rl.policy import policy_summary

    data = learning_curve([started, plain], [], tmp_path / "curve.png")
    hours = policy_summary(SAC_POLICY)["cpu_seconds"] / 3600
    assert hours > 0.1 and (tmp_path / "curve.png").stat().st_size > 0
    (mine, other) = data["exit"]
    assert mine["init_policy"] == SAC_POLICY and mine["init_cpu_hours"] == hours and other["init_cpu_hours"] == 0.0
    assert all(x >= hours for x, _ in mine["policy_alone"] + mine["search_over_policy"])
    assert all(x < hours for x, _ in other["policy_alone"])


@pytest.mark.parametrize("beta", [0.0, 0.5, 1.0])
def test_the_loss_weights_each_label_by_its_scale_to_the_power_two_beta(beta):
    """algo.nll_beta: the gradient one update takes is the Gaussian likelihood's with each
    coordinate's term weighted by scale^(2 beta), the weight held constant; at beta = 1 the
    mean's part of the output layer gets exactly the squared error's gradient."""
    import torch
    from omegaconf import OmegaConf
    from tensordict import TensorDict
    from torchrl.data import Bounded

    from billiards.rl.learners import make_agent
    from billiards.rl.config import ALGO_SCHEMAS

    algo = OmegaConf.structured(ALGO_SCHEMAS["exit"])
    algo.nll_beta, algo.hidden_sizes = beta, [16, 16]
    torch.manual_seed(0)
    agent = make_agent(algo, 28, Bounded(torch.tensor([0.0, 0.0, -1.0, -1.0]), torch.tensor([6.283, 1.0, 1.0, 1.0]), shape=(4,)))
    batch = TensorDict({"observation": torch.randn(64, 28), "target": torch.rand(64, 4) * 1.8 - 0.9}, batch_size=[64])
    net = agent.actor.module[0].module
    loc, scale = net(batch["observation"])
    z = torch.atanh(batch["target"])
    weight = scale.detach() ** (2 * beta)
    expected = (weight * (torch.log(scale) + 0.5 * ((z - loc) / scale) ** 2)).sum(-1).mean()
    expected_grads = torch.autograd.grad(expected, list(net.parameters()), retain_graph=True)
    squared = torch.autograd.grad((0.5 * (z - loc) ** 2).sum(-1).mean(), net[0][-1].weight)[0][:4]

    taken = []
    agent.optimizer.step = lambda: taken.append([p.grad.clone() for p in net.parameters()])
    agent._step(batch)
    for got, want in zip(taken[0], expected_grads):
        assert torch.allclose(got, want, rtol=1e-5, atol=1e-7)
    last = dict(zip([id(p) for p in net.parameters()], taken[0]))[id(net[0][-1].weight)][:4]  # the loc rows
    assert torch.allclose(last, squared, rtol=1e-5, atol=1e-7) == (beta == 1.0)


def test_each_agent_names_its_actors_form_truly():
    """``actor_kind``, which decides what algo.init_policy accepts: the tanh-Gaussian agents'
    actors share one layout (a SAC actor's weights load into expert iteration's), TD3's does not."""
    import torch
    from omegaconf import OmegaConf
    from torchrl.data import Bounded
    from torchrl.modules import ProbabilisticActor

    from billiards.rl.learners import AGENTS, make_agent
    from billiards.rl.config import ALGO_SCHEMAS
    from billiards.rl.policy import _gaussian_actors

    spec = Bounded(torch.tensor([0.0, 0.0, -1.0, -1.0]), torch.tensor([6.283, 1.0, 1.0, 1.0]), shape=(4,))
    def actor_of(name):
        algo = OmegaConf.structured(ALGO_SCHEMAS[name])
        algo.hidden_sizes = [16, 16]
        return make_agent(algo, 32, spec).actor

    exit_actor = actor_of("exit")
    for name in AGENTS:
        actor = actor_of(name)
        gaussian = isinstance(actor, ProbabilisticActor)
        assert AGENTS[name].actor_kind == ("tanh_gaussian" if gaussian else "deterministic"), name
        assert (name in _gaussian_actors()) == gaussian
        if gaussian:
            exit_actor.load_state_dict(actor.state_dict())
        else:
            with pytest.raises(RuntimeError):
                exit_actor.load_state_dict(actor.state_dict())
    assert set(_gaussian_actors()) == {"sac", "ppo", "exit"}
