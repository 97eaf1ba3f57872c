"""The physics presets: the paper's Korean medium table as the default, pooltool's
international table beside it, and the ``physics=`` choice reaching every place that simulates."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from billiards.physics import (
    DEFAULT_PARAMS,
    PRESETS,
    PhysicsParams,
    action_to_cue,
    api,
    canonical_rack,
    get_params,
    random_racks,
    simulate_batch,
    simulate_shot,
)
from billiards.physics import core
from billiards.physics.config import PhysicsConfig, params_from_config, physics_errors

K, I = PRESETS["korean_medium"], PRESETS["international"]
REPO = Path(__file__).resolve().parents[2]


def test_korean_medium_is_the_papers_table_and_the_default():
    assert DEFAULT_PARAMS is K and PhysicsParams() == K and get_params(None) is K
    # docs/physics.md §10
    assert (K.table_width, K.table_length, K.cushion_height) == (1.27, 2.54, 0.037)
    assert (K.ball_radius, K.ball_mass) == (0.03275, 0.21)
    assert (K.cue_mass, K.cue_speed_max, K.max_english) == (0.55, 4.5, 1.0)
    assert (K.u_slide, K.u_roll, K.e_ball, K.e_cushion, K.f_cushion) == (0.2, 0.018, 0.94, 0.85, 0.2)
    assert 5 * K.u_spin * K.g / (2 * K.ball_radius) == pytest.approx(50.0, abs=0.05)  # spin decay, rad/s^2
    assert K.max_time == 12.0 and (K.rack, K.rack_margin, K.rack_clearance) == ("korean", 0.005, 0.002)
    assert not K.squirt and K.ball_ball == "restitution"


def test_international_is_pooltools_billiard_table():
    assert (I.table_width, I.table_length, I.ball_radius, I.ball_mass) == (1.42, 2.84, 0.03075, 0.21)
    assert (I.u_slide, I.u_roll, I.u_spin) == (0.2, 0.01, 0.03075 * 4 / 9)
    assert (I.e_ball, I.e_cushion, I.f_cushion, I.cue_mass, I.cue_speed_max, I.max_english) == (0.95, 0.85, 0.15, 0.567, 6.0, 0.6)
    assert math.isinf(I.max_time) and (I.rack, I.rack_margin, I.rack_clearance) == ("spots", 0.0, 0.0)


def test_korean_opening_rack_coordinates():
    W, L, R = 1.27, 2.54, 0.03275
    np.testing.assert_allclose(canonical_rack(), [[W / 2 + 4 * R, 6 * L / 8], [W / 2, L / 8], [W / 2, 2 * L / 8], [W / 2, 6 * L / 8]])
    np.testing.assert_allclose(canonical_rack(), [[0.766, 1.905], [0.635, 0.3175], [0.635, 0.635], [0.635, 1.905]])
    np.testing.assert_allclose(canonical_rack(I), [[1.22, 0.71], [0.2, 0.71], [0.71, 0.71], [0.71, 2.13]])


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_random_racks_respect_the_presets_margins(name):
    p = PRESETS[name]
    racks = random_racks(np.random.default_rng(3), 4000, p)
    np.testing.assert_array_equal(racks, random_racks(np.random.default_rng(3), 4000, p))
    lo = p.ball_radius + p.rack_margin
    assert racks.min() >= lo
    assert racks[..., 0].max() <= p.table_width - lo and racks[..., 1].max() <= p.table_length - lo
    d = np.linalg.norm(racks[:, :, None] - racks[:, None], axis=-1)
    d[:, range(4), range(4)] = np.inf
    assert d.min() >= 2 * p.ball_radius + p.rack_clearance
    if p.rack_margin:  # the margin binds: some centre lies within 1 mm of it
        assert racks.min() < lo + 1e-3


def test_a_table_that_cannot_hold_the_balls_or_its_rack_fails_clearly(monkeypatch):
    with pytest.raises(ValueError, match="cannot hold four balls"):
        dataclasses.replace(K, table_width=0.2, table_length=0.2)
    with pytest.raises(ValueError, match="'korean' opening rack does not fit"):
        dataclasses.replace(K, table_width=0.3)  # the white beside red2 would sit in the cushion
    with pytest.raises(ValueError, match="rack must be one of"):
        dataclasses.replace(K, rack="diamond")
    with pytest.raises(ValueError, match="max_time"):
        dataclasses.replace(K, max_time=0.0)
    # a table where random racks are rare: a bounded search, then a clear error, never a hang
    tight = dataclasses.replace(I, table_width=0.53, table_length=0.30)  # ~44 % of draws fail
    monkeypatch.setattr(api, "RACK_ATTEMPTS", 2)
    with pytest.raises(ValueError, match="could not be placed in 2 rounds"):
        random_racks(np.random.default_rng(0), 200, tight)


def test_get_params_accepts_names_params_and_dicts_and_names_bad_input():
    assert get_params("international") is I and get_params(K) is K
    custom = get_params({"preset": "international", "u_roll": 0.02})
    assert custom == dataclasses.replace(I, u_roll=0.02) and custom.describe() == "international+u_roll=0.02"
    assert PhysicsParams.from_dict(json.loads(json.dumps(I.to_dict()))) == I  # inf survives JSON
    with pytest.raises(ValueError, match="unknown physics preset 'pool'"):
        get_params("pool")
    with pytest.raises(ValueError, match=r"unknown physics field\(s\) \['u_rol'\]"):
        get_params({"u_rol": 0.1})


def test_tip_offsets_reach_the_full_radius_and_the_strike_follows_marlow():
    V0, _, a, b = action_to_cue([0.0, 1.0, 0.6, 0.8])
    assert (V0, a, b) == pytest.approx((4.5, 0.6, 0.8))  # |(a, b)| = 1 -> 1.0 R, unscaled
    rack = np.array([[0.3, 0.3], [1.2, 2.4], [1.2, 2.0], [0.1, 2.4]])
    for act in ([math.pi / 2, 1.0, 0.0, 0.0], [math.pi / 2, 1.0, 0.6, 0.8]):
        v = np.hypot(*simulate_shot(rack, act).event_state[0, 0, 2:4])
        a, b = act[2], act[3]
        assert v == pytest.approx(4.5 * 2 / (1 + 0.21 / 0.55 + 2.5 * (a * a + b * b)), rel=1e-12)


def test_shots_stop_at_the_twelve_second_limit():
    # a hard shot on a low-friction copy of the table runs far past 12 s unless limited
    slick = dataclasses.replace(K, u_roll=0.002)
    rack = canonical_rack()
    act = [1.0, 1.0, 0.0, 0.0]
    limited = simulate_shot(rack, act, slick)
    free = simulate_shot(rack, act, dataclasses.replace(slick, max_time=math.inf))
    assert free.duration > 12.0 and not free.timed_out
    assert limited.timed_out and limited.duration == 12.0 and not limited.truncated
    assert limited.event_kind[-1] == core.EV_STOP and (limited.event_state[-1, :, 7] == 0).all()
    # until the limit both shots are the same shot; after it the limited one rests where it was
    n = int(np.searchsorted(free.event_time, 12.0))
    np.testing.assert_array_equal(limited.event_time[:n], free.event_time[:n])
    np.testing.assert_array_equal(limited.event_state[:n], free.event_state[:n])
    batch = simulate_batch(rack[None], np.array([act]), slick)
    assert batch.timed_out[0] and batch.duration[0] == 12.0
    np.testing.assert_array_equal(batch.positions[0], limited.positions)


def test_second_red_is_the_later_first_contact_in_the_event_log():
    racks = random_racks(np.random.default_rng(11), 3000)
    acts = np.random.default_rng(12).uniform([0, 0.3, -1, -1], [2 * np.pi, 1, 1, 1], (3000, 4))
    batch = simulate_batch(racks, acts)
    both = np.flatnonzero(batch.hits[:, 1] & batch.hits[:, 2])
    assert both.size >= 5 and (batch.second_red[~(batch.hits[:, 1] & batch.hits[:, 2])] == -1).all()
    for n in both[:20]:
        res = simulate_shot(racks[n], acts[n])
        reds = [o for k, b, o in zip(res.event_kind, res.event_ball, res.event_other) if k == core.EV_BALL_BALL and b == 0 and o >= 2]
        assert res.second_red == batch.second_red[n] == [r for i, r in enumerate(reds) if r not in reds[:i]][1]


def test_random_shot_rates_differ_between_the_tables():
    """Aimed shots score less often on the paper's table than on the international one (the
    figures in results/presets_rates.md); both well away from zero."""
    from billiards import domain

    rates = {}
    for name, p in PRESETS.items():
        rng = np.random.default_rng(0)
        racks = random_racks(rng, 6000, p)
        u = rng.uniform(-1, 1, 6000)
        acts = np.column_stack([domain.constrained_theta(racks, u, p.ball_radius), rng.uniform(0, 1, (6000, 1)),
                                rng.uniform(-1, 1, (6000, 2))])
        rates[name] = simulate_batch(racks, acts, p).score.mean()
    assert 0.02 < rates["korean_medium"] < rates["international"] < 0.15, rates


# ----------------------------------------------------------------------------- physics= reaches everything


def test_physics_config_node_builds_the_params_and_names_bad_values():
    node = OmegaConf.structured(PhysicsConfig)
    assert params_from_config(node) is K and params_from_config(None) is K
    node.preset = "international"
    node.u_roll = 0.02
    assert params_from_config(node) == dataclasses.replace(I, u_roll=0.02)
    node.u_roll = float("nan")
    assert physics_errors(node) == ["physics.u_roll: PhysicsParams.u_roll must be a finite positive number, got nan"]


def test_physics_reaches_the_envs_the_verifier_and_the_rm_data(tmp_path):
    """Each consumer, given physics=international, simulates exactly what simulate_batch does on
    that table, which differs from the default table's outcome for the same shots."""
    import gymnasium as gym

    import billiards.envs  # noqa: F401  (registers the gym id)
    from billiards.envs import make_env, reset_to
    from billiards.rm.data import generate, load_dataset
    from billiards.search.run import make_actor, make_proposer

    rack = np.array([[0.3, 0.3], [0.9, 1.3], [0.5, 0.8], [0.8, 1.1]])
    acts = np.random.default_rng(0).uniform([0, 0.2, -1, -1], [2 * np.pi, 1, 1, 1], (16, 4))
    truth = {n: simulate_batch(np.repeat(rack[None], 16, 0), acts, p).positions for n, p in PRESETS.items()}
    assert not np.array_equal(truth["international"], truth["korean_medium"])

    env = make_env(16, params="international")
    td = reset_to(env, rack)
    td["action"] = torch.as_tensor(acts, dtype=torch.float32).double().float()
    out = env.step(td)["next", "positions"].numpy()
    expect = simulate_batch(np.repeat(rack[None], 16, 0), td["action"].double().numpy(), I).positions
    np.testing.assert_array_equal(out, expect)

    genv = gym.make("Billiards4Ball-v0", physics="international", normalize_actions=False)  # raw actions
    assert genv.unwrapped.params is I
    genv.reset(options={"positions": rack})
    info = genv.step(acts[0].astype(np.float32))[4]
    np.testing.assert_array_equal(info["positions"], simulate_batch(rack[None], acts[:1].astype(np.float32), I).positions[0])

    cfg = OmegaConf.create({"kind": "geometric", "power_low": 0.15, "power_high": 0.9})
    search_cfg = OmegaConf.create({"seed": 0, "noise": {"preset": "none"},
                                   "search": {"kind": "h2", "budget": 40, "k1": 20, "m1": 2, "gamma": 0.99, "foul_penalty": 1.0}})
    actor = make_actor(search_cfg, make_proposer(cfg, I), I)
    assert actor.params is I and actor.proposer.R == I.ball_radius
    res = actor.search(rack[None])
    verified = simulate_batch(rack[None], res.actions, I)
    assert float(verified.score[0]) - float(verified.foul[0]) == res.r1[0]

    meta = generate(tmp_path / "rm", n=64, seed=0, chunk=32, progress=False, physics="international")
    assert meta["physics"] == "international"
    data = load_dataset(tmp_path / "rm")
    from billiards.rm.data import draw_chunk

    pos, act = draw_chunk(0, 0, 32, I)
    np.testing.assert_array_equal(data["score"][:32], simulate_batch(pos, act, I).score)
    from billiards.rm.data import DatasetError

    with pytest.raises(DatasetError, match="physics 'international'"):
        generate(tmp_path / "rm", n=64, seed=0, chunk=32, progress=False)  # the default table: refused


@pytest.mark.slow
def test_search_app_plays_the_chosen_table(tmp_path):
    from conftest import app_here

    proc = app_here("search.py", "physics=international", "protocol=p1", "protocol.n_innings=2", "protocol.shots=2",
                    "search.budget=40", "search.k1=20", "search.m1=2", "progress=false", "picture=false",
                    f"hydra.run.dir={tmp_path}", cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["physics"] == "international" and results["config"]["physics"]["preset"] == "international"
    bad = app_here("search.py", "physics.e_ball=2", cwd=tmp_path)
    assert bad.returncode != 0 and "physics.e_ball" in bad.stderr and "Traceback" not in bad.stderr


def test_things_made_on_another_table_warn_loudly(tmp_path, international_policy):
    import warnings

    from billiards.envs import make_env
    from billiards.physics.config import PhysicsMismatchWarning
    from billiards.search.proposers import load_policy_proposer
    from billiards.rm import RewardModel, save_model

    model = RewardModel(hidden=(4,))
    model.params = I
    path = save_model(tmp_path / "rm.pt", model)
    with pytest.warns(PhysicsMismatchWarning, match="reward model was made on physics 'international'"):
        make_env(2, rm=1.0, rm_model=path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicsMismatchWarning)
        make_env(2, rm=1.0, rm_model=path, params="international")

    shipped = [str(REPO / "results/policies/base/seed0.pt")]  # trained on korean_medium (the campaign's Table 5)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicsMismatchWarning)
        load_policy_proposer(shipped, name="base")
    with pytest.warns(PhysicsMismatchWarning, match="proposer 'base'"):
        load_policy_proposer(shipped, name="base", params=I)
    # the same networks saved as if trained on international: they warn on the default table
    made_on_i = international_policy
    with pytest.warns(PhysicsMismatchWarning, match="proposer 'mine'.*'international'"):
        load_policy_proposer([made_on_i], name="mine")
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicsMismatchWarning)
        prop = load_policy_proposer([made_on_i], name="mine", params=I)
    assert prop.R == I.ball_radius


def test_warm_up_says_when_it_compiles(tmp_path, monkeypatch):
    from billiards.physics import first_use, warmup

    said = []
    monkeypatch.setattr(first_use, "CACHE_DIR", tmp_path)  # an empty cache: the kernels count as not compiled
    assert not warmup.kernels_cached()
    seconds = warmup.warm_up(log=said.append)
    assert seconds >= 0 and said[0].startswith("compiling the simulator") and said[1].startswith("simulator ready")
    monkeypatch.undo()
    said.clear()
    warmup.warm_up(log=said.append)  # cached and already loaded: silent
    assert warmup.kernels_cached() and said == []
