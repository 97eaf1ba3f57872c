"""A learned shot ranker: which candidate shots forgive the execution noise.

Under execution noise the search is limited by its candidates, not by how it scores them
(results/noise/README.md): at 400 simulations per shot the geometric proposer's pool holds too
few shots that still score when the cue errs. The ranker is a small network, trained offline
on simulated shots, that predicts from a table and a candidate shot the probability that the
shot scores when played under the noise. The ``ranked`` proposer (:class:`RankedProposer`)
draws a large pool of geometric candidates -- free: nothing is simulated -- and hands the
search the best ``k`` by the ranker, so every simulation the search spends goes to a shot that
is likely to forgive the noise.

* :func:`shot_features` -- the ranker's input, one place (training and proposing).
* :class:`ShotRanker` -- the network in NumPy (float32), saved and loaded as a tagged torch
  file of tensors and plain values (``weights_only``: loading executes nothing).
* :class:`RankedProposer` -- the proposer.
* :func:`make_dataset` / :func:`fit` / ``python -m billiards.search.ranker`` -- how a ranker is
  made: random racks, candidates from the proposer's own pool distribution, each simulated
  once exactly and, if it scores, ``samples`` times under the noise; the target is the share
  of noisy replays that score (0 for a candidate that misses exactly). See ``--help``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from typing import ClassVar
from pathlib import Path

import numpy as np

from billiards import numerics
from billiards.files import load_tagged, repo_path, save_tagged
from billiards.physics import DEFAULT_PARAMS, DEFAULT_PRESET, PhysicsParams, random_racks, simulate_batch
from billiards.physics.core import RED1, RED2, WHITE, YELLOW
from billiards.physics.noise import NOISE_PRESETS, SIGMA_FIELDS, NoiseModel

from .proposers import GeometricProposer

FORMAT = "billiards-shot-ranker-1"
N_FEATURES = 28
# the pool the ranked proposer draws (and the ranker is trained on): the geometric proposer's
# draws over the whole aim cone, every power up to 1, every tip offset, half of them into the
# cone of the farther red
POOL_DRAWS = dict(power_low=0.15, power_high=1.0, far_share=0.5)


def _angle(x):
    return (x + np.pi) % (2.0 * np.pi) - np.pi


def shot_features(positions: np.ndarray, actions: np.ndarray, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """The ranker's input for shots ``actions`` (..., 4) (theta, p, a, b) on tables
    ``positions`` (..., 4, 2): (..., :data:`N_FEATURES`) float32.

    The reds are ordered by the shot, not by their index: "first" is the red whose
    guaranteed-contact cone the aim lies deeper in (smaller ``|u|``), "second" the other, so
    the two symmetric labellings of a table look the same. Per ball b in (yellow, first red,
    second red): the aim's offset from the centre line in units of the contact cone's half-width
    ``u_b = wrap(theta - theta_b) / asin(2R / d_b)`` (clipped to +-3), the distance ``d_b``,
    and cos / sin of ``theta - theta_b``. Then the white's and the three others' centres as
    fractions of the table (x / W, y / L), the shot's cos theta, sin theta, p, a, b, and the
    second red's position seen from the first along the aim (cos / sin of the direction
    first -> second relative to theta, and the distance).
    """
    positions = np.asarray(positions, dtype=np.float64)
    actions = np.asarray(actions, dtype=np.float64)
    pos = np.broadcast_to(positions, actions.shape[:-1] + (4, 2))
    theta = actions[..., 0]
    R, W, L = params.ball_radius, params.table_width, params.table_length

    def seen(ball):
        d = pos[..., ball, :] - pos[..., WHITE, :]
        dist = np.hypot(d[..., 0], d[..., 1])
        off = _angle(theta - numerics.atan2(d[..., 1], d[..., 0]))
        u = off / numerics.asin(np.minimum(2.0 * R / dist, 0.999))
        return np.clip(u, -3.0, 3.0), dist, off

    reds = [seen(RED1), seen(RED2)]
    swap = np.abs(reds[1][0]) < np.abs(reds[0][0])
    first = [np.where(swap, b, a) for a, b in zip(*reds)]
    second = [np.where(swap, a, b) for a, b in zip(*reds)]
    p_first = np.where(swap[..., None], pos[..., RED2, :], pos[..., RED1, :])
    p_second = np.where(swap[..., None], pos[..., RED1, :], pos[..., RED2, :])
    cols = []
    for u, dist, off in (seen(YELLOW), first, second):
        cols += [u, dist, numerics.cos(off), numerics.sin(off)]
    for p in (pos[..., WHITE, :], pos[..., YELLOW, :], p_first, p_second):
        cols += [p[..., 0] / W, p[..., 1] / L]
    cols += [numerics.cos(theta), numerics.sin(theta), actions[..., 1], actions[..., 2], actions[..., 3]]
    d = p_second - p_first
    rel = numerics.atan2(d[..., 1], d[..., 0]) - theta
    cols += [numerics.cos(rel), numerics.sin(rel), np.hypot(d[..., 0], d[..., 1])]
    out = np.stack(cols, axis=-1).astype(np.float32)
    assert out.shape[-1] == N_FEATURES
    return out


class RankerFileError(ValueError):
    """A ranker file that is missing, corrupt or not a ranker."""


@dataclass
class TaggedMLP:
    """An MLP (Linear/ReLU, one logit out) over standardised features, computed by
    :func:`billiards.numerics.mlp` (float32, the same bits on every CPU), saved as a sealed
    tagged torch file of tensors and plain values (``weights_only``: loading executes nothing).
    Subclasses name their file format, feature count and error (class attributes)."""

    weights: list  # per layer (in, out) float32
    biases: list  # per layer (out,) float32
    mean: np.ndarray  # (n_features,) feature standardisation
    std: np.ndarray
    meta: dict

    FORMAT: ClassVar[str] = ""
    N_FEATURES: ClassVar[int] = 0
    ERROR: ClassVar[type] = ValueError
    WHAT: ClassVar[str] = "model"

    def __post_init__(self):
        n = self.N_FEATURES
        shapes = [w.shape for w in self.weights]
        if (not shapes or len(self.biases) != len(shapes) or shapes[0][0] != n or shapes[-1][1] != 1
                or any(a[1] != b[0] for a, b in zip(shapes, shapes[1:]))
                or any(b.shape != (w.shape[1],) for w, b in zip(self.weights, self.biases))
                or self.mean.shape != (n,) or self.std.shape != (n,)):
            raise self.ERROR(f"{self.WHAT} layers do not chain from {n} features to one logit: {shapes}")

    def logits(self, features: np.ndarray) -> np.ndarray:
        """Logits (...,) of feature rows (..., N_FEATURES)."""
        x = (np.asarray(features, dtype=np.float32) - self.mean) / self.std
        lead = x.shape[:-1]
        x = numerics.mlp(x.reshape(1, -1, x.shape[-1]), [w[None] for w in self.weights], [b[None] for b in self.biases])
        return x[0, :, 0].reshape(lead)

    def save(self, path) -> Path:
        import torch

        t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))
        return save_tagged(path, {"format": self.FORMAT, "weights": [t(w) for w in self.weights],
                                  "biases": [t(b) for b in self.biases], "mean": t(self.mean), "std": t(self.std),
                                  "meta": json.dumps(self.meta)})

    @classmethod
    def check(cls, payload: dict, path) -> dict:
        """The one place a file of this kind is checked, after its seal: its keys and their types,
        every tensor real and finite, the layers a chain of (in, out) matrices from
        :attr:`N_FEATURES` features to one logit with a bias each, the feature scales ``std``
        > 0 (a zero would score NaN), and its metadata a JSON object naming a valid table
        (``physics_params``) and noise (``noise``). ``ERROR`` naming the file and what is wrong;
        returns the metadata."""
        import torch

        from billiards.files import key_problem, tensor_problem
        from billiards.physics.checks import ContractError

        def bad(why: str):
            return cls.ERROR(f"{cls.WHAT} file {path} is not a usable {cls.WHAT}: {why}")

        why = (key_problem(payload, {"weights": list, "biases": list, "mean": torch.Tensor, "std": torch.Tensor,
                                     "meta": str})
               or tensor_problem({k: payload[k] for k in ("weights", "biases", "mean", "std")}, "tensors"))
        if why:
            raise bad(why)
        n, weights, biases = cls.N_FEATURES, payload["weights"], payload["biases"]
        shapes = [tuple(w.shape) for w in weights]
        if (not shapes or len(biases) != len(shapes) or any(len(sh) != 2 for sh in shapes) or shapes[0][0] != n
                or shapes[-1][1] != 1 or any(a[1] != b[0] for a, b in zip(shapes, shapes[1:]))
                or any(tuple(b.shape) != (sh[1],) for sh, b in zip(shapes, biases))):
            raise bad(f"its layers do not chain from {n} features to one logit: weights {shapes}, "
                      f"biases {[tuple(b.shape) for b in biases]}")
        for key in ("mean", "std"):
            if tuple(payload[key].shape) != (n,):
                raise bad(f"{key} has shape {tuple(payload[key].shape)}, not ({n},)")
        if not bool((payload["std"] > 0).all()):
            raise bad(f"std holds {float(payload['std'].min()):g}: a feature's scale must be > 0 (0 would score NaN)")
        try:
            meta = json.loads(payload["meta"])
        except (ValueError, RecursionError) as err:
            raise bad(f"its metadata is not JSON ({err})") from None
        if why := key_problem(meta, {"physics_params": dict, "noise": dict}, "meta"):
            raise bad(why)
        try:
            PhysicsParams.from_dict(meta["physics_params"])
            NoiseModel(**meta["noise"])
        except (ContractError, ValueError, TypeError) as err:
            raise bad(f"its metadata's table or noise is not valid ({err})") from None
        return meta

    @classmethod
    def load(cls, path):
        """Read a file of this kind (tensors and plain values only: nothing in it is executed),
        sealed and checked (:meth:`check`)."""
        payload = load_tagged(path, cls.FORMAT, cls.ERROR, cls.WHAT)
        meta = cls.check(payload, path)
        arr = lambda x: x.numpy().astype(np.float32)  # noqa: E731
        return cls([arr(w) for w in payload["weights"]], [arr(b) for b in payload["biases"]],
                   arr(payload["mean"]), arr(payload["std"]), meta)

    @property
    def params(self) -> PhysicsParams:
        return PhysicsParams.from_dict(self.meta["physics_params"])

    @property
    def noise(self) -> NoiseModel:
        return NoiseModel(**self.meta["noise"])


class ShotRanker(TaggedMLP):
    """The shot ranker: a :class:`TaggedMLP` over :func:`shot_features`.

    ``score`` is the logit of the predicted probability that the shot scores under the noise
    the ranker was trained for (``meta["noise"]``); ``meta`` also records the table
    (``physics_params``), the training command and its figures.
    """

    FORMAT = FORMAT
    N_FEATURES = N_FEATURES
    ERROR = RankerFileError
    WHAT = "shot ranker"

    def score(self, positions: np.ndarray, actions: np.ndarray, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
        """Logits (...,) for shots ``actions`` (..., 4) on tables ``positions`` (..., 4, 2)."""
        return self.logits(shot_features(positions, actions, params))


class RankedProposer:
    """Geometric candidates ranked by a :class:`ShotRanker`: for each state, ``pool`` draws of
    the geometric proposer (:data:`POOL_DRAWS`: both reds, the whole cone, every power and
    spin), the best ``k`` by the ranker's score, best first (candidate 0 is the ranker's pick).
    Nothing is simulated. Asked for more than ``pool`` candidates it ranks ``k`` draws (all of
    them, best first)."""

    def __init__(self, ranker: ShotRanker, pool: int = 2000, name: str = "ranked",
                 params: PhysicsParams = DEFAULT_PARAMS):
        if pool < 1:
            raise ValueError(f"RankedProposer needs pool >= 1, got {pool}")
        self.ranker, self.pool, self.name, self.params = ranker, pool, name, params
        self.draws = GeometricProposer(R=params.ball_radius, **POOL_DRAWS)

    def propose(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        positions = np.asarray(positions, dtype=np.float64)
        cand = self.draws.propose(positions, max(k, self.pool), rng)
        logit = self.ranker.score(positions[:, None], cand, self.params)
        top = np.argsort(-logit, axis=1, kind="stable")[:, :k]
        return np.take_along_axis(cand, top[..., None], axis=1)


def noise_mismatch(proposer, noise: NoiseModel) -> str | None:
    """If ``proposer`` is a :class:`RankedProposer` whose ranker was trained for another noise
    than ``noise``, what to say (naming the shipped ranker for that noise, if there is one). A
    ranker trained for a level that variable ``noise`` plays (fastfiz's or fastfiz_x5's under
    ``noise=variable``) fits it."""
    if not isinstance(proposer, RankedProposer) or proposer.ranker.noise == noise or _plays_at_a_level(noise, proposer.ranker.noise):
        return None
    trained = proposer.ranker.meta.get("noise_preset") or proposer.ranker.noise.describe()
    msg = (f"proposer {proposer.name!r}: its ranker was trained for noise {trained}, this run plays "
           f"{noise.describe()}; it ranks for the noise it was trained for")
    name = noise.describe()
    if name in NOISE_PRESETS and repo_path(f"results/rankers/{name}/ranker.pt").is_file():
        msg += f" (the ranker for {name}: proposer.ranker=results/rankers/{name}/ranker.pt)"
    return msg


def _plays_at_a_level(noise: NoiseModel, trained: NoiseModel) -> bool:
    """Whether variable ``noise`` plays ``trained``'s sigmas at one of its levels."""
    if not noise.is_variable or noise.sigma_aim_deg == 0:
        return False
    level = trained.sigma_aim_deg / noise.sigma_aim_deg
    at_level = noise.scaled(level)
    return (noise.level_range[0] <= level <= noise.level_range[1]
            and np.allclose([getattr(at_level, f) for f in SIGMA_FIELDS], [getattr(trained, f) for f in SIGMA_FIELDS]))


# ----------------------------------------------------------------------------- making a ranker


def make_dataset(n_racks: int, candidates: int, samples: int, noise: NoiseModel, rng: np.random.Generator,
                 params: PhysicsParams = DEFAULT_PARAMS, chunk: int = 500) -> tuple[np.ndarray, np.ndarray]:
    """Features (n_racks * candidates, N_FEATURES) float32 and targets (same rows,) float32:
    random racks, ``candidates`` pool draws each (:data:`POOL_DRAWS`), the share of
    ``samples`` noisy replays that score for those that score exactly (1 under exact ``noise``,
    nothing replayed), 0 for the others."""
    draws = GeometricProposer(R=params.ball_radius, **POOL_DRAWS)
    X, y = [], []
    for start in range(0, n_racks, chunk):
        n = min(chunk, n_racks - start)
        racks = random_racks(rng, n, params)
        cand = draws.propose(racks, candidates, rng)
        exact = simulate_batch(np.repeat(racks, candidates, axis=0), cand.reshape(-1, 4), params).score
        q = np.zeros(n * candidates, dtype=np.float32)
        hit = np.flatnonzero(exact)
        if noise.is_exact:  # every replay would be the exact shot again
            q[hit] = 1.0
        elif hit.size:
            shots = np.repeat(cand.reshape(-1, 4)[hit], samples, axis=0)
            played = noise.apply(shots, noise.draw((len(shots),), rng), params)
            noisy = simulate_batch(np.repeat(racks[hit // candidates], samples, axis=0), played, params).score
            q[hit] = noisy.reshape(-1, samples).mean(axis=1)
        X.append(shot_features(racks[:, None], cand, params).reshape(-1, N_FEATURES))
        y.append(q)
    return np.concatenate(X), np.concatenate(y)


def fit(X: np.ndarray, y: np.ndarray, hidden: int = 256, layers: int = 3, epochs: int = 12, batch: int = 4096,
        lr: float = 2e-3, seed: int = 0, log=print) -> ShotRanker:
    """Train the ranker on (features, target share): :func:`fit_mlp`."""
    return ShotRanker(*fit_mlp(X, y, hidden, layers, epochs, batch, lr, seed, log), {})


def fit_mlp(X: np.ndarray, y: np.ndarray, hidden: int = 256, layers: int = 3, epochs: int = 12, batch: int = 4096,
            lr: float = 2e-3, seed: int = 0, log=print) -> tuple[list, list, np.ndarray, np.ndarray]:
    """Train an MLP (``layers`` hidden layers of ``hidden``) on (features, target share in
    [0, 1]) by binary cross-entropy, Adam with a one-cycle learning rate, on the CPU in one
    thread (deterministic for a seed): (weights (in, out), biases, feature mean, feature std),
    float32, the :class:`TaggedMLP` layout."""
    import torch

    torch.manual_seed(seed)
    Xt, yt = torch.from_numpy(X), torch.from_numpy(y)
    mean, std = Xt.mean(0), Xt.std(0) + 1e-6
    sizes = [X.shape[1]] + [hidden] * layers + [1]
    mods = []
    for a, b in zip(sizes, sizes[1:]):
        mods += [torch.nn.Linear(a, b), torch.nn.ReLU()]
    net = torch.nn.Sequential(*mods[:-1])
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    steps = epochs * math.ceil(len(Xt) / batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, lr, total_steps=steps)
    gen = torch.Generator().manual_seed(seed)
    t0 = time.time()
    for epoch in range(epochs):
        perm = torch.randperm(len(Xt), generator=gen)
        total = 0.0
        for i in range(0, len(Xt), batch):
            j = perm[i:i + batch]
            loss = torch.nn.functional.binary_cross_entropy_with_logits(net((Xt[j] - mean) / std).squeeze(-1), yt[j])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(j)
        log(f"epoch {epoch + 1}/{epochs}: loss {total / len(Xt):.4f} ({time.time() - t0:.0f} s)")
    linear = [m for m in net if isinstance(m, torch.nn.Linear)]
    f32 = lambda t: t.detach().numpy().astype(np.float32).copy()
    return [f32(m.weight).T.copy() for m in linear], [f32(m.bias) for m in linear], f32(mean), f32(std)


def ranking_report(ranker: ShotRanker, X: np.ndarray, y: np.ndarray, per_rack: int, top: int = 50) -> dict:
    """How well ``ranker`` orders held-out candidates (``per_rack`` consecutive rows per rack):
    the best target among its top ``top`` against the first ``top`` in draw order, and the
    share of targets >= 0.9 among its top ``top`` against all."""
    s, q = ranker.logits(X).reshape(-1, per_rack), y.reshape(-1, per_rack)
    ranked = np.take_along_axis(q, np.argsort(-s, axis=1, kind="stable")[:, :top], axis=1)
    return {"racks": int(q.shape[0]), "candidates_per_rack": per_rack, "top": top,
            "best_of_top_ranked": round(float(ranked.max(1).mean()), 4),
            "best_of_first_drawn": round(float(q[:, :top].max(1).mean()), 4),
            "best_of_all": round(float(q.max(1).mean()), 4),
            "share_forgiving_top_ranked": round(float((ranked >= 0.9).mean()), 4),
            "share_forgiving_all": round(float((q >= 0.9).mean()), 4)}


def main(argv=None) -> int:
    from billiards.physics import PRESETS
    from billiards.physics.config import physics_record
    from billiards.provenance import git_commit

    ap = argparse.ArgumentParser(prog="python -m billiards.search.ranker",
                                 description="Train a shot ranker for proposer=ranked (see the module docstring).")
    ap.add_argument("--out", required=True, help="the ranker file to write (e.g. results/rankers/fastfiz/ranker.pt)")
    ap.add_argument("--physics", default=DEFAULT_PRESET, choices=sorted(PRESETS))
    ap.add_argument("--noise", default="fastfiz", choices=[n for n, m in NOISE_PRESETS.items() if not m.is_variable],
                    help="the noise it ranks for (none: whether a shot scores under exact play; no replays)")
    ap.add_argument("--racks", type=int, default=12000, help="training racks")
    ap.add_argument("--candidates", type=int, default=500, help="candidates per rack")
    ap.add_argument("--samples", type=int, default=16, help="noisy replays of each candidate that scores exactly")
    ap.add_argument("--test-racks", type=int, default=500, help="held-out racks for the ranking report")
    ap.add_argument("--hidden", type=int, default=256)
    ap.add_argument("--layers", type=int, default=3)
    ap.add_argument("--epochs", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    for key in ("racks", "candidates", "samples", "test_racks", "hidden", "layers", "epochs"):
        if getattr(args, key) < 1:
            ap.error(f"--{key.replace('_', '-')} must be >= 1")
    import torch

    from billiards.device import start_numba_threads

    start_numba_threads()  # the simulator's pool first: its start would undo torch's count
    torch.set_num_threads(1)
    commit = git_commit()  # the code the ranker is made with (read before anything runs)
    params, noise = PRESETS[args.physics], NOISE_PRESETS[args.noise]
    rng = np.random.default_rng(args.seed)
    t0 = time.time()
    X, y = make_dataset(args.racks, args.candidates, args.samples, noise, rng, params)
    Xt, yt = make_dataset(args.test_racks, args.candidates, args.samples, noise, rng, params)
    print(f"data: {len(y):,} training shots ({(y > 0).mean():.1%} score exactly), {time.time() - t0:.0f} s", flush=True)
    ranker = fit(X, y, hidden=args.hidden, layers=args.layers, epochs=args.epochs, seed=args.seed,
                 log=lambda m: print(m, flush=True))
    report = ranking_report(ranker, Xt, yt, args.candidates)
    ranker.meta = {**physics_record(params), "noise": {k: getattr(noise, k) for k in ("sigma_aim_deg", "sigma_speed",
                                                                                    "sigma_tip_mm")},
                   "noise_preset": args.noise, "command": "python -m billiards.search.ranker " + " ".join(
                       sys.argv[1:] if argv is None else argv),
                   "commit": commit, "args": vars(args), "held_out": report,
                   "cpu_seconds": round(time.process_time(), 1)}
    ranker.save(args.out)
    print(json.dumps(report), flush=True)
    print(f"wrote {args.out} ({time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["N_FEATURES", "POOL_DRAWS", "RankedProposer", "RankerFileError", "ShotRanker", "TaggedMLP", "fit", "fit_mlp",
           "make_dataset",
           "noise_mismatch", "ranking_report", "shot_features"]
