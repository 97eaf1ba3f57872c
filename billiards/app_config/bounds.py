"""The values a composed config may hold, as its app's check sees them: every number in range
(:data:`INT_BOUND`, :func:`numeric_bound_errors`, a schema's :func:`upper_bound_errors`) and
every interpolation through an allowed resolver (:func:`resolver_errors`), resolved
(:func:`resolved_config`)."""

from __future__ import annotations

import re
from typing import Optional

from omegaconf import DictConfig, OmegaConf

INT_BOUND = 2**31 - 1  # the largest count any kernel, array or generator here is sized by


def numeric_bound_errors(cfg, skip: tuple[str, ...] = ("physics", "noise", "hydra")) -> list[str]:
    """Every integer of the composed config within +-(2^31 - 1) and every float finite (the
    physics and noise nodes have their own, tighter bounds; ``skip``): a count of 10^19 or a
    NaN step is refused while validating, not inside a kernel. Run it on the resolved config
    (:func:`resolved_config`): an interpolation is skipped here. Each schema's own check adds
    its keys' finite upper bounds (:func:`upper_bound_errors`)."""
    import math

    errors: list[str] = []

    def walk(node, path: str) -> None:
        if isinstance(node, DictConfig):
            items = ((str(k), node._get_node(k)) for k in node.keys())
        elif OmegaConf.is_list(node):
            items = ((str(i), node._get_node(i)) for i in range(len(node)))
        else:
            return
        for key, child in items:
            name = f"{path}.{key}" if path else key
            if not path and key in skip:
                continue
            if OmegaConf.is_config(child):
                walk(child, name)
                continue
            try:
                value = child._value() if hasattr(child, "_value") else child
            except Exception:  # an unresolvable interpolation: the schema's check reports it
                continue
            if isinstance(value, bool) or value is None or isinstance(value, str):
                continue
            if isinstance(value, int) and not -INT_BOUND <= value <= INT_BOUND:
                errors.append(f"{name}={value}: integers here must lie within +-{INT_BOUND:,}")
            elif isinstance(value, float) and not math.isfinite(value):
                errors.append(f"{name}={value}: must be a finite number")

    walk(cfg, "")
    return errors


def _bound_text(x: float) -> str:
    return f"{int(x):,}" if float(x).is_integer() and abs(x) >= 1000 else f"{x:g}"


def upper_bound_errors(node, prefix: str, bounds: dict) -> list[str]:
    """Each key of ``bounds`` (key -> ``(upper bound, why)``, a schema's ``UPPER``) at most its
    bound in ``node`` (a config node or an option object), every entry of a list value too:
    ``"algo.lr must be at most 1 (...), got 5.0"``. Null, NaN and non-numbers are left to the
    schema's other checks (:func:`numeric_bound_errors` refuses NaN); infinity fails here too."""
    errors = []
    for key, (hi, why) in bounds.items():
        value = getattr(node, key, None) if not hasattr(node, "get") else node.get(key)
        values = list(value) if OmegaConf.is_list(value) or isinstance(value, (list, tuple)) else [value]
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v:
                continue
            if v > hi:
                errors.append(f"{prefix}{key} must be at most {_bound_text(hi)} ({why}), got {v!r}")
                break
    return errors


# ----------------------------------------------------------------------------- the resolved config

# The resolvers a config value may use: the project's own (RESOLVERS: billiards.*) and Hydra's
# ``now`` (a date) and ``hydra`` (the job's own settings). Any other -- oc.env reads this machine's
# environment, oc.decode and oc.create build values from text, oc.select and the others reach
# past the schema -- would hand the validator one value and the run another, or no value at all.
ALLOWED_RESOLVERS = ("now", "hydra")
RESOLVER_CALL = re.compile(r"\$\{\s*([A-Za-z_][\w.\-]*)\s*:")


def _allowed_resolver(name: str) -> bool:
    return name in ALLOWED_RESOLVERS or name.startswith("billiards.")


def resolver_errors(cfg, skip: tuple[str, ...] = ("hydra",)) -> list[str]:
    """One sentence for each value of ``cfg`` (less the ``skip`` nodes: the hydra node is the
    composition guard's) that interpolates through a resolver other than the project's
    ``billiards.*`` and Hydra's ``now`` and ``hydra``, naming its key."""
    errors: list[str] = []

    def walk(node, path: str) -> None:
        if node._is_none() or node._is_missing() or node._is_interpolation():
            return
        keys = list(node.keys()) if isinstance(node, DictConfig) else range(len(node))
        for key in keys:
            name = f"{path}.{key}" if path else str(key)
            if not path and key in skip:
                continue
            child = node._get_node(key)
            if child._is_interpolation():
                text = str(child._value())
                bad = sorted({r for r in RESOLVER_CALL.findall(text) if not _allowed_resolver(r)})
                if bad:
                    errors.append(f"{name}={text}: interpolates through {', '.join(bad)}; a value may refer to other keys "
                                  f"(${{key}}) and use the project's billiards.* resolvers and Hydra's now and hydra, "
                                  f"nothing else (oc.env would read this machine's environment, oc.decode and oc.create "
                                  f"build values no check sees): give the value itself")
            elif OmegaConf.is_config(child):
                walk(child, name)

    walk(cfg, "")
    return errors


def resolved_config(cfg, skip: tuple[str, ...] = ("hydra",)) -> tuple[Optional[DictConfig], list[str]]:
    """``(copy, errors)``: a copy of the composed ``cfg`` (its schema types kept) with every
    interpolation resolved and the ``skip`` nodes left out -- what the run will read, so that
    the app's checks see the values, not ``${...}`` -- or ``(None, errors)``: an interpolation
    through a resolver the project does not allow (:func:`resolver_errors`), or one that does
    not resolve (a missing key, a value its key's type refuses), each naming its key."""
    import copy

    errors = resolver_errors(cfg, skip)
    if errors:
        return None, errors
    out = copy.deepcopy(cfg)
    OmegaConf.set_readonly(out, False)
    struct = OmegaConf.is_struct(out)
    OmegaConf.set_struct(out, False)
    for key in skip:
        out.pop(key, None)
    OmegaConf.set_struct(out, struct)
    try:
        OmegaConf.resolve(out)
    except Exception as err:  # OmegaConf's errors, or one a resolver raised
        key = getattr(err, "full_key", None) or "a value"
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        return None, [f"{key}: its interpolation does not resolve to a valid value ({first})"]
    return out, []
