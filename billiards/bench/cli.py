"""The body of ``python evaluate.py`` (the entry point only composes the config)."""

from __future__ import annotations

import sys

from billiards.files import recorded_command


def run(cfg, out_dir: str, job_overrides: list[str] | None = None) -> dict:
    """Evaluate the config's agent on its track into ``out_dir``; then say where the scorecard
    would rank on the committed leaderboard (a limited run with its caveat), and, without
    ``name=``, what the scorecard names the agent (a submission needs a name). A job of a
    multirun (``job_overrides``: its own overrides) records the command that plays it alone."""
    from billiards.device import set_threads

    from .config import build_agent
    from .leaderboard import placement_line
    from .run import EvaluationError, evaluate

    if cfg.threads is not None:
        set_threads(cfg.threads)
    argv = sys.argv if job_overrides is None else [sys.argv[0], *job_overrides]
    command = " ".join(recorded_command(["python", *argv]))
    try:
        card = evaluate(build_agent(cfg), cfg.track, out=out_dir, limit=cfg.limit, progress=cfg.progress, command=command,
                        group=cfg.group, spec=cfg.agent)
    except EvaluationError as err:
        raise SystemExit(f"Error: {err}") from None
    except KeyboardInterrupt:
        raise SystemExit(f"interrupted: the finished units are kept in {out_dir}; the same command with out={out_dir} "
                         f"continues") from None
    if cfg.progress and not card.get("partial"):
        print(placement_line(card), flush=True)
        if not cfg.name:
            print(f"name: the scorecard names the agent {card['agent']['name']!r} (from its spec); a submission to the "
                  f"leaderboard needs name=<your agent's name>", flush=True)
    return card


__all__ = ["run"]
