"""A learned value of a table under execution noise: how long a run the search makes from it.

Under noise the search picks each shot for its own chance of scoring; a strong player also
picks the shot whose *leave* offers an easy next one. The table value ``V(table, level)`` is a
small network, trained offline on simulated play, that predicts from a table, when the cue errs
with ``level`` times the ``fastfiz`` sigmas (level 1: ``noise=fastfiz``, 5: ``fastfiz_x5``, 0:
exact play), either the probability that the noise-aware search's next shot scores
(``discount`` 0, the first value, ``results/values/value.pt``) or the run it makes from there,
discounted by ``g`` and normalised to [0, 1] (``discount`` g > 0: ``V = E[(1 - g) (s_0 + g s_0 s_1
+ g^2 s_0 s_1 s_2 + ...)]`` over the shots' scores s_t, 1 for a run that never ends; the
shipped run values, made by fitted value iteration with the position-aware search as the
labeller; the file's ``meta["args"]["discount"]`` says which). The robust search
(:mod:`billiards.search.robust`) uses it on the noisy replays it already simulates: a replay
that scores is worth ``1 + position * V(leave)`` (position play), and, in a two-player match,
a replay that misses costs ``leave * V(the opponent's view of the leave)`` (safety play).

* :func:`table_features` -- the input, one place (training and search), and :class:`TableValue`
  -- the network (a :class:`~billiards.search.ranker.TaggedMLP`: float32, the same bits on every
  CPU; a sealed tagged file, loading executes nothing): :mod:`billiards.search.table_value`.
* :func:`make_dataset` / ``python -m billiards.search.value`` -- how a value is made: chains of
  play from random racks, each state labelled by ``check`` fresh noisy replays of the shot a
  labelling search picks there (a small ranked search, or the position-aware search over the
  previous value): the share that score, or with a discount the mean of ``1 - g + g
  V_previous(leave)`` over the replays that score; the chain goes on from one of those
  replays' leaves. See ``--help``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from billiards.physics import DEFAULT_PARAMS, DEFAULT_PRESET, PhysicsParams, random_racks, simulate_batch
from billiards.physics.noise import NOISE_PRESETS

from .ranker import RankedProposer, ShotRanker, fit_mlp
from .table_value import N_FEATURES, TableValue, ValueFileError, table_features

BASE_NOISE = NOISE_PRESETS["fastfiz"]  # level 1
MAX_LEVEL = 5.0


# ----------------------------------------------------------------------------- making a value


def draw_levels(n: int, rng: np.random.Generator) -> np.ndarray:
    """Noise levels for training chains: 40 % at 1 (fastfiz), 30 % at 5 (fastfiz_x5), 30 %
    uniform in [0, 5] (the variable preset's range)."""
    u = rng.random(n)
    return np.where(u < 0.4, 1.0, np.where(u < 0.7, MAX_LEVEL, rng.uniform(0.0, MAX_LEVEL, n)))


def ranked_chooser(ranker: ShotRanker, params: PhysicsParams = DEFAULT_PARAMS, pool: int = 300, top: int = 16,
                   samples: int = 16):
    """The first value's labelling search: the ``top`` of ``pool`` ranked candidates each get
    ``samples`` noisy replays (sigmas ``level`` x fastfiz's); the best by its share that scores
    is the shot. Returns ``choose(positions (C, 4, 2), levels (C,), rng) -> actions (C, 4)``."""
    proposer = RankedProposer(ranker, pool=pool, params=params)

    def choose(pos, lev, rng):
        C = len(pos)
        cand = proposer.propose(pos, top, rng)  # (C, top, 4)
        z = BASE_NOISE.draw((C, top, samples), rng) * lev[:, None, None, None]
        shots = BASE_NOISE.apply(np.repeat(cand[:, :, None], samples, axis=2), z, params)
        share = simulate_batch(np.repeat(pos, top * samples, axis=0), shots.reshape(-1, 4), params).score
        best = np.argmax(share.reshape(C, top, samples).mean(axis=2), axis=1)
        return cand[np.arange(C), best]

    return choose


def search_chooser(bands, value: "TableValue", params: PhysicsParams = DEFAULT_PARAMS, budget: int = 400, k1: int = 300):
    """A labelling search that is the position-aware robust search itself (one step of policy
    iteration: the value it prices leaves with is the previous one). ``bands``: ``(upper level,
    ranker, pool, position weight)`` in increasing order; a table plays the first band whose
    upper level exceeds its level (the last band takes the rest). Returns ``choose`` as
    :func:`ranked_chooser`."""
    from .robust import RobustConfig, robust_search

    plays = [(upper, RankedProposer(ranker, pool=pool, params=params), RobustConfig(budget=budget, k1=k1, position=w))
             for upper, ranker, pool, w in bands]

    def choose(pos, lev, rng):
        out = np.zeros((len(pos), 4))
        band = np.minimum(np.searchsorted([u for u, *_ in plays], lev, side="right"), len(plays) - 1)
        for b, (_, proposer, cfg) in enumerate(plays):
            rows = np.flatnonzero(band == b)
            if len(rows):
                out[rows] = robust_search(pos[rows], proposer, cfg, rng, params, noise=BASE_NOISE, levels=lev[rows],
                                          value=value).actions
        return out

    return choose


def make_dataset(n_states: int, ranker: ShotRanker | None, rng: np.random.Generator,
                 params: PhysicsParams = DEFAULT_PARAMS, chains: int = 256, pool: int = 300, top: int = 16,
                 samples: int = 16, check: int = 16, restart: float = 0.2, log=None, choose=None,
                 discount: float = 0.0, value: "TableValue | None" = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n_states`` labelled tables: (features (n, N_FEATURES), targets (n,), positions (n, 4, 2),
    levels (n,)).

    ``chains`` chains of play advance together. At each table (the chain's level ``l``, drawn
    by :func:`draw_levels` when the chain starts) the labelling search picks a shot (``choose``;
    by default :func:`ranked_chooser` over ``ranker``, ``pool``, ``top``, ``samples``), and the
    target is the share of ``check`` fresh replays of it (sigmas ``l`` x fastfiz's) that score
    (an unbiased estimate of that shot's chance). With ``discount`` g > 0 a replay that scores
    counts ``1 - g + g * value(its leave)`` instead of 1 (a fitted-value-iteration step: the
    target is then the discounted, normalised run the search makes from the table, 1 for a run
    that never ends). The chain goes on from the first fresh replay's leave, or (with
    probability ``restart``) from a new random rack."""
    if not 0.0 <= discount < 1.0 or (discount and value is None):
        raise ValueError(f"discount must lie in [0, 1) and a discount > 0 needs the previous value; got {discount}")
    choose = choose if choose is not None else ranked_chooser(ranker, params, pool, top, samples)
    C = chains
    pos, lev = random_racks(rng, C, params), draw_levels(C, rng)
    X, y, P, Lv = [], [], [], []
    done, t0 = 0, time.time()
    while done < n_states:
        chosen = choose(pos, lev, rng)
        z = BASE_NOISE.draw((C, check), rng) * lev[:, None, None]
        res = simulate_batch(np.repeat(pos, check, axis=0),
                             BASE_NOISE.apply(np.repeat(chosen[:, None], check, axis=1), z, params).reshape(-1, 4), params)
        worth = res.score.astype(np.float64)
        if discount:
            rows = np.flatnonzero(worth > 0)
            worth[rows] = 1.0 - discount + discount * value.predict(res.positions[rows], np.repeat(lev, check)[rows],
                                                                    params)
        X.append(table_features(pos, lev, params))
        y.append(worth.reshape(C, check).mean(axis=1).astype(np.float32))
        P.append(pos.copy())
        Lv.append(lev.copy())
        done += C
        pos = res.positions.reshape(C, check, 4, 2)[:, 0].copy()
        new = rng.random(C) < restart
        if new.any():
            pos[new], lev[new] = random_racks(rng, int(new.sum()), params), draw_levels(int(new.sum()), rng)
        if log is not None:
            log(f"{done:,} / {n_states:,} tables ({time.time() - t0:.0f} s)")
    cut = lambda parts: np.concatenate(parts)[:n_states]
    return cut(X), cut(y), cut(P), cut(Lv)


def held_out_report(value: TableValue, X: np.ndarray, y: np.ndarray, levels: np.ndarray) -> dict:
    """Brier scores of the value's predictions against the held-out targets, beside the best
    constant per level band, overall and per band (exact-ish < 0.5, fastfiz [0.5, 2), high >= 2)."""
    p = 1.0 / (1.0 + np.exp(-value.logits(X).astype(np.float64)))
    out = {"tables": int(len(y))}
    bands = {"all": np.ones(len(y), bool), "level<0.5": levels < 0.5,
             "0.5<=level<2": (levels >= 0.5) & (levels < 2), "level>=2": levels >= 2}
    for name, m in bands.items():
        if m.any():
            out[name] = {"tables": int(m.sum()), "mean_target": round(float(y[m].mean()), 4),
                         "brier": round(float(np.mean((p[m] - y[m]) ** 2)), 4),
                         "brier_constant": round(float(np.var(y[m])), 4),
                         "corr": round(float(np.corrcoef(p[m], y[m])[0, 1]), 4) if m.sum() > 2 else None}
    return out


def main(argv=None) -> int:
    from billiards.files import repo_path
    from billiards.physics import PRESETS
    from billiards.physics.config import physics_record
    from billiards.provenance import git_commit

    ap = argparse.ArgumentParser(prog="python -m billiards.search.value",
                                 description="Train a table value for the position-aware search (see the module docstring).")
    ap.add_argument("--out", required=True, help="the value file to write (e.g. results/values/value.pt)")
    ap.add_argument("--physics", default=DEFAULT_PRESET, choices=sorted(PRESETS))
    ap.add_argument("--ranker", default="results/rankers/fastfiz/ranker.pt", help="the shot ranker the labelling search uses")
    ap.add_argument("--labeller", default="ranked", choices=("ranked", "search"),
                    help="ranked: top of a ranked pool by noisy shares (--pool, --top, --samples); search: the "
                         "position-aware robust search itself over --value (one step of policy iteration)")
    ap.add_argument("--value", help="--labeller search / --discount: the previous value (e.g. results/values/value.pt)")
    ap.add_argument("--high-ranker", default="results/rankers/fastfiz_x5/ranker.pt",
                    help="--labeller search: the ranker for tables at level >= --split")
    ap.add_argument("--split", type=float, default=2.5, help="--labeller search: the level where --high-ranker takes over")
    ap.add_argument("--position", type=float, nargs=2, default=(8.0, 3.0), metavar=("LOW", "HIGH"),
                    help="--labeller search: the position weight below and above --split")
    ap.add_argument("--discount", type=float, default=0.0,
                    help="> 0: a scoring replay counts 1 - g + g V(leave) (V: --value): the discounted run, not one shot")
    ap.add_argument("--states", type=int, default=60000, help="training tables")
    ap.add_argument("--test-states", type=int, default=4096, help="held-out tables")
    ap.add_argument("--pool", type=int, default=300)
    ap.add_argument("--top", type=int, default=16)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--check", type=int, default=16)
    ap.add_argument("--hidden", type=int, default=128)
    ap.add_argument("--layers", type=int, default=2)
    ap.add_argument("--epochs", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    for key in ("states", "test_states", "pool", "top", "samples", "check", "hidden", "layers", "epochs"):
        if getattr(args, key) < 1:
            ap.error(f"--{key.replace('_', '-')} must be >= 1")
    if (args.labeller == "search" or args.discount) and not args.value:
        ap.error("--labeller search and --discount need --value (the previous value)")
    if not 0.0 <= args.discount < 1.0 or min(args.position) < 0:
        ap.error("--discount must lie in [0, 1) and --position weights be >= 0")
    import torch

    from billiards.device import start_numba_threads

    start_numba_threads()
    torch.set_num_threads(1)
    commit = git_commit()
    params = PRESETS[args.physics]
    ranker = ShotRanker.load(repo_path(args.ranker))
    previous = TableValue.load(repo_path(args.value)) if args.value else None
    choose = None
    if args.labeller == "search":
        choose = search_chooser([(args.split, ranker, args.pool, args.position[0]),
                                 (np.inf, ShotRanker.load(repo_path(args.high_ranker)), args.pool, args.position[1])],
                                previous, params)
    rng = np.random.default_rng(args.seed)
    t0 = time.time()
    say = lambda m: print(m, flush=True)
    data = dict(pool=args.pool, top=args.top, samples=args.samples, check=args.check, choose=choose,
                discount=args.discount, value=previous)
    X, y, _, _ = make_dataset(args.states, ranker, rng, params, log=say, **data)
    Xt, yt, _, lt = make_dataset(args.test_states, ranker, np.random.default_rng(args.seed + 10_000), params, **data)
    say(f"data: {len(y):,} training tables (mean target {y.mean():.3f}), {time.time() - t0:.0f} s")
    value = TableValue(*fit_mlp(X, y, hidden=args.hidden, layers=args.layers, epochs=args.epochs, batch=1024,
                                seed=args.seed, log=say), {})
    report = held_out_report(value, Xt, yt, lt)
    value.meta = {**physics_record(params), "noise": {k: getattr(BASE_NOISE, k) for k in
                                                      ("sigma_aim_deg", "sigma_speed", "sigma_tip_mm")},
                  "command": "python -m billiards.search.value " + " ".join(sys.argv[1:] if argv is None else argv),
                  "commit": commit, "args": vars(args), "held_out": report, "cpu_seconds": round(time.process_time(), 1)}
    value.save(args.out)
    say(json.dumps(report))
    say(f"wrote {args.out} ({time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["BASE_NOISE", "MAX_LEVEL", "N_FEATURES", "TableValue", "ValueFileError", "draw_levels", "held_out_report",
           "make_dataset", "ranked_chooser", "search_chooser", "table_features"]
