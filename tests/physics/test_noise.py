"""The execution-noise model (issue #22's first piece): exact by default, the FastFiz sigmas in
physical units, reproducible from the caller's generator."""

import math

import numpy as np
import pytest

from billiards.physics import PRESETS, simulate_batch
from billiards.physics.noise import NOISE_PRESETS, NoiseModel, get_noise

K = PRESETS["korean_medium"]


def test_no_noise_is_the_identity_and_draws_nothing():
    acts = np.random.default_rng(0).uniform([0, 0, -1, -1], [2 * np.pi, 1, 1, 1], (100, 4))
    rng = np.random.default_rng(1)
    state = rng.bit_generator.state
    played = get_noise("none").perturb(acts, rng, K)
    np.testing.assert_array_equal(played, acts)
    assert rng.bit_generator.state == state


@pytest.mark.parametrize("name", ["fastfiz", "fastfiz_x5"])
def test_played_shots_have_the_presets_sigmas_in_physical_units(name):
    model = NOISE_PRESETS[name]
    n = 200_000
    acts = np.tile([1.0, 0.5, 0.0, 0.0], (n, 1))  # mid power, centre tip: no clipping
    played = model.perturb(acts, np.random.default_rng(2), K)
    d_aim = np.degrees(played[:, 0] - acts[:, 0])
    d_speed = (played[:, 1] - acts[:, 1]) * K.cue_speed_max
    d_tip_mm = played[:, 2:] * K.max_english * K.ball_radius * 1e3
    for d, sigma in ((d_aim, model.sigma_aim_deg), (d_speed, model.sigma_speed), (d_tip_mm[:, 0], model.sigma_tip_mm),
                     (d_tip_mm[:, 1], model.sigma_tip_mm)):
        assert abs(d.mean()) < 5 * sigma / math.sqrt(n)
        assert d.std() == pytest.approx(sigma, rel=0.01)
    assert model == NOISE_PRESETS["fastfiz"].scaled(5 if name == "fastfiz_x5" else 1)


def test_noise_is_reproducible_and_keeps_actions_valid():
    acts = np.random.default_rng(3).uniform([0, 0, -1, -1], [2 * np.pi, 1, 1, 1], (5000, 4))
    acts[:10, 1] = 1.0  # full power: the noisy speed is clipped at the table's maximum
    acts[10:20, 2:] = [0.6, 0.8]  # on the rim of the tip disk
    big = NOISE_PRESETS["fastfiz_x5"]
    a = big.perturb(acts, np.random.default_rng(4), K)
    np.testing.assert_array_equal(a, big.perturb(acts, np.random.default_rng(4), K))
    assert not np.array_equal(a, big.perturb(acts, np.random.default_rng(5), K))
    assert ((a[:, 1] >= 0) & (a[:, 1] <= 1)).all() and (np.linalg.norm(a[:, 2:], axis=1) <= 1 + 1e-12).all()
    racks = np.repeat(np.array([[[0.3, 0.3], [0.9, 1.3], [0.5, 0.8], [0.8, 1.1]]]), 5000, axis=0)
    simulate_batch(racks, a, K)  # every played shot is a valid action


def test_bad_noise_is_refused_naming_the_field():
    with pytest.raises(ValueError, match="sigma_speed must be a finite number >= 0"):
        NoiseModel(sigma_speed=-0.1)
    with pytest.raises(ValueError, match="sigma_aim_deg"):
        NoiseModel(sigma_aim_deg=float("nan"))
    with pytest.raises(ValueError, match="unknown noise preset 'loud'"):
        get_noise("loud")
    with pytest.raises(ValueError, match=r"unknown noise field\(s\) \['sigma_v'\]"):
        get_noise({"sigma_v": 0.1})
    assert get_noise({"sigma_aim_deg": 0.125, "sigma_speed": 0.075, "sigma_tip_mm": 0.5}) == NOISE_PRESETS["fastfiz"]


def _rollout(env, actions):
    import torch

    td = env.reset()
    out = []
    for a in actions:
        td["action"] = torch.as_tensor(a, dtype=torch.float32)
        step = env.step(td)
        out.append(step["next"].clone())
        td = step["next"].select("positions", "positions_bits", "shot", "observation").clone()
    return out


def test_torchrl_env_plays_the_noisy_shot_and_records_it():
    from torchrl.envs.utils import check_env_specs

    from billiards.envs import make_env

    B = 64
    acts = np.random.default_rng(6).uniform([0, 0.2, -1, -1], [2 * np.pi, 1, 1, 1], (3, B, 4)).astype(np.float32)
    exact = _rollout(make_env(B, seed=3), acts)
    same = _rollout(make_env(B, seed=3, noise="none"), acts)
    for a, b in zip(exact, same):  # noise off: bit-identical, no extra key
        assert "played_action" not in b.keys()
        assert (a == b).all()
    noisy_env = make_env(B, seed=3, noise="fastfiz")
    check_env_specs(noisy_env, seed=0)
    first_reset = make_env(B, seed=3, noise="fastfiz").reset()["positions"]
    np.testing.assert_array_equal(first_reset.numpy(), make_env(B, seed=3).reset()["positions"].numpy())  # racks unchanged
    noisy = _rollout(make_env(B, seed=3, noise="fastfiz"), acts)
    again = _rollout(make_env(B, seed=3, noise="fastfiz"), acts)
    before = make_env(B, seed=3).reset()["positions"].numpy()
    for t, (n, m) in enumerate(zip(noisy, again)):
        assert (n == m).all()  # the same seed replays the same noisy inning
        played = n["played_action"].numpy()
        assert played.dtype == np.float64 and not np.allclose(played, acts[t].astype(np.float64))
        np.testing.assert_array_equal(n["positions"].numpy(), simulate_batch(before, played, K).positions)
        before = n["positions"].numpy()


def test_gym_env_records_commanded_and_played_shots_and_replays_from_its_seed():
    import gymnasium as gym

    import billiards.envs  # noqa: F401

    def inning(noise, seed):
        env = gym.make("Billiards4Ball-v0", noise=noise, normalize_actions=False)
        env.reset(seed=seed)
        rng = np.random.default_rng(9)
        infos = []
        for _ in range(5):
            infos.append(env.step(rng.uniform([0, 0.2, -1, -1], [2 * np.pi, 1, 1, 1]).astype(np.float32))[4])
        return infos

    plain = inning(None, 1)
    assert all(np.array_equal(i["raw_action"], i["commanded_action"]) for i in plain)
    noisy, again = inning("fastfiz_x5", 1), inning("fastfiz_x5", 1)
    for i, j, p in zip(noisy, again, plain):
        np.testing.assert_array_equal(i["raw_action"], j["raw_action"])
        np.testing.assert_array_equal(i["commanded_action"], p["commanded_action"])
        assert not np.array_equal(i["raw_action"], i["commanded_action"])
    assert not np.array_equal(noisy[0]["raw_action"], inning("fastfiz_x5", 2)[0]["raw_action"])
    with pytest.raises(ValueError, match="unknown noise preset"):
        gym.make("Billiards4Ball-v0", noise="loud")
