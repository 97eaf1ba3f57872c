"""Trained policies out of training checkpoints, for evaluation and as search proposers."""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

from .checkpoint import load_checkpoint
from .config import CHECKPOINT_FILE


def load_policy(path: str | Path):
    """The stochastic policy of a training run: ``path`` is a run dir or its checkpoint file.

    Returns ``(policy, cfg)``: a TensorDict module reading ``"observation"`` and writing
    ``"action"`` in the training env's action space (deterministic under
    ``ExplorationType.DETERMINISTIC``, sampled under ``RANDOM``), and the run's config.
    """
    from billiards.envs import make_env

    from .agents import make_agent
    from .train import env_kwargs

    path = Path(path)
    run_dir = path.parent if path.name == CHECKPOINT_FILE else path
    state = load_checkpoint(run_dir)
    cfg = OmegaConf.create(state["config"])
    env = make_env(1, **env_kwargs(cfg))
    obs_dim = env.observation_spec_unbatched["observation"].shape[-1]
    agent = make_agent(cfg.algo, obs_dim, env.action_spec_unbatched)
    agent.load_state_dict(state["agent"])
    agent.eval()
    return agent.policy, cfg


def load_policy_proposer(paths, name: str = "policy"):
    """A :class:`billiards.search.PolicyProposer` over the policies of several runs (e.g. the
    three seeds of one Table 5 variant); they must share the observation and action layout."""
    from billiards.search import PolicyProposer

    loaded = [load_policy(p) for p in paths]
    layouts = {(bool(c.env.constrain_aim), bool(c.env.extra_features)) for _, c in loaded}
    if len(layouts) != 1:
        raise ValueError(f"proposer {name!r}: checkpoints mix observation/action layouts {sorted(layouts)}")
    constrain_aim, extra_features = layouts.pop()
    return PolicyProposer([p for p, _ in loaded], constrain_aim=constrain_aim, extra_features=extra_features, name=name)
