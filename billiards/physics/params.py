"""Physical parameters of the table, balls, cushions and cue, in one immutable object.

Two named presets (:data:`PRESETS`), the single source of truth for every table the project
plays (``docs/physics.md`` §10):

* ``korean_medium`` -- **the default**: the table and values the paper's authors published
  (1.27 x 2.54 m, 65.5 mm balls, mu_r = 0.018, spin decay 50 rad/s^2, e_b = 0.94, f_c = 0.20,
  cue 0.55 kg at 4.5 m/s, tip offsets up to 1.0 R, a 12 s shot limit), its opening rack and
  its random-rack sampling (5 mm cushion margin, 2 mm pair clearance). ``PhysicsParams()``
  is this preset.
* ``international`` -- pooltool's pocketless BILLIARD table and BILLIARD_GENERIC balls
  (2.84 x 1.42 m, R = 30.75 mm), e_b = 0.95, cue 6 m/s at p = 1, tip offsets up to 0.6 R, runs
  to rest; the project's defaults before the presets existed.

Both use Han 2005 (corrected) cushions, equal-mass restitution ball–ball contact and the
level-cue instantaneous-point strike without squirt.

The numba kernels never see this dataclass: :attr:`PhysicsParams.array` packs it into a flat
float64 vector whose slots are the ``P_*`` indices below.
"""

from __future__ import annotations

import dataclasses
import math
from functools import cached_property

import numpy as np

from .checks import boolean, finite_number, integer, one_of

# Ball–ball contact models.
BALL_BALL_RESTITUTION = 0  # equal-mass restitution exchange (docs/physics.md §4b), the default
BALL_BALL_ELASTIC = 1  # frictionless elastic, e = 1 (docs/physics.md §4a)
BALL_BALL_MODELS = {"restitution": BALL_BALL_RESTITUTION, "elastic": BALL_BALL_ELASTIC}

# Slots of the packed parameter vector.
P_W, P_L, P_R, P_M, P_U_S, P_U_R, P_U_SP, P_E_B, P_E_C, P_F_C, P_G, P_H = range(12)
P_CUE_M, P_CUE_V_MAX, P_MAX_ENGLISH, P_SQUIRT, P_CUE_END_M, P_BALL_BALL = range(12, 18)
P_MAX_EVENTS, P_MIN_DIST, P_MAX_TIME = 18, 19, 20
N_PARAMS = 21

# Opening racks (:func:`billiards.physics.canonical_rack`), by name.
RACKS = ("korean", "spots")


# Upper bounds of the physical parameters: generous (no real table comes near them) but finite,
# so that a typo such as a cue speed of 1e200 m/s is refused instead of simulated.
UPPER_BOUNDS = {
    "table_width": 10.0, "table_length": 10.0, "ball_radius": 0.5, "ball_mass": 10.0, "g": 100.0, "cue_mass": 10.0,
    "cue_speed_max": 50.0, "cushion_height": 1.0, "min_dist": 0.01, "u_slide": 5.0, "u_roll": 1.0, "u_spin": 10.0,
    "f_cushion": 5.0, "cue_end_mass": 10.0, "rack_margin": 1.0, "rack_clearance": 1.0,
}
MAX_TIME_BOUND = 3600.0  # seconds of one shot (or inf: to rest)
MAX_EVENTS_BOUND = 10_000_000  # events of one shot (the kernel's counter is an int64; the default is 5,000)
POSITIVE = ("table_width", "table_length", "ball_radius", "ball_mass", "g", "cue_mass", "cue_speed_max",
            "cushion_height", "min_dist", "u_slide", "u_roll", "u_spin")
NON_NEGATIVE = ("f_cushion", "cue_end_mass", "rack_margin", "rack_clearance")


def _positive(high: float):
    return lambda v, name: finite_number(v, name, 0.0, high, lo_open=True, what="a finite positive number",
                                         note="a physical bound")


def _non_negative(high: float):
    return lambda v, name: finite_number(v, name, 0.0, high, what="a finite number >= 0", note="a physical bound")


def _fraction(note: str = ""):
    return lambda v, name: finite_number(v, name, 0.0, 1.0, what=f"a finite number in [0, 1]{note}")


# The type and range of every field of PhysicsParams, in one place (checked by __post_init__
# in this order; the relations between fields, such as a rack that fits its table, after it).
FIELD_CHECKS = {
    **{name: _positive(UPPER_BOUNDS[name]) for name in POSITIVE},
    **{name: _non_negative(UPPER_BOUNDS[name]) for name in NON_NEGATIVE},
    "e_ball": _fraction(),
    "e_cushion": _fraction(),
    "max_english": _fraction(" (a miscue beyond)"),
    "squirt": boolean,
    "ball_ball": lambda v, name: one_of(v, name, tuple(BALL_BALL_MODELS)),
    "max_time": lambda v, name: finite_number(v, name, 0.0, MAX_TIME_BOUND, lo_open=True, allow_inf=True,
                                              what=f"a number of seconds in (0, {MAX_TIME_BOUND:g}] or inf "
                                                   "(run every shot to rest)"),
    "max_events": lambda v, name: integer(v, name, 1, MAX_EVENTS_BOUND),
    "rack": lambda v, name: one_of(v, name, RACKS),
}


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
    table_width: float = 1.27  # x extent of the playing surface (nose line to nose line)
    table_length: float = 2.54  # y extent
    cushion_height: float = 0.037  # nose height h above the cloth
    # balls
    ball_radius: float = 0.03275
    ball_mass: float = 0.21
    u_slide: float = 0.2  # mu_s, ball–cloth sliding friction
    u_roll: float = 0.018  # mu_r, rolling resistance
    u_spin: float = 0.0668  # mu_sp (a length): spin decays at 5 mu_sp g / (2R) = 50 rad/s^2 for R = 32.75 mm
    e_ball: float = 0.94  # ball–ball restitution
    e_cushion: float = 0.85  # ball–cushion restitution
    f_cushion: float = 0.20  # ball–cushion friction
    g: float = 9.81
    # cue
    cue_mass: float = 0.55
    cue_speed_max: float = 4.5  # cue speed at power p = 1 (m/s)
    max_english: float = 1.0  # tip offset radius at |(a, b)| = 1, fraction of R
    squirt: bool = False  # cue-ball deflection from side spin (docs/physics.md §1.3)
    cue_end_mass: float = 0.170097 / 30.0  # m_e, only used with squirt
    # models and numerics
    ball_ball: str = "restitution"  # "restitution" (§4b) or "elastic" (§4a)
    max_time: float = 12.0  # a shot is simulated for at most this many seconds, then every ball rests (inf: to rest)
    max_events: int = 5000  # safety net: a shot with more events is stopped (flagged)
    min_dist: float = 1e-6  # make_kiss spacer between touching bodies (m)
    # racks
    rack: str = "korean"  # the opening rack: "korean" (the paper's) or "spots" (see canonical_rack)
    rack_margin: float = 0.005  # random racks: every centre at least R + margin inside the nose lines (m)
    rack_clearance: float = 0.002  # random racks: every pair of centres at least 2R + clearance apart (m)

    def __post_init__(self) -> None:
        for name, check in FIELD_CHECKS.items():  # each field typed and ranged here, once
            check(getattr(self, name), f"PhysicsParams.{name}")
        if not self.ball_radius < self.cushion_height < 2 * self.ball_radius:
            raise ValueError("PhysicsParams.cushion_height must lie between R and 2R for the Han cushion model")
        # Random racks need room for four balls with the margin and clearance; the opening rack
        # is checked by canonical_rack's own layout (see billiards.physics.api).
        inner_w = self.table_width - 2 * (self.ball_radius + self.rack_margin)
        inner_l = self.table_length - 2 * (self.ball_radius + self.rack_margin)
        pitch = 2 * self.ball_radius + self.rack_clearance
        if min(inner_w, inner_l) < 0 or inner_w * inner_l < 4 * pitch * pitch:
            raise ValueError(
                f"PhysicsParams: a {self.table_width} x {self.table_length} m table cannot hold four balls of "
                f"radius {self.ball_radius} m {self.rack_margin} m inside the cushions and {self.rack_clearance} m apart"
            )
        self._check_opening_rack()

    def opening_rack(self) -> np.ndarray:
        """The opening rack (4, 2) of this table (white, yellow, red1, red2); see
        :func:`billiards.physics.canonical_rack` for the layouts."""
        w, l, R = self.table_width, self.table_length, self.ball_radius
        if self.rack == "korean":
            rack = [[w / 2 + 4 * R, 6 * l / 8], [w / 2, l / 8], [w / 2, 2 * l / 8], [w / 2, 6 * l / 8]]
        else:
            rack = [[w - 0.2, l / 4], [0.2, l / 4], [w / 2, l / 4], [w / 2, 3 * l / 4]]
        return np.array(rack, dtype=np.float64)

    def _check_opening_rack(self) -> None:
        rack, R = self.opening_rack(), self.ball_radius
        on_table = ((rack >= R) & (rack <= [self.table_width - R, self.table_length - R])).all()
        gaps = [np.hypot(*(rack[i] - rack[j])) for i in range(4) for j in range(i + 1, 4)]
        if not on_table or min(gaps) < 2 * R:
            raise ValueError(
                f"PhysicsParams: the {self.rack!r} opening rack does not fit a {self.table_width} x "
                f"{self.table_length} m table with balls of radius {R} m: {rack.tolist()}"
            )

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
        p[P_MAX_EVENTS], p[P_MIN_DIST], p[P_MAX_TIME] = int(self.max_events), self.min_dist, self.max_time
        p.flags.writeable = False
        return p

    @property
    def cushion_angle(self) -> float:
        """Han's contact angle theta_a = asin(h/R - 1) (rad)."""
        return math.asin(self.cushion_height / self.ball_radius - 1.0)


    def to_dict(self) -> dict:
        """Every field as a plain JSON-able dict (``PhysicsParams(**d)`` rebuilds it; max_time
        inf is written as the string "inf")."""
        d = dataclasses.asdict(self)
        if math.isinf(d["max_time"]):
            d["max_time"] = "inf"
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "PhysicsParams":
        """The inverse of :meth:`to_dict`; unknown keys raise a ValueError naming them."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown PhysicsParams field(s) {unknown}; known: {sorted(known)}")
        d = dict(d)
        if isinstance(d.get("max_time"), str):
            d["max_time"] = float(d["max_time"])
        return cls(**d)

    def preset_name(self) -> str | None:
        """The name of the preset these parameters equal, or None for custom physics."""
        return next((name for name, p in PRESETS.items() if p == self), None)

    def describe(self) -> str:
        """A short label: the preset's name, or "custom" with the fields that differ from the
        nearest preset (e.g. ``korean_medium+u_roll=0.02``)."""
        name = self.preset_name()
        if name:
            return name
        base_name, diff = min(((n, _diff(p, self)) for n, p in PRESETS.items()), key=lambda x: len(x[1]))
        return base_name + "".join(f"+{k}={v}" for k, v in diff.items())


assert list(FIELD_CHECKS) != [] and set(FIELD_CHECKS) == {f.name for f in dataclasses.fields(PhysicsParams)}


def _diff(base: PhysicsParams, other: PhysicsParams) -> dict:
    return {f.name: getattr(other, f.name) for f in dataclasses.fields(PhysicsParams)
            if getattr(other, f.name) != getattr(base, f.name)}


PRESETS: dict[str, PhysicsParams] = {
    # The paper's table and values (docs/physics.md §10): the field defaults.
    "korean_medium": PhysicsParams(),
    # pooltool's BILLIARD table and BILLIARD_GENERIC balls (the project's defaults before §10).
    "international": PhysicsParams(
        table_width=1.42, table_length=2.84, ball_radius=0.03075, u_roll=0.01, u_spin=0.03075 * 4.0 / 9.0,
        e_ball=0.95, f_cushion=0.15, cue_mass=0.567, cue_speed_max=6.0, max_english=0.6, max_time=math.inf,
        rack="spots", rack_margin=0.0, rack_clearance=0.0,
    ),
}
DEFAULT_PRESET = "korean_medium"
DEFAULT_PARAMS = PRESETS[DEFAULT_PRESET]


def get_params(physics=None) -> PhysicsParams:
    """PhysicsParams from anything a user may pass: None (the default preset), a preset name,
    a PhysicsParams, or a dict of fields (optionally with ``"preset"`` naming the base the other
    fields override). Raises ValueError naming a bad preset or field."""
    if physics is None:
        return DEFAULT_PARAMS
    if isinstance(physics, PhysicsParams):
        return physics
    if isinstance(physics, str):
        if physics not in PRESETS:
            raise ValueError(f"unknown physics preset {physics!r}; presets: {sorted(PRESETS)}")
        return PRESETS[physics]
    if isinstance(physics, dict):
        d = dict(physics)
        base = get_params(d.pop("preset", DEFAULT_PRESET))
        if not d:
            return base
        merged = base.to_dict()
        known = set(merged)
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown physics field(s) {unknown}; known: {sorted(known)}")
        merged.update(d)
        return PhysicsParams.from_dict(merged)
    raise ValueError(f"physics must be a preset name, a PhysicsParams or a dict, got {type(physics).__name__}")
