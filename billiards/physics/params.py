"""Physical parameters of the table, balls, cushions and cue, in one immutable object.

Defaults are the paper's stack (see ``shared/physics_reference.md``, first table):
pooltool's pocketless BILLIARD table and BILLIARD_GENERIC balls, Han 2005 (corrected)
cushions, equal-mass restitution ball–ball contact with e_b = 0.95, level-cue
instantaneous-point strike without squirt.

The numba kernels never see this dataclass: :meth:`PhysicsParams.as_array` packs it into a
flat float64 vector whose slots are the ``P_*`` indices below.
"""

from __future__ import annotations

import dataclasses
import math
from functools import cached_property

import numpy as np

# Ball–ball contact models.
BALL_BALL_RESTITUTION = 0  # equal-mass restitution exchange (reference §4b), the default
BALL_BALL_ELASTIC = 1  # frictionless elastic, e = 1 (reference §4a)
BALL_BALL_MODELS = {"restitution": BALL_BALL_RESTITUTION, "elastic": BALL_BALL_ELASTIC}

# Slots of the packed parameter vector.
P_W, P_L, P_R, P_M, P_U_S, P_U_R, P_U_SP, P_E_B, P_E_C, P_F_C, P_G, P_H = range(12)
P_CUE_M, P_CUE_V_MAX, P_MAX_ENGLISH, P_SQUIRT, P_CUE_END_M, P_BALL_BALL = range(12, 18)
P_MAX_EVENTS, P_MIN_DIST = 18, 19
N_PARAMS = 20


@dataclasses.dataclass(frozen=True)
class PhysicsParams:
    """Everything the simulator needs to know about the world. Immutable; build variants
    with :func:`dataclasses.replace` or ``PhysicsParams(**overrides)``.

    Units are SI. ``cue_speed_max`` is the cue speed (m/s) at power p = 1; the ball leaves at
    up to 2/(1 + m/M) = 1.4595 times that. ``max_english`` is the largest contact-point
    offset, as a fraction of R, that the action's tip offset (projected onto the unit disk)
    is scaled to (pooltool's GUI limit is 0.6).
    """

    # table
    table_width: float = 1.42  # x extent of the playing surface (nose line to nose line)
    table_length: float = 2.84  # y extent
    cushion_height: float = 0.037  # nose height h above the cloth
    # balls
    ball_radius: float = 0.03075
    ball_mass: float = 0.21
    u_slide: float = 0.2  # mu_s, ball–cloth sliding friction
    u_roll: float = 0.01  # mu_r, rolling resistance
    u_spin: float = 0.03075 * 4.0 / 9.0  # mu_sp (a length): (4/9) R
    e_ball: float = 0.95  # ball–ball restitution
    e_cushion: float = 0.85  # ball–cushion restitution
    f_cushion: float = 0.15  # ball–cushion friction
    g: float = 9.81
    # cue
    cue_mass: float = 0.567
    cue_speed_max: float = 6.0  # cue speed at power p = 1 (m/s)
    max_english: float = 0.6  # tip offset radius at |(a, b)| = 1, fraction of R
    squirt: bool = False  # cue-ball deflection from side spin (reference §1.3)
    cue_end_mass: float = 0.170097 / 30.0  # m_e, only used with squirt
    # models and numerics
    ball_ball: str = "restitution"  # "restitution" (§4b) or "elastic" (§4a)
    max_events: int = 5000  # safety net: a shot with more events is stopped (flagged)
    min_dist: float = 1e-6  # make_kiss spacer between touching bodies (m)

    def __post_init__(self) -> None:
        positive = [
            "table_width", "table_length", "ball_radius", "ball_mass", "g", "cue_mass",
            "cue_speed_max", "cushion_height", "min_dist", "u_slide", "u_roll", "u_spin",
        ]
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"PhysicsParams.{name} must be a finite positive number, got {value!r}")
        for name in ["f_cushion", "cue_end_mass"]:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"PhysicsParams.{name} must be finite and >= 0, got {value!r}")
        for name in ["e_ball", "e_cushion"]:
            value = getattr(self, name)
            if not (0.0 <= value <= 1.0):
                raise ValueError(f"PhysicsParams.{name} must lie in [0, 1], got {value!r}")
        if not 0.0 <= self.max_english <= 1.0:
            raise ValueError(f"PhysicsParams.max_english must lie in [0, 1] (miscue beyond), got {self.max_english!r}")
        if not self.ball_radius < self.cushion_height < 2 * self.ball_radius:
            raise ValueError("PhysicsParams.cushion_height must lie between R and 2R for the Han cushion model")
        if self.ball_ball not in BALL_BALL_MODELS:
            raise ValueError(f"PhysicsParams.ball_ball must be one of {sorted(BALL_BALL_MODELS)}, got {self.ball_ball!r}")
        if int(self.max_events) < 1:
            raise ValueError(f"PhysicsParams.max_events must be >= 1, got {self.max_events!r}")
        if 2 * self.ball_radius * 2 > min(self.table_width, self.table_length):
            raise ValueError("PhysicsParams: the table is too small for four balls")

    @cached_property
    def array(self) -> np.ndarray:
        """The packed float64 parameter vector the kernels read (read-only)."""
        p = np.empty(N_PARAMS, dtype=np.float64)
        p[P_W], p[P_L], p[P_R], p[P_M] = self.table_width, self.table_length, self.ball_radius, self.ball_mass
        p[P_U_S], p[P_U_R], p[P_U_SP] = self.u_slide, self.u_roll, self.u_spin
        p[P_E_B], p[P_E_C], p[P_F_C], p[P_G], p[P_H] = self.e_ball, self.e_cushion, self.f_cushion, self.g, self.cushion_height
        p[P_CUE_M], p[P_CUE_V_MAX], p[P_MAX_ENGLISH] = self.cue_mass, self.cue_speed_max, self.max_english
        p[P_SQUIRT], p[P_CUE_END_M] = float(self.squirt), self.cue_end_mass
        p[P_BALL_BALL] = BALL_BALL_MODELS[self.ball_ball]
        p[P_MAX_EVENTS], p[P_MIN_DIST] = int(self.max_events), self.min_dist
        p.flags.writeable = False
        return p

    def as_array(self) -> np.ndarray:
        return self.array

    @property
    def cushion_angle(self) -> float:
        """Han's contact angle theta_a = asin(h/R - 1) (rad)."""
        return math.asin(self.cushion_height / self.ball_radius - 1.0)


DEFAULT_PARAMS = PhysicsParams()
