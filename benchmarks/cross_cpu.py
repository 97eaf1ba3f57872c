"""Same bits on any x86-64 CPU? Everything between a committed model and a cited number, run
side by side under the settings in which one machine differs from another.

    python benchmarks/cross_cpu.py [--out results/cross_cpu.json] [--chains 2] [--cap 600]

Each setting runs in fresh interpreters with one environment variable changed:

* ``OPENBLAS_CORETYPE`` = Prescott, Sandybridge, Haswell, SkylakeX, Zen (and unset): the BLAS
  kernel NumPy's matmuls would take on another processor;
* ``NUMBA_CPU_NAME=generic``: numba compiling for a baseline x86-64 instead of this host;
* ``NPY_DISABLE_CPU_FEATURES``: NumPy's own loops for a CPU without AVX2 / AVX-512;
* ``GLIBC_TUNABLES`` without FMA and AVX2: the C library's ``exp``, ``sin``, ``atan2`` ...
  variants of a processor older than x86-64-v3 (pre-2013 Intel, pre-2015 AMD). Outside the
  promise (the simulator itself calls those functions); measured and reported as such.

and prints, per setting: the simulator's fingerprint (``kernel_fingerprint.py``), both envs'
fingerprint (``env_fingerprint.py``), a fingerprint of the trained proposer ensemble, the shot
ranker and the elementary functions on fixed inputs, and the lengths of a few Table 6 chains
(``search.py proposer=base search=h2 protocol=p3``, the trained ensemble's chains, chaotic in
every bit). A row equal to the default row everywhere is marked ``same``.

``--training`` instead trains ``python train.py budget=smoke seed=0`` under torch's own CPU
switches (``ATEN_CPU_CAPABILITY`` avx2 / default, ``MKL_CBWR=COMPATIBLE``: the code paths
another processor's torch would take) and reports the first logged step whose losses or
evaluations differ from the default run's: training is not promised bit-identical across CPUs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

VARIABLES = ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "NUMBA_CPU_NAME", "NPY_DISABLE_CPU_FEATURES", "GLIBC_TUNABLES")
NO_FMA = "glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4,-AVX512F,-AVX"
SETTINGS = {  # name -> (environment, inside the promise)
    "default": ({}, True),
    **{f"openblas_{k.lower()}": ({"OPENBLAS_CORETYPE": k}, True) for k in ("Prescott", "Sandybridge", "Haswell", "SkylakeX", "Zen")},
    "numba_generic": ({"NUMBA_CPU_NAME": "generic"}, True),
    "numpy_no_avx2": ({"NPY_DISABLE_CPU_FEATURES": "AVX512_ICL AVX512_SPR X86_V4 X86_V3"}, True),
    "glibc_no_fma": ({"GLIBC_TUNABLES": NO_FMA}, False),
}

PROBE = """
import hashlib, numpy as np
from billiards import domain, numerics
from billiards.physics import random_racks
from billiards.search.proposers import load_policy_proposer
from billiards.search.ranker import RankedProposer, ShotRanker
rng = np.random.default_rng(0)
pos = random_racks(rng, 256)
h = hashlib.sha256()
p = load_policy_proposer([f"results/policies/near_miss/seed{s}.pt" for s in range(3)])
h.update(p.propose(pos, 48, np.random.default_rng(1)).tobytes())
ranked = RankedProposer(ShotRanker.load("results/rankers/fastfiz/ranker.pt"), pool=2000)
h.update(ranked.propose(pos[:32], 16, np.random.default_rng(2)).tobytes())
x = rng.uniform(-3, 3, 1 << 16)
for f in (numerics.asin, numerics.exp, numerics.log1p, numerics.tanh, numerics.sin, numerics.cos):
    h.update(f(np.clip(x, -1, 1) if f is numerics.asin else x).tobytes())
h.update(numerics.atan2(x, x[::-1]).tobytes())
h.update(domain.observation(pos, True).tobytes() + domain.aim_window(pos)[1].tobytes())
print(h.hexdigest())
"""


def _env(extra: dict) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in VARIABLES}
    env.update(extra, PYTHONPATH=str(ROOT), NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    return env


def _run(cmd: list[str], env: dict) -> str:
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800)
    if proc.returncode != 0:
        raise SystemExit(f"failed ({proc.returncode}): {' '.join(cmd)}\n{proc.stderr[-3000:]}")
    return proc.stdout


def _total(output: str) -> str:
    return next(line.split()[1] for line in output.splitlines() if line.startswith("TOTAL"))


def measure(extra: dict, chains: int, cap: int) -> dict:
    env = _env(extra)
    py = sys.executable
    row = {"kernel": _total(_run([py, "benchmarks/kernel_fingerprint.py", "--shots", "5000"], env))[:16],
           "envs": _total(_run([py, "benchmarks/env_fingerprint.py", "--steps", "200"], env))[:16],
           "networks": _run([py, "-c", PROBE], env).strip().splitlines()[-1][:16]}
    with tempfile.TemporaryDirectory() as tmp:
        for proposer in ("base", "near_miss"):
            _run([py, "search.py", f"proposer={proposer}", "search=h2", "protocol=p3", f"protocol.seeds={chains}",
                  f"protocol.cap={cap}", "seed=0", "threads=1", "progress=false", "picture=false",
                  "hydra.output_subdir=null", "hydra/job_logging=stdout", f"hydra.run.dir={tmp}/{proposer}"], env)
            row[f"chains_{proposer}"] = [int(v) for v in json.loads(Path(tmp, proposer, "results.json").read_text())["values"]]
    return row


TRAINING = {"default": {}, "aten_avx2": {"ATEN_CPU_CAPABILITY": "avx2"}, "aten_baseline": {"ATEN_CPU_CAPABILITY": "default"},
            "mkl_compatible": {"MKL_CBWR": "COMPATIBLE"}}


def training_rows() -> dict:
    """``train.py budget=smoke seed=0`` per torch setting: the metrics rows (timings dropped) and the
    final evaluation, and the first step that differs from the default run's."""
    import csv

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, extra in TRAINING.items():
            run = Path(tmp, name)
            _run([sys.executable, "train.py", "budget=smoke", "seed=0", "threads=1", "progress=false",
                  "hydra/job_logging=stdout", f"hydra.run.dir={run}"], _env(extra))
            with (run / "metrics.csv").open(newline="") as f:
                rows = [{k: v for k, v in r.items() if k not in ("wall_time", "cpu_time", "fps", "ups")} for r in csv.DictReader(f)]
            out[name] = {"settings": extra, "rows": rows, "eval_mean": json.loads((run / "eval.json").read_text())["mean"]}
    ref = out["default"]["rows"]
    for r in out.values():
        r["first_difference_at_step"] = next((int(float(a["step"])) for a, b in zip(ref, r["rows"]) if a != b), None)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=None, help="write the rows as JSON here (e.g. results/cross_cpu.json)")
    ap.add_argument("--chains", type=int, default=2, help="Table 6 P3 chains per proposer (default 2)")
    ap.add_argument("--cap", type=int, default=600, help="their cap (default 600)")
    ap.add_argument("--only", nargs="*", default=None, help=f"settings (default all: {', '.join(SETTINGS)})")
    ap.add_argument("--training", action="store_true", help="compare smoke training runs under torch's CPU switches instead")
    args = ap.parse_args(argv)
    if args.training:
        rows = training_rows()
        print(f"{'torch setting':<18} {'environment':<36} {'final eval':<11} first differing step")
        for name, r in rows.items():
            first = r["first_difference_at_step"]
            print(f"{name:<18} {str(r['settings']):<36} {r['eval_mean']:<11} {'identical' if first is None else first}")
            del r["rows"]
        if args.out is not None:
            _write(args.out, argv, {"training": rows})
        return 0
    names = args.only or list(SETTINGS)
    if "default" not in names:
        names = ["default", *names]
    rows, t0 = {}, time.perf_counter()
    for name in names:
        extra, promised = SETTINGS[name]
        rows[name] = {"settings": extra, "promised": promised, **measure(extra, args.chains, args.cap)}
    ref = rows["default"]
    keys = ("kernel", "envs", "networks", "chains_base", "chains_near_miss")
    print(f"{'setting':<22} {'simulator':<17} {'envs':<17} {'networks':<17} {'chains base':<14} {'chains near_miss':<17} verdict")
    for name, r in rows.items():
        r["same"] = all(r[k] == ref[k] for k in keys)
        verdict = "reference" if name == "default" else ("same" if r["same"] else "DIFFERENT")
        verdict += "" if r["promised"] else " (outside the promise)"
        print(f"{name:<22} {r['kernel']:<17} {r['envs']:<17} {r['networks']:<17} {str(r['chains_base']):<14} "
              f"{str(r['chains_near_miss']):<17} {verdict}")
    broken = [n for n, r in rows.items() if r["promised"] and not r["same"]]
    print(f"{len(rows)} settings in {time.perf_counter() - t0:.0f} s; "
          + ("every promised setting gives the default's bits" if not broken else f"DIFFERENT: {', '.join(broken)}"))
    if args.out is not None:
        _write(args.out, argv, {"chains": args.chains, "cap": args.cap, "rows": rows})
    return 1 if broken else 0


def _write(out: Path, argv, payload: dict) -> None:
    from billiards.files import atomic_write_text
    from billiards.provenance import cpu, git_commit

    cmd = "python benchmarks/cross_cpu.py" + "".join(f" {a}" for a in (argv if argv is not None else sys.argv[1:]))
    atomic_write_text(out, json.dumps({"command": cmd, "commit": git_commit(), "cpu": cpu(), **payload}, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    sys.exit(main())
