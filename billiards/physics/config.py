"""The ``physics`` node of the Hydra apps (``train.py``, ``search.py``): a preset name plus
optional per-field overrides, turned into a :class:`PhysicsParams` in one place.

``python train.py physics=international`` picks a preset (``conf/physics/<name>.yaml`` sets
``preset``); ``physics.u_roll=0.02`` overrides one field of it. Every field of
:class:`PhysicsParams` is a typed, optional key of :class:`PhysicsConfig`, generated from the
dataclass itself so the two never drift apart; ``null`` means "the preset's value". The values
themselves live only in :data:`billiards.physics.PRESETS`.

Plain dataclasses, no Hydra and no torch: the apps register the node in their ConfigStore.
"""

from __future__ import annotations

import dataclasses
import logging
import warnings
from typing import Any, Optional

from .params import DEFAULT_PRESET, PRESETS, PhysicsParams, get_params

_TYPES = {"float": float, "int": int, "bool": bool, "str": str}

PhysicsConfig = dataclasses.make_dataclass(
    "PhysicsConfig",
    [("preset", str, dataclasses.field(default=DEFAULT_PRESET))]
    + [(f.name, Optional[_TYPES[f.type if isinstance(f.type, str) else f.type.__name__]], dataclasses.field(default=None))
       for f in dataclasses.fields(PhysicsParams)],
)
PhysicsConfig.__module__ = __name__
PhysicsConfig.__doc__ = ("A physics preset (``preset``) and optional overrides of its fields (null: the preset's "
                         "value); see billiards.physics.config.")


def overrides_of(node: Any) -> dict:
    """The non-null field overrides of a physics config node (a DictConfig or a dict)."""
    return {f.name: node[f.name] for f in dataclasses.fields(PhysicsParams) if node.get(f.name) is not None}


def params_from_config(node: Any | None) -> PhysicsParams:
    """The PhysicsParams a ``physics`` config node describes (None: the default preset). A
    saved config is read through :mod:`billiards.compat` first, which gives it its node."""
    if node is None:
        return PRESETS[DEFAULT_PRESET]
    return get_params({"preset": node["preset"], **overrides_of(node)})


def physics_errors(node: Any) -> list[str]:
    """Problems of a physics config node, each naming its key (empty if it is valid)."""
    if node["preset"] not in PRESETS:
        return [f"physics.preset={node['preset']!r} is not a preset; presets: {', '.join(sorted(PRESETS))} "
                f"(choose one with physics=<name>)"]
    try:
        params_from_config(node)
    except ValueError as err:
        keys = ", ".join(f"physics.{k}" for k in overrides_of(node)) or "physics"
        return [f"{keys}: {err}"]
    return []


def physics_record(params: PhysicsParams) -> dict:
    """What a result file records of its table: ``{"physics": label, "physics_params": fields}``
    (read back by :func:`recorded_physics`)."""
    return {"physics": params.describe(), "physics_params": params.to_dict()}


def recorded_physics(record: dict) -> PhysicsParams:
    """The table a saved artefact (data set, model) records as ``physics_params`` (a
    :meth:`PhysicsParams.to_dict`; its metadata read through
    :func:`billiards.compat.upgrade_artefact_meta` first)."""
    return PhysicsParams.from_dict(record)


class PhysicsMismatchWarning(UserWarning):
    """A policy, proposer, reward model or checkpoint used on another table than its own."""


def warn_physics_mismatch(what: str, made_on: PhysicsParams, used_on: PhysicsParams) -> bool:
    """Warn loudly (a :class:`PhysicsMismatchWarning` and a log line) when something made on
    one table is used on another; returns whether it warned."""
    if made_on == used_on:
        return False
    msg = (f"{what} was made on physics {made_on.describe()!r} but is used on {used_on.describe()!r}: "
           f"its behaviour there is untested (use physics={made_on.describe()} to match)")
    warnings.warn(msg, PhysicsMismatchWarning, stacklevel=3)
    logging.getLogger("billiards").warning(msg)
    return True


__all__ = ["PhysicsConfig", "PhysicsMismatchWarning", "overrides_of", "params_from_config",
           "physics_errors", "physics_record", "recorded_physics", "warn_physics_mismatch"]
