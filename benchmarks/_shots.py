"""Shared by the physics benchmarks: random shots, and running them in the pooltool oracle."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from billiards.physics import action_to_cue, random_racks
from billiards.provenance import git_commit  # noqa: F401  (re-exported for the benchmarks)

ROOT = Path(__file__).resolve().parent.parent
POOLTOOL_PY = Path(os.environ.get("POOLTOOL_VENV", ROOT / ".venv-pooltool")) / "bin" / "python"


def random_shots(n: int, seed: int):
    """n uniform random racks and actions: theta U[0, 2pi), p U[0.05, 1], a, b U[-1, 1]."""
    rng = np.random.default_rng(seed)
    racks = random_racks(rng, n)
    actions = np.column_stack([
        rng.uniform(0, 2 * np.pi, n), rng.uniform(0.05, 1.0, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n),
    ])
    return racks, actions


def run_pooltool(racks: np.ndarray, actions: np.ndarray, repeat: int = 1) -> dict:
    """Simulate the shots in pooltool 0.6.0 with the same physics (see pooltool_oracle.py)."""
    if not POOLTOOL_PY.exists():
        sys.exit(f"pooltool venv not found at {POOLTOOL_PY}: run `bash benchmarks/setup_pooltool.sh` first")
    cue = action_to_cue(actions)
    with tempfile.TemporaryDirectory() as tmp:
        inp, out = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(inp, positions=racks, V0=cue[:, 0], phi_deg=np.degrees(cue[:, 1]), a=cue[:, 2], b=cue[:, 3])
        cmd = [str(POOLTOOL_PY), str(ROOT / "benchmarks" / "pooltool_oracle.py"), str(inp), str(out),
               "--threads", "1", "--repeat", str(repeat), "--quiet"]
        subprocess.run(cmd, check=True)
        with np.load(out, allow_pickle=False) as data:
            return {k: data[k] for k in data.files if k != "error"}


def write_json(path: Path | None, summary: dict) -> None:
    """Write a benchmark's summary (which names its command and commit) to path, if given."""
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(summary, indent=2) + "\n")
    print("wrote", path)
