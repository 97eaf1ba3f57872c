"""The paper's reproduction on Hydra's launchers: ``python -m billiards.campaign``.

Each paper table (:mod:`billiards.tables`, ``conf/experiment/<table>.yaml``) is one *stage*: one
Hydra multirun of ``train.py`` or ``search.py`` over its rows and seeds, into
``<root>/<table>/`` (:mod:`.stages`). Any Hydra launcher runs it: joblib or submitit_local on
one machine, submitit_slurm or Ray on a cluster. Every job runs with ``resume=auto``: launched
again, a finished run does nothing and a stopped one continues from its checkpoint, so a stage is
resumed by running it again. ``status`` and ``report`` read the run directories
(:mod:`.status`, :mod:`billiards.report.reproduction`); there is no other state.

This package imports neither torch nor the simulator.
"""

from .stages import Stage, StageError, paper_stages

__all__ = ["Stage", "StageError", "paper_stages"]
