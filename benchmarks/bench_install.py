"""What installing the package costs, measured from scratch: the wheel and the sdist (built by
``python -m build``), a fresh virtual environment with the pinned torch and the wheel, its size, the
first use's compile, and ``sagu evaluate`` on a whole track for a NumPy agent from outside the
repository (the first run, which compiles, and a second, cached).

    python benchmarks/bench_install.py --out results/install/footprint.json

Needs network access to the package index (or pip's cache) as any install does; takes a few minutes.
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

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

AGENT = "import numpy as np\n\n\ndef act(obs):\n    return np.tile(np.array([0.5, 1.0, 0.0, 0.0], dtype=np.float32), (len(obs), 1))\n"


def timed(cmd: list[str], **kwargs) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, **kwargs)
    if proc.returncode != 0:
        raise SystemExit(f"failed ({proc.returncode}): {' '.join(cmd)}\n{(proc.stdout + proc.stderr)[-3000:]}")
    return time.perf_counter() - t0, proc.stdout + proc.stderr


def size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file() and not p.is_symlink())


def main() -> None:
    from billiards.provenance import cpu, git_commit

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="write the figures here as JSON")
    parser.add_argument("--track", default="p1-exact-v1")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench_install_"))
    fig: dict = {"commit": git_commit(), "cpu": cpu(), "python": sys.version.split()[0],
                 "load_before": round(os.getloadavg()[0], 2)}
    fig["build_s"], _ = timed([sys.executable, "-m", "build", "--outdir", str(work / "dist"), str(REPO)])
    wheel = next((work / "dist").glob("*.whl"))
    sdist = next((work / "dist").glob("*.tar.gz"))
    fig["wheel"], fig["wheel_bytes"], fig["sdist_bytes"] = wheel.name, wheel.stat().st_size, sdist.stat().st_size
    env = work / "env"
    py = str(env / "bin" / "python")
    fig["venv_s"], _ = timed([sys.executable, "-m", "venv", str(env)])
    fig["torch_install_s"], _ = timed([py, "-m", "pip", "install", "-q", "torch==2.13.0"])
    fig["wheel_install_s"], _ = timed([py, "-m", "pip", "install", "-q", str(wheel)])
    fig["env_bytes"] = size(env)
    site = Path(subprocess.run([py, "-c", "import billiards, pathlib; print(pathlib.Path(billiards.__file__).parent)"],
                               capture_output=True, text=True, check=True).stdout.strip())
    fig["package_bytes"] = size(site)
    outside = work / "outside"
    outside.mkdir()
    (outside / "agent.py").write_text(AGENT)
    sagu = str(env / "bin" / "sagu")
    cache = {**os.environ, "NUMBA_CACHE_DIR": str(work / "numba")}  # an empty cache: the first use
    fig["first_compile_s"], said = timed([py, "-c", "from billiards.physics.warmup import warm_up; warm_up()"], env=cache,
                                        cwd=outside)
    fig["first_compile_said"] = [line for line in said.splitlines() if "compil" in line]
    cold = {**os.environ, "NUMBA_CACHE_DIR": str(work / "numba_evaluate")}
    for key, environ in (("evaluate_first_s", cold), ("evaluate_cached_s", cold)):
        fig[key], _ = timed([sagu, "evaluate", f"track={args.track}", "agent=agent.py:act", "name=numpy-straight",
                             f"out=runs/{key}"], env=environ, cwd=outside)
    fig["track"] = args.track
    fig = {k: round(v, 1) if isinstance(v, float) else v for k, v in fig.items()}
    text = json.dumps(fig, indent=2)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
