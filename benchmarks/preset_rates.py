"""Score and foul rates of random shots on each physics preset (issue #15's table).

    python benchmarks/preset_rates.py --n 20000 --seed 0 --out results/preset_rates

For every preset (``korean_medium``, the paper's table and the default; ``international``) and
both starts (the preset's random racks; its opening rack), plays ``--n`` one-shot trials of
two random policies and prints the share of shots that score, foul and hit the shot-time
limit:

* uniform: (theta, p, a, b) uniform in the raw action box [0, 2pi) x [0, 1] x [-1, 1]^2;
* aimed: theta uniform inside the aim-constraint window of the nearest red
  (:func:`billiards.domain.constrained_theta` with u ~ U[-1, 1]), p, a, b as above.

Rates come with their binomial standard error. Writes ``OUT.json`` and ``OUT.md``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from billiards import domain
from billiards.physics import PRESETS, canonical_rack, random_racks, simulate_batch
from billiards.provenance import git_commit


def trials(params, start: str, policy: str, n: int, rng: np.random.Generator) -> dict:
    """One cell of the table: n shots of ``policy`` from ``start`` racks on ``params``."""
    racks = random_racks(rng, n, params) if start == "random" else np.broadcast_to(canonical_rack(params), (n, 4, 2)).copy()
    acts = rng.uniform(domain.ACTION_LOW, domain.ACTION_HIGH, (n, 4))
    if policy == "aimed":
        acts[:, 0] = domain.constrained_theta(racks, rng.uniform(-1.0, 1.0, n), params.ball_radius)
    t0 = time.perf_counter()
    res = simulate_batch(racks, acts, params)
    seconds = time.perf_counter() - t0

    def rate(x):
        p = float(np.mean(x))
        return {"pct": 100 * p, "se_pct": 100 * float(np.sqrt(p * (1 - p) / n))}

    return {"score": rate(res.score), "foul": rate(res.foul), "timed_out": rate(res.timed_out),
            "n": n, "seconds": round(seconds, 3)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=20_000, help="shots per cell")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="write OUT.json and OUT.md")
    args = ap.parse_args(argv)
    command = "python " + " ".join(shlex.quote(a) for a in sys.argv)
    rows = []
    for name, params in PRESETS.items():
        for start in ("random", "opening"):
            for policy in ("uniform", "aimed"):
                rng = np.random.default_rng([args.seed, len(rows)])
                cell = trials(params, "random" if start == "random" else "canonical", policy, args.n, rng)
                rows.append({"physics": name, "start": start, "policy": policy, **cell})
                print(f"{name:>14} {start:>7} rack {policy:>7} shots: score {cell['score']['pct']:5.2f} % "
                      f"± {cell['score']['se_pct']:.2f}, foul {cell['foul']['pct']:5.2f} % ± {cell['foul']['se_pct']:.2f}, "
                      f"12 s limit {cell['timed_out']['pct']:.2f} %")
    if args.out is None:
        return
    args.out.parent.mkdir(parents=True, exist_ok=True)
    commit = git_commit()
    args.out.with_suffix(".json").write_text(json.dumps({"command": command, "commit": commit, "rows": rows}, indent=2) + "\n")
    lines = [
        "# Random shots on each physics preset",
        "",
        f"{args.n:,} shots per row (seed {args.seed}). uniform: (theta, p, a, b) uniform in the raw action box; "
        "aimed: theta uniform inside the aim-constraint window of the nearest red, p, a, b uniform. "
        "random rack: the preset's random racks; opening rack: its canonical rack. ± is the binomial standard error. "
        "limit: shots stopped by the preset's shot-time limit (12 s on korean_medium, none on international).",
        "",
        f"Command: `{command}`  ",
        f"Commit: `{commit}`",
        "",
        "| physics | rack | shots | score (%) | foul (%) | limit (%) |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['physics']} | {r['start']} | {r['policy']} | {r['score']['pct']:.2f} ± {r['score']['se_pct']:.2f} | "
                     f"{r['foul']['pct']:.2f} ± {r['foul']['se_pct']:.2f} | {r['timed_out']['pct']:.2f} |")
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out.with_suffix('.json')} and {args.out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
