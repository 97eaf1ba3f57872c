"""Two-player matches (billiards.envs.sagu_v0): PettingZoo's API and seed tests, TorchRL's
wrapper, either cue ball striking, and the turn rules on shots chosen to score, foul or miss."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from billiards import domain  # noqa: E402
from billiards.envs import sagu_v0  # noqa: E402
from billiards.envs._common import initial_racks  # noqa: E402
from billiards.envs.sagu import SWAP, SaguEnv, shooter_view  # noqa: E402
from billiards.physics import DEFAULT_PARAMS, simulate_batch  # noqa: E402


def test_pettingzoo_api_and_seed_tests_pass():
    from pettingzoo.test import api_test, seed_test

    api_test(sagu_v0.env(noise="fastfiz_x5", target=3), num_cycles=300)
    seed_test(lambda: sagu_v0.env(noise="fastfiz", target=3), num_cycles=50)


def test_torchrl_runs_it_through_its_pettingzoo_wrapper():
    from torchrl.envs import PettingZooWrapper

    env = PettingZooWrapper(env=sagu_v0.env(noise="fastfiz_x5", target=2), use_mask=True, categorical_actions=False, seed=0)
    td = env.rollout(40)
    assert set(env.group_map) == {"white", "yellow"} and td.batch_size[0] >= 1
    assert td["white", "observation"].shape[-1] == td["yellow", "observation"].shape[-1] == 28 + 3
    # zero-sum: what one player gains the other loses
    assert float(td["next", "white", "reward"].sum() + td["next", "yellow", "reward"].sum()) == 0.0


def _shots(game: SaguEnv, player: int, n: int = 3000, seed: int = 0):
    """n normalised actions and what each does from the table for ``player`` (exact play)."""
    x = np.random.default_rng(seed).uniform(-1, 1, (n, 4)).astype(np.float32)  # as an agent acts
    raw = domain.raw_action(domain.unnormalize_action(x.astype(np.float64)), np.repeat(shooter_view(game.positions, player)[None], n, 0),
                            DEFAULT_PARAMS.ball_radius, False)
    return x, simulate_batch(np.repeat(shooter_view(game.positions, player)[None], n, 0), raw, DEFAULT_PARAMS)


def test_a_yellow_shot_is_the_white_shot_of_the_swapped_table():
    """Either cue ball strikes: yellow's shot from table T is the simulator's (white's) shot from
    T with the cue balls' slots exchanged, exchanged back; yellow's observation puts its own ball
    first."""
    game = SaguEnv(start="random")
    game.reset(np.random.default_rng(3), first=1)
    x, res = _shots(game, 1, n=1)
    before = game.positions.copy()
    game.shoot(x[0].astype(np.float32), np.random.default_rng(0))
    assert np.array_equal(game.positions, res.positions[0][SWAP])
    assert np.array_equal(game.observe(1)[:28], domain.observation(game.positions[SWAP][None], False)[0])
    assert np.array_equal(game.observe(0)[:28], domain.observation(game.positions[None], False)[0])
    assert not np.array_equal(before, game.positions)


def test_turns_pass_on_a_miss_or_a_foul_and_the_target_ends_the_match():
    env = sagu_v0.raw_env(target=2, foul_penalty=1.0)
    env.reset(seed=0)
    x, res = _shots(env.game, 0)
    score, foul = np.flatnonzero(res.score), np.flatnonzero(res.foul)
    miss = np.flatnonzero(res.miss)
    assert len(score) and len(foul) and len(miss)
    # a score: the same player again, +1 / -1
    env.step(x[score[0]].astype(np.float32))
    assert env.agent_selection == "white" and env.rewards == {"white": 1.0, "yellow": -1.0}
    assert (env.infos["white"]["own_score"], env.infos["yellow"]["opponent_score"]) == (1.0, 1.0)
    # a foul from a fresh table: one point lost, the turn passes
    env.game.positions = initial_racks(np.random.default_rng(0), "canonical", 1, DEFAULT_PARAMS)[0]
    env.step(x[foul[0]].astype(np.float32))
    assert env.agent_selection == "yellow" and env.rewards == {"white": -1.0, "yellow": 1.0}
    assert env.game.scores == [0.0, 0.0] and env.game.innings == 2 and bool(env.infos["white"]["shot_foul"])
    # yellow scores twice from scoring tables: the match is over, yellow won
    for _ in range(2):
        y, res = _shots(env.game, 1)
        env.step(y[np.flatnonzero(res.score)[0]].astype(np.float32))
    assert all(env.terminations.values()) and env.game.scores == [0.0, 2.0]
    # a foul at 0 points costs nothing (scores never go below 0)
    env.reset(seed=0)
    env.step(x[foul[0]].astype(np.float32))
    assert env.rewards == {"white": 0.0, "yellow": 0.0} and env.agent_selection == "yellow"


def test_the_innings_limit_truncates_a_match_and_bad_settings_are_refused():
    env = sagu_v0.raw_env(max_innings=3)
    env.reset(seed=0)
    x, res = _shots(env.game, 0)
    miss = x[np.flatnonzero(res.miss)[0]].astype(np.float32)
    for _ in range(3):
        assert not any(env.truncations.values())
        env.step(miss if env.agent_selection == "white" else _miss(env))
    assert all(env.truncations.values()) and env.game.innings == 4
    for bad, message in (({"target": 0}, "target"), ({"start": "break"}, "start"), ({"foul_penalty": -1.0}, "foul_penalty"),
                         ({"first": "red"}, "first"), ({"noise": "fastfiz_x50"}, "noise")):
        with pytest.raises((ValueError, KeyError), match=message):
            sagu_v0.raw_env(**bad)


def _miss(env) -> np.ndarray:
    x, res = _shots(env.game, 1, n=200, seed=1)
    return x[np.flatnonzero(res.miss)[0]].astype(np.float32)
