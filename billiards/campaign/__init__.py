"""The paper's reproduction campaign as one restartable job: ``python -m billiards.campaign``.

* :mod:`.spec` -- every run of every table, declared once (:func:`paper_campaign`), or a small
  campaign read from a file (``--spec FILE``);
* :mod:`.ledger` -- the state on disk under ``outputs/campaign/<name>/``;
* :mod:`.runner` -- runs the unfinished entries N at a time, resumes, drains before a deadline;
* :mod:`.status` -- done / running / left, CPU-hours spent and left.

This package imports neither torch nor the simulator: it starts ``train.py``, ``search.py``
and ``python -m billiards.rl.policy export`` as processes.
"""

from .spec import Campaign, Entry, SpecError, campaign_named, load_spec, paper_campaign

__all__ = ["Campaign", "Entry", "SpecError", "campaign_named", "load_spec", "paper_campaign"]
