"""The learned table value (billiards/search/value.py) and the robust search's position and
leave terms (billiards/search/robust.py)."""

from pathlib import Path

import numpy as np
import pytest
import torch

from billiards.physics import PRESETS, random_racks, simulate_batch
from billiards.physics.noise import NOISE_PRESETS
from billiards.search import GeometricProposer
from billiards.search import robust as robust_mod
from billiards.search.actors import build_actor
from billiards.search.ranker import RankerFileError, ShotRanker, fit_mlp
from billiards.envs.sagu import SWAP
from billiards.search.robust import RobustConfig, leave_terms, robust_search
from billiards.physics.noise import noise_level
from billiards.search.value import (N_FEATURES, TableValue, ValueFileError, draw_levels, make_dataset,
                                    table_features)

ROOT = Path(__file__).resolve().parents[2]
K = PRESETS["korean_medium"]
FASTFIZ = NOISE_PRESETS["fastfiz"]
META = {"physics_params": K.to_dict(), "noise": {"sigma_aim_deg": 0.125, "sigma_speed": 0.075, "sigma_tip_mm": 0.5}}


def racks(n, seed=0):
    return random_racks(np.random.default_rng(seed), n, K)


def small_value(seed=0, hidden=8):
    rng = np.random.default_rng(seed)
    sizes = [N_FEATURES, hidden, 1]
    return TableValue([rng.standard_normal((a, b)).astype(np.float32) for a, b in zip(sizes, sizes[1:])],
                      [rng.standard_normal(b).astype(np.float32) for b in sizes[1:]],
                      np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32), dict(META))


class LeftHalf:
    """A stand-in value: 1 where the shooter's cue ball lies in the left half of the table."""

    def predict(self, positions, levels, params=None):
        return (np.asarray(positions)[..., 0, 0] < K.table_width / 2).astype(np.float64)


def test_features_fold_the_tables_symmetries_and_the_reds_names():
    pos = racks(30)
    f = table_features(pos, 1.0, K)
    assert f.shape == (30, N_FEATURES) and f.dtype == np.float32
    mirrored = pos.copy()
    mirrored[..., 0] = K.table_width - mirrored[..., 0]
    flipped = pos.copy()
    flipped[..., 1] = K.table_length - flipped[..., 1]
    for other in (mirrored, flipped, pos[:, [0, 1, 3, 2]]):
        np.testing.assert_allclose(table_features(other, 1.0, K), f, atol=1e-6)
    # ... but not the cue balls' roles, nor the level
    assert not np.allclose(table_features(pos[:, SWAP], 1.0, K), f)
    assert not np.allclose(table_features(pos, 5.0, K), f)


def test_value_file_round_trip_and_bad_files(tmp_path):
    value = small_value()
    back = TableValue.load(value.save(tmp_path / "v.pt"))
    pos = racks(5)
    np.testing.assert_array_equal(back.predict(pos, 1.0), value.predict(pos, 1.0))
    p = back.predict(pos, np.linspace(0, 5, 5))
    assert p.shape == (5,) and ((p > 0) & (p < 1)).all() and back.params == K
    with pytest.raises(ValueFileError, match="does not exist"):
        TableValue.load(tmp_path / "missing.pt")
    with pytest.raises(ValueFileError, match="not a table value"):  # a ranker is not a value
        ranker = ShotRanker([w for w in [np.zeros((28, 1), np.float32)]], [np.zeros(1, np.float32)],
                            np.zeros(28, np.float32), np.ones(28, np.float32), dict(META))
        TableValue.load(ranker.save(tmp_path / "ranker.pt"))
    with pytest.raises(RankerFileError, match="not a shot ranker"):
        ShotRanker.load(tmp_path / "v.pt")
    data = bytearray((tmp_path / "v.pt").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (tmp_path / "flipped.pt").write_bytes(bytes(data))
    with pytest.raises(ValueFileError):
        TableValue.load(tmp_path / "flipped.pt")
    torch.save({"format": "billiards-table-value-1", "weights": []}, tmp_path / "torn.pt")
    with pytest.raises(ValueFileError):
        TableValue.load(tmp_path / "torn.pt")


def test_dataset_targets_are_shares_of_fresh_replays_and_levels_span_the_range():
    ranker = ShotRanker.load(ROOT / "results/rankers/fastfiz/ranker.pt")
    X, y, pos, lev = make_dataset(64, ranker, np.random.default_rng(0), K, chains=32, pool=40, top=4, samples=4, check=8)
    assert X.shape == (64, N_FEATURES) and y.shape == (64,) and pos.shape == (64, 4, 2)
    assert set(np.unique(y * 8)) <= set(range(9))  # shares of 8 replays
    np.testing.assert_array_equal(X, table_features(pos, lev, K))
    levels = draw_levels(10_000, np.random.default_rng(1))
    assert levels.min() >= 0 and levels.max() <= 5
    assert 0.35 < (levels == 1).mean() < 0.45 and 0.25 < (levels == 5).mean() < 0.35
    # easy noise scores more often than hard noise (the labels carry the level)
    _, y0, _, l0 = make_dataset(256, ranker, np.random.default_rng(2), K, chains=128, pool=60, top=6, samples=4, check=8)
    assert y0[l0 <= 1].mean() > y0[l0 >= 4].mean() + 0.1


def test_fit_learns_a_learnable_value():
    rng = np.random.default_rng(0)
    pos = racks(3000)
    X = table_features(pos, rng.uniform(0, 5, 3000), K)
    y = (1 / (1 + np.exp(-(3 * X[:, 0] - 2 * X[:, -2] / 5 + 0.5)))).astype(np.float32)
    value = TableValue(*fit_mlp(X, y, hidden=32, layers=2, epochs=20, batch=256), dict(META))
    p = 1 / (1 + np.exp(-value.logits(X).astype(np.float64)))
    assert np.corrcoef(p, y)[0, 1] > 0.95


def test_noise_level_is_in_fastfiz_units():
    assert noise_level(FASTFIZ) == 1.0 and noise_level(NOISE_PRESETS["fastfiz_x5"]) == 5.0
    assert noise_level(NOISE_PRESETS["none"]) == 0.0


# ----------------------------------------------------------------------------- the search's terms


def test_leave_terms_price_scoring_leaves_for_the_shooter_and_misses_for_the_opponent():
    pos = racks(40, seed=3)
    acts = GeometricProposer(R=K.ball_radius).propose(pos, 1, np.random.default_rng(0))[:, 0]
    res = simulate_batch(pos, acts, K)
    assert 0 < res.score.sum() < len(pos)
    value = small_value()
    levels = np.full(len(pos), 1.0)
    cfg = RobustConfig(position=0.5, leave=2.0)
    terms = leave_terms(res, cfg, value, levels)
    own, theirs = value.predict(res.positions, levels), value.predict(res.positions[:, SWAP], levels)
    np.testing.assert_allclose(terms, np.where(res.score, 0.5 * own, -2.0 * theirs))
    np.testing.assert_array_equal(leave_terms(res, RobustConfig(), value, levels), 0.0)


def test_zero_weights_search_bit_for_bit_as_without_a_value():
    pos = racks(6, seed=4)
    cfg = RobustConfig(budget=200, k1=100)
    a = robust_search(pos, GeometricProposer(R=K.ball_radius), cfg, np.random.default_rng(0), K, FASTFIZ)
    b = robust_search(pos, GeometricProposer(R=K.ball_radius), cfg, np.random.default_rng(0), K, FASTFIZ,
                      value=small_value())
    for x, y in zip((a.actions, a.value, a.r1, a.positions), (b.actions, b.value, b.r1, b.positions)):
        np.testing.assert_array_equal(x, y)
    assert a.n_sims == b.n_sims


def test_position_aware_search_counts_every_simulation_and_prefers_valued_leaves(recorded):
    pos = racks(12, seed=5)
    prop = GeometricProposer(R=K.ball_radius)
    plain = robust_search(pos, prop, RobustConfig(budget=300, k1=150), np.random.default_rng(0), K, FASTFIZ)
    plain_calls = sum(len(a) for _, a in recorded)
    recorded.clear()
    placed = robust_search(pos, prop, RobustConfig(budget=300, k1=150, position=5.0), np.random.default_rng(0), K, FASTFIZ,
                           value=LeftHalf())
    assert placed.n_sims == sum(len(a) for _, a in recorded) == plain.n_sims == plain_calls
    # the chosen shots' leaves: replay each chosen shot under the noise and look where the cue ball stops
    rng = np.random.default_rng(9)

    def left_share(actions):
        played = FASTFIZ.perturb(np.repeat(actions, 50, axis=0), rng, K)
        res = simulate_batch(np.repeat(pos, 50, axis=0), played, K)
        return (LeftHalf().predict(res.positions, 1.0) * res.score).mean()

    assert left_share(placed.actions) > left_share(plain.actions) + 0.05
    assert ((placed.r1 >= 0) & (placed.r1 <= 1)).all()  # r1 stays the verifier reward alone
    with pytest.raises(ValueError, match="needs a table value"):
        robust_search(pos, prop, RobustConfig(position=1.0), np.random.default_rng(0), K, FASTFIZ)


def test_the_search_option_checks_its_value_file_before_anything_runs(tmp_path):
    assert RobustConfig(position=1.0).errors()[0].startswith("search.position=1.0")
    assert "no table value file" in RobustConfig(position=1.0, value=str(tmp_path / "no.pt")).errors()[0]
    (tmp_path / "bad.pt").write_bytes(b"junk")
    assert RobustConfig(leave=1.0, value=str(tmp_path / "bad.pt")).errors()[0].startswith("search.value:")
    good = small_value().save(tmp_path / "good.pt")
    assert RobustConfig(position=1.0, value=str(good)).errors() == []
    assert "position and leave must be finite" in RobustConfig(position=-1.0, value=str(good)).errors()[0]
    actor = build_actor(RobustConfig(position=1.0, value=str(good)), GeometricProposer(R=K.ball_radius), 0, K, FASTFIZ)
    assert isinstance(actor.value, TableValue)
    assert build_actor(RobustConfig(), GeometricProposer(R=K.ball_radius), 0, K, FASTFIZ).value is None


def test_the_shipped_value_loads_and_records_how_it_was_made():
    from billiards.search.settings import VALUE_COMMAND

    value = TableValue.load(ROOT / "results/values/value.pt")
    assert value.params == K and value.meta["command"] == VALUE_COMMAND and len(value.meta["commit"]) >= 7
    held = value.meta["held_out"]
    for band in ("all", "0.5<=level<2", "level>=2"):  # better than the best constant where the noise matters
        assert held[band]["brier"] < 0.8 * held[band]["brier_constant"]
    # easy tables are worth more than hard ones, and more noise is worth less
    p = value.predict(racks(200, seed=7), 1.0)
    assert p.std() > 0.05 and value.predict(racks(200, seed=7), 5.0).mean() < p.mean() - 0.1


def test_safety_shots_are_screened_misses_weighed_beside_the_attempts(recorded):
    pos = racks(6, seed=6)
    prop = GeometricProposer(R=K.ball_radius)
    value = small_value()
    cfg = RobustConfig(budget=300, k1=150, leave=1.0, safeties=4)
    res = robust_search(pos, prop, cfg, np.random.default_rng(0), K, FASTFIZ, value=value)
    assert res.n_sims == sum(len(a) for _, a in recorded) == 6 * 300

    class Dead:  # no shot reaches a ball: nothing scores, every candidate is a (feeble) safety
        name = "dead"

        def propose(self, positions, k, rng):
            return np.zeros((len(positions), k, 4))

    recorded.clear()
    res = robust_search(pos, Dead(), cfg, np.random.default_rng(0), K, FASTFIZ, value=value)
    assert res.n_sims == sum(len(a) for _, a in recorded) == 6 * 300  # the budget goes to the safeties (without them: the screen only)
    alive = robust_mod._with_safeties([[] for _ in pos], np.where(np.arange(10) < 3, 1.0, 0.0)[None].repeat(6, 0),
                                      np.repeat(pos[:, None], 10, axis=1), 2, value, np.ones(6))
    assert all(len(a) == 2 and min(a) >= 3 for a in alive)  # only misses, the two the value rates lowest
    with pytest.raises(ValueError, match="safeties"):
        RobustConfig(safeties=2).check()  # safety shots need the leave weight

    # soft safety draws: screened beside the proposer's candidates, in the budget, chosen from
    recorded.clear()
    soft = RobustConfig(budget=300, k1=150, leave=1.0, safeties=4, safety_draws=40)
    res = robust_search(pos, Dead(), soft, np.random.default_rng(0), K, FASTFIZ, value=value)
    assert res.n_sims == sum(len(a) for _, a in recorded) == 6 * 300
    waves = soft.k1 // soft.wave  # the adaptive screen's waves (nothing scores), then the soft shots, exactly
    assert [len(a) for _, a in recorded[:waves + 1]] == [6 * soft.wave] * waves + [6 * 40]
    assert (res.actions[:, 1] > 0).all()  # the dead proposer's shots go nowhere: a soft shot is played
    drawn = recorded[waves][1].reshape(6, 40, 4)
    assert all(any(np.array_equal(a, d) for d in drawn[s]) for s, a in enumerate(res.actions))
    for bad in (dict(safety_draws=5), dict(leave=1.0, safeties=2, safety_draws=-1),
                dict(budget=300, k1=150, leave=1.0, safeties=2, safety_draws=150)):
        with pytest.raises(ValueError, match="safety_draws|halving leaves"):
            RobustConfig(**bad).check()


def test_the_training_command_writes_a_value_the_search_plays(tmp_path, capsys):
    from billiards.search.value import main

    out = tmp_path / "v.pt"
    args = ["--out", str(out), "--states", "64", "--test-states", "64", "--pool", "20", "--top", "2", "--samples", "2",
            "--check", "4", "--hidden", "4", "--layers", "1", "--epochs", "1"]
    assert main(args) == 0
    value = TableValue.load(out)
    assert value.meta["command"] == "python -m billiards.search.value " + " ".join(args)
    assert value.meta["held_out"]["tables"] == 64 and value.params == K
    res = robust_search(racks(2), GeometricProposer(R=K.ball_radius), RobustConfig(budget=100, k1=50, position=1.0),
                        np.random.default_rng(0), K, FASTFIZ, value=value)
    assert res.n_sims == 200
    with pytest.raises(SystemExit):
        main(["--out", str(out), "--states", "0"])


def test_the_search_labeller_and_the_discount_make_run_targets(tmp_path, monkeypatch):
    """``--labeller search`` plays the position-aware robust search itself; with a discount g a
    scoring replay counts 1 - g + g V(its leave): on the same draws every target lies between g'
    = 1 - g times and 1 times the plain share that scores."""
    from billiards.search.value import search_chooser

    ranker = ShotRanker.load(ROOT / "results/rankers/fastfiz/ranker.pt")
    value, g = small_value(), 0.5
    searched = []
    real = robust_mod.robust_search

    def spy(positions, proposer, cfg, rng, *args, **kwargs):
        res = real(positions, proposer, cfg, rng, *args, **kwargs)
        searched.append((cfg.position, kwargs["levels"].copy(), res.actions.copy()))
        return res

    monkeypatch.setattr(robust_mod, "robust_search", spy)
    choose = lambda: search_chooser([(2.5, ranker, 60, 8.0), (np.inf, ranker, 60, 3.0)], value, K, budget=60, k1=30)
    _, share, _, lev = make_dataset(48, None, np.random.default_rng(4), K, chains=16, check=8, choose=choose())
    assert searched and {w for w, *_ in searched} == {8.0, 3.0}  # each band plays its own weight
    assert all((lv < 2.5).all() if w == 8.0 else (lv >= 2.5).all() for w, lv, _ in searched)
    first = [a for _, _, a in searched]
    searched.clear()
    _, run, _, lev2 = make_dataset(48, None, np.random.default_rng(4), K, chains=16, check=8, choose=choose(),
                                   discount=g, value=value)
    assert all(np.array_equal(a, b) for a, (_, _, b) in zip(first, searched))  # the same shots, the same replays
    np.testing.assert_array_equal(lev, lev2)
    assert (run <= share + 1e-6).all() and (run >= (1 - g) * share - 1e-6).all() and (run < share).any()
    with pytest.raises(ValueError, match="discount"):
        make_dataset(8, None, np.random.default_rng(0), K, chains=8, choose=choose(), discount=0.5)  # no value
    from billiards.search.value import main

    for bad in (["--labeller", "search"], ["--discount", "0.5"], ["--value", "results/values/value.pt", "--discount", "1"]):
        with pytest.raises(SystemExit):
            main(["--out", str(tmp_path / "never.pt"), *bad])
    assert not (tmp_path / "never.pt").exists()
