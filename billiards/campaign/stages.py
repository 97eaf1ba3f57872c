"""The stages of the paper's reproduction: one Hydra multirun per table.

A training table's stage is ``python train.py -m experiment=<table> hydra.sweep.dir=<root>/<table>
resume=auto ...``: its runs land in ``<root>/<table>/<row>/seed<k>/`` (the preset's
``hydra.sweep.subdir``), Table 6's in ``<root>/table6/<proposer>/<method>_<protocol>/``. The
stages run in the order of :data:`ORDER` (Table 3 and 5 share rows with Table 4, so Table 4 comes
first; Table 6 searches the shipped ensembles, ``results/policies/``, which the Table 5 runs were
exported to). ``extra`` runs only when asked for (``--only extra``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from billiards.app_config import override_errors
from billiards.files import display_path
from billiards.tables import paper_tables

ORDER = ("table1", "table2", "table4", "table3", "table5", "table6")
OPTIONAL = ("extra",)
# the launchers a stage may name (conf/hydra/launcher/ and the plugins' own)
LAUNCHERS = ("basic", "joblib", "local_parallel", "submitit_local", "submitit_slurm", "slurm", "ray_tasks")
BUDGETS = ("paper", "quick", "smoke")


class StageError(ValueError):
    """A stage that cannot run as asked; the message says why."""


@dataclass(frozen=True)
class Stage:
    table: str
    app: str  # train | search
    root: Path

    @property
    def dir(self) -> Path:
        return self.root / self.table

    def command(self, launcher: str | None = None, budget: str | None = None, overrides: tuple[str, ...] = ()) -> list[str]:
        """The multirun's command line (``python train.py -m ...``), cwd = the repository."""
        args = ["python", f"{self.app}.py", "-m", f"experiment={self.table}", f"hydra.sweep.dir={display_path(self.dir)}",
                "resume=auto", "threads=1", "progress=false"]
        if launcher and launcher != "basic":
            args.append(f"hydra/launcher={launcher}")
        if budget and self.app == "train":
            args.append(f"budget={budget}")
        return args + list(overrides)


def paper_stages(root: Path, only: list[str] | None = None) -> list[Stage]:
    """The stages of the paper's tables in :data:`ORDER` (``only``: these tables, in that order)."""
    tables = paper_tables()
    known = ORDER + OPTIONAL
    if only:
        if unknown := sorted(set(only) - set(known)):
            raise StageError(f"--only {','.join(unknown)}: no such stage (stages: {', '.join(known)})")
        chosen = [t for t in known if t in only]
    else:
        chosen = list(ORDER)
    return [Stage(t, tables[t].app, Path(root)) for t in chosen]


def check_options(launcher: str | None, budget: str | None, overrides: list[str]) -> None:
    """Refuse, before anything runs, a launcher or budget not offered and overrides that name
    code or Hydra's sweep (the stage's own)."""
    if launcher is not None and launcher not in LAUNCHERS:
        raise StageError(f"--launcher {launcher!r}: one of {', '.join(LAUNCHERS)}")
    if budget is not None and budget not in BUDGETS:
        raise StageError(f"--budget {budget!r}: one of {', '.join(BUDGETS)}")
    errors = override_errors(overrides, what="override")
    errors += [f"override {o!r}: the stage sets the sweep's directory and experiment itself"
               for o in overrides if re.match(r"[+~]*(hydra\.sweep\.dir|experiment)=", o)]
    if errors:
        raise StageError("\n".join(errors))
