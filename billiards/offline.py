"""Offline datasets in Minari's format: innings played by an agent, every transition with the
gymnasium env's observation, the shot, the reward, the flags and the env's info.

An episode is one inning of the benchmark's ``innings-v1`` protocol (a random rack, continue on a
miss, 10 shots; ``docs/benchmark.md``), played on the gymnasium vector env with raw actions, its
rack and noise from its own seed (``DATASET_SEED`` + the inning's index: far from every
benchmark track's held-out seeds). The agent is any spec the benchmark takes
(:func:`billiards.bench.agents.resolve_agent`), under the track's simulation budget. The
datasets of the issue, per noise preset (``none``, ``fastfiz``):

* ``expert``: the default search of ``search.py`` for that noise (``search:h2`` exact -- the
  default's h2 over the geometric proposer --, ``search:default`` under noise: the position-aware
  robust search over the learned shot ranker);
* ``medium``: SAC with the aim constraint and the carom features (``results/policies/base``
  exact, ``results/policies/fastfiz_aim_features`` under fastfiz, seed 0);
* ``random``: uniform raw shots.

``python -m billiards.offline generate --dataset expert --noise none --shots 200000 --out DIR``
plays blocks of innings side by side and writes each block to ``DIR/blocks/`` as it ends (a
killed run keeps its finished blocks; the same command resumes with the rest);
``python -m billiards.offline build DIR`` writes the Minari dataset
(``billiards/<noise>/<dataset>-v0``) under ``DIR/minari`` and prints its size and the sha256 of its content;
``minari.load_dataset`` reads it with ``MINARI_DATASETS_PATH=DIR/minari``, and TorchRL's
``MinariExperienceReplay(..., load_from_local_minari=True)`` too.

The actions are the raw shots as played (float64 theta, p, a, b): the searches' angles come
from ``atan2`` (within one turn either way), so the dataset's action space spans
``[-2pi, 2pi]`` for the angle, not the env's ``[0, 2pi]``; the simulator plays either.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

from billiards.files import atomic_write_bytes

DATASET_SEED = 9_000_000
BLOCK = 100  # innings played side by side, one file each
SHOTS = 10  # shots per inning (the innings-v1 protocol)
NOISES = ("none", "fastfiz")
DATASETS = {
    "expert": {"none": "search:h2", "fastfiz": "search:default"},
    "medium": {"none": "results/policies/base/seed0.pt", "fastfiz": "results/policies/fastfiz_aim_features/seed0.pt"},
    "random": {"none": "random", "fastfiz": "random"},
}
INFO = ("score", "foul", "miss", "first_contact", "second_red", "cushions", "positions", "raw_action", "commanded_action")


def dataset_id(dataset: str, noise: str) -> str:
    return f"billiards/{noise}/{dataset}-v0"


def track_for(noise: str):
    """The ``innings-v1`` track with the dataset's noise and seeds (its budget for a search)."""
    from billiards.bench.tracks import get_track

    return dataclasses.replace(get_track("innings-v1"), noise=noise, seed=DATASET_SEED, name="innings-v1")


def play_block(agent, track, first: int, n: int) -> dict[str, np.ndarray]:
    """Innings ``first .. first + n - 1``, played by the benchmark's own loop
    (:func:`billiards.bench.run.play_innings`): observations (n, T+1, D), actions (n, T, 4),
    rewards, terminations, truncations (n, T) and the env's info keys :data:`INFO` (n, T+1, ...;
    the entry before the first shot holds the rack and zeros)."""
    from billiards.bench.run import play_innings

    out = {"observations": [], "actions": [], "rewards": [], "terminations": [], "truncations": []}
    infos = {k: [] for k in INFO}
    racks = []

    def record(t, before, obs, raw, step):
        next_obs, reward, term, trunc, info = step
        if t < track.shots - 1 and (term.any() or trunc.any()):
            raise RuntimeError("an inning ended before its last shot: the protocol continues on a miss")
        if t == 0:
            out["observations"].append(obs)
            racks.append(before)
        for key, value in zip(("observations", "actions", "rewards", "terminations", "truncations"),
                              (next_obs, np.asarray(raw, dtype=np.float64), reward, term, trunc)):
            out[key].append(value)
        for k in INFO:
            infos[k].append(info[k])

    play_innings(agent, track, first, n, on_step=record)
    arrays = {k: np.stack(v, axis=1) for k, v in out.items()}
    for k, v in infos.items():  # row 0, before the first shot: the rack, zeros for the rest
        arrays[f"info/{k}"] = np.stack([racks[0] if k == "positions" else np.zeros_like(v[0]), *v], axis=1)
    return arrays


def _block_path(out: Path, index: int) -> Path:
    return out / "blocks" / f"block{index:05d}.npz"


def _manifest(out: Path) -> dict:
    return json.loads((out / "dataset.json").read_text())


def generate(dataset: str, noise: str, shots: int, out: Path, agent_spec: str | None = None, progress: bool = True) -> dict:
    """Play ``shots`` shots (rounded up to whole blocks of innings) into ``out``; resumes."""
    from billiards.bench.agents import resolve_agent
    from billiards.provenance import git_commit

    if noise not in NOISES and agent_spec is None:
        raise SystemExit(f"Error: --noise must be one of {', '.join(NOISES)} (or give --agent), got {noise!r}")
    if dataset not in DATASETS and agent_spec is None:
        raise SystemExit(f"Error: --dataset must be one of {', '.join(DATASETS)} (or give --agent), got {dataset!r}")
    if shots < 1:
        raise SystemExit(f"Error: --shots must be >= 1, got {shots}")
    spec = agent_spec or DATASETS[dataset][noise]
    track = track_for(noise)
    blocks = math.ceil(shots / (SHOTS * BLOCK))
    manifest = {"dataset_id": dataset_id(dataset, noise), "dataset": dataset, "noise": noise, "agent": spec,
                "physics": track.physics, "shots_per_inning": SHOTS, "block": BLOCK, "blocks": blocks,
                "seed": DATASET_SEED, "budget": track.budget}
    out.mkdir(parents=True, exist_ok=True)
    if (out / "dataset.json").exists():
        held = {k: v for k, v in _manifest(out).items() if k != "commit"}
        if held != manifest:
            raise SystemExit(f"Error: {out} holds another dataset ({held}); give another --out")
    else:
        atomic_write_bytes(out / "dataset.json", json.dumps({**manifest, "commit": git_commit()}, indent=1).encode())
    todo = [b for b in range(blocks) if not _block_path(out, b).exists()]
    if not todo:
        return manifest
    agent = resolve_agent(spec, track)
    print(f"{manifest['dataset_id']}: {blocks} blocks of {BLOCK} innings x {SHOTS} shots by {spec}; "
          f"{blocks - len(todo)} done, {len(todo)} to play -> {out}", flush=True)
    import time

    start = time.perf_counter()
    for i, b in enumerate(todo):
        arrays = play_block(agent, track, b * BLOCK, BLOCK)
        path = _block_path(out, b)
        path.parent.mkdir(exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **arrays)
        os.replace(tmp, path)
        if progress:
            left = (time.perf_counter() - start) / (i + 1) * (len(todo) - i - 1)
            print(f"block {b + 1}/{blocks} written; about {left / 60:.1f} min left", file=sys.stderr, flush=True)
    return manifest


def episodes(out: Path):
    """The dataset's innings as Minari episode buffers, in seed order."""
    manifest = _manifest(out)
    for b in range(manifest["blocks"]):
        with np.load(_block_path(out, b)) as data:
            arrays = {k: data[k] for k in data.files}
        for i in range(arrays["observations"].shape[0]):
            yield {"observations": arrays["observations"][i], "actions": arrays["actions"][i],
                   "rewards": arrays["rewards"][i], "terminations": arrays["terminations"][i],
                   "truncations": arrays["truncations"][i], "id": b * manifest["block"] + i,
                   "seed": manifest["seed"] + b * manifest["block"] + i,
                   "infos": {k.split("/", 1)[1]: arrays[k][i] for k in arrays if k.startswith("info/")}}


def build(out: Path, root: Path | None = None):
    """The Minari dataset of the blocks in ``out`` (every block must be there), under ``root``
    (default ``out/minari``); returns it."""
    import gymnasium as gym
    import minari

    from billiards import GYM_ID

    manifest = _manifest(out)
    missing = [b for b in range(manifest["blocks"]) if not _block_path(out, b).exists()]
    if missing:
        raise SystemExit(f"Error: {out}: {len(missing)} of {manifest['blocks']} blocks not played yet; run generate again")
    root = Path(root or out / "minari").resolve()  # Minari resolves a relative one against itself
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    env = gym.make(GYM_ID, start="random", on_miss="continue", max_shots=SHOTS, physics=manifest["physics"],
                   noise=manifest["noise"], normalize_actions=False)
    action_space = gym.spaces.Box(low=np.array([-2 * math.pi, 0.0, -1.0, -1.0]), high=np.array([2 * math.pi, 1.0, 1.0, 1.0]),
                                  dtype=np.float64)
    from minari.data_collector import EpisodeBuffer

    buffers = [EpisodeBuffer(**ep) for ep in episodes(out)]
    if (root / manifest["dataset_id"]).exists():
        raise SystemExit(f"Error: {root / manifest['dataset_id']} exists already; remove it to build the dataset again")
    import warnings

    with warnings.catch_warnings():  # no e-mail address and no URL of the code: the commit names the code
        warnings.filterwarnings("ignore", message=".*(author_email|code_permalink).*is set to None", category=UserWarning)
        return minari.create_dataset_from_buffers(
            dataset_id=manifest["dataset_id"], buffer=buffers, env=env, action_space=action_space,
            algorithm_name=manifest["agent"], author="billiards", code_permalink=f"billiards commit {manifest.get('commit')}",
            description=(f"Korean 4-ball billiards, {manifest['noise']} execution noise: innings of the innings-v1 protocol "
                         f"(random rack, continue on a miss, {SHOTS} shots) played by {manifest['agent']}; episode k from seed "
                         f"{manifest['seed']} + k"), eval_env=env)


def checksum(out: Path) -> str:
    """sha256 over the dataset's content: every block's arrays in order (name, dtype, shape and
    bytes), so the same command gives the same checksum whatever Minari's files hold besides."""
    h = hashlib.sha256()
    for b in range(_manifest(out)["blocks"]):
        with np.load(_block_path(out, b)) as data:
            for name in sorted(data.files):
                a = np.ascontiguousarray(data[name])
                h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
                h.update(a.tobytes())
    return h.hexdigest()


# The offline baseline: TorchRL's IQL (implicit Q-learning) on a dataset read with
# minari.load_dataset into a TorchRL replay buffer (TorchRL 0.14.1's MinariExperienceReplay reads
# these datasets' layout but not their values: docs/datasets.md), scored on the benchmark track of
# the dataset's noise.
IQL_TRACK = {"none": "innings-v1", "fastfiz": "p1-fastfiz-v1"}
# What the learner sees and emits: ``raw`` the gymnasium env's observation (28 floats) and
# normalised action box (the angle over the whole turn); ``aim_features`` what the project's own
# agents use (env=aim_features): the observation with the carom features (32 floats) and the
# aim-constrained action (u inside the nearest red's window, p, a, b), both from the table the
# observation holds (billiards.domain.observed_positions).
SPACES = ("raw", "aim_features")
IQL_SETTINGS = {"batch_size": 256, "lr": 3e-4, "gamma": 0.9, "tau": 0.005, "expectile": 0.7, "temperature": 3.0,
                "hidden_sizes": [256, 256]}


EDGE = 1.0 - 1e-3  # a learner's normalised actions are kept this far inside [-1, 1] (a squashed Gaussian's log-likelihood is finite)


def normalized_actions(actions: np.ndarray) -> np.ndarray:
    """The datasets' raw shots (theta within one turn either way, p, a, b) as the normalised box
    [-1, 1]^4 of the gymnasium env (theta taken into [0, 2 pi) first), kept :data:`EDGE` inside
    it."""
    from billiards import domain

    raw = np.array(actions, dtype=np.float64)
    raw[..., 0] = np.mod(raw[..., 0], 2 * math.pi)
    return np.clip(domain.normalize_action(raw), -EDGE, EDGE).astype(np.float32)


def _radius(R: float | None) -> float:
    from billiards.physics import DEFAULT_PARAMS

    return DEFAULT_PARAMS.ball_radius if R is None else float(R)


def track_radius(track: str) -> float:
    """The ball radius of a benchmark track's table (where a learner's aim-space policy plays)."""
    from billiards.bench import get_track
    from billiards.physics import get_params

    return get_params(get_track(track).physics).ball_radius


def _check_space(space: str) -> None:
    if space not in SPACES:
        raise ValueError(f"space must be one of {', '.join(SPACES)}, got {space!r}")


def space_observation(obs: np.ndarray, space: str) -> np.ndarray:
    """The gymnasium env's observations (..., 28) as the learner of ``space`` sees them
    (:data:`SPACES`), float32: themselves, or under ``aim_features`` the observed table's
    observation with the carom features (..., 32)."""
    from billiards import domain

    _check_space(space)
    if space == "raw":
        return np.asarray(obs, dtype=np.float32)
    return domain.observation(domain.observed_positions(obs), extra_features=True)


def space_action(obs: np.ndarray, actions: np.ndarray, space: str, R: float | None = None) -> np.ndarray:
    """Raw shots (..., 4) played on the tables of observations (..., 28) as the learner of
    ``space`` emits them, float32 in [-1, 1]^4 kept :data:`EDGE` inside it: the env's normalised
    box, or under ``aim_features`` the aim-constrained action (a shot aimed outside the nearest
    red's window clipped to the window's edge; the window of balls of radius ``R``, the table's:
    default the default table's)."""
    from billiards import domain

    _check_space(space)
    if space == "raw":
        return normalized_actions(actions)
    R = _radius(R)
    return np.clip(domain.normalized_aim_action(domain.observed_positions(obs), actions, R), -EDGE, EDGE).astype(np.float32)


def space_agent(policy, space: str, name: str, R: float | None = None):
    """A benchmark agent (:class:`~billiards.bench.agents.CallableAgent`) of ``policy``, a NumPy
    function from the learner's observations (:func:`space_observation`) to its normalised
    actions in ``space``: raw, the env's own normalised box; under ``aim_features`` mapped back to
    the raw shot on the observed table (:func:`billiards.domain.raw_action`, balls of radius
    ``R``: the table it plays on; default the default table's)."""
    from billiards import domain
    from billiards.bench.agents import CallableAgent

    _check_space(space)
    R = _radius(R)

    def act(obs):
        obs = np.asarray(obs)
        a = policy(space_observation(obs[..., :domain.OBS_DIM], space))
        return a if space == "raw" else domain.raw_action(a, domain.observed_positions(obs), R, constrain_aim=True,
                                                          normalized=True)

    return CallableAgent(act, name, normalized=space == "raw")


def transitions(directory: Path, space: str = "raw"):
    """Every transition of the Minari dataset built in ``directory``, read with
    ``minari.load_dataset``, as one TensorDict in the learner's ``space`` (:func:`space_observation`,
    :func:`space_action`):
    observation, action (normalised), next observation, reward, done and terminated."""
    import minari
    import torch
    from tensordict import TensorDict

    from billiards.physics import get_params

    manifest = _manifest(directory)
    root = (directory / "minari").resolve()
    if not (root / manifest["dataset_id"]).exists():
        raise SystemExit(f"Error: {directory}: no Minari dataset yet; run python -m billiards.offline build {directory}")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    parts = {k: [] for k in ("obs", "next", "action", "reward", "terminated", "truncated")}
    R = get_params(manifest["physics"]).ball_radius  # the aim window of the table the dataset was played on
    for ep in minari.load_dataset(manifest["dataset_id"]).iterate_episodes():
        x = space_observation(ep.observations, space)
        parts["obs"].append(x[:-1])
        parts["next"].append(x[1:])
        parts["action"].append(space_action(ep.observations[:-1], ep.actions, space, R))
        parts["reward"].append(ep.rewards)
        parts["terminated"].append(ep.terminations)
        parts["truncated"].append(ep.truncations)
    cat = {k: torch.from_numpy(np.concatenate(v)) for k, v in parts.items()}
    n = cat["obs"].shape[0]
    flag = lambda x: x.bool().reshape(n, 1)
    return TensorDict({"observation": cat["obs"].float(), "action": cat["action"],
                       "next": {"observation": cat["next"].float(), "reward": cat["reward"].float().reshape(n, 1),
                                "terminated": flag(cat["terminated"]),
                                "done": flag(cat["terminated"]) | flag(cat["truncated"])}}, batch_size=[n])


def train_iql(directory: Path, updates: int, out: Path, seed: int = 0, progress: bool = True, space: str = "raw") -> dict:
    """IQL (TorchRL's ``IQLLoss``, :data:`IQL_SETTINGS`) for ``updates`` gradient steps on the
    dataset built in ``directory`` in the learner's ``space`` (:func:`transitions`), then its
    deterministic policy (mapped back to the raw shot on the observed table) scored on
    the dataset noise's track (:data:`IQL_TRACK`) by the benchmark (``out/scorecard``); writes
    ``out/iql.json`` (settings, CPU seconds, the scorecard's figures) and returns it."""
    import time

    import torch
    from tensordict.nn import NormalParamExtractor, TensorDictModule
    from torchrl.data import Bounded, LazyTensorStorage, ReplayBuffer
    from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator
    from torchrl.objectives import IQLLoss, SoftUpdate, ValueEstimators

    from billiards.bench import evaluate
    from billiards.rl.agents import mlp

    manifest, cfg = _manifest(directory), IQL_SETTINGS
    _check_space(space)
    torch.manual_seed(seed)
    data = transitions(directory, space)
    rb = ReplayBuffer(storage=LazyTensorStorage(data.shape[0]), batch_size=cfg["batch_size"])
    rb.extend(data)
    dim, ones = int(data["observation"].shape[-1]), torch.ones(4)
    actor = ProbabilisticActor(
        TensorDictModule(torch.nn.Sequential(mlp(dim, 8, cfg["hidden_sizes"]), NormalParamExtractor()),
                         in_keys=["observation"], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"], out_keys=["action"], spec=Bounded(-ones, ones, shape=(4,)),
        distribution_class=TanhNormal, distribution_kwargs={"low": -ones, "high": ones})
    q = ValueOperator(mlp(dim + 4, 1, cfg["hidden_sizes"]), in_keys=["observation", "action"])
    v = ValueOperator(mlp(dim, 1, cfg["hidden_sizes"]), in_keys=["observation"])
    loss = IQLLoss(actor, q, v, expectile=cfg["expectile"], temperature=cfg["temperature"])
    loss.make_value_estimator(ValueEstimators.TD0, gamma=cfg["gamma"])
    target = SoftUpdate(loss, tau=cfg["tau"])
    optimizer = torch.optim.Adam(loss.parameters(), lr=cfg["lr"])
    start, cpu = time.perf_counter(), time.process_time()
    for i in range(updates):
        losses = loss(rb.sample())
        total = losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_value"]
        optimizer.zero_grad()
        total.backward()
        optimizer.step()
        target.step()
        if progress and (i + 1) % max(1, updates // 10) == 0:
            shown = ", ".join(f"{k} {float(losses[f'loss_{k}'].detach()):.3f}" for k in ("actor", "qvalue", "value"))
            print(f"iql {i + 1}/{updates}: {shown}", file=sys.stderr, flush=True)
    train_cpu = time.process_time() - cpu
    net = actor.module[0].module

    def policy(x):
        with torch.no_grad():
            return torch.tanh(net(torch.as_tensor(x, dtype=torch.float32))[0]).numpy()

    track = IQL_TRACK[manifest["noise"]]
    flag = "" if space == "raw" else f" --space {space}"
    card = evaluate(space_agent(policy, space, f"iql:{space}", track_radius(track)), track, out=out / "scorecard", progress=False,
                    command=f"python -m billiards.offline iql {directory} --updates {updates} --seed {seed}{flag} --out {out}")
    record = {"dataset_id": manifest["dataset_id"], "updates": updates, "seed": seed, "space": space, "settings": cfg,
              "train_cpu_seconds": round(train_cpu, 1), "train_wall_seconds": round(time.perf_counter() - start, 1),
              "track": track, **{k: card[k] for k in ("success_per_shot", "points_per_inning", "foul_per_shot", "ms_per_decision")}}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "iql.json", (json.dumps(record, indent=2) + "\n").encode())
    return record


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m billiards.offline", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate", help="play the dataset's innings into --out (resumable)")
    g.add_argument("--dataset", default="expert", help=f"one of {', '.join(DATASETS)} (default expert)")
    g.add_argument("--noise", default="none", help=f"one of {', '.join(NOISES)} (default none)")
    g.add_argument("--shots", type=int, default=200_000, help="shots to play, in whole blocks of innings (default 200000)")
    g.add_argument("--agent", default=None, help="another agent spec (docs/benchmark.md) instead of the dataset's own")
    g.add_argument("--out", type=Path, required=True, help="the dataset's folder (blocks/, dataset.json)")
    g.add_argument("--no-progress", action="store_true")
    b = sub.add_parser("build", help="write the Minari dataset of a generated folder and print its size and checksum")
    b.add_argument("out", type=Path)
    b.add_argument("--root", type=Path, default=None, help="Minari's datasets folder (default OUT/minari)")
    q = sub.add_parser("iql", help="train TorchRL's IQL on a built dataset and score it on its noise's track")
    q.add_argument("dataset_dir", type=Path, metavar="DIR", help="the dataset's folder (built)")
    q.add_argument("--updates", type=int, default=20_000)
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--space", default="raw", choices=SPACES,
                   help="what the learner sees and emits: the env's raw observation and action box (default), or "
                        "aim_features: the carom features and the aim-constrained action, as the project's own agents")
    q.add_argument("--out", type=Path, required=True, help="where iql.json and the scorecard go")
    args = parser.parse_args(argv)
    if args.command == "iql":
        rec = train_iql(args.dataset_dir, args.updates, args.out, args.seed, space=args.space)
        print(json.dumps({k: rec[k] for k in ("dataset_id", "updates", "train_cpu_seconds", "track", "success_per_shot")}))
        return 0
    if args.command == "generate":
        generate(args.dataset, args.noise, args.shots, args.out, args.agent, progress=not args.no_progress)
        return 0
    ds = build(args.out, args.root)
    root = Path(args.root or args.out / "minari").resolve()
    size = sum(p.stat().st_size for p in root.rglob("*") if p.is_file())
    rewards = np.stack([ep["rewards"] for ep in episodes(args.out)])
    print(f"{ds.spec.dataset_id}: {ds.total_episodes} episodes, {ds.total_steps} steps, {size / 2**20:.0f} MiB under {root}; "
          f"success per shot {rewards.mean():.2%}, points per inning {rewards.sum(axis=1).mean():.3f}; "
          f"content sha256 {checksum(args.out)}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
