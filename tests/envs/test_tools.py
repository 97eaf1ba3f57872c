"""The envs meet the tools researchers already use: a gymnasium path free of torch (checked in a
fresh interpreter: tests/test_fresh_interpreter.py), a normalised action space, info that
TorchRL's GymEnv reads, an exact table that TorchRL's DoubleToFloat cannot round, numpy
(Stable-Baselines3-style) policies under the protocol."""

import math
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from torchrl.envs import DoubleToFloat, GymEnv

from billiards import domain
from billiards.envs import GYM_ID, GYM_INFO_KEYS, Billiards4BallInningEnv, NormalizedActions, make_env, reset_to
from billiards.evaluation import evaluate_policy, numpy_policy
from billiards.physics import DEFAULT_PARAMS, random_racks, simulate_batch

ROOT = Path(__file__).resolve().parents[2]
R = DEFAULT_PARAMS.ball_radius


# ----------------------------------------------------------------------------- gymnasium path


def test_gym_info_has_the_same_numpy_keys_on_reset_and_step():
    env = Billiards4BallInningEnv()
    _, info0 = env.reset(seed=0)
    _, _, _, _, info1 = env.step(np.zeros(4, dtype=np.float32))
    assert tuple(info0) == tuple(info1) == GYM_INFO_KEYS
    for key in GYM_INFO_KEYS:
        assert isinstance(info0[key], (np.generic, np.ndarray)), key
        assert np.asarray(info0[key]).dtype == np.asarray(info1[key]).dtype, key
        assert np.shape(info0[key]) == np.shape(info1[key]), key
    assert not info0["score"] and info0["first_contact"] == -1 and info0["shot"] == 0
    assert info1["shot"] == 1 and info1["n_events"] > 0
    envs = gym.make_vec(GYM_ID, num_envs=2, vectorization_mode="sync")  # stacks typed arrays, not objects
    for info in (envs.reset(seed=0)[1], envs.step(np.zeros((2, 4), dtype=np.float32))[-1]):
        assert info["score"].dtype == bool and info["hits"].shape == (2, 3) and info["positions"].dtype == np.float64


def test_torchrl_gymenv_reads_score_and_foul_from_info():
    # TorchRL's GymEnv over the registered id, with the info reader it builds from info itself.
    tenv = GymEnv(GYM_ID, max_shots=12)
    tenv.auto_register_info_dict()
    tenv.set_seed(3)
    actions = torch.rand(12, 4, generator=torch.Generator().manual_seed(0)) * 2 - 1
    td = tenv.reset()
    start = td["positions"].numpy()  # read from the reset's info
    got = []
    for a in actions:
        td["action"] = a
        full, td = tenv.step_and_maybe_reset(td)
        got.append((bool(full["next", "score"]), bool(full["next", "foul"]), int(full["next", "shot"])))
    # the same inning played on the gym env directly
    env = Billiards4BallInningEnv(max_shots=12)
    env.reset(options={"positions": start})
    want = []
    for a in actions.numpy():
        info = env.step(a)[-1]
        want.append((bool(info["score"]), bool(info["foul"]), int(info["shot"])))
    assert got == want
    assert any(f for _, f, _ in want)  # some foul, so the check reads a real True


# ----------------------------------------------------------------------------- normalised actions


def test_normalised_action_space_maps_to_the_documented_shot():
    env = Billiards4BallInningEnv()
    assert env.action_space.low.tolist() == [-1] * 4 and env.action_space.high.tolist() == [1] * 4
    rng = np.random.default_rng(0)
    for n in range(5):
        env.reset(seed=n)
        pos = env.positions
        x = rng.uniform(-1, 1, 4).astype(np.float32)
        _, _, _, _, info = env.step(x)
        x = x.astype(np.float64)
        shot = np.array([math.pi * (x[0] + 1), (x[1] + 1) / 2, x[2], x[3]])  # by hand
        np.testing.assert_allclose(info["raw_action"], shot, rtol=1e-15, atol=1e-15)
        np.testing.assert_array_equal(info["positions"], simulate_batch(pos[None], info["raw_action"][None]).positions[0])
        np.testing.assert_allclose(domain.normalize_action(shot), x, atol=1e-12)
    # with the aim constraint the first coordinate is u = x0
    env = Billiards4BallInningEnv(constrain_aim=True)
    env.reset(seed=1)
    pos = env.positions
    _, _, _, _, info = env.step(np.array([0.5, 0.0, 0.0, 0.0], dtype=np.float32))
    assert info["raw_action"][0] == domain.constrained_theta(pos, 0.5, R) and info["raw_action"][1] == 0.5
    # the paper's raw box by a flag
    raw = Billiards4BallInningEnv(normalize_actions=False)
    assert raw.action_space.high[0] == np.float32(2 * math.pi) and raw.action_space.low[1] == 0
    with pytest.raises(ValueError, match=r"normalised.*\[-1, 1\]"):
        env.step(np.array([0.0, 1.5, 0.0, 0.0]))


def test_gymnasium_and_sb3_checkers_have_no_advice_for_the_default_env():
    from gymnasium.utils.env_checker import check_env

    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")

    def advice(env):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env)
            sb3_checker.check_env(env)
        return [str(w.message) for w in caught]

    assert advice(gym.make(GYM_ID).unwrapped) == []
    assert advice(gym.make(GYM_ID, constrain_aim=True, extra_features=True).unwrapped) == []
    assert any("symmetric and normalized Box" in m for m in advice(gym.make(GYM_ID, normalize_actions=False).unwrapped))


def test_torchrl_normalized_actions_transform_plays_the_same_shots():
    B, steps = 8, 3
    pos = random_racks(np.random.default_rng(5), B)
    for constrain in (False, True):
        norm = make_env(B, constrain_aim=constrain, normalize_actions=True, seed=0)
        raw = make_env(B, constrain_aim=constrain, seed=0)
        assert norm.action_spec_unbatched.space.low.tolist() == [-1] * 4
        assert raw.action_spec_unbatched.space.low.tolist() == domain.action_bounds(constrain)[0].tolist()
        xs = [torch.rand(B, 4, generator=torch.Generator().manual_seed(k), dtype=torch.float64) * 2 - 1 for k in range(steps)]
        a = norm.rollout(steps, lambda td: td.set("action", xs[int(td["shot"][0])]), break_when_any_done=False,
                         auto_reset=False, tensordict=reset_to(norm, pos))
        raw_xs = [torch.from_numpy(domain.unnormalize_action(x.numpy(), constrain)) for x in xs]
        b = raw.rollout(steps, lambda td: td.set("action", raw_xs[int(td["shot"][0])]), break_when_any_done=False,
                        auto_reset=False, tensordict=reset_to(raw, pos))
        torch.testing.assert_close(a["next", "positions"], b["next", "positions"], rtol=0, atol=0)
    with pytest.raises(ValueError, match="constrain_aim=True"):
        make_env(2, constrain_aim=True).append_transform(NormalizedActions()).action_spec


def test_numpy_policy_is_evaluated_like_the_raw_policy():
    x = np.array([-0.3, 0.2, 0.1, -0.1])
    shot = torch.from_numpy(domain.unnormalize_action(x))
    a = evaluate_policy(numpy_policy(lambda obs: np.tile(x, (len(obs), 1))), n_innings=6, max_shots=3)
    b = evaluate_policy(lambda td: td.set("action", shot.expand(td.batch_size[0], 4).clone()), n_innings=6, max_shots=3)
    assert a == b and a.shots == 18


# ----------------------------------------------------------------------------- exact table


def test_double_to_float_does_not_change_outcomes():
    B, steps = 40, 10  # 400 shots
    layers = dict(constrain_aim=True, extra_features=True, foul_penalty=1.0, gentle=0.2, near_miss=0.05)
    gen = torch.Generator().manual_seed(0)
    actions = [torch.rand(B, 4, generator=gen) * torch.tensor([2, 1, 2, 2]) - torch.tensor([1, 0, 1, 1]) for _ in range(steps)]
    outs = []
    for cast in (False, True):
        env = make_env(B, seed=1, **layers)
        if cast:
            env.append_transform(DoubleToFloat())
            assert env.observation_spec["positions"].dtype == torch.float32  # the transform did reach "positions"
        it = iter(actions)
        outs.append(env.rollout(steps, lambda td: td.set("action", next(it)), break_when_any_done=False))
    plain, cast = outs
    assert cast["next", "positions"].dtype == torch.float32
    for key in ("score", "foul", "first_contact", "positions_bits"):
        assert torch.equal(plain["next", key], cast["next", key]), key
    torch.testing.assert_close(plain["next", "reward"], cast["next", "reward"], rtol=0, atol=0)
    assert plain["next", "score"].any()


def test_table_not_float64_is_refused_and_a_new_table_wins_over_stale_bits():
    env = make_env(2, seed=0)
    td = env.reset()
    td["action"] = torch.tensor([[1.0, 0.5, 0.0, 0.0]] * 2)
    bad = td.exclude("positions_bits").set("positions", td["positions"].float())
    with pytest.raises(ValueError, match=r'"positions" must be the exact float64 table'):
        env.step(bad)
    new = random_racks(np.random.default_rng(9), 2)
    stale = td.clone().set("positions", torch.from_numpy(new))  # bits still of the old table
    out = env.step(stale)["next", "positions"].numpy()
    np.testing.assert_array_equal(out, simulate_batch(new, td["action"].numpy().astype(np.float64)).positions)


# ----------------------------------------------------------------------------- spec and rendering


@pytest.mark.parametrize(
    "physics",
    [None, "international", {"preset": "international", "u_roll": 0.02}, DEFAULT_PARAMS.__class__(u_roll=0.012)],
)
def test_gym_spec_round_trips_through_json_with_any_physics(physics):
    kwargs = {} if physics is None else {"physics": physics}
    env = gym.make(GYM_ID, max_shots=3, **kwargs)
    spec = gym.envs.registration.EnvSpec.from_json(env.spec.to_json())
    again = gym.make(spec)
    assert again.unwrapped.params == env.unwrapped.params and again.unwrapped.max_shots == 3
    # the same physics: the same shot from the same table
    pos = env.reset(seed=0)[1]["positions"]
    again.reset(options={"positions": pos})
    x = np.array([0.3, 0.4, 0.1, -0.2], dtype=np.float32)
    np.testing.assert_array_equal(env.step(x)[-1]["positions"], again.step(x)[-1]["positions"])
    if physics is not None:
        assert gym.make(GYM_ID, params=physics).spec.to_json()  # the older spelling too


def test_human_render_names_the_missing_dependency(monkeypatch):
    monkeypatch.setitem(sys.modules, "pygame", None)  # as if not installed
    with pytest.raises(gym.error.DependencyNotInstalled, match=r"pygame.*billiards\[render\]"):
        Billiards4BallInningEnv(render_mode="human")


def test_human_render_shows_frames(monkeypatch):
    pygame = pytest.importorskip("pygame")
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    env = Billiards4BallInningEnv(render_mode="human")
    env.reset(seed=0)
    env.step(np.zeros(4, dtype=np.float32))
    shown = pygame.surfarray.array3d(pygame.display.get_surface()).swapaxes(0, 1)
    env.unwrapped.render_mode = "rgb_array"
    frame = env.render()
    assert shown.shape == frame.shape
    assert (shown == frame).all(-1).mean() > 0.98  # the frame (up to the display's colour conversion)
    env.close()


def test_rgb_array_shows_the_last_shot():
    from billiards.render import table_rgb_array

    env = Billiards4BallInningEnv(render_mode="rgb_array")
    env.reset(seed=0)
    np.testing.assert_array_equal(env.render(), table_rgb_array(env.positions, env.params))  # balls at rest
    env.step(np.array([0.2, 0.5, 0.0, 0.0], dtype=np.float32))
    after = env.render()
    still = table_rgb_array(env.positions, env.params)  # the same rest table without the shot
    assert after.shape == still.shape
    assert (np.abs(after.astype(int) - still.astype(int)).sum(-1) > 60).sum() > 200  # the paths and start balls


def test_citation_file_matches_the_package_metadata():
    """CITATION.cff (GitHub's "Cite this repository") names the version and license pyproject
    ships and the paper it reproduces; a version bump that forgets it fails here."""
    import tomllib

    import yaml

    import billiards

    root = Path(__file__).resolve().parents[2]
    cff = yaml.safe_load((root / "CITATION.cff").read_text())
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert project["dynamic"] == ["version"] and "version" not in project  # one place: billiards.__version__
    assert str(cff["version"]) == billiards.__version__
    assert cff["license"] == project["license"]
    assert cff["authors"] and all("name" in a or "family-names" in a for a in cff["authors"])
    (paper,) = cff["references"]
    assert paper["title"].startswith("Korean 4-Ball Billiards")
    assert [a["family-names"] for a in paper["authors"]] == ["Oh", "Kang", "Park"]
