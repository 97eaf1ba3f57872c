"""Inning options shared by the gymnasium and the TorchRL environment."""

from __future__ import annotations

import numpy as np

from billiards.physics import (
    DEFAULT_PARAMS,
    PhysicsParams,
    canonical_rack,
    random_racks,
)

STARTS = ("random", "canonical")
ON_MISS = ("continue", "reset")
# The paper's four training paradigms (start x miss handling), by name: the one spelling of
# make_env, the training config (env.paradigm) and the report. The hyphenated names the env
# factory took before ("random-continue") are still accepted, with a DeprecationWarning.
PARADIGMS = {
    "canonical_reset": ("canonical", "reset"),
    "canonical_continue": ("canonical", "continue"),
    "random_reset": ("random", "reset"),
    "random_continue": ("random", "continue"),
}


def check_inning_options(start: str, on_miss: str, max_shots: int) -> int:
    """Validate the inning options; returns max_shots as an int."""
    if start not in STARTS:
        raise ValueError(f"start must be one of {STARTS}, got {start!r}")
    if on_miss not in ON_MISS:
        raise ValueError(f"on_miss must be one of {ON_MISS}, got {on_miss!r}")
    if int(max_shots) != max_shots or max_shots < 1:
        raise ValueError(f"max_shots must be a positive integer, got {max_shots!r}")
    return int(max_shots)


def resolve_paradigm(paradigm: str | None, start: str | None, on_miss: str | None) -> tuple[str, str]:
    """(start, on_miss) from a paradigm name such as ``"random_continue"`` and/or explicit values.

    Explicit values must agree with the paradigm; unset ones default to random / continue.
    """
    if isinstance(paradigm, str) and paradigm not in PARADIGMS and paradigm.replace("-", "_") in PARADIGMS:
        import warnings

        warnings.warn(f"paradigm {paradigm!r} is spelt {paradigm.replace('-', '_')!r} now", DeprecationWarning, stacklevel=3)
        paradigm = paradigm.replace("-", "_")
    if paradigm is not None:
        if paradigm not in PARADIGMS:
            raise ValueError(f"paradigm must be one of {sorted(PARADIGMS)}, got {paradigm!r}")
        p_start, p_miss = PARADIGMS[paradigm]
        if (start is not None and start != p_start) or (on_miss is not None and on_miss != p_miss):
            raise ValueError(f"paradigm {paradigm!r} conflicts with start={start!r}, on_miss={on_miss!r}")
        return p_start, p_miss
    return start or "random", on_miss or "continue"


def initial_racks(rng: np.random.Generator, start: str, n: int, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """n starting racks (n, 4, 2) float64: uniform random non-overlapping racks drawn from rng,
    or copies of the canonical rack (which consumes no randomness)."""
    if start == "canonical":
        return np.broadcast_to(canonical_rack(params), (n, 4, 2)).copy()
    return random_racks(rng, n, params)


def terminated_truncated(score: np.ndarray, shot: np.ndarray, on_miss: str, max_shots: int):
    """Inning end flags after a shot, from the score and the number of shots played so far.

    terminated = not score            under reset-on-miss (a miss or a foul ends the inning),
               = False                under continue-on-miss;
    truncated  = shot >= max_shots and not terminated  (the shot budget cut the inning).
    """
    score = np.asarray(score, dtype=bool)
    terminated = ~score if on_miss == "reset" else np.zeros_like(score)
    truncated = (np.asarray(shot) >= max_shots) & ~terminated
    return terminated, truncated


def validate_action(action, expected_shape: tuple[int, ...]) -> np.ndarray:
    """The action as a float64 array of exactly ``expected_shape``, or a ValueError that names
    the key ``"action"`` and the expected shape. Checks shape and finiteness here; the
    simulator then checks the ranges of p, a and b (also naming ``action``)."""
    if action is None:
        raise ValueError(f'missing "action": expected a tensor of shape {expected_shape} = (theta, p, a, b) per shot')
    try:
        arr = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f'"action" must be numeric with shape {expected_shape}; got {type(action).__name__}: {err}') from None
    if arr.shape != tuple(expected_shape):
        raise ValueError(
            f'"action" must have shape {tuple(expected_shape)} = (theta, p, a, b) per shot; got shape {arr.shape}'
        )
    if not np.isfinite(arr).all():
        rows = np.unique(np.argwhere(~np.isfinite(arr.reshape(-1, arr.shape[-1])))[:, 0]).tolist()
        raise ValueError(
            f'"action" of shape {tuple(expected_shape)} has non-finite (NaN/inf) entries in row(s) {rows[:8]}'
        )
    return arr
