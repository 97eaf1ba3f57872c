"""This checkout's simulator against another git revision's, on the same natural shots: how
many results differ bit for bit, and the kernel time of each, measured interleaved in one run.

    NUMBA_NUM_THREADS=1 python benchmarks/compare_physics.py --rev main --out results/compare_physics.json

For every preset: --shots random racks with uniform actions (theta, p, a, b), and --chains
innings of --chain-len shots, each shot starting from the previous one's rest positions (each
revision plays its own innings). A shot differs if any output of the kernel (rest positions,
outcome integers, closest gaps, duration) differs. The revision's ``billiards/physics`` is
read with ``git show`` into a temporary package; timing is the compiled kernel
(``run_batch_serial``, one thread) on the single shots, best of --repeat, alternating the two.
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This checkout's benchmarks and package first, so the figures come from the code (and the
# commit) of the checkout the script lives in, not from another installed copy of billiards.
HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]
from _shots import ROOT, git_commit, write_json  # noqa: E402

from billiards.physics import PRESETS, random_racks  # noqa: E402
from billiards.physics import core as this_core  # noqa: E402


def load_revision(rev: str, into: Path):
    """Import ``billiards/physics`` of git revision rev as a package in directory into; its core."""
    names = subprocess.run(["git", "ls-tree", "--name-only", f"{rev}:billiards/physics"], cwd=ROOT,
                           capture_output=True, text=True)
    if names.returncode != 0:
        raise SystemExit(f"--rev {rev!r}: no billiards/physics there ({names.stderr.strip()})")
    pkg = into / "rev_physics"
    pkg.mkdir()
    for name in names.stdout.split():
        if name.endswith(".py"):
            text = subprocess.run(["git", "show", f"{rev}:billiards/physics/{name}"], cwd=ROOT,
                                  capture_output=True, text=True, check=True).stdout
            (pkg / name).write_text(text)
    sys.path.insert(0, str(into))
    return importlib.import_module("rev_physics.core")


def run(core, racks, actions, p):
    n = racks.shape[0]
    out = (np.empty((n, 4, 2)), np.empty((n, core.N_OUT_INT), np.int64), np.empty((n, core.N_OUT_FLOAT)))
    core.run_batch_serial(racks, actions, p, *out)
    return out


def differ(a, b) -> np.ndarray:
    """(N,) mask of the shots whose outputs differ (columns both revisions have)."""
    mask = np.zeros(a[0].shape[0], bool)
    for x, y in zip(a, b):
        k = min(x.shape[-1], y.shape[-1])
        mask |= ~np.all((x[..., :k] == y[..., :k]).reshape(x.shape[0], -1), axis=1)
    return mask


def uniform_actions(rng, n):
    return np.column_stack([rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)])


def compare(rev_core, params, args) -> dict:
    p = params.array
    rng = np.random.default_rng(args.seed)
    racks, acts = random_racks(rng, args.shots, params), uniform_actions(rng, args.shots)
    single = differ(run(rev_core, racks, acts, p), run(this_core, racks, acts, p))
    a = b = random_racks(rng, args.chains, params)
    chained, first = 0, []
    for step in range(args.chain_len):
        act = uniform_actions(rng, args.chains)
        ra, rb = run(rev_core, a, act, p), run(this_core, b, act, p)
        d = differ(ra, rb)
        chained += int(d.sum())
        first += [(step, int(i)) for i in np.flatnonzero(d)[:3]]
        a, b = ra[0], rb[0]
    best = {"rev": np.inf, "this": np.inf}
    for _ in range(args.repeat):
        for name, core in (("rev", rev_core), ("this", this_core)):
            t0 = time.perf_counter()
            run(core, racks, acts, p)
            best[name] = min(best[name], time.perf_counter() - t0)
    return {"single_changed": int(single.sum()), "single_shots": args.shots,
            "single_changed_index": np.flatnonzero(single)[:10].tolist(),
            "chained_changed": chained, "chained_shots": args.chains * args.chain_len,
            "chained_changed_first": first[:10],
            "rev_shots_per_s": args.shots / best["rev"], "this_shots_per_s": args.shots / best["this"],
            "time_ratio_this_over_rev": best["this"] / best["rev"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rev", default="main", help="git revision to compare against")
    ap.add_argument("--shots", type=int, default=20000)
    ap.add_argument("--chains", type=int, default=2000)
    ap.add_argument("--chain-len", type=int, default=10)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--seed", type=int, default=123)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    if min(args.shots, args.chains, args.chain_len, args.repeat) < 1:
        raise SystemExit("--shots, --chains, --chain-len and --repeat must be >= 1")
    rev_commit = subprocess.run(["git", "rev-parse", "--short", args.rev], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        rev_core = load_revision(args.rev, Path(tmp))
        results = {name: compare(rev_core, params, args) for name, params in PRESETS.items()}
    print(f"this checkout {git_commit()} against {args.rev} ({rev_commit}), kernel on one thread")
    for name, r in results.items():
        print(f"{name:14s} single shots changed {r['single_changed']} of {r['single_shots']}, chained "
              f"{r['chained_changed']} of {r['chained_shots']} (first: {r['chained_changed_first'][:3]}); "
              f"{r['rev_shots_per_s']:.0f} vs {r['this_shots_per_s']:.0f} shots/s, time ratio "
              f"{r['time_ratio_this_over_rev']:.3f}")
    if args.out:
        argv_used = argv if argv is not None else sys.argv[1:]
        write_json(args.out, {"command": " ".join(["python", "benchmarks/compare_physics.py"] + argv_used),
                              "commit": git_commit(), "rev": args.rev, "rev_commit": rev_commit, "seed": args.seed,
                              "presets": results})


if __name__ == "__main__":
    main()
