"""Where the project's files are and what they are called: the package and the repository root
(:data:`ROOT`, :data:`CONF_DIR`, :data:`OUTPUTS`: the checkout, or the copy an installed wheel
carries), the names of the files a run directory holds, and paths as configs give them
(:func:`repo_path`) and as logs and records write them (:func:`display_path`,
:func:`recorded_command`)."""

from __future__ import annotations

from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]
# Where the project's own files are read from (conf/, the shipped models under results/, the
# leaderboard's snapshot): the repository when this package is a source checkout's (billiards/
# beside conf/ and pyproject.toml), else the copy an installed wheel carries in billiards/_data,
# laid out as in the repository (setup.py: SHIPPED). Nothing is written under it outside a checkout.
IN_CHECKOUT = (PACKAGE.parent / "conf").is_dir() and (PACKAGE.parent / "pyproject.toml").is_file()
ROOT = PACKAGE.parent if IN_CHECKOUT else PACKAGE / "_data"
CONF_DIR = ROOT / "conf"  # the Hydra configs every app composes
OUTPUTS = PACKAGE.parent / "outputs" if IN_CHECKOUT else Path("outputs")  # where tools write by default (an install: the working directory)

# What a training run directory holds (billiards.rl) ...
CONFIG_FILE = "config.yaml"  # the resolved config, written at start (training and search runs)
CHECKPOINT_FILE = "checkpoint.pt"
EVAL_FILE = "eval.json"
EVAL_HISTORY_FILE = "eval_history.jsonl"
METRICS_FILE = "metrics.csv"
SUMMARY_FILE = "summary.json"
# ... a search run directory (billiards.search) ...
RESULTS_FILE = "results.json"
CHAINS_FILE = "chains.jsonl"  # a P3's ledger: one finished chain a line
# ... a league's run directory (billiards.league) ...
MATCHES_FILE = "matches.jsonl"  # one finished match a line
LEAGUE_FILE = "league.json"
# ... and a benchmark evaluation's (billiards.bench.run)
IDENTITY_FILE = "evaluation.json"  # the track and agent it scores
UNITS_FILE = "units.jsonl"  # its ledger: one finished unit (a block of innings, a chain, a match) a line
SCORECARD_JSON = "scorecard.json"
SCORECARD_MD = "scorecard.md"


def repo_path(path) -> Path:
    """A path a config or a command line gives: itself if it is absolute or exists (relative to
    the working directory), else the same path under the repository root, so the shipped
    ``results/...`` files are found from any working directory."""
    p = Path(path)
    if p.is_absolute() or p.exists():
        return p
    return ROOT / p


def display_path(path) -> str:
    """How a path is written into logs and records: relative to the repository when it lies
    inside it, so no committed file names a folder of the machine that wrote it."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(ROOT.resolve()))
    except ValueError:
        return str(path)


def recorded_command(cmd) -> list[str]:
    """A command line as recorded: the interpreter as ``python`` and paths inside the repository
    relative to it (``hydra.run.dir=/abs/repo/x`` -> ``hydra.run.dir=x``); an app run by the
    console command (:mod:`billiards.cli` names it ``sagu <app>``) as ``sagu <app> ...``."""
    import sys

    root = str(ROOT.resolve()) + "/"
    out = ["python" if c == sys.executable else c.replace(root, "") for c in cmd]
    if len(out) > 1 and out[0] == "python" and out[1].startswith("sagu "):
        out = [*out[1].split(), *out[2:]]
    return out
