"""Reading what earlier versions wrote, in one place.

Files an earlier version saved -- a training run's checkpointed config (``resume=``), a search
run's saved config (``search.py resume=``, pictures of a search), an exported policy's training
config -- are brought to today's form here, and nothing else in the package knows an old form.
The committed results were migrated once instead (every committed training config and search
result names its table and row, or its physics). What changed:

* the physics presets: a config saved before them has no ``physics`` node and played pooltool's
  international table (:data:`LEGACY_PHYSICS`);
* execution noise: a search config saved before it has no ``noise`` node and played exact shots;
* retired keys (:data:`RETIRED_KEYS`) are dropped: nothing reads them any more;
* the search configs' old union nodes: each group's node held every option's keys
  (:data:`LEGACY_UNION_KEYS`); today each option has its own closed schema.

Artefacts that record their table as ``physics_params`` (data sets, reward models) keep their
own reader, :func:`billiards.physics.config.recorded_physics` (the physics layer cannot import
this module); it reads a missing record the same way, as :data:`LEGACY_PHYSICS`.
"""

from __future__ import annotations

from typing import Callable

from billiards.physics.config import LEGACY_PHYSICS

RETIRED_KEYS = ("budget.kill_after_checkpoint",)
LEGACY_UNION_KEYS = {
    "search": ("k1", "m1", "c_puct", "pw_c", "pw_alpha", "pool", "max_depth",
               "samples", "schedule", "screen", "quantile", "k2", "target", "wave", "antithetic"),
    "protocol": ("n_innings", "shots", "seeds", "cap"),
    "proposer": ("checkpoints", "command", "power_low", "power_high", "u_low", "u_high", "spin_low", "spin_high"),
}


def with_physics(container: dict) -> dict:
    """A saved config with its ``physics`` node (``international`` for one saved before the presets)."""
    return container if "physics" in container else {**container, "physics": {"preset": LEGACY_PHYSICS}}


def _without(d: dict, path: list[str]) -> dict:
    head, *rest = path
    return {k: (_without(v, rest) if k == head and rest else v) for k, v in d.items() if rest or k != head}


def without_retired(container: dict) -> dict:
    """A saved config without the :data:`RETIRED_KEYS` (a copy where it had any)."""
    out = container
    for key in RETIRED_KEYS:
        *parents, leaf = key.split(".")
        node = out
        for p in parents:
            node = node.get(p) if isinstance(node, dict) else None
        if isinstance(node, dict) and leaf in node:
            out = _without(out, [*parents, leaf])
    return out


def training_config(container: dict) -> dict:
    """A saved training config (a plain dict) in today's form."""
    return without_retired(with_physics(container))


def search_config(saved: dict, own_keys: Callable[[str, dict], set]) -> dict:
    """A saved search config (a plain dict) in today's form: the other options' keys of the old
    union nodes dropped (``own_keys(group, node)``: the keys of the node's option schema), and
    ``physics`` and ``noise`` added where it was saved before they existed."""
    out = dict(saved)
    for group, legacy in LEGACY_UNION_KEYS.items():
        node = out.get(group)
        if isinstance(node, dict):
            own = own_keys(group, node)
            out[group] = {k: v for k, v in node.items() if k in own or k not in legacy}
    out = with_physics(out)
    out.setdefault("noise", {"preset": "none"})
    return out


def saved_physics_node(cfg) -> dict | None:
    """The ``physics`` node of a saved training config, ``international``'s for one saved before the presets."""
    node = cfg.get("physics")
    return node if node is not None else {"preset": LEGACY_PHYSICS}


__all__ = ["LEGACY_PHYSICS", "LEGACY_UNION_KEYS", "RETIRED_KEYS", "saved_physics_node", "search_config", "training_config",
           "with_physics", "without_retired"]
