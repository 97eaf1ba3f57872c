"""A SHA-256 fingerprint of both environments' rollouts, for every env configuration.

    NUMBA_NUM_THREADS=1 python benchmarks/env_fingerprint.py [--steps 400] [--expect HEX]

A refactor of the envs that claims to keep their behaviour bit for bit must print the same
hash before and after. Each configuration (default, aim constraint, carom features, every
shaping term alone and together, reset-on-miss from the canonical rack, the international
table, execution noise) is played

* in the gymnasium env, with normalised and with raw actions: the spaces' bounds, then
  ``--steps`` steps of fixed random actions (reset with a fixed seed at every inning end):
  observations, rewards, flags and every info entry (its dtype and bytes);
* in the TorchRL env (:func:`billiards.envs.make_env`, B = 4 innings), with raw and with
  normalised actions: the specs' bounds and shapes, then ``--steps`` steps with auto-reset:
  every entry of every transition tensordict;
* behind TorchRL's ``DoubleToFloat`` (the exact table through ``positions_bits``).

Prints a hash per configuration and the total; ``--expect`` exits 1 unless the total matches.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import torch  # noqa: E402
from _shots import report_fingerprint  # noqa: E402
from torchrl.envs import DoubleToFloat  # noqa: E402

from billiards.envs import Billiards4BallInningEnv, make_env  # noqa: E402

CONFIGS = {
    "default": {},
    "aim": dict(constrain_aim=True),
    "features": dict(extra_features=True),
    "aim_features": dict(constrain_aim=True, extra_features=True),
    "foul_penalty": dict(foul_penalty=1.0),
    "gentle": dict(gentle=0.2),
    "gentle_power": dict(gentle=0.5, gentle_kind="power"),
    "near_miss": dict(near_miss=0.05),
    "near_miss_sigma": dict(near_miss=0.1, near_miss_sigma=0.05),
    "both": dict(foul_penalty=1.0, gentle=0.2, near_miss=0.05),
    "all": dict(constrain_aim=True, extra_features=True, foul_penalty=1.0, gentle=0.2, near_miss=0.05),
    "canonical_reset": dict(constrain_aim=True, start="canonical", on_miss="reset", max_shots=5),
    "international": dict(extra_features=True, gentle=0.2, physics="international"),
    "noise": dict(noise="fastfiz_x5"),
    "noise_all": dict(constrain_aim=True, extra_features=True, foul_penalty=1.0, gentle=0.2, near_miss=0.05,
                      noise="fastfiz"),
}


def _digest(h, value) -> None:
    a = np.ascontiguousarray(value)
    h.update(f"{a.dtype}{a.shape}".encode())
    h.update(a.tobytes())


def gym_hash(config: dict, normalize: bool, steps: int, seed: int) -> str:
    h = hashlib.sha256()
    env = Billiards4BallInningEnv(normalize_actions=normalize, **config)
    for space in (env.action_space, env.observation_space):
        _digest(h, space.low)
        _digest(h, space.high)
    rng = np.random.default_rng(seed)
    low, high = env.action_space.low.astype(np.float64), env.action_space.high.astype(np.float64)
    episode = 0
    obs, info = env.reset(seed=seed)
    for _ in range(steps):
        _digest(h, obs)
        for key in sorted(info):
            h.update(key.encode() + type(info[key]).__name__.encode())
            _digest(h, info[key])
        action = (low + (high - low) * rng.random(4)).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        h.update(f"{type(reward).__name__}{reward!r}{terminated!r}{truncated!r}".encode())
        if terminated or truncated:
            _digest(h, obs)
            episode += 1
            obs, info = env.reset(seed=seed + 1000 * episode) if episode % 2 else env.reset()
    return h.hexdigest()


def _hash_td(h, td) -> None:
    for key in sorted(td.keys(include_nested=True, leaves_only=True), key=str):
        h.update(str(key).encode())
        _digest(h, td.get(key).detach().cpu().numpy())


def torchrl_hash(config: dict, normalize: bool, steps: int, seed: int, double_to_float: bool = False) -> str:
    h = hashlib.sha256()
    kwargs = dict(config)
    if "physics" in kwargs:
        kwargs["params"] = kwargs.pop("physics")
    env = make_env(4, seed=seed, normalize_actions=normalize, **kwargs)
    if double_to_float:
        env.append_transform(DoubleToFloat())
    for spec in (env.action_spec, env.observation_spec["observation"]):
        h.update(f"{spec.dtype}{tuple(spec.shape)}".encode())
        if hasattr(spec, "space") and hasattr(spec.space, "low"):
            _digest(h, spec.space.low.numpy())
            _digest(h, spec.space.high.numpy())
    h.update(str(sorted(map(str, env.observation_spec.keys(True, True)))).encode())
    gen = torch.Generator().manual_seed(seed)
    low, high = env.action_spec.space.low, env.action_spec.space.high
    td = env.reset()
    _hash_td(h, td)
    for _ in range(steps):
        td["action"] = low + (high - low) * torch.rand(env.action_spec.shape, generator=gen)
        full, td = env.step_and_maybe_reset(td)
        _hash_td(h, full)
        _hash_td(h, td)
    return h.hexdigest()


def fingerprint(steps: int, seed: int) -> tuple[dict[str, str], str]:
    sections = {}
    for name, config in CONFIGS.items():
        for normalize in (True, False):
            sections[f"gym/{name}/{'norm' if normalize else 'raw'}"] = gym_hash(config, normalize, steps, seed)
        for normalize in (False, True):
            sections[f"torchrl/{name}/{'norm' if normalize else 'raw'}"] = torchrl_hash(config, normalize, steps, seed)
    for name in ("default", "all"):
        sections[f"torchrl/{name}/double_to_float"] = torchrl_hash(CONFIGS[name], False, steps, seed, True)
    total = hashlib.sha256()
    for name, digest in sections.items():
        total.update(name.encode() + bytes.fromhex(digest))
    return sections, total.hexdigest()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=400, help="steps per rollout")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--expect", default=None, help="the total hash this run must reproduce")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    sections, total = fingerprint(args.steps, args.seed)
    report_fingerprint(sections, total, time.perf_counter() - t0, f"--steps {args.steps} --seed {args.seed}", args.expect)


if __name__ == "__main__":
    main()
