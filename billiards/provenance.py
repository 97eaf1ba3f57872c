"""Where a result came from: the git commit it was produced at."""

from __future__ import annotations

import subprocess

from billiards.files import ROOT

__all__ = ["ROOT", "git_commit"]


def git_commit() -> str:
    """Short commit of the repository, with ``+dirty`` if tracked files under ``billiards/``
    differ from it; ``unknown`` outside a git checkout."""

    def run(*cmd: str) -> str:
        try:
            return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()
        except OSError:
            return ""

    commit = run("git", "rev-parse", "--short", "HEAD") or "unknown"
    dirty = commit != "unknown" and bool(run("git", "status", "--porcelain", "--untracked-files=no", "--", "billiards"))
    return commit + ("+dirty" if dirty else "")
