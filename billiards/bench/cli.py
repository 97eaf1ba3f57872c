"""The body of ``python evaluate.py`` (the entry point only composes the config)."""

from __future__ import annotations

import sys

from billiards.files import recorded_command


def run(cfg, out_dir: str) -> dict:
    from billiards.device import set_threads

    from .config import build_agent
    from .run import EvaluationError, evaluate

    if cfg.threads is not None:
        set_threads(cfg.threads)
    command = " ".join(recorded_command(["python", *sys.argv]))
    try:
        return evaluate(build_agent(cfg), cfg.track, out=out_dir, limit=cfg.limit, progress=cfg.progress, command=command,
                        group=cfg.group, spec=cfg.agent)
    except EvaluationError as err:
        raise SystemExit(f"Error: {err}") from None
    except KeyboardInterrupt:
        raise SystemExit(f"interrupted: the finished units are kept in {out_dir}; the same command with out={out_dir} "
                         f"continues") from None


__all__ = ["run"]
