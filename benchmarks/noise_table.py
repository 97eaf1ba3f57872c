"""The execution-noise table (results/noise/): search methods under fastfiz and fastfiz_x5.

Each row is one ``python search.py <overrides>`` configuration, run in this process (Hydra's
compose API, one simulator warm-up) once with protocol P1 (per-shot success) and once with P3
(chain length until the first miss). Every run's results.json goes to
``<out>/runs/<row>_<protocol>/``; ``<out>/table.json`` and ``<out>/table.md`` collect them with
their commands, a binomial standard error for the per-shot success and the standard error of
the mean chain length.

    python benchmarks/noise_table.py --out results/noise                 # the full table
    python benchmarks/noise_table.py --out /tmp/t --only geo_h2 --budgets 400 --noises fastfiz
    python benchmarks/noise_table.py --out results/noise --only both_h2 --redo   # again, replacing its cells
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

P1 = ["protocol=p1", "protocol.n_innings={innings}", "protocol.shots={shots}"]
P3 = ["protocol=p3", "protocol.seeds={seeds}", "protocol.cap={cap}"]


def rows(budget: int, noise: str = "fastfiz") -> dict[str, list[str]]:
    """Row name -> search.py overrides (without noise, budget and protocol); the ``ranked`` rows
    play the shot ranker trained for the row's noise (results/rankers/<noise>/ranker.pt)."""
    b = budget
    geo, trained = ["proposer=geometric"], ["proposer=both"]
    h2 = ["search=h2", f"search.k1={b // 2}", "search.m1=10"]
    uniform = lambda k1: ["search=robust", "search.schedule=uniform", "search.screen=false", f"search.k1={k1}",
                          f"search.samples={b // k1}"]
    halving = ["search=robust", f"search.k1={b * 5 // 8}", "search.target=0"]  # a fixed screen
    adaptive = ["search=robust", f"search.k1={b * 3 // 4}", f"search.target={10 if b <= 400 else 20}"]
    forgiving = ["proposer=forgiving"]
    ranked = ["proposer=ranked", f"proposer.ranker=results/rankers/{noise}/ranker.pt"]
    return {
        "geo_h2": geo + h2,
        "geo_uniform_x4": geo + uniform(b // 4),
        "geo_uniform_x8": geo + uniform(b // 8),
        "geo_uniform_x16": geo + uniform(b // 16),
        "geo_halving": geo + halving,
        "forgiving_halving": forgiving + halving,
        "geo_adaptive": geo + adaptive,
        "forgiving_h2": forgiving + h2,
        "forgiving_adaptive": forgiving + adaptive,
        "geo_puct": geo + ["search=puct"],
        "both_h2": trained + h2,
        "both_uniform_x4": trained + uniform(b // 4),
        "both_halving": trained + halving,
        "both_adaptive": trained + adaptive,
        "both_puct": trained + ["search=puct"],
        "ranked_adaptive": ranked + adaptive,
    }


def run_one(overrides: list[str], out_dir: Path) -> dict:
    from hydra import compose, initialize_config_dir

    from billiards.search.run import RESULTS_FILE, run

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="search", overrides=overrides)
    run(cfg, out_dir)
    return json.loads((out_dir / RESULTS_FILE).read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/noise")
    ap.add_argument("--noises", nargs="+", default=["fastfiz", "fastfiz_x5"])
    ap.add_argument("--budgets", nargs="+", type=int, default=[400, 1600])
    ap.add_argument("--only", nargs="*", default=None, help="row names (default: all)")
    ap.add_argument("--innings", type=int, default=20)
    ap.add_argument("--shots", type=int, default=50)
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--cap", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--redo", action="store_true",
                    help="run the selected cells again and replace their records (default: skip recorded cells), "
                         "e.g. after the ensemble a row plays changed")
    args = ap.parse_args()

    from billiards.provenance import git_commit
    import billiards.search.config  # noqa: F401  (registers the search app's schemas)

    out = Path(args.out)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    table_path = out / "table.json"
    table = json.loads(table_path.read_text()) if table_path.is_file() else {"rows": []}
    done = set() if args.redo else {(r["row"], r["noise"], r["budget"]) for r in table["rows"]}
    for noise in args.noises:
        for budget in args.budgets:
            for name, over in rows(budget, noise).items():
                if args.only and name not in args.only or (name, noise, budget) in done:
                    continue
                base = over + [f"noise={noise}", f"search.budget={budget}", f"seed={args.seed}", "threads=1",
                               "progress=false", "picture=false"]
                rec = {"row": name, "noise": noise, "budget": budget}
                t0 = time.perf_counter()
                for proto, extra in (("p1", P1), ("p3", P3)):
                    o = base + [e.format(**vars(args)) for e in extra]
                    res = run_one(o, out / "runs" / f"{name}_{noise}_{budget}_{proto}")
                    rec[f"{proto}_command"] = "python search.py " + " ".join(o)
                    if proto == "p1":
                        p, n = res["extra"]["success_per_shot"], res["shots"]
                        rec.update(success=p, success_se=math.sqrt(p * (1 - p) / n), shots=n,
                                   foul=res["extra"]["foul_per_shot"], sims_per_shot=res["sims_per_decision"],
                                   ms_per_shot=res["ms_per_decision"])
                    else:
                        vals = res["values"]
                        rec.update(p3_mean=res["mean"], p3_se=res["std"] / math.sqrt(len(vals)), p3_chains=len(vals),
                                   p3_max=res["max"], p3_reached_cap=res["extra"]["reached_cap"])
                rec.update(seconds=round(time.perf_counter() - t0, 1), commit=git_commit())
                table["rows"] = [r for r in table["rows"] if (r["row"], r["noise"], r["budget"]) != (name, noise, budget)]
                table["rows"].append(rec)
                table_path.write_text(json.dumps(table, indent=2) + "\n")
                print(f"{name:18s} {noise:10s} {budget:5d}: success {100 * rec['success']:.1f} ± "
                      f"{100 * rec['success_se']:.1f}%  P3 {rec['p3_mean']:.2f} ± {rec['p3_se']:.2f}  "
                      f"({rec['sims_per_shot']:.0f} sims/shot, {rec['seconds']:.0f} s)", flush=True)
    write_md(table, out / "table.md")


def write_md(table: dict, path: Path) -> None:
    lines = ["| row | noise | sims/shot budget | per-shot success % (± s.e.) | shots | P3 chain mean (± s.e.) | chains | "
             "sims spent/shot | ms/shot |", "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(table["rows"], key=lambda r: (r["noise"], r["budget"], r["row"])):
        lines.append(f"| {r['row']} | {r['noise']} | {r['budget']} | {100 * r['success']:.1f} ± {100 * r['success_se']:.1f} | "
                     f"{r['shots']} | {r['p3_mean']:.2f} ± {r['p3_se']:.2f} | {r['p3_chains']} | "
                     f"{r['sims_per_shot']:.0f} | {r['ms_per_shot']:.1f} |")
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
