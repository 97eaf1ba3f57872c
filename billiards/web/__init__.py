"""The viewer: a local web app to replay runs, try shots, ask agents and play matches
(``python -m billiards.web``; docs/viewer.md).

* :mod:`.app` -- the FastAPI app (:func:`create_app`): the JSON API and the page;
* :mod:`.sim` -- one shot as the API answers it (exact simulation, noise, paths, outcome);
* :mod:`.catalogue` -- the closed list of agents the page may ask, built once and kept;
* :mod:`.runs` -- the recorded runs it replays, and the folders it may read;
* :mod:`.replays` -- runs whose records hold scores, not shots, played again shot by shot
  (benchmark scorecards' units, search runs' P1 innings, training runs' evaluations);
* :mod:`.match` -- matches between the person and a league player, kept on disk from their start
  (a sealed ledger of shots, resumed after a reload or a restart) and saved as league ledgers at their end;
* ``static/`` -- the page (HTML, one script, one stylesheet; nothing from elsewhere).
"""

from __future__ import annotations


def create_app(*args, **kwargs):
    """:func:`billiards.web.app.create_app` (FastAPI is imported only when an app is made)."""
    from .app import create_app as make

    return make(*args, **kwargs)


__all__ = ["create_app"]
