"""Shared by the physics benchmarks: random shots, and running them in the pooltool oracle."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from billiards.physics import DEFAULT_PARAMS, PhysicsParams, action_to_cue, random_racks
from billiards.provenance import cpu, git_commit  # noqa: F401  (re-exported for the benchmarks)

ROOT = Path(__file__).resolve().parent.parent
POOLTOOL_PY = Path(os.environ.get("POOLTOOL_VENV", ROOT / ".venv-pooltool")) / "bin" / "python"


def random_shots(n: int, seed: int, params: PhysicsParams = DEFAULT_PARAMS):
    """n random racks of params's table (its own sampling) and actions over its whole range:
    theta U[0, 2pi), p U[0.05, 1], a, b U[-1, 1] (the simulator projects (a, b) onto the unit
    disk and scales it by params.max_english, so tip offsets cover the preset's whole disk)."""
    rng = np.random.default_rng(seed)
    racks = random_racks(rng, n, params)
    actions = np.column_stack([
        rng.uniform(0, 2 * np.pi, n), rng.uniform(0.05, 1.0, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n),
    ])
    return racks, actions


def pooltool_physics(params: PhysicsParams = DEFAULT_PARAMS) -> dict:
    """params as pooltool_oracle.py's --physics values (pooltool's names: u_sp_proportionality
    = mu_sp / R, cue_M the cue mass). Raises ValueError naming a field the oracle's fixed engine
    (equal-mass restitution ball-ball, no squirt, 1e-6 m make_kiss spacer) cannot reproduce.
    max_time and max_events have no pooltool counterpart: callers handle them."""
    unsupported = {"squirt": False, "ball_ball": "restitution", "min_dist": 1e-6}
    for field, want in unsupported.items():
        if getattr(params, field) != want:
            raise ValueError(f"the pooltool oracle runs with {field}={want!r}; these physics have "
                             f"{field}={getattr(params, field)!r}")
    return dict(
        table_w=params.table_width, table_l=params.table_length, cushion_height=params.cushion_height,
        R=params.ball_radius, m=params.ball_mass, u_s=params.u_slide, u_r=params.u_roll,
        u_sp_proportionality=params.u_spin / params.ball_radius, e_b=params.e_ball, e_c=params.e_cushion,
        f_c=params.f_cushion, g=params.g, cue_M=params.cue_mass,
    )


def run_pooltool(racks: np.ndarray, actions: np.ndarray, repeat: int = 1,
                 params: PhysicsParams = DEFAULT_PARAMS, selfcheck: bool = False) -> dict:
    """Simulate the shots in pooltool 0.6.0 with params's table, balls, cue and tip offsets
    (see pooltool_oracle.py); with selfcheck, the oracle first runs its hand checks on those
    physics and a failure stops here."""
    if not POOLTOOL_PY.exists():
        sys.exit(f"pooltool venv not found at {POOLTOOL_PY}: run `bash benchmarks/setup_pooltool.sh` first")
    cue = action_to_cue(actions, params)
    with tempfile.TemporaryDirectory() as tmp:
        inp, out, phys = Path(tmp) / "in.npz", Path(tmp) / "out.npz", Path(tmp) / "physics.json"
        np.savez(inp, positions=racks, V0=cue[:, 0], phi_deg=np.degrees(cue[:, 1]), a=cue[:, 2], b=cue[:, 3])
        phys.write_text(json.dumps(pooltool_physics(params)))
        cmd = [str(POOLTOOL_PY), str(ROOT / "benchmarks" / "pooltool_oracle.py"), str(inp), str(out),
               "--physics", str(phys), "--threads", "1", "--repeat", str(repeat), "--quiet"]
        subprocess.run(cmd + ["--selfcheck"] * selfcheck, check=True)
        with np.load(out, allow_pickle=False) as data:
            return {k: data[k] for k in data.files if k != "error"}


def write_json(path: Path | None, summary: dict) -> None:
    """Write a benchmark's summary (which names its command and commit) to path, if given."""
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(summary, indent=2) + "\n")
    print("wrote", path)


def report_fingerprint(sections: dict[str, str], total: str, seconds: float, settings: str, expect: str | None,
                       width: int = 40) -> None:
    """Print a fingerprint's section hashes and its total; exit 1 if ``expect`` is given and differs."""
    for name, digest in sections.items():
        print(f"{name:{width}s} {digest}")
    print(f"{'TOTAL':{width}s} {total}   ({seconds:.0f} s, {settings})")
    if expect is not None and expect != total:
        print("MISMATCH: expected", expect)
        sys.exit(1)
