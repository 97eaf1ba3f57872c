"""Cross-check the simulator against pooltool 0.6.0 run with the same physics.

    bash benchmarks/setup_pooltool.sh                     # once: pooltool in its own venv
    python benchmarks/crosscheck_pooltool.py --n 2000 --seed 0 --out results/crosscheck_pooltool.json

Prints the share of random shots whose final positions (every ball) lie within --tol (1 mm)
of pooltool's, the share with the same carom facts (what the white touched, first contact),
and classifies every disagreement by the first place the two event histories part.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _shots import git_commit, write_json, random_shots, run_pooltool  # noqa: E402

from billiards.physics import simulate_batch, simulate_shot  # noqa: E402


def classify(ours, theirs_seq, theirs_ok) -> str:
    """Why one shot disagrees: the first difference between the white's contact sequences,
    or a later divergence of an otherwise identical story."""
    if not theirs_ok:
        return "pooltool failed"
    seq = [o for _, k, b, o in ours.events() if k == "ball_ball" and b == 0]
    theirs = [int(x) for x in theirs_seq if x >= 0]
    if seq[: len(theirs)] != theirs[: len(seq)] or (len(seq) != len(theirs) and len(theirs) < 8):
        return "different white contact sequence"
    return "same white contacts, other balls diverge"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tol", type=float, default=1e-3, help="metres")
    ap.add_argument("--out", type=Path, default=None, help="write a JSON summary here")
    args = ap.parse_args(argv)

    racks, actions = random_shots(args.n, args.seed)
    t0 = time.perf_counter()
    ref = run_pooltool(racks, actions)
    t_pt = time.perf_counter() - t0
    ours = simulate_batch(racks, actions)

    ok = ref["ok"].astype(bool)
    err = np.linalg.norm(ours.positions - ref["final_positions"], axis=-1).max(axis=-1)
    err[~ok] = np.inf
    agree = err <= args.tol
    same_facts = ok & (ours.first_contact == ref["first_contact"]) & np.all(ours.hits == ref["cue_hits"], axis=-1)
    same_outcome = ok & (ours.score == (ref["cue_hits"][:, 1] & ref["cue_hits"][:, 2] & ~ref["cue_hits"][:, 0])) \
        & (ours.foul == ref["cue_hits"][:, 0])

    classes: dict[str, list[int]] = {}
    for n in np.flatnonzero(~agree):
        res = simulate_shot(racks[n], actions[n])
        classes.setdefault(classify(res, ref["cue_ball_seq"][n], ok[n]), []).append(int(n))

    quantiles = np.quantile(err[ok], [0.5, 0.9, 0.99, 0.999, 1.0]) if ok.any() else [np.nan] * 5
    summary = {
        "command": " ".join(["python", "benchmarks/crosscheck_pooltool.py"] + (argv or sys.argv[1:])),
        "commit": git_commit(),
        "n_shots": args.n,
        "seed": args.seed,
        "tolerance_m": args.tol,
        "pooltool_failed": int((~ok).sum()),
        "share_within_tol": float(agree.mean()),
        "share_same_carom_facts": float(same_facts.mean()),
        "share_same_outcome": float(same_outcome.mean()),
        "position_error_quantiles_m": dict(zip(["p50", "p90", "p99", "p99.9", "max"], map(float, quantiles))),
        "mean_events_ours": float(ours.n_events.mean()),
        "disagreements": {k: {"count": len(v), "examples": v[:10]} for k, v in classes.items()},
        "pooltool_wall_seconds": t_pt,
    }
    print(f"{args.n} random shots, seed {args.seed}: {100 * agree.mean():.2f} % within {1e3 * args.tol:g} mm of pooltool; "
          f"{100 * same_facts.mean():.2f} % same carom facts; {100 * same_outcome.mean():.2f} % same outcome")
    print("final-position error quantiles (m):", summary["position_error_quantiles_m"])
    for k, v in classes.items():
        print(f"  disagreement: {k}: {len(v)} shots, e.g. {v[:5]}")
    write_json(args.out, summary)


if __name__ == "__main__":
    main()
