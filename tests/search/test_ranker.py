"""The learned shot ranker and the ranked proposer (billiards/search/ranker.py)."""

from pathlib import Path

import numpy as np
import pytest
import torch

from billiards import domain
from billiards.physics import PRESETS, random_racks, simulate_batch
from billiards.physics.noise import NOISE_PRESETS
from billiards.search import GeometricProposer
from billiards.search.ranker import (N_FEATURES, POOL_DRAWS, RankedProposer, RankerFileError, ShotRanker, fit,
                                     make_dataset, shot_features)

ROOT = Path(__file__).resolve().parents[2]
K = PRESETS["korean_medium"]
FASTFIZ = NOISE_PRESETS["fastfiz"]


def racks(n, seed=0):
    return random_racks(np.random.default_rng(seed), n, K)


def small_ranker(seed=0, hidden=8):
    rng = np.random.default_rng(seed)
    sizes = [N_FEATURES, hidden, hidden, 1]
    return ShotRanker([rng.standard_normal((a, b)).astype(np.float32) for a, b in zip(sizes, sizes[1:])],
                      [rng.standard_normal(b).astype(np.float32) for b in sizes[1:]],
                      rng.standard_normal(N_FEATURES).astype(np.float32),
                      (1 + rng.random(N_FEATURES)).astype(np.float32),
                      {"physics_params": K.to_dict(), "noise": {"sigma_aim_deg": 0.125, "sigma_speed": 0.075,
                                                                "sigma_tip_mm": 0.5}})


def test_features_do_not_depend_on_which_red_is_called_red1():
    pos = racks(20)
    acts = GeometricProposer(R=K.ball_radius, far_share=0.5).propose(pos, 30, np.random.default_rng(1))
    swapped = pos[:, [0, 1, 3, 2]]
    f, g = shot_features(pos[:, None], acts, K), shot_features(swapped[:, None], acts, K)
    assert f.shape == (20, 30, N_FEATURES) and f.dtype == np.float32
    np.testing.assert_array_equal(f, g)
    # ... but they do depend on the shot and on the table
    assert not np.allclose(f[:, 0], f[:, 1]) and not np.allclose(f[0], shot_features(pos[1], acts[0], K))


def test_first_red_is_the_one_the_aim_lies_in():
    pos = racks(40)
    near = domain.nearest_red(pos)
    target, half = domain.aim_window(pos, K.ball_radius, red=domain.RED1 + domain.RED2 - near)
    near_target, near_half = domain.aim_window(pos, K.ball_radius)
    outside = np.abs(np.angle(np.exp(1j * (target + 0.2 * half - near_target)))) > 0.2 * near_half
    pos, near, target, half = pos[outside], near[outside], target[outside], half[outside]
    assert len(pos) >= 10
    acts = np.zeros((len(pos), 4))
    acts[:, 0], acts[:, 1] = target + 0.2 * half, 0.5  # into the far red's cone, u = 0.2
    f = shot_features(pos, acts, K)
    np.testing.assert_allclose(f[:, 4], 0.2, atol=1e-5)  # the first red's u (after the yellow's 4 columns)
    far = np.take_along_axis(pos, (domain.RED1 + domain.RED2 - near)[:, None, None].repeat(2, -1), 1)[:, 0]
    np.testing.assert_allclose(f[:, 5], np.linalg.norm(far - pos[:, 0], axis=-1), rtol=1e-6)


def test_far_share_zero_draws_as_before_and_one_aims_every_candidate_but_the_mode_at_the_far_red():
    pos = racks(8)
    np.testing.assert_array_equal(GeometricProposer(R=K.ball_radius).propose(pos, 40, np.random.default_rng(5)),
                                  GeometricProposer(R=K.ball_radius, far_share=0.0).propose(pos, 40, np.random.default_rng(5)))
    got = GeometricProposer(R=K.ball_radius, far_share=1.0).propose(pos, 40, np.random.default_rng(5))
    far = domain.RED1 + domain.RED2 - domain.nearest_red(pos)
    target, half = domain.aim_window(pos, K.ball_radius, red=far)
    u = (got[:, 1:, 0] - target[:, None]) / half[:, None]
    assert np.abs(u).max() <= 1 + 1e-9
    np.testing.assert_array_equal(got[:, 0, 0], domain.constrained_theta(pos, np.zeros(8), K.ball_radius))
    with pytest.raises(ValueError, match="far_share"):
        GeometricProposer(far_share=1.5)
    from billiards.search.config import GeometricProposerConfig

    assert GeometricProposerConfig(far_share=0.3).build(K).far_share == 0.3  # proposer.far_share=0.3


def test_ranked_proposer_returns_the_best_of_its_pool_by_the_ranker_best_first():
    pos, ranker = racks(4), small_ranker()
    got = RankedProposer(ranker, pool=300, params=K).propose(pos, 25, np.random.default_rng(9))
    pool = GeometricProposer(R=K.ball_radius, **POOL_DRAWS).propose(pos, 300, np.random.default_rng(9))
    score = ranker.score(pos[:, None], pool, K)
    want = np.take_along_axis(pool, np.argsort(-score, axis=1, kind="stable")[:, :25, None], axis=1)
    np.testing.assert_array_equal(got, want)
    s = ranker.score(pos[:, None], got, K)
    assert (np.diff(s, axis=1) <= 0).all()
    # asked for more than its pool: all of k draws, ranked
    assert RankedProposer(ranker, pool=10, params=K).propose(pos, 50, np.random.default_rng(9)).shape == (4, 50, 4)


def test_ranker_file_round_trip_and_bad_files(tmp_path):
    ranker = small_ranker()
    path = ranker.save(tmp_path / "r.pt")
    back = ShotRanker.load(path)
    pos = racks(3)
    acts = GeometricProposer(R=K.ball_radius).propose(pos, 10, np.random.default_rng(0))
    np.testing.assert_array_equal(back.score(pos[:, None], acts, K), ranker.score(pos[:, None], acts, K))
    assert back.params == K and back.noise == FASTFIZ
    with pytest.raises(RankerFileError, match="does not exist"):
        ShotRanker.load(tmp_path / "missing.pt")
    torch.save({"format": "something-else"}, tmp_path / "other.pt")
    with pytest.raises(RankerFileError, match="not a shot ranker"):
        ShotRanker.load(tmp_path / "other.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a torch file")
    with pytest.raises(RankerFileError, match="corrupt"):
        ShotRanker.load(tmp_path / "junk.pt")
    with pytest.raises(RankerFileError, match="do not chain"):
        ShotRanker(ranker.weights[:1], ranker.biases[:1], ranker.mean, ranker.std, {})


def test_dataset_targets_are_noisy_success_shares_of_exact_scorers():
    X, y = make_dataset(30, 40, 8, FASTFIZ, np.random.default_rng(0), K, chunk=7)
    assert X.shape == (1200, N_FEATURES) and y.shape == (1200,)
    assert set(np.unique(y * 8).round(6)) <= set(range(9)) and (y > 0).any()
    # the same draws again, simulated here: zero wherever the exact shot does not score
    rng = np.random.default_rng(0)
    draws = GeometricProposer(R=K.ball_radius, **POOL_DRAWS)
    pos = random_racks(rng, 7, K)
    cand = draws.propose(pos, 40, rng)
    exact = simulate_batch(np.repeat(pos, 40, axis=0), cand.reshape(-1, 4), K).score
    assert (y[:280][~exact] == 0).all()
    # under exact play the target is whether the shot scores, the same draws (nothing replayed)
    X0, y0 = make_dataset(7, 40, 8, NOISE_PRESETS["none"], np.random.default_rng(0), K, chunk=7)
    np.testing.assert_array_equal(y0, exact.astype(np.float32))
    np.testing.assert_array_equal(X0, X[:280])
    np.testing.assert_array_equal(X[:280], shot_features(pos[:, None], cand, K).reshape(-1, N_FEATURES))


def test_fit_learns_to_rank_a_learnable_target():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((4000, N_FEATURES)).astype(np.float32)
    y = (1 / (1 + np.exp(-3 * (X[:, 4] - X[:, 7])))).astype(np.float32)
    ranker = fit(X, y, hidden=16, layers=2, epochs=8, batch=256, seed=0, log=lambda m: None)
    rank = lambda v: np.argsort(np.argsort(v))
    assert np.corrcoef(rank(ranker.logits(X)), rank(y))[0, 1] > 0.95  # Spearman: the ranker orders as the target does


@pytest.mark.slow
def test_training_command_writes_a_ranker_the_search_app_plays(tmp_path):
    out = tmp_path / "r.pt"
    from conftest import app_here

    proc = app_here("billiards.search.ranker", "--out", str(out), "--racks", "40", "--candidates", "50", "--test-racks", "10",
                    "--epochs", "1", "--hidden", "16", cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    ranker = ShotRanker.load(out)
    assert ranker.meta["noise_preset"] == "fastfiz" and ranker.params == K
    assert ranker.meta["command"].startswith("python -m billiards.search.ranker --out")
    assert set(ranker.meta["held_out"]) >= {"best_of_top_ranked", "best_of_first_drawn"}
    proc = app_here("search.py", "noise=fastfiz", "proposer=ranked", f"proposer.ranker={out}", "proposer.pool=200", "protocol=p1",
                    "protocol.n_innings=2", "protocol.shots=3", "search.budget=60", "search.k1=40", "search.wave=20", "threads=1",
                    "progress=false", "picture=false", f"hydra.run.dir={tmp_path / 'run'}", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    import json

    results = json.loads((tmp_path / "run" / "results.json").read_text())
    assert results["config"]["proposer"]["kind"] == "ranked"


@pytest.mark.slow
def test_a_missing_ranker_fails_fast_and_writes_nothing(tmp_path):
    from conftest import app_here

    proc = app_here("search.py", "noise=fastfiz", "proposer=ranked", "proposer.ranker=nowhere/r.pt", cwd=tmp_path)
    assert proc.returncode != 0 and "no ranker file at nowhere/r.pt" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and list(tmp_path.iterdir()) == []


def test_the_shipped_rankers_load_and_record_how_they_were_made():
    """proposer=ranked plays results/rankers/fastfiz/ranker.pt by default: it validates, builds a
    RankedProposer over a ranker trained for fastfiz on korean_medium, and every shipped ranker
    records its command, commit and held-out ranking figures."""
    from billiards.search.config import RankedProposerConfig, errors, option, search_config

    cfg = search_config("robust", "p1", "ranked")
    cfg.noise.preset = "fastfiz"
    assert errors(cfg) == []
    node = option("proposer", cfg.proposer)
    assert isinstance(node, RankedProposerConfig)
    proposer = node.build(K)
    assert isinstance(proposer, RankedProposer) and proposer.ranker.meta["noise_preset"] == "fastfiz"
    files = sorted((ROOT / "results" / "rankers").glob("*/ranker.pt"))
    assert files
    for path in files:
        ranker = ShotRanker.load(path)
        preset = ranker.meta["noise_preset"]  # each in a folder named for its noise (results/rankers/<noise>[_<variant>])
        assert ranker.params == K and ranker.noise == NOISE_PRESETS[preset]
        assert path.parent.name == preset or path.parent.name.startswith(preset + "_")
        assert ranker.meta["command"].startswith("python -m billiards.search.ranker") and ranker.meta["commit"]
        held = ranker.meta["held_out"]
        assert held["best_of_top_ranked"] > held["best_of_first_drawn"]  # it ranks better than drawing


def test_a_ranker_used_under_another_noise_says_so_and_names_the_right_one():
    from billiards.search.ranker import noise_mismatch

    ranker = ShotRanker.load(ROOT / "results" / "rankers" / "fastfiz" / "ranker.pt")
    proposer = RankedProposer(ranker, pool=10, params=K)
    assert noise_mismatch(proposer, FASTFIZ) is None
    assert noise_mismatch(GeometricProposer(), NOISE_PRESETS["fastfiz_x5"]) is None
    msg = noise_mismatch(proposer, NOISE_PRESETS["fastfiz_x5"])
    assert "trained for noise fastfiz" in msg and "proposer.ranker=results/rankers/fastfiz_x5/ranker.pt" in msg
    assert "proposer.ranker=" not in noise_mismatch(proposer, FASTFIZ.scaled(2.0))  # no shipped ranker for it
