"""Gymnasium and TorchRL environments, transforms, evaluation protocol and baselines."""

import math
import warnings

import gymnasium as gym
import dataclasses

import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs, step_mdp

from billiards import compat, domain
from billiards.baselines import make_policy, nearest_red_policy, random_policy
from billiards.envs import (
    GYM_ID,
    AimConstraint,
    Billiards4BallInningEnv,
    BilliardsEnv,
    CaromFeatures,
    FoulPenalty,
    GentleShotBonus,
    NearMissBonus,
    make_env,
    reset_to,
)
from billiards.evaluation import EvalResult, evaluate_policy, summarize
from billiards.physics import (
    DEFAULT_PARAMS,
    canonical_rack,
    random_racks,
    simulate_batch,
)

R = DEFAULT_PARAMS.ball_radius
ALL_LAYERS = dict(constrain_aim=True, extra_features=True, foul_penalty=1.0, gentle=0.2, near_miss=0.05)  # the paper's


def leave_bonus(beta, positions, second_red):
    """The paper's gentle bonus by hand: beta exp(-(d - 0.2)^2 / 0.02), d white -> second red at rest."""
    red = np.take_along_axis(positions, np.maximum(second_red, 2)[..., None, None], axis=-2)[..., 0, :]
    d = np.linalg.norm(red - positions[..., 0, :], axis=-1)
    return beta * np.exp(-((d - 0.2) ** 2) / (2 * 0.1 ** 2))


def random_actions(env, n_steps, seed=0):
    """n_steps batched actions drawn uniformly from env's action spec."""
    gen = torch.Generator().manual_seed(seed)
    spec = env.action_spec
    low, high = spec.space.low, spec.space.high
    return [low + (high - low) * torch.rand(spec.shape, generator=gen) for _ in range(n_steps)]


def play(env, actions, td=None):
    """Step env through the given actions (auto-resetting finished innings); returns the
    stacked transitions (B, T) as a TensorDict."""
    td = env.reset() if td is None else td
    out = []
    for action in actions:
        td["action"] = action
        full, td = env.step_and_maybe_reset(td)
        out.append(full)
    return torch.stack(out, dim=1)


def clear_racks(rng, n, margin=1e-3):
    """n random racks on which nothing can block the white's straight path to the nearest red
    and no cushion lies in the way: the yellow and the other red are farther than 4R from the
    white->nearest-red segment, and the nearest red is at least 3R from every cushion."""
    w, l = DEFAULT_PARAMS.table_width, DEFAULT_PARAMS.table_length
    out = []
    while len(out) < n:
        pos = random_racks(rng, 1)[0]
        near = int(domain.nearest_red(pos))
        a, b = pos[0], pos[near]
        ok = all(3 * R + margin <= c <= lim - 3 * R - margin for c, lim in zip(b, (w, l)))
        for k in (1, 5 - near):
            t = np.clip((pos[k] - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
            ok &= np.linalg.norm(pos[k] - (a + t * (b - a))) > 4 * R + margin
        if ok:
            out.append(pos)
    return np.array(out)


# ----------------------------------------------------------------------------- gymnasium


def test_gym_registered_and_check_env_passes():
    for kwargs in [{}, dict(ALL_LAYERS, on_miss="reset", render_mode="rgb_array")]:
        env = gym.make(GYM_ID, **kwargs)
        assert isinstance(env.unwrapped, Billiards4BallInningEnv)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # advice about the asymmetric action box
            check_env(env.unwrapped)
        obs, _ = env.reset(seed=3)
        assert obs.shape == ((32,) if kwargs else (28,)) and obs.dtype == np.float32
        assert env.observation_space.contains(obs)


def test_gym_observation_and_info():
    env = Billiards4BallInningEnv(extra_features=True)
    obs, info = env.reset(seed=0)
    pos = info["positions"]
    np.testing.assert_array_equal(obs[:28], domain.rest_observation(pos))
    np.testing.assert_allclose(obs[28:], domain.carom_features(pos), rtol=1e-6)
    obs, reward, terminated, truncated, info = env.step(np.array([1.0, 0.7, 0.0, 0.0], dtype=np.float32))
    assert reward == float(info["score"])
    assert not terminated and not truncated  # continue-on-miss, 1 of 10 shots
    assert sum([info["score"], info["foul"], info["miss"]]) == 1
    assert info["shot"] == 1 and info["n_events"] > 0 and info["hits"].shape == (3,)
    np.testing.assert_array_equal(obs[:28], domain.rest_observation(info["positions"]))


def test_gym_bad_actions_name_the_key_and_shape():
    env = Billiards4BallInningEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r'"action".*\(4,\)'):
        env.step(np.array([np.nan, 0.5, 0.0, 0.0]))
    with pytest.raises(ValueError, match=r'"action" must have shape \(4,\).*got shape \(3,\)'):
        env.step(np.array([1.0, 0.5, 0.0]))
    with pytest.raises(ValueError, match="action"):
        env.step(np.array([1.0, 1.5, 0.0, 0.0]))  # p outside [0, 1]


@pytest.mark.parametrize("on_miss", ["continue", "reset"])
def test_gym_inning_lengths(on_miss):
    env = Billiards4BallInningEnv(on_miss=on_miss, max_shots=4)
    rng = np.random.default_rng(0)
    for episode in range(6):
        env.reset(seed=episode)
        scores = []
        for shot in range(1, 5):
            action = env.action_space.sample() if episode % 2 else np.array([rng.uniform(0, 6.28), 0.5, 0, 0])
            _, _, terminated, truncated, info = env.step(action)
            scores.append(info["score"])
            assert info["shot"] == shot
            if terminated or truncated:
                break
        if on_miss == "continue":
            assert len(scores) == 4 and truncated and not terminated
        else:
            # ends at the first miss/foul, or by truncation after 4 scoring shots
            assert terminated == (not scores[-1]) and all(scores[:-1])
            assert truncated == (len(scores) == 4 and scores[-1])


def test_gym_same_seed_same_inning_and_reset_to_positions():
    def inning(seed):
        env = Billiards4BallInningEnv(max_shots=5)
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        trace = [obs]
        for _ in range(5):
            trace.append(env.step(env.action_space.sample())[0])
        return np.array(trace)

    np.testing.assert_array_equal(inning(7), inning(7))
    assert not np.array_equal(inning(7), inning(8))
    env = Billiards4BallInningEnv(start="canonical")
    np.testing.assert_array_equal(env.reset(seed=1)[1]["positions"], canonical_rack())
    pos = random_racks(np.random.default_rng(2), 1)[0]
    _, info = env.reset(options={"positions": pos})
    np.testing.assert_array_equal(info["positions"], pos)


def _assert_same(a, b, where="out"):
    """a == b to the bit, through tuples and dicts (keys in the same order, arrays of the same dtype)."""
    assert type(a) is type(b), (where, type(a), type(b))
    if isinstance(a, tuple):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for key in a:
            _assert_same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, (where, a.dtype, b.dtype, a.shape, b.shape)
        assert np.array_equal(a.view(np.uint8), b.view(np.uint8)), where
    else:
        assert a == b, where


VECTOR_CONFIGS = {
    "defaults": {},
    "all_layers": dict(ALL_LAYERS, max_shots=4),
    "reset_on_miss_canonical": dict(on_miss="reset", start="canonical", max_shots=6),
    "noise": dict(noise="fastfiz", max_shots=3, foul_penalty=1.0),
    "raw_international_power": dict(normalize_actions=False, physics="international", gentle=0.5, gentle_kind="power",
                                    on_miss="reset"),
}


@pytest.mark.parametrize("name", list(VECTOR_CONFIGS))
def test_gym_vector_env_is_the_sync_vector_env_bit_for_bit(name):
    """gymnasium.make_vec builds the batched vector env (one simulate_batch per step); its
    observations, rewards, flags and stacked info equal SyncVectorEnv's over single envs to
    the bit, through autoresets, per-inning seeds and per-inning execution noise."""
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    config, B = VECTOR_CONFIGS[name], 5
    sync = gym.make_vec(GYM_ID, num_envs=B, vectorization_mode="sync", **config)
    batched = gym.make_vec(GYM_ID, num_envs=B, **config)
    assert isinstance(batched.unwrapped, Billiards4BallVectorEnv)
    assert batched.action_space == sync.action_space and batched.observation_space == sync.observation_space
    _assert_same(batched.reset(seed=4), sync.reset(seed=4), "reset")
    rng = np.random.default_rng(0)
    low, high = sync.single_action_space.low, sync.single_action_space.high
    ended = 0
    for t in range(25):
        action = (low + (high - low) * rng.random((B, 4))).astype(np.float32)
        out = batched.step(action)
        _assert_same(out, sync.step(action), f"step {t}")
        ended += int((out[2] | out[3]).sum())
    assert ended >= B  # innings ended and were reset along the way


def test_gym_vector_env_resets_like_the_sync_vector_env():
    """Per-inning seeds, a reset mask and a given table reset the same innings the same way; a
    bad option or a render mode is refused."""
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    sync = gym.make_vec(GYM_ID, num_envs=4, vectorization_mode="sync", max_shots=3)
    batched = gym.make_vec(GYM_ID, num_envs=4, max_shots=3)
    actions = [np.random.default_rng(t).uniform(-1, 1, (4, 4)).astype(np.float32) for t in range(3)]
    table = random_racks(np.random.default_rng(5), 1)[0]
    for kwargs in (dict(seed=[3, 9, 1, 2]), dict(options={"reset_mask": np.array([True, False, False, True])}),
                   dict(seed=7, options={"positions": table})):
        _assert_same(batched.reset(**kwargs), sync.reset(**kwargs), str(kwargs))
        for t, action in enumerate(actions):
            _assert_same(batched.step(action), sync.step(action), f"{kwargs} step {t}")
    with pytest.raises(ValueError, match="reset options may only be"):
        batched.reset(options={"postions": table})
    with pytest.raises(ValueError, match="reset_mask"):
        batched.reset(options={"reset_mask": np.zeros(4, dtype=bool)})
    with pytest.raises(ValueError, match="does not render"):
        Billiards4BallVectorEnv(2, render_mode="rgb_array")


def test_random_racks_each_draws_every_generators_own_rack():
    """Row i is random_racks(rngs[i], 1) to the bit, and each generator ends where that call
    leaves it, also when racks are redrawn (a clearance that rejects most draws)."""
    from billiards.physics import get_params
    from billiards.physics.api import random_racks_each

    for params in (DEFAULT_PARAMS, get_params({"rack_clearance": 0.5})):
        mine, theirs = [np.random.default_rng(s) for s in range(6)], [np.random.default_rng(s) for s in range(6)]
        racks = random_racks_each(mine, params)
        for i, rng in enumerate(theirs):
            np.testing.assert_array_equal(racks[i], random_racks(rng, 1, params)[0])
            assert mine[i].bit_generator.state == rng.bit_generator.state


def test_gym_shaping_and_constraint_match_domain():
    rng = np.random.default_rng(1)
    env = Billiards4BallInningEnv(**ALL_LAYERS, normalize_actions=False)  # the paper's raw (u, p, a, b)
    for n in range(30):
        env.reset(seed=n)
        pos = env.positions
        action = np.array([rng.uniform(-1, 1), rng.uniform(0.2, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)])
        _, reward, _, _, info = env.step(action)
        theta = domain.constrained_theta(pos, action[0], R)
        assert info["theta"] == theta
        ref = simulate_batch(pos[None], np.r_[theta, action[1:]][None])
        np.testing.assert_array_equal(info["positions"], ref.positions[0])
        gap = (info["closest"][1] if info["hits"][1] else info["closest"][0])
        one_red = info["hits"][1] != info["hits"][2]
        expected = (
            info["score"]
            - 1.0 * info["foul"]
            + (leave_bonus(0.2, info["positions"], np.array(info["second_red"])) if info["score"] else 0.0)
            + (0.05 * math.exp(-gap / 0.03) if one_red and info["miss"] else 0.0)
        )
        assert reward == pytest.approx(expected)


# ----------------------------------------------------------------------------- gymnasium = TorchRL

SHAPED = dict(constrain_aim=True)  # shaping on aimed shots: plenty of scores, fouls and near misses
CROSS_CONFIGS = {
    "default": {},
    "aim": dict(constrain_aim=True),
    "features": dict(extra_features=True),
    "aim_features": dict(constrain_aim=True, extra_features=True),
    "shaping_none": dict(SHAPED),
    "foul_penalty": dict(SHAPED, foul_penalty=1.0),
    "gentle": dict(SHAPED, gentle=0.2),
    "gentle_power": dict(SHAPED, gentle=0.5, gentle_kind="power"),
    "near_miss": dict(SHAPED, near_miss=0.05, near_miss_sigma=0.04),
    "both": dict(SHAPED, foul_penalty=1.0, gentle=0.2, near_miss=0.05),
    "all_reset_on_miss": dict(ALL_LAYERS, on_miss="reset", max_shots=4),
    "international": dict(SHAPED, extra_features=True, gentle=0.2, physics="international"),
}


def gym_and_torchrl(config: dict, normalized: bool, seed: int):
    trl_config = {("params" if k == "physics" else k): v for k, v in config.items()}
    return (Billiards4BallInningEnv(normalize_actions=normalized, **config),
            make_env(1, seed=seed, normalize_actions=normalized, **trl_config))


@pytest.mark.slow
@pytest.mark.parametrize("normalized", [True, False], ids=["normalized", "raw"])
@pytest.mark.parametrize("name", list(CROSS_CONFIGS))
def test_gym_and_torchrl_envs_play_the_same_innings(name, normalized):
    """Same seed, same actions: the gymnasium env (the shared step code on a batch of one) and
    the TorchRL env (make_env, B = 1) draw the same racks, play the same shots and return the
    same observations, outcomes, flags and rewards, inning after inning (the TorchRL reward
    sums its float32 terms in float32, the gymnasium one in float64)."""
    config, seed, steps = CROSS_CONFIGS[name], 11, 30
    gym_env, trl_env = gym_and_torchrl(config, normalized, seed)
    low, high = gym_env.action_space.low, gym_env.action_space.high
    np.testing.assert_array_equal(low, trl_env.action_spec_unbatched.space.low.numpy())
    np.testing.assert_array_equal(high, trl_env.action_spec_unbatched.space.high.numpy())
    assert gym_env.observation_space.shape == trl_env.observation_spec_unbatched["observation"].shape
    rng = np.random.default_rng(seed)
    obs, info = gym_env.reset(seed=seed)
    td = trl_env.reset()
    shaped, innings = 0, 1
    for _ in range(steps):
        np.testing.assert_array_equal(obs, td["observation"][0].numpy())
        np.testing.assert_array_equal(info["positions"], td["positions"][0].numpy())
        action = (low + (high - low) * rng.random(4)).astype(np.float32)
        obs, reward, terminated, truncated, info = gym_env.step(action)
        td["action"] = torch.from_numpy(action)[None]
        full, td = trl_env.step_and_maybe_reset(td)
        nxt = full["next"]
        np.testing.assert_array_equal(obs, nxt["observation"][0].numpy())
        np.testing.assert_array_equal(info["positions"], nxt["positions"][0].numpy())
        for key in ("score", "foul", "miss", "first_contact", "second_red", "hits", "n_events", "shot"):
            np.testing.assert_array_equal(np.reshape(info[key], -1), nxt[key][0].numpy(), err_msg=key)
        np.testing.assert_array_equal(info["closest"].astype(np.float32), nxt["closest"][0].numpy())
        assert (terminated, truncated) == (bool(nxt["terminated"]), bool(nxt["truncated"]))
        assert reward == pytest.approx(float(nxt["reward"]), rel=0, abs=5e-7)
        shaped += reward != float(info["score"])
        if terminated or truncated:
            obs, info = gym_env.reset()
            innings += 1
    assert innings >= 3
    if any(config.get(k) for k in ("foul_penalty", "gentle", "near_miss")):
        assert shaped  # the shaping terms were exercised, not only the score


def test_gym_and_torchrl_envs_play_the_same_noisy_shots():
    """With execution noise the envs draw from different generators by design (the gymnasium
    env from its np_random, as gymnasium's seeding asks; the TorchRL env from one of its own,
    so that its racks do not shift), so their innings differ. The step is the same: the shot
    either one played under noise, commanded to the other without noise on the same table,
    gives the same outcome, bit for bit."""
    rng = np.random.default_rng(4)
    noisy_trl, exact_trl = make_env(1, seed=3, noise="fastfiz_x5"), make_env(1, seed=3)
    noisy_gym, exact_gym = (Billiards4BallInningEnv(normalize_actions=False, noise=n) for n in ("fastfiz_x5", None))
    noisy_gym.reset(seed=5)
    td = noisy_trl.reset()
    low, high = domain.action_bounds()
    for _ in range(8):
        action = low + (high - low) * rng.random(4)
        td["action"] = torch.from_numpy(action)[None]
        full, td = noisy_trl.step_and_maybe_reset(td)
        played = full["next", "played_action"][0].numpy()
        assert not np.array_equal(played, action)
        exact_gym.reset(options={"positions": full["positions"][0].numpy()})
        _, _, _, _, info = exact_gym.step(played)
        np.testing.assert_array_equal(info["positions"], full["next", "positions"][0].numpy())
        np.testing.assert_array_equal(info["hits"], full["next", "hits"][0].numpy())

        table = noisy_gym.positions
        _, _, _, _, info = noisy_gym.step(action)
        assert not np.array_equal(info["raw_action"], info["commanded_action"])
        replay = reset_to(exact_trl, table[None])
        replay["action"] = torch.from_numpy(info["raw_action"])[None]
        nxt = exact_trl.step(replay)["next"]
        np.testing.assert_array_equal(info["positions"], nxt["positions"][0].numpy())
        np.testing.assert_array_equal(info["hits"], nxt["hits"][0].numpy())


@pytest.mark.slow
def test_the_power_gentle_bonus_reads_the_commanded_power_under_noise_in_both_envs():
    """Under execution noise the played power differs from the commanded one; the gentle power
    bonus rewards the agent's choice, the commanded power, in the gymnasium env as in the TorchRL
    transform (beta * score * (1 - p))."""
    beta = 0.5
    kw = dict(SHAPED, gentle=beta, gentle_kind="power", noise="fastfiz_x5")
    gym_env = Billiards4BallInningEnv(normalize_actions=False, **kw)
    trl_env = make_env(1, seed=3, normalize_actions=False, **kw)
    gym_env.reset(seed=5)
    td = trl_env.reset()
    rng = np.random.default_rng(0)
    gym_scored = trl_scored = 0
    for _ in range(400):
        target, _ = domain.aim_window(gym_env.positions)  # u in [-1, 1] (the aim constraint), spread by the table
        action = np.array([target / np.pi, rng.uniform(0.2, 0.9), 0.0, 0.0])
        _, reward, terminated, truncated, info = gym_env.step(action)
        p_cmd, p_played = info["commanded_action"][1], info["raw_action"][1]
        assert p_cmd != p_played
        assert reward == float(info["score"]) * (1 + beta * (1 - p_cmd))
        gym_scored += int(info["score"])
        if terminated or truncated:
            gym_env.reset()
        target, _ = domain.aim_window(td["positions"][0].numpy())
        td["action"] = torch.tensor([[target / np.pi, rng.uniform(0.2, 0.9), 0.0, 0.0]])
        full, td = trl_env.step_and_maybe_reset(td)
        score = float(full["next", "score"][0, 0])
        expected = score * (1 + beta * (1 - float(full["action"][0, 1])))
        assert float(full["next", "reward"][0, 0]) == pytest.approx(expected, rel=0, abs=5e-7)
        trl_scored += int(score)
    assert gym_scored and trl_scored  # the bonus was exercised


# ----------------------------------------------------------------------------- TorchRL specs


@pytest.mark.parametrize(
    "layers",
    [
        {},
        dict(constrain_aim=True),
        dict(extra_features=True),
        dict(foul_penalty=1.0),
        dict(gentle=0.2),
        dict(gentle=0.5, gentle_kind="power"),
        dict(near_miss=0.05),
        ALL_LAYERS,
        dict(ALL_LAYERS, paradigm="canonical_reset"),
        dict(normalize_actions=True),
        dict(ALL_LAYERS, normalize_actions=True),
    ],
)
def test_check_env_specs(layers):
    env = make_env(4, seed=0, **layers)
    check_env_specs(env, seed=0)
    assert env.action_spec_unbatched.shape == (4,)
    expected_low = [-1.0 if layers.get("constrain_aim") else 0.0, 0.0, -1.0, -1.0]
    expected_high = [1.0 if layers.get("constrain_aim") else np.float32(2 * math.pi), 1.0, 1.0, 1.0]
    if layers.get("normalize_actions"):
        expected_low, expected_high = [-1.0] * 4, [1.0] * 4
    np.testing.assert_array_equal(env.action_spec_unbatched.space.low.numpy(), expected_low)
    np.testing.assert_array_equal(env.action_spec_unbatched.space.high.numpy(), np.float32(expected_high))
    assert env.observation_spec["observation"].shape == (4, 32 if layers.get("extra_features") else 28)


def test_bare_env_specs_and_keys():
    env = BilliardsEnv(3, seed=0)
    check_env_specs(env, seed=0)
    td = env.reset()
    assert td["positions"].dtype == torch.float64 and td["positions"].shape == (3, 4, 2)
    np.testing.assert_array_equal(td["observation"].numpy(), domain.rest_observation(td["positions"].numpy()))
    td["action"] = env.action_spec.rand()
    nxt = env.step(td)["next"]
    for key, shape in [("reward", (3, 1)), ("done", (3, 1)), ("terminated", (3, 1)), ("truncated", (3, 1)),
                       ("score", (3, 1)), ("foul", (3, 1)), ("miss", (3, 1)), ("first_contact", (3, 1)),
                       ("hits", (3, 3)), ("closest", (3, 2)), ("shot", (3, 1)), ("n_events", (3, 1))]:
        assert nxt[key].shape == shape, key
    assert (nxt["score"] | nxt["foul"] | nxt["miss"]).all()
    assert (nxt["score"].int() + nxt["foul"].int() + nxt["miss"].int() == 1).all()
    np.testing.assert_array_equal(nxt["reward"].numpy(), nxt["score"].float().numpy())


def test_step_is_exactly_simulate_batch_and_reset_to_is_exact():
    pos = random_racks(np.random.default_rng(11), 5)
    env = BilliardsEnv(5, seed=0)
    td = reset_to(env, pos)
    np.testing.assert_array_equal(td["positions"].numpy(), pos)  # bit-exact float64
    assert (td["shot"] == 0).all()
    actions = torch.tensor([[0.3, 0.8, 0.1, -0.2]] * 5, dtype=torch.float64)
    td["action"] = actions
    nxt = env.step(td)["next"]
    ref = simulate_batch(pos, actions.numpy())
    np.testing.assert_array_equal(nxt["positions"].numpy(), ref.positions)
    np.testing.assert_array_equal(nxt["hits"].numpy(), ref.hits)
    np.testing.assert_array_equal(nxt["first_contact"][:, 0].numpy(), ref.first_contact)
    # TorchRL's implicit form (state in the reset tensordict) starts from the same table
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        td2 = env.reset(TensorDict({"positions": torch.from_numpy(pos)}, batch_size=[5]))
    np.testing.assert_array_equal(td2["positions"].numpy(), pos)
    with pytest.raises(ValueError, match="positions"):
        bad = pos.copy()
        bad[0, 1] = bad[0, 0]  # yellow on top of the white
        reset_to(env, bad)


def test_bad_actions_raise_naming_action_and_shape():
    for env in [make_env(4, seed=0), make_env(4, seed=0, constrain_aim=True)]:
        td = env.reset()
        action = env.action_spec.rand()
        action[2, 1] = float("nan")
        td["action"] = action
        with pytest.raises(ValueError, match=r'"action".*\(4, 4\)'):
            env.step(td)
        td["action"] = torch.zeros(4, 3)
        with pytest.raises(ValueError, match=r'"action" must have shape \(4, 4\).*got shape \(4, 3\)'):
            env.step(td)
    # a normalised power or tip outside [-1, 1] is refused by the same check in both envs
    env, gym_env = make_env(4, seed=0, normalize_actions=True), Billiards4BallInningEnv()
    td = env.reset()
    td["action"] = torch.tensor([[0.0, 0.0, 0.0, 0.0]] * 3 + [[0.0, 1.5, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r'"action" is normalised.*\[0.0, 1.5, 0.0, 0.0\]'):
        env.step(td)
    gym_env.reset(seed=0)
    with pytest.raises(ValueError, match=r'"action" is normalised.*\[0.0, 1.5, 0.0, 0.0\]'):
        gym_env.step(np.array([0.0, 1.5, 0.0, 0.0]))
    for make in (lambda: make_env(2, gentle_kind="soft"), lambda: Billiards4BallInningEnv(gentle_kind="soft")):
        with pytest.raises(ValueError, match="gentle_kind must be one of"):
            make()


# ----------------------------------------------------------------------------- transforms


def test_aim_constraint_first_contact_is_nearest_red_for_every_u():
    racks = clear_racks(np.random.default_rng(0), 12)
    u_grid = np.linspace(-0.99, 0.99, 23)
    n = len(racks) * len(u_grid)
    env = make_env(n, seed=0, constrain_aim=True)
    td = reset_to(env, np.repeat(racks, len(u_grid), axis=0))
    rng = np.random.default_rng(1)
    # tip offsets up to 0.6 R: a full-radius draw can stop the white short of the red
    action = np.column_stack([np.tile(u_grid, len(racks)), rng.uniform(0.4, 1.0, n), rng.uniform(-0.6, 0.6, (n, 2))])
    td["action"] = torch.tensor(action, dtype=torch.float32)
    nxt = env.step(td)["next"]
    expected = np.repeat(domain.nearest_red(racks), len(u_grid))
    np.testing.assert_array_equal(nxt["first_contact"][:, 0].numpy(), expected)
    # the same shots on the bare env with theta from the domain function: identical tables
    bare = BilliardsEnv(n, seed=0)
    td_bare = reset_to(bare, np.repeat(racks, len(u_grid), axis=0))
    theta = domain.constrained_theta(td_bare["positions"].numpy(), action[:, 0].astype(np.float32), R)
    td_bare["action"] = torch.tensor(np.column_stack([theta, action[:, 1:].astype(np.float32)]))
    np.testing.assert_array_equal(bare.step(td_bare)["next", "positions"].numpy(), nxt["positions"].numpy())


def test_carom_features_in_observation():
    hand = np.array([[0.3, 0.3], [1.1, 2.5], [0.3, 0.7], [0.7, 0.7]])
    env = make_env(2, seed=0, extra_features=True)
    td = reset_to(env, np.stack([hand, hand[[0, 1, 3, 2]]]))
    expected = [0.4, math.hypot(0.4, 0.4), -1.0, 0.0]
    np.testing.assert_allclose(td["observation"][:, 28:].numpy(), [expected, expected], atol=1e-6)
    np.testing.assert_array_equal(td["observation"][:, :28].numpy(), domain.rest_observation(td["positions"].numpy()))
    td["action"] = env.action_spec.rand()
    nxt = env.step(td)["next"]
    feats = domain.carom_features(nxt["positions"].numpy()).astype(np.float32)
    np.testing.assert_array_equal(nxt["observation"][:, 28:].numpy(), feats)
    # also after auto-resets inside a rollout
    roll = env.rollout(12, break_when_any_done=False)
    np.testing.assert_array_equal(
        roll["observation"][..., 28:].numpy(), domain.carom_features(roll["positions"].numpy()).astype(np.float32)
    )


@pytest.mark.parametrize(
    "transform_kwargs",
    [dict(foul_penalty=1.5), dict(gentle=0.7), dict(gentle=0.7, gentle_kind="power"),
     dict(near_miss=0.6, near_miss_sigma=0.04), dict(foul_penalty=1.0, gentle=0.2, near_miss=0.05)],
)
def test_shaping_terms_equal_their_formulas(transform_kwargs):
    B, T = 256, 3
    env = make_env(B, seed=5, constrain_aim=True, **transform_kwargs)  # constrained aim: plenty of scores and near misses
    data = play(env, random_actions(env, T, seed=2))
    nxt = data["next"]
    score, foul, miss = (nxt[k][..., 0].numpy() for k in ("score", "foul", "miss"))
    hits, closest = nxt["hits"].numpy(), nxt["closest"].numpy().astype(np.float64)
    power = data["action"][..., 1].numpy().astype(np.float64)
    assert score.any() and foul.any()
    one_red = hits[..., 1] ^ hits[..., 2]
    assert (one_red & miss).any()
    gap = np.where(hits[..., 1], closest[..., 1], closest[..., 0])
    c = transform_kwargs.get("foul_penalty", 0.0)
    beta_g = transform_kwargs.get("gentle", 0.0)
    beta_n, sigma = transform_kwargs.get("near_miss", 0.0), transform_kwargs.get("near_miss_sigma", 0.03)
    if transform_kwargs.get("gentle_kind") == "power":
        gentle = beta_g * score * (1 - power)
    else:
        gentle = np.where(score, leave_bonus(beta_g, nxt["positions"].numpy(), nxt["second_red"][..., 0].numpy()), 0.0)
        assert not beta_g or (score & (gentle > 0.01 * beta_g)).any()  # some scores earn a real bonus
    expected = score - c * foul + gentle + np.where(one_red & miss, beta_n * np.exp(-gap / sigma), 0.0)
    np.testing.assert_allclose(nxt["reward"][..., 0].numpy(), expected, rtol=1e-5, atol=1e-6)
    # the raw outcome is untouched: "score" is still the carom score
    bare = play(make_env(B, seed=5, constrain_aim=True), random_actions(env, T, seed=2))
    np.testing.assert_array_equal(bare["next", "score"].numpy(), nxt["score"].numpy())
    np.testing.assert_array_equal(bare["next", "reward"][..., 0].numpy(), score.astype(np.float32))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -1.0])
def test_bad_shaping_coefficients_are_refused_where_they_enter(bad):
    """The Python API refuses NaN, inf and negative shaping coefficients at construction --
    make_env, the gymnasium env and each transform -- naming the argument."""
    from billiards.envs import RewardModelBonus
    from billiards.rm import RewardModel

    for key in ("foul_penalty", "gentle", "near_miss", "near_miss_sigma", "rm"):
        with pytest.raises(ValueError, match=f"^{key} must be a finite number"):
            make_env(2, **{key: bad})
        if key != "rm":
            with pytest.raises(ValueError, match=f"^{key} must be a finite number"):
                Billiards4BallInningEnv(**{key: bad})
    for make, name in ((lambda: FoulPenalty(bad), "foul penalty c"), (lambda: GentleShotBonus(bad), "gentle beta"),
                       (lambda: NearMissBonus(bad), "near-miss beta"), (lambda: NearMissBonus(1.0, bad), "near-miss sigma"),
                       (lambda: RewardModelBonus(RewardModel([4]), bad), "reward-model beta")):
        with pytest.raises(ValueError, match=f"^{name} must be a finite number"):
            make()


def test_one_shaping_schema_for_both_envs_and_the_training_config():
    """The shaping's keys, types and defaults are written once (billiards.shaping.ShapingOptions):
    what both envs reward with (Shaping), make_env's options (EnvOptions) and the training
    config's node (ShapingConfig) derive from it; the gymnasium env's keywords default to it and
    its sigma is the domain's. The trainer's reward model alone differs: a path, the committed one.
    The env's objects stay read-only."""
    import inspect

    from billiards.envs import EnvOptions
    from billiards.envs._common import Shaping
    from billiards.rl.config import ShapingConfig
    from billiards.shaping import ShapingOptions

    keys = [f.name for f in dataclasses.fields(ShapingOptions)]
    env = ShapingOptions()
    for cls in (Shaping, EnvOptions, ShapingConfig):
        assert issubclass(cls, ShapingOptions) and [f.name for f in dataclasses.fields(cls)][:len(keys)] == keys
    assert env.near_miss_sigma == domain.NEAR_MISS_SIGMA and env.rm_model is None
    assert all(getattr(EnvOptions(), k) == getattr(Shaping(), k) == getattr(env, k) for k in keys)
    gym_kwargs = inspect.signature(Billiards4BallInningEnv).parameters
    assert all(gym_kwargs[k].default == getattr(env, k) for k in keys if k not in ("rm", "rm_model"))
    trainer = ShapingConfig()
    assert [getattr(trainer, k) for k in keys[:-1]] == [getattr(env, k) for k in keys[:-1]]
    assert keys[-1] == "rm_model" and trainer.rm_model == "results/rm/model.pt"
    options = EnvOptions(foul_penalty=1.0, max_shots=5)
    assert Shaping.of(options) == Shaping(foul_penalty=1.0) and hash(options) == hash(EnvOptions(foul_penalty=1.0, max_shots=5))
    for obj, key in ((options, "foul_penalty"), (options, "max_shots"), (Billiards4BallInningEnv(gentle=0.2).shaping, "gentle")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, key, 0.5)
    with pytest.raises(TypeError):
        EnvOptions("random")  # keywords only: the fields are make_env's keyword arguments


def test_transform_classes_compose_by_hand():
    from torchrl.envs import Compose, TransformedEnv

    env = TransformedEnv(BilliardsEnv(4, seed=0), Compose(AimConstraint(), CaromFeatures(), FoulPenalty(1.0),
                                                         GentleShotBonus(0.2), NearMissBonus(0.05, 0.03)))
    check_env_specs(env, seed=0)
    assert env.observation_spec["observation"].shape == (4, 32)


# ----------------------------------------------------------------------------- paradigms


@pytest.mark.parametrize("start", ["random", "canonical"])
def test_continue_on_miss_runs_full_innings_then_resets(start):
    M, B = 3, 16
    env = make_env(B, start=start, on_miss="continue", max_shots=M, seed=0)
    data = play(env, random_actions(env, 2 * M + 1, seed=0))
    shot = data["next", "shot"][..., 0].numpy()
    np.testing.assert_array_equal(shot, np.tile([1, 2, 3, 1, 2, 3, 1], (B, 1)))
    assert not data["next", "terminated"].any()
    np.testing.assert_array_equal(data["next", "truncated"][..., 0].numpy(), np.tile(shot == M, 1))
    np.testing.assert_array_equal(data["next", "done"].numpy(), data["next", "truncated"].numpy())
    pos, nxt_pos = data["positions"].numpy(), data["next", "positions"].numpy()
    for t in range(2 * M):
        if (t + 1) % M:  # inside an inning the next shot starts where the last one left the table
            np.testing.assert_array_equal(pos[:, t + 1], nxt_pos[:, t])
        else:  # a new inning starts from a new rack
            if start == "canonical":
                np.testing.assert_array_equal(pos[:, t + 1], np.broadcast_to(canonical_rack(), (B, 4, 2)))
            else:
                assert not np.array_equal(pos[:, t + 1], nxt_pos[:, t])
                assert len({pos[b, t + 1].tobytes() for b in range(B)}) == B
    if start == "canonical":
        np.testing.assert_array_equal(pos[:, 0], np.broadcast_to(canonical_rack(), (B, 4, 2)))


@pytest.mark.parametrize("start", ["random", "canonical"])
def test_reset_on_miss_ends_innings_at_first_miss_or_foul(start):
    M, B, T = 2, 1024, 6  # 2-shot innings that score twice from the opening rack are rare (~0.1 %)
    env = make_env(B, start=start, on_miss="reset", max_shots=M, seed=0, constrain_aim=True)
    data = play(env, random_actions(env, T, seed=1))
    score = data["next", "score"][..., 0].numpy()
    shot = data["next", "shot"][..., 0].numpy()
    term, trunc = data["next", "terminated"][..., 0].numpy(), data["next", "truncated"][..., 0].numpy()
    np.testing.assert_array_equal(term, ~score)
    np.testing.assert_array_equal(trunc, score & (shot == M))
    assert score.any() and (~score).any() and trunc.any()
    pos, nxt_pos = data["positions"].numpy(), data["next", "positions"].numpy()
    done = term | trunc
    for b in range(B):
        for t in range(T - 1):
            if done[b, t]:
                assert shot[b, t + 1] == 1
                if start == "canonical":
                    np.testing.assert_array_equal(pos[b, t + 1], canonical_rack())
                else:
                    assert not np.array_equal(pos[b, t + 1], nxt_pos[b, t])
            else:
                assert shot[b, t + 1] == shot[b, t] + 1
                np.testing.assert_array_equal(pos[b, t + 1], nxt_pos[b, t])


def test_partial_reset_only_touches_marked_innings():
    env = make_env(3, seed=1)
    td = env.reset()
    td["action"] = env.action_spec.rand()
    nxt = step_mdp(env.step(td))
    before = nxt["positions"].clone()
    nxt["done"] = torch.tensor([[True], [False], [False]])
    after = env.maybe_reset(nxt)
    changed = (after["positions"] != before).flatten(1).any(1)
    np.testing.assert_array_equal(changed.numpy(), [True, False, False])
    np.testing.assert_array_equal(after["shot"][:, 0].numpy(), [0, 1, 1])


def test_same_seed_same_innings():
    def run(seed):
        env = make_env(8, seed=seed, max_shots=4, **ALL_LAYERS)
        return env.rollout(10, random_policy(env.action_spec_unbatched, seed=3), break_when_any_done=False)

    a, b, c = run(0), run(0), run(1)
    for key in [("next", "positions"), ("next", "reward"), ("next", "observation"), "action"]:
        np.testing.assert_array_equal(a[key].numpy(), b[key].numpy())
    assert not np.array_equal(a["positions"].numpy(), c["positions"].numpy())
    env = make_env(8, seed=0)
    first = env.reset()["positions"].clone()
    env.set_seed(0)
    np.testing.assert_array_equal(env.reset()["positions"].numpy(), first.numpy())


# ----------------------------------------------------------------------------- evaluation


def test_summarize_statistics():
    score = np.array([[1, 1, 0], [0, 0, 0], [1, 0, 1], [1, 1, 1]], dtype=bool)
    foul = np.array([[0, 0, 1], [0, 0, 0], [0, 1, 0], [0, 0, 0]], dtype=bool)
    res = summarize(score, foul)
    assert res.mean == pytest.approx(1.75) and res.std == pytest.approx(np.std([2, 0, 2, 3]))
    assert res.best == 3 and res.points == [2, 0, 2, 3]
    assert res.foul_innings_pct == pytest.approx(50.0)
    assert res.foul_per_shot_pct == pytest.approx(100 * 2 / 12)
    assert res.success_per_shot_pct == pytest.approx(100 * 7 / 12)
    assert res.n_innings == 4 and res.shots == 12 and res.max_shots == 3
    assert res.first_miss_points == [2, 0, 1, 3] and res.first_miss_mean == pytest.approx(1.5)


def test_points_to_the_first_miss_are_the_end_at_first_miss_innings():
    """From the same racks, a deterministic policy's continue-on-miss inning is, up to its first
    miss, the inning the reset-on-miss env plays: its leading points are that inning's points."""
    n = 400
    res = evaluate_policy(nearest_red_policy(), n_innings=n, max_shots=4, seed=5)
    env = make_env(n, on_miss="reset", max_shots=4, seed=5)
    td = env.reset()
    points, alive = np.zeros(n, dtype=int), np.ones(n, dtype=bool)
    for _ in range(4):
        td = env.step(nearest_red_policy()(td))
        points += (td["next", "score"][:, 0].numpy() & alive)
        alive &= ~td["next", "done"][:, 0].numpy()
        td = step_mdp(td)
    assert res.first_miss_points == points.tolist()
    assert res.first_miss_mean == pytest.approx(points.mean()) and 0 < points.sum() < sum(res.points)
    older = {k: v for k, v in dataclasses.asdict(res).items() if k != "first_miss_points"}  # an eval.json before the field
    assert EvalResult(**compat.upgrade_eval_record(older)).first_miss_mean is None  # billiards.compat: not recorded


def test_evaluate_protocol_and_json(tmp_path):
    res = evaluate_policy(nearest_red_policy(), n_innings=16, max_shots=5, seed=3)
    assert res.n_innings == 16 and res.shots == 80 and len(res.points) == 16
    assert res.mean == pytest.approx(np.mean(res.points)) and 0 <= res.best <= 5
    # the protocol by hand: continue-on-miss innings with the same racks and policy
    env = make_env(16, on_miss="continue", max_shots=5, seed=3)
    td = env.reset()
    points = np.zeros(16, dtype=int)
    for _ in range(5):
        td = step_mdp(env.step(nearest_red_policy()(td)))
        points += td["score"][:, 0].numpy()
    assert res.points == points.tolist()
    assert evaluate_policy(nearest_red_policy(), n_innings=16, max_shots=5, seed=3) == res
    res.to_json(tmp_path / "r.json")
    assert EvalResult.from_json(tmp_path / "r.json") == res
    canon = evaluate_policy(nearest_red_policy(), n_innings=4, max_shots=3, start="canonical")
    assert len(set(canon.points)) == 1  # identical racks, deterministic policy


def test_baseline_policies():
    env = make_env(5, seed=0)
    td = env.reset()
    act = nearest_red_policy()(td.clone())["action"]
    theta, _ = domain.aim_window(td["positions"].numpy(), R)
    np.testing.assert_allclose(act[:, 0].numpy(), np.mod(theta, 2 * math.pi), rtol=1e-6)
    np.testing.assert_array_equal(act[:, 1:].numpy(), np.tile([0.5, 0.0, 0.0], (5, 1)))
    assert env.action_spec.is_in(act)
    constrained = make_policy("nearest", constrain_aim=True)(td.clone())["action"]
    np.testing.assert_array_equal(constrained[:, 0].numpy(), 0.0)
    rand = make_policy("random", seed=0)(td.clone())["action"]
    assert env.action_spec.is_in(rand)
    np.testing.assert_array_equal(rand.numpy(), make_policy("random", seed=0)(td.clone())["action"].numpy())
    with pytest.raises(ValueError):
        make_policy("oracle")
