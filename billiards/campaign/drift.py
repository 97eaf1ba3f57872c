"""``status --check-config``: has the training configuration of a started run drifted?

A resume keeps a run's checkpointed config, so a change of ``conf/`` defaults in the middle
of a campaign (say ``conf/algo/sac.yaml``'s lr) never changes a run halfway; but the seeds of
one variant started before and after the change would train different configs. This composes
each started training run's campaign arguments with the *current* ``conf/`` (Hydra's compose
API, in this process) and lists every key whose value differs from the run's own
``config.yaml``, ignoring run-time switches (the trainer's ``RUNTIME_KEYS`` and
``RESUME_KEYS``), keys the schema has retired (``RETIRED_KEYS``), the logger, and keys the
schema gained after the run started that its arguments do not set (a resume gives them their
defaults, which keep the old behaviour: ``noise`` none). Runs with
drift should start over (``--restart-stale`` after changing their arguments, or delete the
run dir).
"""

from __future__ import annotations

from pathlib import Path

import yaml

from billiards.provenance import ROOT
from billiards.report import flatten_config

from .ledger import entry_dir, fill
from .spec import Campaign, Entry


def config_drift(campaign: Campaign, root: Path, entries: list[Entry]) -> dict[str, list[tuple[str, object, object]]]:
    """``{key: [(config key, value in the run's config.yaml, value composed now), ...]}`` for
    every started training run (a ``config.yaml`` in its dir) among ``entries`` that differs."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf

    import billiards.rl.config  # noqa: F401  (the schema and resolvers)
    from billiards.rl.train import RESUME_KEYS, RETIRED_KEYS, RUNTIME_KEYS

    ignored = set(RUNTIME_KEYS) | set(RESUME_KEYS) | set(RETIRED_KEYS) | {"resume"}
    started = [(e, entry_dir(root, campaign, e) / "config.yaml") for e in entries
               if e.kind == "train" and not e.same_as]
    started = [(e, path) for e, path in started if path.is_file()]
    out: dict[str, list[tuple[str, object, object]]] = {}
    if not started:
        return out
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        for e, path in started:
            now = flatten_config(OmegaConf.to_container(compose("config", overrides=[fill(a, root) for a in e.args]),
                                               resolve=True, enum_to_str=True))
            saved = flatten_config(yaml.safe_load(path.read_text()) or {})
            named = {a.split("=", 1)[0].lstrip("+~") for a in e.args}
            diff = [(k, saved.get(k), now.get(k)) for k in sorted(set(now) | set(saved))
                    if k not in ignored and not k.startswith("logger.") and saved.get(k) != now.get(k)
                    and not _added_since(k, saved, named)]
            if diff:
                out[e.key] = diff
    GlobalHydra.instance().clear()
    return out


def _added_since(key: str, saved: dict, named: set[str]) -> bool:
    """A key the schema gained after the run started (absent from its config.yaml) and that the
    run's arguments do not set: a resume gives it its default, which by the project's rule for
    new options keeps the old behaviour (``noise`` none, ``device`` the command line's), so it
    is not drift."""
    if key in saved:
        return False
    parts = key.split(".")
    return not any(".".join(parts[:i]) in named for i in range(1, len(parts) + 1))


def drift_text(drift: dict[str, list[tuple[str, object, object]]], checked: int) -> str:
    if not drift:
        return f"config check: the {checked} started training runs match what their arguments compose to now\n"
    lines = [f"config check: {len(drift)} of {checked} started training runs differ from what their arguments compose to now:"]
    for key, diff in drift.items():
        lines.append(f"  {key}: " + "; ".join(f"{k} = {a!r} in the run, {b!r} now" for k, a, b in diff))
    return "\n".join(lines) + "\n"
