"""Pictures of a player's shots: play an inning with a baseline, a trained policy or a search
run, and draw it with :mod:`billiards.render` (which only draws).

API:
* :func:`play_inning` -- the shots a policy plays in one continue-on-miss inning;
* :func:`load_player` -- a baseline, a trained policy or a search run, ready to play;
* :func:`main` -- the command line.

Command line::

    python -m billiards.pictures shot --out shot.png --seed 0 --policy nearest
    python -m billiards.pictures inning --out inning.gif --seed 0 --policy nearest --max-shots 5
    python -m billiards.pictures inning --out inning.gif --policy results/policies/base/seed0.pt   # a trained policy
    python -m billiards.pictures shot --out shot.png --policy outputs/search/<date>/<run>             # a search run
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from billiards import domain
from billiards.files import CONFIG_FILE
from billiards.physics import DEFAULT_PARAMS, DEFAULT_PRESET, PRESETS, PhysicsParams
from billiards.render import outcome_text, render_inning, render_shot


def play_inning(
    policy,
    *,
    start: str = "random",
    seed: int = 0,
    max_shots: int = 10,
    constrain_aim: bool = False,
    extra_features: bool = False,
    positions=None,
    params: PhysicsParams = DEFAULT_PARAMS,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Play one continue-on-miss inning with ``policy`` (deterministic) in a B = 1 env.

    Returns the shots as (positions (4, 2) before the shot, raw action (theta, p, a, b)); with
    ``constrain_aim`` the policy's u is mapped to the theta that was played.
    """
    import torch
    from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

    from billiards.envs import make_env, reset_to

    env = make_env(1, start=start, on_miss="continue", max_shots=max_shots, constrain_aim=constrain_aim,
                   extra_features=extra_features, seed=seed, params=params)
    td = reset_to(env, positions) if positions is not None else env.reset()
    shots = []
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        for _ in range(max_shots):
            td = policy(td)
            pos = td["positions"][0].numpy().copy()
            act = td["action"][0].numpy().astype(np.float64)
            if constrain_aim:
                act[0] = domain.constrained_theta(pos, act[0], env.base_env.params.ball_radius)
            shots.append((pos, act))
            td = step_mdp(env.step(td))
    return shots


def _is_search_run(path: Path) -> bool:
    return path.is_dir() and (path / CONFIG_FILE).is_file() and "proposer" in (path / CONFIG_FILE).read_text()


def load_player(spec: str, seed: int = 0, constrain_aim: bool = False):
    """What plays the inning of a picture: ``"nearest"`` or ``"random"`` (the baselines), a
    trained policy (a training run dir, its checkpoint.pt or an exported policy file), or a
    search run dir (``search.py``'s output: its proposer and search, rebuilt from its config,
    in whatever form the run saved it).

    Returns ``(policy, constrain_aim, extra_features, physics)``: a TensorDict module reading
    the env's keys and writing ``"action"``, the layers it needs, and the table it was made on
    (None for the baselines, which play on any table)."""
    if spec in ("nearest", "random"):
        from billiards.baselines import make_policy

        return make_policy(spec, constrain_aim=constrain_aim, seed=seed), constrain_aim, False, None
    path = Path(spec)
    if not path.exists():
        raise SystemExit(f"Error: --policy {spec!r}: not nearest, random, or an existing run dir / policy file")
    if _is_search_run(path):
        from billiards.physics.config import params_from_config
        from billiards.search.config import saved_config
        from billiards.search.run import make_actor, make_proposer

        cfg = saved_config(path)
        params = params_from_config(cfg.physics)
        actor = make_actor(cfg, make_proposer(cfg.proposer, params), params)
        return actor, False, False, params
    from billiards.rl.policy import level_input_error, load_policy, policy_physics, reads_level

    policy, cfg = load_policy(path)
    if reads_level(cfg):
        raise ValueError(level_input_error(path, "pictures play exact shots and tell none"))
    return policy, bool(cfg.env.constrain_aim), bool(cfg.env.extra_features), policy_physics(cfg)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m billiards.pictures", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="what", required=True)
    for name, help_ in [("shot", "PNG of the first shot of an inning"), ("inning", "animated GIF of an inning")]:
        p = sub.add_parser(name, help=help_)
        p.add_argument("--out", required=True, help="output file (.png for shot, .gif for inning)")
        p.add_argument("--seed", type=int, default=0, help="rack seed (and the random policy's seed)")
        p.add_argument("--policy", default="nearest",
                       help="nearest | random | a training run dir, checkpoint or exported policy | a search run dir")
        p.add_argument("--start", choices=["random", "canonical"], default="random")
        p.add_argument("--constrain-aim", action="store_true", help="play the policy through the aim constraint")
        p.add_argument("--dpi", type=int, default=100 if name == "shot" else 80)
        p.add_argument("--physics", default=None, choices=sorted(PRESETS),
                       help=f"the table (default: the policy's own, else {DEFAULT_PRESET})")
        if name == "inning":
            p.add_argument("--max-shots", type=int, default=10)
            p.add_argument("--fps", type=int, default=15)
            p.add_argument("--speed", type=float, default=2.0, help="simulated seconds per second of GIF")
    args = parser.parse_args(argv)
    policy, constrain_aim, extra_features, made_on = load_player(args.policy, args.seed, args.constrain_aim)
    params = PRESETS[args.physics] if args.physics else (made_on or DEFAULT_PARAMS)
    if made_on is not None:
        from billiards.physics.config import warn_physics_mismatch

        warn_physics_mismatch(f"--policy {args.policy}", made_on, params)
    n_shots = 1 if args.what == "shot" else args.max_shots
    shots = play_inning(policy, start=args.start, seed=args.seed, max_shots=n_shots, constrain_aim=constrain_aim,
                        extra_features=extra_features, params=params)
    name = Path(args.policy).name if made_on is not None else f"{args.policy} policy"
    if args.what == "shot":
        pos, act = shots[0]
        result = render_shot(pos, act, args.out, params=params, dpi=args.dpi,
                             title=f"{name}, {args.start} rack, seed {args.seed}, {params.describe()}")
        print(f"{args.out}: {outcome_text(result)}")
    else:
        n = render_inning(shots, args.out, params=params, fps=args.fps, speed=args.speed, dpi=args.dpi,
                          title=f"{name}: ")
        print(f"{args.out}: {len(shots)} shots, {n} frames")


if __name__ == "__main__":
    main()
