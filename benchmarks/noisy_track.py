"""The noisy track's baselines (results/noisy_track/): agents under execution noise.

Rows are agents, columns noise settings. Each search agent is one ``python search.py
<overrides>`` configuration, run in this process (Hydra's compose API) once with protocol P1
(per-shot success, continue-on-miss from random racks) and once with P3 (chains from the opening
rack until the first miss); a trained policy (``sac``: the runs of ``--sac``, each seed
evaluated and the seeds pooled) is evaluated with the same two protocols by
:func:`billiards.evaluation.evaluate_policy` (P1: random-start innings; P3: innings from the opening
rack, the points before the first miss, capped at ``--cap``). Two tables:

* ``--table``: the noise presets ``fastfiz``, ``fastfiz_x5`` and ``variable`` (a level drawn per
  shot from [0, 5] and told to the agent);
* ``--figure``: ``noise=fastfiz noise.scale=m`` for the multipliers m of ``--scales``, and the
  figure (per-shot success and mean P3 chain against m, one line per agent).

Every cell's command is recorded; a recorded cell is skipped unless ``--redo``.

    python benchmarks/noisy_track.py --out results/noisy_track --table --figure --seed 3
    python benchmarks/noisy_track.py --out /tmp/t --table --only ranked --innings 2 --shots 5 --chains 3
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# agent -> search.py overrides (under every noise); "sac" is evaluated separately. The last two
# play the noise preset's shot proposer (proposer=for_noise_<preset>: the shot ranker of the
# preset, the fastfiz one under noise=fastfiz noise.scale=m, from a pool of 500; SHOT_PROPOSER):
# "ranked" with the robust search blind to the leave, "position" the noise's default search (the
# position-aware one)
AGENTS = {
    "h2": ["proposer=geometric", "search=h2"],
    "robust": ["proposer=geometric", "search=robust"],
    "ranked": ["search=robust"],
    "position": [],
}
SHOT_PROPOSER = ("ranked", "position")
TABLE_NOISES = {"fastfiz": ["noise=fastfiz"], "fastfiz_x5": ["noise=fastfiz_x5"], "variable": ["noise=variable"]}
P3_SEEDS = 10_000  # P3's chains: seeds P3_SEEDS + seed, ... (apart from every P1 seed and the tuning chains 0-99)
EXACT_ONLY = ("h2",)  # the searches that plan without noise: the only ones at multiplier 0 (robust refuses exact play)


def run_search(overrides: list[str], out_dir: Path) -> dict:
    from hydra import compose, initialize_config_dir

    from billiards.search.run import RESULTS_FILE, run

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="search", overrides=overrides)
    run(cfg, out_dir)
    return json.loads((out_dir / RESULTS_FILE).read_text())


def noise_of(noise_over: list[str]):
    """The noise model (and, for ``variable``, None) a cell's overrides name, via the search app's config."""
    from hydra import compose, initialize_config_dir

    from billiards.physics.noise import noise_from_config

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="search", overrides=noise_over)
    return noise_from_config(cfg.noise)


def search_cell(agent: str, noise: str, noise_over: list[str], args, out: Path) -> dict:
    preset = next(o.split("=", 1)[1] for o in noise_over if o.startswith("noise="))
    shot = [f"proposer=for_noise_{preset}"] if agent in SHOT_PROPOSER else []
    base = AGENTS[agent] + noise_over + shot + ["threads=1", "progress=false", "picture=false"]
    rec = {}
    for proto, extra in (("p1", ["protocol=p1", f"protocol.n_innings={args.innings}", f"protocol.shots={args.shots}",
                                 f"seed={args.seed}"]),
                         ("p3", ["protocol=p3", f"protocol.seeds={args.chains}", f"protocol.cap={args.cap}",
                                 f"seed={P3_SEEDS + args.seed}"])):
        o = base + extra
        res = run_search(o, out / "runs" / f"{agent}_{noise}_{proto}")
        rec[f"{proto}_command"] = "python search.py " + " ".join(o)
        if proto == "p1":
            rec.update(success=res["extra"]["success_per_shot"], shots=res["shots"],
                       ms_per_shot=res["ms_per_decision"], sims_per_shot=res["sims_per_decision"])
        else:
            rec.update(p3_values=res["values"])
    return rec


def blind(policy):
    """A policy trained without the noise level in its observation, played under variable
    noise: it sees the observation less its last entry (the level the env appends)."""

    def act(td):
        sub = td.clone(False)
        sub.set("observation", td.get("observation")[..., :-1])
        td.set("action", policy(sub).get("action"))
        return td

    return act


def sac_cell(noise: str, noise_over: list[str], args) -> dict:
    """The trained policies of ``--sac`` (run dirs), each evaluated; seeds pooled."""
    from billiards.evaluation import evaluate_policy
    from billiards.rl.policy import load_policy

    model = noise_of(noise_over)
    success, chains, shots = [], [], 0
    for run in args.sac:
        policy, cfg = load_policy(ROOT / run if not Path(run).is_absolute() else Path(run))
        if model.is_variable and not cfg.noise.preset == "variable":
            policy = blind(policy)
        kw = dict(constrain_aim=bool(cfg.env.constrain_aim), extra_features=bool(cfg.env.extra_features), noise=model)
        p1 = evaluate_policy(policy, n_innings=args.innings, max_shots=args.shots, start="random", seed=args.seed, **kw)
        p3 = evaluate_policy(policy, n_innings=args.chains, max_shots=args.cap, start="canonical", seed=P3_SEEDS + args.seed, **kw)
        success.append(p1.success_per_shot_pct / 100.0)
        shots += args.innings * args.shots
        chains += list(p3.first_miss_points)
    return {"success": float(np.mean(success)), "shots": shots, "p3_values": chains, "runs": list(args.sac),
            "command": f"billiards.evaluation.evaluate_policy(policy of each run, n_innings={args.innings}, max_shots="
                       f"{args.shots}, random start, seed={args.seed}) and (n_innings={args.chains}, max_shots={args.cap}, "
                       f"canonical start, seed={P3_SEEDS + args.seed}) under {' '.join(noise_over)}"}


def finish(rec: dict) -> dict:
    p, n = rec["success"], rec["shots"]
    v = np.asarray(rec.pop("p3_values"), dtype=float)
    rec.update(success_se=math.sqrt(p * (1 - p) / n), p3_mean=float(v.mean()),
               p3_se=float(v.std() / math.sqrt(len(v))), p3_chains=int(len(v)), p3_max=float(v.max()))
    return rec


def fill(name: str, cells: dict[str, list[str]], agents: list[str], args, out: Path) -> dict:
    from billiards.provenance import git_commit

    path = out / f"{name}.json"
    table = json.loads(path.read_text()) if path.is_file() else {"rows": []}
    done = set() if args.redo else {(r["agent"], r["noise"]) for r in table["rows"]}
    for noise, noise_over in cells.items():
        for agent in agents:
            if (agent, noise) in done or (noise == "x0" and agent not in EXACT_ONLY + ("sac",)):
                continue
            t0 = time.perf_counter()
            rec = sac_cell(noise, noise_over, args) if agent == "sac" else search_cell(agent, noise, noise_over, args, out)
            rec = finish({"agent": agent, "noise": noise, **rec})
            rec.update(seconds=round(time.perf_counter() - t0, 1), commit=git_commit())
            table["rows"] = [r for r in table["rows"] if (r["agent"], r["noise"]) != (agent, noise)] + [rec]
            path.write_text(json.dumps(table, indent=2) + "\n")
            print(f"{name}: {agent:9s} {noise:12s} success {100 * rec['success']:.1f} ± {100 * rec['success_se']:.1f} %"
                  f"  P3 {rec['p3_mean']:.2f} ± {rec['p3_se']:.2f} ({rec['seconds']:.0f} s)", flush=True)
    return table


def write_md(table: dict, path: Path, columns: list[str]) -> None:
    from billiards.report.markdown import md_table

    agents = list(dict.fromkeys(r["agent"] for r in table["rows"]))
    cell = {(r["agent"], r["noise"]): r for r in table["rows"]}
    body = []
    for a in agents:
        row = [a]
        for c in columns:
            r = cell.get((a, c))
            row.append("—" if r is None else f"{100 * r['success']:.1f} ± {100 * r['success_se']:.1f} · "
                                              f"{r['p3_mean']:.2f} ± {r['p3_se']:.2f}")
        body.append(row)
    path.write_text(md_table(["agent"] + columns, body) + "\n")


def plot(table: dict, scales: list[float], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cell = {(r["agent"], r["noise"]): r for r in table["rows"]}
    agents = list(dict.fromkeys(r["agent"] for r in table["rows"]))
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for a in agents:
        xs = [m for m in scales if (a, f"x{m:g}") in cell]
        rs = [cell[(a, f"x{m:g}")] for m in xs]
        axes[0].errorbar(xs, [100 * r["success"] for r in rs], [100 * r["success_se"] for r in rs], marker="o", label=a)
        axes[1].errorbar(xs, [r["p3_mean"] for r in rs], [r["p3_se"] for r in rs], marker="o", label=a)
    axes[0].set(xlabel="noise multiplier (x fastfiz sigmas)", ylabel="per-shot success % (P1)")
    axes[1].set(xlabel="noise multiplier (x fastfiz sigmas)", ylabel="mean P3 chain (shots)", yscale="log")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/noisy_track")
    ap.add_argument("--table", action="store_true", help="the presets table (fastfiz, fastfiz_x5, variable)")
    ap.add_argument("--figure", action="store_true", help="the multiplier sweep and its figure")
    ap.add_argument("--scales", nargs="+", type=float, default=[0, 0.5, 1, 2, 3, 5])
    ap.add_argument("--only", nargs="*", default=None, help="agents (default: all, sac if --sac names runs)")
    ap.add_argument("--sac", nargs="*", default=[], help="training run dirs of the sac baseline")
    ap.add_argument("--innings", type=int, default=20)
    ap.add_argument("--shots", type=int, default=50)
    ap.add_argument("--chains", type=int, default=100)
    ap.add_argument("--cap", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--redo", action="store_true", help="run the selected cells again (default: skip recorded ones)")
    args = ap.parse_args()

    import billiards.search.config  # noqa: F401  (registers the search app's schemas)

    out = Path(args.out)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    agents = (["sac"] if args.sac else []) + list(AGENTS)
    agents = [a for a in agents if not args.only or a in args.only]
    if args.table:
        table = fill("table", TABLE_NOISES, agents, args, out)
        write_md(table, out / "table.md", list(TABLE_NOISES))
    if args.figure:
        cells = {f"x{m:g}": ["noise=fastfiz", f"noise.scale={m:g}"] for m in args.scales}
        table = fill("figure", cells, agents, args, out)
        write_md(table, out / "figure.md", list(cells))
        plot(table, args.scales, out / "figure.png")


if __name__ == "__main__":
    main()
