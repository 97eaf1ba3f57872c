"""What the safe checkpoint format costs: save and load time of a SAC training checkpoint
(``billiards.rl.checkpoint``: serialised in memory, SHA-256 over the payload, atomic write;
``weights_only=True`` load after the checksum) against a bare atomic ``torch.save`` /
``torch.load(weights_only=True)`` of the same state (format 1's way, without checksum), side
by side.

The state is what a SAC run at the default width checkpoints: the agent (actor, twin critics,
targets, temperature) and its Adam state after some updates, a replay buffer of ``--rows``
rows (observation 32 floats, as with ``env=aim_features``), the counters and every RNG state.
Both ways write to and read from the same directory; they run interleaved, ``--repeats``
times, and the medians are printed, so both see the same machine load.

    python benchmarks/checkpoint_io.py                                   # 100k rows, ~1 minute
    python benchmarks/checkpoint_io.py --rows 100000 --out results/checkpoint_io.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "benchmarks")]  # this checkout's billiards, and update_cost


def training_state(rows: int, obs_dim: int = 32) -> dict:
    """A SAC checkpoint's content with a filled buffer of ``rows`` rows."""
    import numpy as np
    from update_cost import make_agent, random_batch

    from billiards.rl.checkpoint import rng_state

    agent = make_agent(256, obs_dim)
    batch = random_batch(256, obs_dim)
    for _ in range(3):  # Adam state for every parameter
        agent.update(batch)
    buffer = random_batch(rows, obs_dim)
    return {
        "config": {"seed": 0, "algo": {"name": "sac"}},
        "agent": agent.state_dict(),
        "agent_extra": agent.state_dict_extra(),
        "buffer": {"data": buffer.to_dict(), "rows": rows, "writer": {"_cursor": rows, "_write_count": rows}},
        "counters": {"frames": rows, "owed": 0.0, "next_log": rows, "next_eval": rows, "next_ckpt": rows},
        "eval_history": [],
        "rng": rng_state(np.random.default_rng(0)),
        "wandb_id": None,
        "stage_log": [],
    }


def bare_save(directory: Path, state: dict) -> Path:
    """What format 1 did: torch.save straight into a temporary file, fsync, rename."""
    import torch

    from billiards.files import atomic_open

    path = directory / "bare.pt"
    with atomic_open(path, "wb") as f:
        torch.save(state, f)
    return path


def bare_load(directory: Path) -> dict:
    import torch

    return torch.load(directory / "bare.pt", map_location="cpu", weights_only=True)


def timed(fn, *args) -> float:
    t0 = time.perf_counter()
    fn(*args)
    return 1e3 * (time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=int, default=100_000, help="replay-buffer rows in the checkpoint")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="also write the figures as JSON")
    args = parser.parse_args(argv)

    import torch

    from billiards.files import atomic_write_text
    from billiards.provenance import git_commit
    from billiards.rl.checkpoint import load_checkpoint, save_checkpoint

    torch.set_num_threads(args.threads)
    state = training_state(args.rows)
    times: dict[str, list[float]] = {k: [] for k in ("bare_save", "bare_load", "safe_save", "safe_load")}
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for _ in range(args.repeats):
            times["bare_save"].append(timed(bare_save, d, state))
            times["safe_save"].append(timed(save_checkpoint, d, state))
            times["bare_load"].append(timed(bare_load, d))
            times["safe_load"].append(timed(load_checkpoint, d))
        sizes = {"bare": (d / "bare.pt").stat().st_size, "safe": (d / "checkpoint.pt").stat().st_size}
    ms = {k: round(statistics.median(v), 1) for k, v in times.items()}
    result = {
        "command": "python benchmarks/checkpoint_io.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "commit": git_commit(),
        "rows": args.rows,
        "repeats": args.repeats,
        "threads": args.threads,
        "mb": {k: round(v / 1e6, 2) for k, v in sizes.items()},
        "ms_median": ms,
        "save_ratio": round(ms["safe_save"] / ms["bare_save"], 2),
        "load_ratio": round(ms["safe_load"] / ms["bare_load"], 2),
    }
    print(f"checkpoint with {args.rows:,} buffer rows: {result['mb']['safe']:.1f} MB "
          f"(bare torch.save {result['mb']['bare']:.1f} MB); medians of {args.repeats}")
    print(f"  save: {ms['safe_save']:8.1f} ms  vs bare {ms['bare_save']:8.1f} ms  (x{result['save_ratio']})")
    print(f"  load: {ms['safe_load']:8.1f} ms  vs bare {ms['bare_load']:8.1f} ms  (x{result['load_ratio']})")
    if args.out:
        atomic_write_text(args.out, json.dumps(result, indent=2) + "\n")
    return result


if __name__ == "__main__":
    main()
