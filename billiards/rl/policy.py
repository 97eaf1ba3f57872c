"""Trained policies out of training runs, for evaluation and for search (an ensemble of them
becomes a proposer in :func:`billiards.search.proposers.load_policy_proposer`).

A policy can be loaded from a run dir, its ``checkpoint.pt`` (everything needed to resume:
networks, optimizers, replay buffer -- tens of MB), or a small exported policy file (the
actor's weights and the run's config, ~0.3 MB) written by

    python -m billiards.rl.policy export RUN_DIR [RUN_DIR ...] --out DIR

which is what the repository ships for the search proposers (``results/policies/``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from omegaconf import OmegaConf

from billiards.files import CHECKPOINT_FILE, EVAL_FILE, SUMMARY_FILE, display_path, save_tagged
from billiards.physics import PhysicsParams
from billiards import compat
from billiards.physics.config import params_from_config

from .checkpoint import CheckpointError, load_checkpoint

POLICY_FORMAT = "billiards-policy-1"


def _build_agent(config: dict):
    from billiards.envs import make_env

    from .agents import make_agent

    from billiards.physics.noise import noise_from_config

    cfg = OmegaConf.create(config)
    # only the observation and action layout matter here (no shaping, e.g. no reward model); the
    # noise adds the level to the observation when it is variable
    env = make_env(1, constrain_aim=bool(cfg.env.constrain_aim), extra_features=bool(cfg.env.extra_features),
                   noise=noise_from_config(cfg.get("noise")))
    obs_dim = env.observation_spec_unbatched["observation"].shape[-1]
    return make_agent(cfg.algo, obs_dim, env.action_spec_unbatched), cfg


def _load_policy_file(path: Path) -> dict:
    from billiards.files import load_tagged

    return load_tagged(path, POLICY_FORMAT, CheckpointError, "exported policy")


def load_policy(path: str | Path):
    """The stochastic policy of a training run: ``path`` is a run dir, its checkpoint file or
    an exported policy file (:func:`export_policy`).

    Returns ``(policy, cfg)``: a TensorDict module reading ``"observation"`` and writing
    ``"action"`` in the training env's action space (deterministic under
    ``ExplorationType.DETERMINISTIC``, sampled under ``RANDOM``), and the run's config.
    """
    path = Path(path)
    if path.is_file() and path.name != CHECKPOINT_FILE:
        state = _load_policy_file(path)
        agent, cfg = _build_agent(state["config"])
        agent.actor.load_state_dict(state["actor"])  # the exported (evaluated) actor
        policy = agent.policy
    else:
        run_dir = path.parent if path.name == CHECKPOINT_FILE else path
        state = load_checkpoint(run_dir)
        agent, cfg = _build_agent(state["config"])
        agent.load_state_dict(state["agent"])
        policy = agent.eval_policy  # the averaged actor when algo.actor_ema > 0
    agent.eval()
    return policy, cfg


def export_policy(run_dir: str | Path, out: str | Path) -> Path:
    """Write the policy of a finished run (the evaluated actor's weights, config, final
    evaluation and summary) to ``out``, a few hundred kB instead of the full checkpoint."""
    run_dir, out = Path(run_dir), Path(out)
    state = load_checkpoint(run_dir)
    agent, _ = _build_agent(state["config"])
    agent.load_state_dict(state["agent"])
    read = lambda name: json.loads((run_dir / name).read_text()) if (run_dir / name).is_file() else None
    payload = {
        "format": POLICY_FORMAT,
        "config": state["config"],
        # the actor the run's evaluations measure: the averaged one when algo.actor_ema > 0
        "actor": {k: v.clone() for k, v in agent.eval_actor.state_dict().items()},
        "eval": read(EVAL_FILE),
        "summary": read(SUMMARY_FILE),
        "source": display_path(run_dir),
    }
    return save_tagged(out, payload)


def reads_level(cfg) -> bool:
    """Whether a run's policy reads each shot's noise level as its observation's last entry
    (trained under variable noise, ``noise=variable``)."""
    from billiards.physics.noise import noise_from_config

    return noise_from_config(cfg.get("noise")).is_variable


def level_input_error(path, why: str) -> str:
    """The message for a policy that reads the level (:func:`reads_level`) where ``why`` none is given."""
    return f"policy {path} was trained under variable noise and reads each shot's level; {why}"


def policy_physics(cfg) -> PhysicsParams:
    """The table a run trained on (runs saved before the presets existed: ``international``)."""
    return params_from_config(compat.saved_physics_node(cfg))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m billiards.rl.policy", description="Export small policy files from training runs.")
    sub = parser.add_subparsers(dest="command", required=True)
    ex = sub.add_parser("export", help="write <out>/<prefix>seed<k>.pt for each run dir")
    ex.add_argument("runs", nargs="+", type=Path)
    ex.add_argument("--out", type=Path, required=True)
    ex.add_argument("--prefix", default="")
    args = parser.parse_args(argv)
    for run in args.runs:
        try:
            seed = OmegaConf.create(load_checkpoint(run)["config"]).seed
            path = export_policy(run, args.out / f"{args.prefix}seed{seed}.pt")
        except CheckpointError as err:
            raise SystemExit(f"Error: {err}") from None
        print(f"{run} -> {path} ({path.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
