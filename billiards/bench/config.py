"""``python evaluate.py``'s configuration (``conf/evaluate.yaml``): a typed schema, checked
before anything is written: the track exists, the agent spec builds (code is imported only from
a spec on the command line), the output directory is free or holds this very evaluation."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from omegaconf import MISSING, DictConfig, OmegaConf

from billiards.app_config import ValidatingCallback, numeric_bound_errors, register_app
from billiards.files import run_folder_names


@dataclass
class EvaluateConfig:
    track: str = "p1-exact-v1"  # a track of billiards.bench.tracks (python evaluate.py --help lists them)
    agent: str = MISSING  # the agent spec (docs/benchmark.md): file.py:act, module:act, a .pt policy, search:h2, league:greedy, ...
    name: Optional[str] = None  # the agent's name on its scorecard and row, required to submit (default: from the spec, never a path)
    group: Optional[str] = None  # the leaderboard row it pools into (training seeds of one setting)
    limit: Optional[int] = None  # only the first N innings / chains / matches per opponent (a quick look, not a leaderboard entry)
    out: Optional[str] = None  # the run directory (default outputs/evaluate/<track>/<date>/<time>); the same out resumes
    threads: Optional[int] = 1  # simulator and torch threads (1: the timings are one core's)
    progress: bool = True


register_app("evaluate_schema", EvaluateConfig, {})

_BUILT: dict = {}  # (agent, track, limit, name) -> the agent validation built, reused by the run


def build_agent(cfg):
    """The agent of a config, built once a process."""
    from .adapters import resolve_agent
    from .tracks import get_track

    key = (cfg.agent, cfg.track, cfg.limit, cfg.name)
    if key not in _BUILT:
        track = get_track(cfg.track)
        _BUILT[key] = resolve_agent(cfg.agent, track.scaled(cfg.limit) if cfg.limit else track, cfg.name)
    return _BUILT[key]


def errors(cfg) -> list[str]:
    """Every problem of an evaluate config, each a sentence naming its key."""
    from .adapters import AgentError
    from .run import IDENTITY_FILE, EvaluationError, out_problem, read_identity
    from .tracks import TRACKS

    errs = numeric_bound_errors(cfg) if isinstance(cfg, DictConfig) else []
    if OmegaConf.is_missing(cfg, "agent"):
        return ["agent=<spec> is required (docs/benchmark.md: file.py:act, package.module:act, a .pt policy or training run "
                "dir, sb3:<algo>:<model.zip>, search:<search>[/<proposer>], league:<player>, random, nearest, random_aim)"]
    if cfg.track not in TRACKS:
        return [f"track={cfg.track!r} is not a track; tracks: {', '.join(TRACKS)}"]
    if cfg.limit is not None and not 1 <= cfg.limit <= TRACKS[cfg.track].units:
        errs.append(f"limit must lie in 1..{TRACKS[cfg.track].units} for {cfg.track}, got {cfg.limit}")
    if cfg.threads is not None and not 1 <= cfg.threads <= 256:
        errs.append(f"threads must lie in 1..256, got {cfg.threads}")
    out = cfg.get("out")
    if out and not errs:  # before anything is built (the agent's code imported) or written
        path = Path(out)
        why = out_problem(out)
        if why is not None:
            errs.append(why)
        elif path.is_dir() and os.path.lexists(path / IDENTITY_FILE):  # read_identity refuses a link, a FIFO ...
            try:
                read_identity(path)
            except EvaluationError as err:
                errs.append(f"out={out}: {err}")
        elif path.is_dir() and run_folder_names(path):
            errs.append(f"out={out}: not empty and holds no evaluation; choose an empty or new directory")
    if errs:
        return errs
    try:
        build_agent(cfg)
    except (AgentError, EvaluationError) as err:
        return [str(err)]
    return errs


def validate(cfg) -> None:
    errs = errors(cfg)
    if errs:
        raise ValueError("invalid evaluate config:\n  - " + "\n  - ".join(errs))


class ValidateEvaluateConfig(ValidatingCallback):
    """Hydra callback (conf/evaluate.yaml): :func:`validate` before Hydra creates the run directory."""

    validate = staticmethod(validate)


def tracks_help() -> str:
    from .tracks import track_help

    return track_help()


OmegaConf.register_new_resolver("billiards.help_tracks", tracks_help, replace=True)

__all__ = ["EvaluateConfig", "ValidateEvaluateConfig", "build_agent", "errors", "validate"]
