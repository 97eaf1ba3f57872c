"""Cross-check the simulator against pooltool 0.6.0 run with the same physics, on one preset.

    bash benchmarks/setup_pooltool.sh                     # once: pooltool in its own venv
    python benchmarks/crosscheck_pooltool.py --physics korean_medium --n 2000 --seed 0 \
        --out results/crosscheck_pooltool_korean_medium.json
    python benchmarks/crosscheck_pooltool.py --physics international --n 2000 --seed 0 \
        --out results/crosscheck_pooltool_international.json

pooltool gets the preset's table (BilliardTableSpecs l, w, cushion_height), ball values, cue
mass and tip offsets (see pooltool_oracle.py); the random shots come from the preset's own
random racks and cover its whole action range (tip offsets over the whole disk, the rim
included). pooltool has no shot-length limit, so our side runs with max_time = inf; the
output says how many shots the preset's limit would have stopped early, on both sides.

Prints the share of shots whose final positions (every ball) lie within --tol (1 mm) of
pooltool's, the share with the same carom facts (what the white touched, first contact), and
classifies every disagreement by the first place the two event histories part.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

# This checkout's benchmarks and package first, so the figures come from the code (and the
# commit) of the checkout the script lives in, not from another installed copy of billiards.
HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]
from _shots import git_commit, pooltool_physics, random_shots, run_pooltool, write_json  # noqa: E402

from billiards.physics import DEFAULT_PRESET, PRESETS, simulate_batch, simulate_shot  # noqa: E402


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


def shot_limit(params, ours_limited, ref) -> dict:
    """How the preset's shot-length limit relates to this comparison (run without it)."""
    if math.isinf(params.max_time):
        return {"max_time_s": "inf", "note": "the preset runs every shot to rest, like pooltool"}
    return {
        "max_time_s": params.max_time,
        "note": "pooltool has no shot limit: our side ran with max_time = inf; every shot is compared",
        "shots_over_limit_ours": int(ours_limited.timed_out.sum()),
        "shots_over_limit_pooltool": int((ref["sim_time"] > params.max_time).sum()),
        "longest_shot_s_pooltool": float(np.nanmax(ref["sim_time"])),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--physics", choices=sorted(PRESETS), default=DEFAULT_PRESET,
                    help=f"physics preset (default {DEFAULT_PRESET})")
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tol", type=float, default=1e-3, help="metres")
    ap.add_argument("--out", type=Path, default=None, help="write a JSON summary here")
    args = ap.parse_args(argv)

    params = PRESETS[args.physics]
    unlimited = dataclasses.replace(params, max_time=math.inf)
    racks, actions = random_shots(args.n, args.seed, params)
    t0 = time.perf_counter()
    ref = run_pooltool(racks, actions, params=params, selfcheck=True)
    t_pt = time.perf_counter() - t0
    ours = simulate_batch(racks, actions, unlimited)
    limit = shot_limit(params, simulate_batch(racks, actions, params), ref)

    ok = ref["ok"].astype(bool)
    err = np.linalg.norm(ours.positions - ref["final_positions"], axis=-1).max(axis=-1)
    err[~ok] = np.inf
    agree = err <= args.tol
    same_facts = ok & (ours.first_contact == ref["first_contact"]) & np.all(ours.hits == ref["cue_hits"], axis=-1)
    same_outcome = ok & (ours.score == (ref["cue_hits"][:, 1] & ref["cue_hits"][:, 2] & ~ref["cue_hits"][:, 0])) \
        & (ours.foul == ref["cue_hits"][:, 0])

    classes: dict[str, list[int]] = {}
    for n in np.flatnonzero(~agree):
        res = simulate_shot(racks[n], actions[n], unlimited)
        classes.setdefault(classify(res, ref["cue_ball_seq"][n], ok[n]), []).append(int(n))

    tip = np.hypot(actions[:, 2], actions[:, 3])
    quantiles = np.quantile(err[ok], [0.5, 0.9, 0.99, 0.999, 1.0]) if ok.any() else [np.nan] * 5
    summary = {
        "command": " ".join(["python", "benchmarks/crosscheck_pooltool.py"] + (argv or sys.argv[1:])),
        "commit": git_commit(),
        "physics": args.physics,
        "physics_params": params.to_dict(),
        "pooltool_physics": pooltool_physics(params),
        "pooltool_selfcheck": "passed",
        "shot_limit": limit,
        "n_shots": args.n,
        "seed": args.seed,
        "actions": (f"racks: random_racks of the preset; theta U[0, 2pi), p U[0.05, 1], (a, b) U[-1, 1]^2 "
                    f"projected onto the unit disk, times max_english = {params.max_english} R"),
        "shots_at_max_english": int((tip >= 1.0).sum()),  # (a, b) projected onto the rim: offset = max_english R
        "tip_offsets_pulled_in_for_pooltool": int(ref["offset_pulled_in"].sum()),
        "tolerance_m": args.tol,
        "pooltool_failed": int((~ok).sum()),
        "share_within_tol": float(agree.mean()),
        "share_same_carom_facts": float(same_facts.mean()),
        "share_same_outcome": float(same_outcome.mean()),
        "position_error_quantiles_m": dict(zip(["p50", "p90", "p99", "p99.9", "max"], map(float, quantiles))),
        "mean_events_ours": float(ours.n_events.mean()),
        "longest_shot_s_ours": float(ours.duration.max()),
        "score_rate_ours": float(ours.score.mean()),
        "disagreements": {k: {"count": len(v), "examples": v[:10]} for k, v in classes.items()},
        "pooltool_wall_seconds": t_pt,
    }
    print(f"{args.physics}: {args.n} random shots, seed {args.seed}: {100 * agree.mean():.2f} % within "
          f"{1e3 * args.tol:g} mm of pooltool; {100 * same_facts.mean():.2f} % same carom facts; "
          f"{100 * same_outcome.mean():.2f} % same outcome; {int((~ok).sum())} pooltool failures")
    print("final-position error quantiles (m):", summary["position_error_quantiles_m"])
    print("shot limit:", limit)
    for k, v in classes.items():
        print(f"  disagreement: {k}: {len(v)} shots, e.g. {v[:5]}")
    write_json(args.out, summary)


if __name__ == "__main__":
    main()
