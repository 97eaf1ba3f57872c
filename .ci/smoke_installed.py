"""The installed package, used from outside the repository (.ci/run runs it with the python of a
fresh environment holding only the wheel, in an empty folder): each agent kind on a tiny limit,
the placement line, a search over a shipped ensemble, a Hydra multirun on the joblib launcher,
the other commands' help. Exits non-zero on the first thing that fails.

    python .ci/smoke_installed.py            # with the environment's python, from any folder
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

AGENT = '''import numpy as np
import torch
from tensordict.nn import TensorDictModule


def act(obs):
    """A full-power shot straight along the table's long axis, whatever the table."""
    return np.tile(np.array([0.5, 1.0, 0.0, 0.0], dtype=np.float32), (len(obs), 1))


class Straight(torch.nn.Module):
    def forward(self, obs):
        return torch.tensor([0.5, 1.0, 0.0, 0.0]).expand(obs.shape[0], 4)


net = Straight()  # a plain torch module: observation tensor -> action tensor
module = TensorDictModule(Straight(), in_keys=["observation"], out_keys=["action"])  # a TorchRL module
'''


def sagu(*args: str, expect: tuple[str, ...] = (), cwd: Path, code: int = 0) -> str:
    exe = shutil.which("sagu", path=str(Path(sys.executable).parent))
    if exe is None:
        raise SystemExit(f"FAIL: no `sagu` command beside {sys.executable}")
    t0 = time.perf_counter()
    proc = subprocess.run([exe, *args], cwd=cwd, capture_output=True, text=True, timeout=900)
    out = proc.stdout + proc.stderr
    print(f"$ sagu {' '.join(args)}   ({time.perf_counter() - t0:.1f} s, exit {proc.returncode})", flush=True)
    missing = [e for e in expect if e not in out]
    if proc.returncode != code or missing:
        raise SystemExit(f"FAIL: exit {proc.returncode}, missing {missing}\n{out[-4000:]}")
    shown = [line for line in out.splitlines() if line.strip() and "%|" not in line]
    print("  " + "\n  ".join(shown[-4:]), flush=True)
    return out


def main() -> None:
    import billiards
    from billiards import files

    where = Path(billiards.__file__).resolve().parent
    if files.IN_CHECKOUT or "site-packages" not in where.parts:
        raise SystemExit(f"FAIL: billiards imported from {where}, not from an installed wheel")
    print(f"billiards {billiards.__version__} from {where}; data in {files.ROOT}")
    with tempfile.TemporaryDirectory() as tmp:
        cwd = Path(tmp)
        (cwd / "my_agent.py").write_text(AGENT)
        sagu("--version", expect=(f"sagu-bench {billiards.__version__}",), cwd=cwd)
        for command in ("evaluate", "train", "search", "match", "view", "leaderboard"):
            sagu(command, "--help", cwd=cwd)
        limited = ("limit=1",)
        runs = [("p1-exact-v1", "my_agent.py:act", "smoke-numpy"), ("innings-v1", "my_agent.py:net", "smoke-torch"),
                ("p1-x5-v1", "my_agent.py:module", "smoke-torchrl"), ("p1-exact-v1", "search:h2", "smoke-h2"),
                ("innings-v1", "results/policies/base/seed0.pt", "smoke-policy"), ("match-x5-v1", "league:greedy", "smoke-league")]
        for track, spec, name in runs:
            sagu("evaluate", f"track={track}", f"agent={spec}", f"name={name}", *limited, f"out=runs/{name}",
                 expect=("scorecard", "would rank"), cwd=cwd)
            if not (cwd / "runs" / name / "scorecard.json").is_file():
                raise SystemExit(f"FAIL: no scorecard for {name}")
        # an optional extra not installed: the sentence says what to install, and blames no agent
        said = sagu("evaluate", "track=p1-exact-v1", "agent=sb3:sac:model.zip", "name=smoke-sb3", *limited, cwd=cwd, code=1,
                    expect=('pip install "sagu-bench[sb3]"',))
        if "failed" in said:
            raise SystemExit(f"FAIL: a missing extra was blamed on the agent:\n{said}")
        sagu("search", "proposer=near_miss", "protocol=p1", "protocol.n_innings=1", "protocol.shots=2", "progress=false",
             "hydra.run.dir=runs/search", expect=("results",), cwd=cwd)  # a shipped ensemble
        sagu("train", "-m", "budget=smoke", "seed=0,1", "hydra/launcher=joblib", "hydra.launcher.n_jobs=2", "logger=none",
             "progress=false", "hydra.sweep.dir=runs/sweep", cwd=cwd)  # a Hydra multirun on a launcher
        if len(list((cwd / "runs" / "sweep").glob("*/summary.json"))) != 2:
            raise SystemExit("FAIL: the multirun did not finish both jobs")
        # no scorecards of one's own here: it says where it looked, and writes nothing
        sagu("leaderboard", "--out", "board", expect=(str(cwd / "results" / "bench"), "nothing written"), cwd=cwd, code=1)
        if (cwd / "board").exists():
            raise SystemExit("FAIL: sagu leaderboard wrote a board of nothing")
    print("the installed package works from outside the repository")


if __name__ == "__main__":
    main()
