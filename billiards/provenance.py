"""Where a result came from: the git commit it was produced at, and the processor a timing was taken on."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from billiards.files import ROOT, recorded_command

__all__ = ["ROOT", "STARTS_FILE", "cpu", "git_commit", "record_start"]

STARTS_FILE = "starts.jsonl"  # one line per start of a run in its directory: the commit it ran under


def git_commit() -> str:
    """Short commit of the repository, with ``+dirty`` if tracked files under ``billiards/``
    differ from it; for an installed package (no checkout), its release (``sagu-bench==X.Y.Z``);
    ``unknown`` in a source tree outside git."""
    from billiards.files import IN_CHECKOUT

    if not IN_CHECKOUT:
        from billiards import __version__

        return f"sagu-bench=={__version__}"

    def run(*cmd: str) -> str:
        try:
            return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()
        except OSError:
            return ""

    commit = run("git", "rev-parse", "--short", "HEAD") or "unknown"
    dirty = commit != "unknown" and bool(run("git", "status", "--porcelain", "--untracked-files=no", "--", "billiards"))
    return commit + ("+dirty" if dirty else "")


def cpu() -> str:
    """The processor a benchmark ran on, for its record: the model name, its widest vector
    extension and the cores this process may use (timings, and their ratios, depend on all
    three; "unknown" where /proc/cpuinfo cannot be read)."""
    name, flags = "unknown", set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and name == "unknown":
                name = value.strip()
            elif key.strip() == "flags" and not flags:
                flags = set(value.split())
    except OSError:
        pass
    vector = next((v for v, need in (("avx512f", {"avx512f"}), ("avx2+fma", {"avx2", "fma"})) if need <= flags),
                  "no avx2" if flags else "flags unknown")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{name} ({vector}, {cores} cores)"


def record_start(run_dir, mode: str, frames: int = 0, command: list[str] | None = None) -> dict:
    """Append a start record to ``<run_dir>/starts.jsonl``: the commit, the UTC time, ``mode``
    (fresh, resume), the frames done before it and the command (default: this process's command
    line; an app under a launcher passes its own, ``python train.py <overrides>``), recorded
    repo-relative. A run resumed under other code thus lists every commit it ran under."""
    record = {"commit": git_commit(), "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
              "mode": mode, "frames": int(frames), "command": recorded_command(command or ["python", *sys.argv])}
    path = Path(run_dir) / STARTS_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as f:
        f.write(json.dumps(record) + "\n")
    return record
