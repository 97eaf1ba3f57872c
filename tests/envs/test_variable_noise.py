"""Variable execution noise and ``noise.scale`` (issue #34, item 4): a level drawn per shot from
the env's own noise generator, told with the table (gymnasium, vector, TorchRL and two-player
envs) and handed to the noise-aware search; a multiplier of any preset's sigmas, 1 leaving it
bit for bit as it was."""

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import billiards.envs  # noqa: F401  (registers Billiards4Ball-v0)
import billiards.search.actors as actors_mod
from billiards.envs import BilliardsEnv, make_env
from billiards.physics import DEFAULT_PARAMS, PRESETS, random_racks, simulate_batch
from billiards.physics.noise import NOISE_PRESETS, NoiseModel, noise_errors, noise_from_config, noise_record

ROOT = Path(__file__).resolve().parents[2]
K = PRESETS["korean_medium"]
FASTFIZ, VARIABLE = NOISE_PRESETS["fastfiz"], NOISE_PRESETS["variable"]


def gym_inning(seed, steps=6, noise="variable"):
    """(observations, infos) of one gym inning under ``noise``, fixed raw actions."""
    env = gym.make("Billiards4Ball-v0", noise=noise, normalize_actions=False, max_shots=steps)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(9)
    out, infos = [obs], []
    for _ in range(steps):
        obs, _, _, _, info = env.step(rng.uniform([0, 0.2, -1, -1], [2 * np.pi, 1, 1, 1]).astype(np.float32))
        out.append(obs)
        infos.append(info)
    return np.array(out), infos


# ----------------------------------------------------------------------------- the model and the config node


def test_variable_is_fastfiz_times_a_level_drawn_in_its_range():
    assert VARIABLE.is_variable and not FASTFIZ.is_variable and VARIABLE.level_range == (0.0, 5.0)
    assert (VARIABLE.sigma_aim_deg, VARIABLE.sigma_speed, VARIABLE.sigma_tip_mm) == (0.125, 0.075, 0.5)
    assert VARIABLE.describe() == "variable" and noise_from_config({"preset": "variable"}) == VARIABLE
    levels = VARIABLE.draw_levels((20_000,), np.random.default_rng(0))
    assert levels.min() >= 0 and levels.max() <= 5 and abs(levels.mean() - 2.5) < 0.05
    np.testing.assert_array_equal(levels, VARIABLE.draw_levels((20_000,), np.random.default_rng(0)))
    np.testing.assert_array_equal(levels, levels.astype(np.float32))  # what a float32 observation tells is what is played
    with pytest.raises(ValueError, match="level_range must be"):
        NoiseModel(0.1, 0.1, 0.1, level_range=(3.0, 1.0))


def test_a_shot_at_level_l_plays_l_times_the_errors_and_level_0_is_exact():
    n = 50_000
    acts = np.tile([1.0, 0.5, 0.3, -0.2], (n, 1))
    for level in (0.0, 1.0, 3.0):
        played = VARIABLE.perturb(acts, np.random.default_rng(1), K, levels=np.full(n, level))
        if level == 0:
            np.testing.assert_array_equal(played, acts)  # the commanded shot, bit for bit
            continue
        assert np.degrees(played[:, 0] - acts[:, 0]).std() == pytest.approx(level * 0.125, rel=0.02)
        assert ((played[:, 1] - acts[:, 1]) * K.cue_speed_max).std() == pytest.approx(level * 0.075, rel=0.02)
        # the same errors as fastfiz's model scaled by the level
        np.testing.assert_allclose(played, FASTFIZ.scaled(level).perturb(acts, np.random.default_rng(1), K), atol=1e-12)


def test_noise_scale_1_is_the_preset_bit_for_bit_and_2_doubles_every_sigma():
    acts = np.random.default_rng(0).uniform([0, 0, -1, -1], [6, 1, 1, 1], (500, 4))
    for preset in ("fastfiz", "fastfiz_x5", "variable"):
        one = noise_from_config({"preset": preset, "scale": 1.0})
        assert one == NOISE_PRESETS[preset] and one.describe() == preset and noise_record(one)["noise_scale"] == 1.0
    one = noise_from_config({"preset": "fastfiz", "scale": 1.0})
    np.testing.assert_array_equal(one.perturb(acts, np.random.default_rng(2), K), FASTFIZ.perturb(acts, np.random.default_rng(2), K))
    two = noise_from_config({"preset": "fastfiz", "scale": 2.0})
    assert two == NoiseModel(0.25, 0.15, 1.0)
    np.testing.assert_array_equal(two.perturb(acts, np.random.default_rng(2), K),
                                  NoiseModel(0.25, 0.15, 1.0).perturb(acts, np.random.default_rng(2), K))
    record = noise_record(two)
    assert record["noise"] == "fastfiz*2" and record["noise_scale"] == 2.0
    assert record["noise_sigmas"] == {"aim_deg": 0.25, "speed": 0.15, "tip_mm": 1.0}
    assert noise_record(noise_from_config({"preset": "variable", "scale": 0.5}))["noise_levels"] == [0.0, 5.0]
    assert noise_from_config({"preset": "fastfiz", "scale": 0.0}).is_exact  # the sweep's 0: exact play


@pytest.mark.parametrize("node,message", [
    ({"scale": -1.0}, "noise.scale must be a finite number >= 0"),
    ({"scale": float("nan")}, "noise.scale must be a finite number >= 0"),
    ({"scale": float("inf")}, "noise.scale must be a finite number >= 0"),
    ({"level_range": [3.0, 1.0]}, "noise.level_range must be [low, high]"),
    ({"level_range": [0.0]}, "noise.level_range must be [low, high]"),
])
def test_bad_scale_and_level_range_are_named(node, message):
    errs = noise_errors({"preset": "fastfiz", **node})
    assert len(errs) == 1 and message in errs[0]


@pytest.mark.parametrize("app,override", [("search.py", "noise.scale=-1"), ("train.py", "noise.scale=nan")])
@pytest.mark.slow
def test_a_bad_noise_scale_fails_before_any_directory_is_written(tmp_path, app, override):
    from conftest import app_here

    proc = app_here(app, "noise=fastfiz", override, cwd=tmp_path)
    assert proc.returncode != 0 and "noise.scale must be a finite number >= 0" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- the envs tell the level


def test_gym_env_tells_each_shots_level_and_replays_it_from_its_seed():
    obs, infos = gym_inning(seed=3)
    env = gym.make("Billiards4Ball-v0", noise="variable")
    assert env.observation_space.shape == (29,) and gym.make("Billiards4Ball-v0").observation_space.shape == (28,)
    assert gym.make("Billiards4Ball-v0", noise="variable", extra_features=True).observation_space.shape == (33,)
    levels = obs[:, -1]
    assert ((levels >= 0) & (levels <= 5)).all() and len(np.unique(levels)) == len(levels)  # a new level per shot
    again, infos2 = gym_inning(seed=3)
    np.testing.assert_array_equal(obs, again)  # same seed: same levels, same tables
    for i, j in zip(infos, infos2):
        np.testing.assert_array_equal(i["raw_action"], j["raw_action"])
    assert not np.array_equal(levels, gym_inning(seed=4)[0][:, -1])
    # each shot played at the level its observation told: its error, in units of the errors at level 1
    for level, info in zip(levels[:-1], infos):
        d_aim = np.degrees(info["raw_action"][0] - info["commanded_action"][0])
        assert abs(d_aim) < 6 * 0.125 * level + 1e-12


def test_gym_vector_env_is_the_sync_env_under_variable_noise():
    B = 4
    vec = gym.make_vec("Billiards4Ball-v0", num_envs=B, noise="variable", max_shots=3)
    sync = gym.make_vec("Billiards4Ball-v0", num_envs=B, noise="variable", max_shots=3, vectorization_mode="sync")
    a, _ = vec.reset(seed=5)
    b, _ = sync.reset(seed=5)
    np.testing.assert_array_equal(a, b)
    rng = np.random.default_rng(0)
    for _ in range(8):  # past two autoresets
        act = rng.uniform(-1, 1, (B, 4)).astype(np.float32)
        (a, *_, ia), (b, *_, ib) = vec.step(act), sync.step(act)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(ia["raw_action"], ib["raw_action"])
    assert a.shape == (B, 29)


def test_torchrl_env_carries_the_level_and_plays_the_one_its_input_holds():
    B = 4000
    env = BilliardsEnv(B, seed=0, params=K, noise="variable")
    td = env.reset()
    assert "noise_level" in env.observation_spec.keys() and "noise_level" in env.state_spec.keys()
    assert "noise_level" not in BilliardsEnv(2, seed=0, noise="fastfiz").observation_spec.keys()
    levels = td["noise_level"].numpy()[:, 0]
    assert td["noise_level"].dtype == torch.float32 and ((levels >= 0) & (levels <= 5)).all()
    np.testing.assert_array_equal(td["positions"].numpy(), BilliardsEnv(B, seed=0, params=K).reset()["positions"].numpy())
    commanded = np.tile([1.0, 0.5, 0.0, 0.0], (B, 1))
    told = np.repeat([0.0, 1.0, 4.0, 2.0], B // 4).astype(np.float32)
    td["noise_level"] = torch.from_numpy(told[:, None])
    td["action"] = torch.from_numpy(commanded)
    out = env.step(td)["next"]
    d = out["played_action"].numpy() - commanded
    np.testing.assert_array_equal(d[told == 0], 0.0)  # level 0: the commanded shot exactly
    for level in (1.0, 4.0, 2.0):
        assert np.degrees(d[told == level, 0]).std() == pytest.approx(0.125 * level, rel=0.08)
    nxt = out["noise_level"].numpy()[:, 0]
    assert ((nxt >= 0) & (nxt <= 5)).all() and not np.array_equal(nxt, levels)  # the next shots' levels
    with pytest.raises(KeyError, match="noise_level"):
        env.step(td.exclude("noise_level"))


def test_make_env_appends_the_level_to_the_observation_and_replays_it_from_its_seed():
    from torchrl.envs.utils import check_env_specs

    env = make_env(6, seed=2, noise="variable", extra_features=True)
    check_env_specs(env, seed=0)
    td = env.reset()
    assert td["observation"].shape == (6, 33)
    np.testing.assert_array_equal(td["observation"][:, -1].numpy(), td["noise_level"][:, 0].numpy())
    assert make_env(6, seed=2, extra_features=True).reset()["observation"].shape == (6, 32)  # unchanged without it
    roll = make_env(6, seed=2, noise="variable").rollout(4, break_when_any_done=False)
    again = make_env(6, seed=2, noise="variable").rollout(4, break_when_any_done=False)
    np.testing.assert_array_equal(roll["next", "noise_level"].numpy(), again["next", "noise_level"].numpy())
    np.testing.assert_array_equal(roll["next", "observation"][..., -1].numpy(), roll["next", "noise_level"][..., 0].numpy())


def test_the_two_player_env_tells_the_next_shots_level():
    from billiards.envs.sagu import SaguEnv

    def match(seed):
        game = SaguEnv(noise="variable", target=50, start="random")
        rng = np.random.default_rng(seed)
        game.reset(rng)
        told, played = [], []
        for _ in range(12):
            told.append(game.observe(game.mover)[-1])
            level = game.shot_level
            shot = game.shoot(np.array([0.1, 0.0, 0.0, 0.0], np.float32), rng)
            played.append((level, shot["raw_action"] - shot["commanded_action"]))
        return np.array(told), played

    told, played = match(0)
    assert ((told >= 0) & (told <= 5)).all() and len(np.unique(told)) == len(told)
    for t, (level, d) in zip(told, played):
        assert t == np.float32(level) and abs(np.degrees(d[0])) < 6 * 0.125 * level + 1e-12
    np.testing.assert_array_equal(told, match(0)[0])
    assert SaguEnv(noise="fastfiz").observe(0)[-1] == 1.0  # a fixed noise tells its constant level, as before


# ----------------------------------------------------------------------------- the search gets the level


def test_the_noise_aware_actors_search_at_the_level_the_env_told(monkeypatch):
    from billiards.search import GeometricProposer, PUCTConfig, RobustConfig
    from billiards.search.actors import NoisyPUCTActor, RobustActor

    calls = []
    original = actors_mod.robust_search

    def recording(*args, **kwargs):
        calls.append(kwargs.get("levels"))
        return original(*args, **kwargs)

    monkeypatch.setattr(actors_mod, "robust_search", recording)
    env = BilliardsEnv(3, seed=1, params=K, noise="variable")
    td = env.reset()
    actor = RobustActor(GeometricProposer(R=K.ball_radius), RobustConfig(budget=40, k1=20), VARIABLE, params=K)
    actor(td)
    np.testing.assert_array_equal(calls[0], td["noise_level"].numpy()[:, 0].astype(np.float64))
    with pytest.raises(ValueError, match="noise_level"):
        actor.search(td["positions"].numpy())  # variable noise, searched blind: refused

    # at level 0 the noisy replays of PUCT are the exact shot, at level 3 they scatter around it
    simulated = []

    def sim(positions, actions, params=K):
        simulated.append(np.array(actions))
        return simulate_batch(positions, actions, params)

    import billiards.search.puct_noise as puct_noise_mod

    monkeypatch.setattr(puct_noise_mod, "simulate_batch", sim)
    shot = np.array([1.0, 0.5, 0.0, 0.0])
    one_shot = type("OneShot", (), {"name": "one", "propose": lambda self, pos, k, rng: np.tile(shot, (len(pos), k, 1))})()
    puct = NoisyPUCTActor(one_shot, PUCTConfig(budget=30, pool=8), VARIABLE, params=K)
    puct.search(random_racks(np.random.default_rng(0), 2, K), np.array([0.0, 3.0]))
    played = np.stack(simulated)  # (visits, state, 4)
    np.testing.assert_array_equal(played[:, 0], np.tile(shot, (30, 1)))
    assert np.degrees(played[:, 1, 0] - shot[0]).std() > 0.125


def small_search_config(*overrides):
    from hydra import compose, initialize_config_dir

    import billiards.search.config  # noqa: F401  (registers the search app's schemas)

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return compose(config_name="search", overrides=["noise=variable", "search.budget=40", "search.k1=20", "search.wave=10",
                                                         "proposer=for_noise_variable", "proposer.pool=100", "progress=false",
                                                         "picture=false", *overrides])


@pytest.mark.parametrize("protocol", [["protocol=p1", "protocol.n_innings=2", "protocol.shots=2"],
                                      ["protocol=p3", "protocol.seeds=1", "protocol.cap=3"]], ids=["p1", "p3"])
@pytest.mark.slow
def test_search_app_plays_variable_noise_and_records_it(tmp_path, monkeypatch, protocol):
    from billiards.search import run as search_run

    told = []
    original = actors_mod.RobustActor.search

    def recording(self, positions, levels=None):
        told.append(levels)
        return original(self, positions, levels)

    monkeypatch.setattr(actors_mod.RobustActor, "search", recording)
    cfg = small_search_config(*protocol)
    assert (cfg.search.kind, cfg.proposer.kind) == ("robust", "ranked")  # the default search over the noise's shot ranker
    search_run.run(cfg, tmp_path)
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["noise"] == "variable" and results["noise_levels"] == [0.0, 5.0] and results["noise_scale"] == 1.0
    assert results["config"]["noise"]["preset"] == "variable"
    levels = np.concatenate([t for t in told if t is not None and len(t)])
    assert len(levels) == sum(len(t) for t in told) > 0 and ((levels >= 0) & (levels <= 5)).all()
    if "protocol=p3" in protocol:  # the ledger keeps each last shot's level: the one the search was told
        from billiards.search.protocols import read_chains

        (chain,) = read_chains(tmp_path / "chains.jsonl").values()
        recorded = [shot[4] for shot in chain["last_shots"]]
        assert all(len(shot) == 5 for shot in chain["last_shots"])
        np.testing.assert_array_equal(recorded, levels[-len(recorded):])


def test_search_app_refuses_a_bad_scale_before_writing_anything(tmp_path):
    from billiards.search import run as search_run
    from billiards.search.config import SearchConfigError

    with pytest.raises(SearchConfigError, match="noise.scale must be a finite number >= 0"):
        search_run.run(small_search_config("noise.scale=nan"), tmp_path / "never")
    assert not (tmp_path / "never").exists()


def test_league_players_are_told_their_shots_level():
    from billiards.league.players import RandomAgent
    from billiards.league.play import play_match

    class Telling(RandomAgent):
        def __init__(self):
            super().__init__()
            self.levels = []

        def act(self, view, level=None):
            self.levels.append(level)
            return super().act(view, level)

    a, b = Telling(), Telling()
    play_match(a, b, seed=3, noise="variable", target=2, max_innings=6)
    levels = np.array(a.levels + b.levels, dtype=float)
    assert len(levels) and ((levels >= 0) & (levels <= 5)).all() and len(np.unique(levels)) > 1
    c, d = Telling(), Telling()
    play_match(c, d, seed=3, noise="fastfiz", target=2, max_innings=6)
    assert set(c.levels + d.levels) == {None}  # fixed noise: no level is handed over


@pytest.mark.slow
def test_a_policy_trained_under_variable_noise_is_told_the_level_or_refused_clearly(tmp_path):
    """Such a policy reads the level as its last input: the league's policy player feeds it; the
    policy proposer and the pictures, which have no level to give, refuse it by name."""
    from billiards.files import save_tagged
    from billiards.league.players import PolicyAgent
    from billiards.pictures import load_player
    from billiards.rl.policy import POLICY_FORMAT, _build_agent, _load_policy_file
    from billiards.search.proposers import load_policy_proposer

    state = _load_policy_file(ROOT / "results" / "policies" / "fastfiz_aim_features" / "seed0.pt")
    config = {**state["config"], "noise": {**state["config"]["noise"], "preset": "variable"}}
    agent, _ = _build_agent(config)
    path = save_tagged(tmp_path / "variable.pt", {**state, "config": config,
                                                    "actor": {k: v.clone() for k, v in agent.actor.state_dict().items()}})
    player = PolicyAgent(str(path), DEFAULT_PARAMS)
    view = random_racks(np.random.default_rng(0), 1)[0]
    low, high = player.act(view, 0.0), player.act(view, 5.0)
    assert low.shape == (4,) and not np.array_equal(low, high)  # the level reaches the network
    with pytest.raises(ValueError, match="trained under variable noise"):
        player.act(view, None)
    with pytest.raises(ValueError, match="trained under variable noise"):
        load_policy_proposer([path], name="v")
    with pytest.raises(ValueError, match="trained under variable noise"):
        load_player(str(path))
    assert state["format"] == POLICY_FORMAT
