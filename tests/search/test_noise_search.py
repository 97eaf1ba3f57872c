"""Execution noise in the search app, the protocols and the evaluation: off by default and then
identical to exact play; reproducible from the seed; the noise-aware searches count every
simulation and sample the configured noise model."""

from pathlib import Path

import numpy as np
import pytest

from billiards.physics import PRESETS, random_racks, simulate_batch
from billiards.physics.noise import NOISE_PRESETS, NoiseModel, noise_from_config, noise_record
from billiards.search import (GeometricProposer, H2Config, LookaheadActor, PUCTConfig, RobustConfig, h2_search,
                              noisy_puct_search, robust_search)
from billiards.search.protocols import run_chain, run_p1

ROOT = Path(__file__).resolve().parents[2]
K = PRESETS["korean_medium"]
FASTFIZ, X5 = NOISE_PRESETS["fastfiz"], NOISE_PRESETS["fastfiz_x5"]


def racks(n, seed=0):
    return random_racks(np.random.default_rng(seed), n, K)


def easy_racks(n, seed=1):
    """Racks where >= 5% of the geometric candidates score, so any screen of >= 30 candidates
    finds a scoring one (all but surely) and the search spends its whole budget."""
    pos = racks(10 * n, seed)
    cand = GeometricProposer(R=K.ball_radius).propose(pos, 400, np.random.default_rng(seed))
    rate = simulate_batch(np.repeat(pos, 400, axis=0), cand.reshape(-1, 4), K).score.reshape(len(pos), 400).mean(1)
    return pos[rate >= 0.05][:n]


# ----------------------------------------------------------------------------- noise off: as before


def test_default_geometric_draws_are_unchanged_by_the_new_ranges():
    pos = racks(5)
    got = GeometricProposer(R=K.ball_radius).propose(pos, 30, np.random.default_rng(3))
    rng = np.random.default_rng(3)  # the draws the proposer has always made, in its order
    u, p, ab = rng.uniform(-1, 1, (5, 30)), rng.uniform(0.15, 0.9, (5, 30)), rng.uniform(-1, 1, (5, 30, 2))
    u[:, 0], p[:, 0], ab[:, 0] = 0.0, 0.5, 0.0
    from billiards.domain import constrained_theta

    np.testing.assert_array_equal(got[..., 0], constrained_theta(pos[:, None], u, K.ball_radius))
    np.testing.assert_array_equal(got[..., 1], p)
    np.testing.assert_array_equal(got[..., 2:], ab)
    narrow = GeometricProposer(R=K.ball_radius, u_low=0.3, u_high=0.9, spin_low=-0.2).propose(pos, 400, np.random.default_rng(3))
    from billiards.domain import aim_window

    target, half = aim_window(pos[:, None], K.ball_radius)
    u_abs = np.abs((narrow[..., 0] - target) / half)[:, 1:]
    assert u_abs.min() >= 0.3 - 1e-9 and u_abs.max() <= 0.9 + 1e-9 and narrow[:, 1:, 3].min() >= -0.2


def test_perturb_is_apply_of_the_errors_drawn_in_its_order():
    acts = np.random.default_rng(0).uniform([0, 0, -1, -1], [6, 1, 1, 1], (50, 4))
    z = FASTFIZ.draw((50,), np.random.default_rng(1))
    np.testing.assert_array_equal(FASTFIZ.perturb(acts, np.random.default_rng(1), K), FASTFIZ.apply(acts, z, K))
    rng = np.random.default_rng(1)  # the stream perturb has always read: aim, speed, then the two tip axes
    aim, speed, tip = rng.standard_normal(50), rng.standard_normal(50), rng.standard_normal((50, 2))
    np.testing.assert_array_equal(z, np.column_stack([aim, speed, tip]))


def test_without_noise_p1_and_p3_are_identical_to_exact_play():
    cfg = H2Config.from_budget(40, 20, 4)
    actor = LookaheadActor(GeometricProposer(R=K.ball_radius), cfg, params=K)
    plain = run_p1(actor, n_innings=4, shots=5, seed=2, params=K, progress=False)
    none = run_p1(actor, n_innings=4, shots=5, seed=2, params=K, progress=False, noise="none")
    assert plain.values == none.values and plain.extra == none.extra and plain.extra["mispredicted_shots"] == 0
    a = run_chain(actor, seed=1, cap=6, params=K)
    b = run_chain(actor, seed=1, cap=6, params=K, noise=NoiseModel())
    assert a[0] == b[0] and all(len(s) == 3 for s in b[1])
    for (p, c, s), (q, d, t) in zip(a[1], b[1]):
        np.testing.assert_array_equal(p, q), np.testing.assert_array_equal(c, d)


def compose(*overrides):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    import billiards.search.config  # noqa: F401  (registers the search app's schemas)

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return hydra_compose(config_name="search", overrides=list(overrides))


@pytest.mark.slow
def test_search_app_default_is_plain_h2_without_noise_and_robust_with_it():
    from omegaconf import OmegaConf

    default, explicit = compose(), compose("search=h2", "noise=none")
    assert OmegaConf.to_container(default) == OmegaConf.to_container(explicit)
    assert default.search.kind == "h2" and default.noise.preset == "none"
    assert compose("noise=fastfiz").search.kind == "robust"
    assert compose("noise=fastfiz_x5", "search=puct").search.kind == "puct"  # an explicit choice wins
    custom = compose("noise=fastfiz", "noise.aim_deg=0.3")
    model = noise_from_config(custom.noise)
    assert model == NoiseModel(0.3, FASTFIZ.sigma_speed, FASTFIZ.sigma_tip_mm)
    assert noise_record(model)["noise_sigmas"] == {"aim_deg": 0.3, "speed": 0.075, "tip_mm": 0.5}
    assert noise_record(FASTFIZ)["noise"] == "fastfiz" and model.describe().startswith("custom(aim_deg=0.3")


BAD = [
    (["noise=loud"], "noise/loud"),
    (["noise=fastfiz", "noise.aim_deg=-1"], "noise.aim_deg must be a finite number >= 0"),
    (["search=robust"], "search=robust scores candidates over noisy replays: it needs execution noise"),
    (["noise=fastfiz", "search.schedule=uniform"], "schedule=uniform gives every candidate `samples` noisy samples"),
    (["noise=fastfiz", "search.schedule=uniform", "search.screen=false", "search.k1=100", "search.samples=3"],
     "not the budget 400"),
    (["noise=fastfiz", "search.k1=400"], "schedule=halving leaves 0 simulations"),
    (["noise=fastfiz", "search.quantile=1.5"], "quantile must lie in [0, 1]"),
    (["noise=fastfiz", "search.schedule=race"], "schedule must be one of uniform, halving"),
    (["proposer.u_low=0.95", "proposer.u_high=0.5"], "proposer.u_low and proposer.u_high must satisfy"),
    (["proposer=forgiving", "proposer.far_share=1.5"], "proposer.far_share must lie in [0, 1], got 1.5"),
    (["search=h2", "search.samples=4"], "H2Config"),  # a robust knob: not h2's
    (["noise=fastfiz", "search=puct", "search.k1=10"], "PUCTConfig"),
]


@pytest.mark.slow
@pytest.mark.parametrize("overrides,message", BAD, ids=[" ".join(o) for o, _ in BAD])
def test_each_bad_noise_override_is_refused_with_its_message(tmp_path, overrides, message):
    from conftest import refusal

    said = refusal("search.py", *overrides, cwd=tmp_path)
    assert message in said, said
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize("overrides,message", [BAD[0], BAD[5]], ids=[" ".join(BAD[0][0]), " ".join(BAD[5][0])])
def test_bad_noise_overrides_fail_fast_and_write_nothing(tmp_path, overrides, message):
    from conftest import app_here

    proc = app_here("search.py", *overrides, cwd=tmp_path)
    assert proc.returncode != 0 and message in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_train_config_takes_the_noise_group_and_refuses_bad_sigmas():
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from billiards.rl.config import ConfigError  # importing it registers the training schemas
    from billiards.rl.validation import validate
    from billiards.rl.config import env_options

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        plain = hydra_compose(config_name="config", overrides=["budget=smoke"])
        noisy = hydra_compose(config_name="config", overrides=["budget=smoke", "noise=fastfiz_x5", "noise.speed=0.2"])
        bad = hydra_compose(config_name="config", overrides=["budget=smoke", "noise=fastfiz", "noise.tip_mm=-0.5"])
    assert env_options(plain).noise.is_exact
    assert env_options(noisy).noise == NoiseModel(X5.sigma_aim_deg, 0.2, X5.sigma_tip_mm)
    validate(noisy)
    with pytest.raises(ConfigError, match="noise.tip_mm must be a finite number >= 0"):
        validate(bad)


# ----------------------------------------------------------------------------- noise on: reproducible, as configured


def test_evaluation_plays_noisy_shots_reproducibly_from_its_seed():
    from billiards.evaluation import evaluate_policy

    def policy(td):
        import torch

        pos = td["positions"].numpy()
        td.set("action", torch.from_numpy(GeometricProposer(R=K.ball_radius).propose(pos, 1, np.random.default_rng(0))[:, 0]))
        return td

    exact = evaluate_policy(policy, n_innings=30, max_shots=3, seed=4, env_kwargs=dict(params=K))
    assert exact.noise == "none"
    noisy = evaluate_policy(policy, n_innings=30, max_shots=3, seed=4, env_kwargs=dict(params=K), noise="fastfiz_x5")
    again = evaluate_policy(policy, n_innings=30, max_shots=3, seed=4, env_kwargs=dict(params=K), noise="fastfiz_x5")
    assert noisy.noise == "fastfiz_x5" and noisy.points == again.points
    assert noisy.points != exact.points  # the baseline shot scores differently once perturbed


def test_env_played_shots_have_the_configured_sigmas():
    from billiards.envs import BilliardsEnv
    import torch

    B = 20_000
    env = BilliardsEnv(B, seed=0, params=K, noise="fastfiz_x5")
    td = env.reset()
    commanded = np.tile([1.0, 0.5, 0.0, 0.0], (B, 1))
    td["action"] = torch.from_numpy(commanded)
    d = env.step(td)["next", "played_action"].numpy() - commanded
    assert np.degrees(d[:, 0]).std() == pytest.approx(X5.sigma_aim_deg, rel=0.03)
    assert (d[:, 1] * K.cue_speed_max).std() == pytest.approx(X5.sigma_speed, rel=0.03)
    assert (d[:, 2:] * K.max_english * K.ball_radius * 1e3).std(axis=0) == pytest.approx([X5.sigma_tip_mm] * 2, rel=0.03)


def test_the_same_seed_replays_the_same_noisy_inning_and_chain():
    cfg = RobustConfig(budget=60, k1=30)
    from billiards.search import RobustActor

    actor = RobustActor(GeometricProposer(R=K.ball_radius), cfg, FASTFIZ, params=K)
    a = run_p1(actor, n_innings=3, shots=4, seed=5, params=K, progress=False, noise=FASTFIZ)
    b = run_p1(actor, n_innings=3, shots=4, seed=5, params=K, progress=False, noise=FASTFIZ)
    assert a.values == b.values and a.extra == b.extra and a.extra["noise"] == "fastfiz"
    assert "mispredicted_shots" not in a.extra  # under noise the env's outcome need not be the search's
    c1, h1 = run_chain(actor, seed=3, cap=5, params=K, noise=X5)
    c2, h2 = run_chain(actor, seed=3, cap=5, params=K, noise=X5)
    assert c1 == c2 and len(h1) == len(h2)
    for (p, cmd, s, played), (q, cmd2, t, played2) in zip(h1, h2):
        np.testing.assert_array_equal(played, played2), np.testing.assert_array_equal(cmd, cmd2)
        assert not np.array_equal(cmd, played)  # commanded and played are both recorded, and differ
        # the recorded played shot is the one the table followed
        assert bool(simulate_batch(p[None], played[None], K).score[0]) == s


# ----------------------------------------------------------------------------- every simulation counted


@pytest.mark.slow
@pytest.mark.parametrize("cfg", [
    RobustConfig(budget=400, k1=100, samples=4, schedule="uniform", screen=False),
    RobustConfig(budget=400, k1=50, samples=6, schedule="uniform", screen=False, m1=5, k2=20),
    RobustConfig(budget=400, k1=250),
    RobustConfig(budget=400, k1=200, m1=4, k2=10, quantile=0.25),
    RobustConfig(budget=97, k1=30, screen=False),
], ids=["uniform", "uniform+expand", "halving", "halving+expand+quantile", "halving-unscreened-odd"])
def test_robust_search_counts_every_simulation(recorded, cfg):
    pos = easy_racks(6)
    res = robust_search(pos, GeometricProposer(R=K.ball_radius), cfg, np.random.default_rng(0), K, FASTFIZ)
    per_state = np.zeros(len(pos), dtype=int)
    for start, _ in recorded:
        for t in start:
            per_state[np.flatnonzero((pos == t).all(axis=(1, 2)))] += 1
    shots = sum(len(a) for _, a in recorded)
    assert res.n_sims == shots
    # every state spends exactly the budget (the expansion starts from other tables, not counted per state)
    expand = cfg.m1 * cfg.k2
    np.testing.assert_array_equal(per_state, cfg.budget - expand)
    assert shots == len(pos) * cfg.budget


def test_robust_search_spends_only_the_screen_when_nothing_scores(recorded):
    class Dead:  # shots with no power never reach a ball
        name = "dead"

        def propose(self, positions, k, rng):
            return np.zeros((len(positions), k, 4))

    res = robust_search(racks(3), Dead(), RobustConfig(budget=400, k1=250), np.random.default_rng(0), K, FASTFIZ)
    assert res.n_sims == 3 * 250 == sum(len(a) for _, a in recorded)


def test_noisy_puct_counts_every_simulation_and_revisits_draw_new_outcomes(recorded):
    pos = racks(4, seed=2)
    cfg = PUCTConfig(budget=120, pool=8)
    proposed = []

    class Recording(GeometricProposer):
        def propose(self, positions, k, rng):
            out = super().propose(positions, k, rng)
            proposed.extend(out.reshape(-1, 4))
            return out

    res = noisy_puct_search(pos, Recording(R=K.ball_radius), cfg, np.random.default_rng(0), K, FASTFIZ)
    assert res.n_sims == 4 * 120 == sum(len(a) for _, a in recorded)
    played = np.concatenate([a for _, a in recorded])
    commanded = np.asarray(proposed)
    nearest = np.argmin(np.abs(played[:, None, 0] - commanded[None, :, 0]) + np.abs(played[:, None, 1] - commanded[None, :, 1]), 1)
    visits = np.bincount(nearest)
    assert visits.max() > 1 and (visits > 0).sum() < len(played)  # children are revisited ...
    assert len(np.unique(played, axis=0)) == len(played)  # ... and every visit plays a new noisy shot


def test_the_searches_sample_the_configured_noise_model(recorded):
    pos = np.repeat(racks(1, seed=3), 2, axis=0)

    class Fixed:  # one candidate, the same every time: every sample is a replay of it
        name = "fixed"

        def propose(self, positions, k, rng):
            return np.tile([1.0, 0.5, 0.0, 0.0], (len(positions), k, 1))

    robust_search(pos, Fixed(), RobustConfig(budget=3000, k1=1, samples=3000, schedule="uniform", screen=False),
                  np.random.default_rng(0), K, X5)
    d = recorded[0][1] - [1.0, 0.5, 0.0, 0.0]
    assert np.degrees(d[:, 0]).std() == pytest.approx(X5.sigma_aim_deg, rel=0.05)
    assert (d[:, 1] * K.cue_speed_max).std() == pytest.approx(X5.sigma_speed, rel=0.05)


def true_success(pos, actions, noise, n=100):
    played = noise.perturb(np.repeat(actions, n, axis=0), np.random.default_rng(99), K)
    return simulate_batch(np.repeat(pos, n, axis=0), played, K).score.mean()


def test_noise_aware_choices_succeed_more_often_under_noise_than_plain_lookahead():
    pos = racks(40, seed=4)
    prop = GeometricProposer(R=K.ball_radius)
    plain = h2_search(pos, prop, H2Config.from_budget(400, 200, 10), np.random.default_rng(0), K).actions
    robust = robust_search(pos, prop, RobustConfig(budget=400, k1=250), np.random.default_rng(0), K, FASTFIZ).actions
    assert true_success(pos, robust, FASTFIZ) > true_success(pos, plain, FASTFIZ) + 0.05


def test_the_adaptive_screen_stops_at_its_target_and_never_passes_k1():
    from billiards.search.robust import _screen

    pos = np.concatenate([easy_racks(4), racks(4, seed=7)])
    cfg = RobustConfig(budget=400, k1=230, target=5, wave=20)
    a1, exact, leave, screened = _screen(pos, GeometricProposer(R=K.ball_radius), cfg, np.random.default_rng(0), K)
    scoring = (exact > 0).sum(axis=1)
    assert (screened <= 230).all() and (screened[:4] < 230).all()  # easy tables stop early
    for s in range(len(pos)):
        assert scoring[s] >= 5 or screened[s] == 230  # stopped at the target, or screened k1
        before_last_wave = screened[s] - (screened[s] - 1) % 20 - 1
        assert (exact[s, :before_last_wave] > 0).sum() < 5  # it screened on only while short of the target
        assert np.isneginf(exact[s, screened[s]:]).all() and np.isfinite(exact[s, : screened[s]]).all()
        res = simulate_batch(np.repeat(pos[s][None], screened[s], 0), a1[s, : screened[s]], K)
        np.testing.assert_array_equal(res.positions, leave[s, : screened[s]])


def test_the_table6_report_keeps_noisy_runs_apart_from_exact_ones():
    from billiards.search.report import table6_markdown

    run = {"protocol": "p3", "search": "h2", "proposer": "geometric", "physics": "korean_medium", "mean": 5.0, "max": 9,
           "values": [5], "extra": {"cap": 10000}}
    text = table6_markdown([run, {**run, "noise": "fastfiz", "mean": 2.0}, {**run, "noise": "none", "mean": 7.0}])
    assert text.count("Table 6:") == 2 and "Physics: `korean_medium`, execution noise `fastfiz`." in text


def test_a_search_config_saved_before_the_noise_keys_still_validates_and_runs_exactly(tmp_path):
    from omegaconf import OmegaConf

    from billiards.search.config import saved_config, validate
    from billiards.search.run import make_actor, make_proposer

    old = OmegaConf.to_container(compose())
    del old["noise"]
    for key in ("u_low", "u_high", "spin_low", "spin_high"):
        del old["proposer"][key]
    # (the h2 node has no robust knobs since each search option has its own schema)
    OmegaConf.save(OmegaConf.create(old), tmp_path / "config.yaml")
    old = saved_config(tmp_path)  # what resume= loads from such a run's config.yaml (billiards.compat brings it to today's form)
    assert old.noise.preset == "none"
    validate(old)
    proposer = make_proposer(old.proposer, K)
    assert (proposer.u_low, proposer.u_high, proposer.spin_low, proposer.spin_high) == (0.0, 1.0, -1.0, 1.0)
    assert type(make_actor(old, proposer, K)).__name__ == "LookaheadActor"


def test_forgiving_is_a_stored_geometric_proposer_option():
    from billiards.search.config import SHIPPED_PROPOSERS, GeometricProposerConfig, option, proposer_options

    cfg = compose("noise=fastfiz", "proposer=forgiving")
    proposer = option("proposer", cfg.proposer)
    assert isinstance(proposer, GeometricProposerConfig) and proposer.name == "forgiving"
    assert (proposer.u_low, proposer.u_high, proposer.spin_low, proposer.power_low) == (0.3, 0.9, -0.2, 0.5)
    assert "forgiving" in proposer_options() and "forgiving" not in SHIPPED_PROPOSERS


@pytest.mark.slow
def test_the_noise_runs_saved_union_configs_load_in_the_per_option_dialect():
    """results/noise/ was written with one union node per group (robust knobs and u_*/spin_* in every node)."""
    from billiards.search.config import errors, saved_config

    dirs = sorted((ROOT / "results" / "noise").glob("*/*/config.yaml"))
    assert dirs
    for path in dirs:
        cfg = saved_config(path.parent)
        assert errors(cfg) == [], path
        assert cfg.noise.preset != "none" or cfg.search.kind != "robust"
