"""Exact event-based 4-ball carom simulator (NumPy + numba, no torch).

Ball order everywhere: 0 white (the player's cue ball), 1 yellow, 2 and 3 the reds.
Table frame: x across the width in [0, w], y along the length in [0, l], origin at a corner.
"""

from .api import (
    BALL_NAMES,
    CUSHION_NAMES,
    EVENT_KINDS,
    MOTION_LABELS,
    POSITION_TOL,
    BatchResult,
    ShotResult,
    action_to_cue,
    canonical_rack,
    check_actions,
    check_positions,
    random_rack,
    random_racks,
    simulate_batch,
    simulate_shot,
    trajectory,
)
from .params import DEFAULT_PARAMS, DEFAULT_PRESET, PRESETS, PhysicsParams, get_params
from .rules import carom_outcome, unhit_red_gap

__all__ = [
    "BALL_NAMES", "CUSHION_NAMES", "EVENT_KINDS", "MOTION_LABELS", "POSITION_TOL",
    "BatchResult", "ShotResult", "DEFAULT_PARAMS", "DEFAULT_PRESET", "PRESETS", "PhysicsParams", "get_params",
    "action_to_cue", "canonical_rack", "check_actions", "check_positions", "random_rack",
    "random_racks", "simulate_batch", "simulate_shot", "trajectory", "carom_outcome", "unhit_red_gap",
]
