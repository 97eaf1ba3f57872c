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
import functools
import hashlib
import json
from pathlib import Path

from omegaconf import OmegaConf

from billiards import compat
from billiards.files import CHECKPOINT_FILE, EVAL_FILE, SUMMARY_FILE, display_path, save_tagged
from billiards.physics import PhysicsParams
from billiards.physics.config import params_from_config

from .checkpoint import CheckpointError, agent_from_config, config_problem, load_checkpoint

POLICY_FORMAT = "billiards-policy-1"

_build_agent = agent_from_config  # the agent a stored config describes (billiards.rl.checkpoint)


def check_policy(payload: dict, path):
    """The one place an exported policy's content is checked, after its seal (and read in today's
    form: :func:`billiards.compat.upgrade_policy_file`): its keys (a config,
    the actor's tensors; its evaluation and summary records, if any), the config plain data that
    describes networks (:func:`~billiards.rl.checkpoint.config_problem`: no interpolation, an
    algorithm of this version, positive layer widths ...), the actor's tensors real, finite and
    of the names and shapes of the actor that config builds -- compared before anything is
    loaded (a config that says 32 inputs for a 28-input actor is refused). CheckpointError
    naming the file and what is wrong; returns ``(agent, cfg)``, the agent built from the config
    with the actor's weights loaded."""
    from billiards.files import key_problem, plain_data_problem, shape_problem, tensor_problem

    def bad(why: str) -> CheckpointError:
        return CheckpointError(f"exported policy file {path} is not a usable policy: {why}")

    why = (key_problem(payload, {"config": dict, "actor": dict}) or config_problem(payload["config"])
           or next((p for key in ("eval", "summary") if (p := plain_data_problem(payload.get(key), key))), None)
           or tensor_problem(payload["actor"], "actor"))
    if why:
        raise bad(why)
    try:
        agent, cfg = agent_from_config(payload["config"])
    except CheckpointError as err:
        raise bad(str(err)) from None
    expected = {k: v.shape for k, v in agent.actor.state_dict().items()}
    if why := shape_problem(expected, payload["actor"], "actor"):
        raise bad(f"{why} (its config: algo={cfg.algo.name}, hidden_sizes={list(cfg.algo.hidden_sizes)}, "
                  f"extra_features={bool(cfg.env.get('extra_features', False))}, noise={cfg.noise.preset})")
    agent.actor.load_state_dict(payload["actor"])
    return agent, cfg


def _load_policy(path: Path):
    """``(payload, agent, cfg)`` of an exported policy file, sealed, in today's form
    (:func:`billiards.compat.upgrade_policy_file`) and checked (:func:`check_policy`)."""
    from billiards.files import load_tagged

    payload = compat.upgrade_policy_file(load_tagged(path, POLICY_FORMAT, CheckpointError, "exported policy"))
    return (payload, *check_policy(payload, path))


def _load_policy_file(path: Path) -> dict:
    """An exported policy file's payload, sealed and checked (:func:`check_policy`)."""
    return _load_policy(path)[0]


def policy_file_error(path) -> str | None:
    """Why the policy at ``path`` (an exported policy file, a run dir or its checkpoint) cannot
    be played, or None: the file loaded and checked now (its seal, then its content), e.g. by an
    app's validation before any directory is written."""
    path = Path(path)
    exported = path.is_file() and path.name != CHECKPOINT_FILE
    if exported:
        try:
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError:
            digest = None  # unreadable: the loader below says so
        if digest is not None:
            return _exported_file_error(str(path), digest)
    try:
        if exported:
            _load_policy(path)
        else:
            load_checkpoint(path.parent if path.name == CHECKPOINT_FILE else path)
    except CheckpointError as err:
        return str(err)
    return None


@functools.lru_cache(maxsize=64)
def _exported_file_error(path: str, digest: str) -> str | None:
    """:func:`policy_file_error` of the exported policy file at ``path`` whose bytes have the
    SHA-256 ``digest``: the same bytes at the same path give the same answer, so a config naming
    one file in many places (a search's proposers, a league's players) builds its agent once."""
    try:
        _load_policy(Path(path))
    except CheckpointError as err:
        return str(err)
    return None


def load_policy(path: str | Path):
    """The stochastic policy of a training run: ``path`` is a run dir, its checkpoint file or
    an exported policy file (:func:`export_policy`).

    Returns ``(policy, cfg)``: a TensorDict module reading ``"observation"`` and writing
    ``"action"`` in the training env's action space (deterministic under
    ``ExplorationType.DETERMINISTIC``, sampled under ``RANDOM``), and the run's config.
    """
    path = Path(path)
    if path.is_file() and path.name != CHECKPOINT_FILE:
        _, agent, cfg = _load_policy(path)  # the exported (evaluated) actor's weights loaded
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


def _gaussian_actors() -> tuple[str, ...]:
    """The algorithms whose actor is the tanh-Gaussian one expert iteration trains (each agent's
    ``actor_kind``, billiards.rl.learners)."""
    from .learners import AGENTS

    return tuple(name for name, agent in AGENTS.items() if agent.actor_kind == "tanh_gaussian")


def init_policy_problem(path, cfg) -> str | None:
    """Why the exported policy file at ``path`` cannot be where expert iteration's policy starts
    (``algo.init_policy`` of the training config ``cfg``), or None: the file checked on load
    (its seal, then its content), its actor the tanh-Gaussian one of the same hidden layers, its
    observation the same (carom features or not; no noise level), on the same table."""
    from billiards.files import repo_path

    path = repo_path(path)
    if not path.is_file() or path.name == CHECKPOINT_FILE:
        return f"{display_path(path)} is not an exported policy file (python -m billiards.rl.policy export <run dir>)"
    try:  # sealed and checked, once
        _, _, pcfg = _load_policy(path)
    except CheckpointError as err:
        return str(err)
    gaussian = _gaussian_actors()
    mine = {"algo": pcfg.algo.name, "hidden_sizes": list(pcfg.algo.hidden_sizes),
            "extra_features": bool(pcfg.env.get("extra_features", False)), "constrain_aim": bool(pcfg.env.constrain_aim)}
    wanted = {"algo": f"one of {', '.join(gaussian)}", "hidden_sizes": list(cfg.algo.hidden_sizes),
              "extra_features": bool(cfg.env.extra_features), "constrain_aim": True}
    differ = [f"{key}={mine[key]} (this run: {wanted[key]})" for key in mine
              if (mine[key] not in gaussian if key == "algo" else mine[key] != wanted[key])]
    if reads_level(pcfg):
        differ.append("it reads each shot's noise level (trained under variable noise)")
    if policy_physics(pcfg) != params_from_config(cfg.physics):
        differ.append(f"its table is physics={pcfg.physics.preset}'s (this run: physics={cfg.physics.preset})")
    return f"{display_path(path)} cannot start this policy: {'; '.join(differ)}" if differ else None


def policy_summary(path) -> dict:
    """The training summary an exported policy file records (``summary.json`` of its run: its
    frames, CPU seconds, ...; empty where it has none), the file checked on load."""
    from billiards.files import repo_path

    return dict(_load_policy_file(repo_path(path)).get("summary") or {})


def init_actor_state(path) -> dict:
    """The actor's weights of the exported policy file at ``path`` (checked by
    :func:`init_policy_problem`), where expert iteration's policy starts."""
    from billiards.files import repo_path

    return _load_policy_file(repo_path(path))["actor"]


def reads_level(cfg) -> bool:
    """Whether a run's policy reads each shot's noise level as its observation's last entry
    (trained under variable noise, ``noise=variable``)."""
    from billiards.physics.noise import noise_from_config

    return noise_from_config(cfg.noise).is_variable


def level_input_error(path, why: str) -> str:
    """The message for a policy that reads the level (:func:`reads_level`) where ``why`` none is given."""
    return f"policy {path} was trained under variable noise and reads each shot's level; {why}"


def policy_physics(cfg) -> PhysicsParams:
    """The table a run trained on (``cfg``: its config as :func:`load_policy` returns it, in
    today's form)."""
    return params_from_config(cfg.physics)


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
