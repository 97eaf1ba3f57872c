"""Execution noise: the shot actually played differs from the shot commanded.

The model lives in physical units, as the computational-billiards tournaments (FastFiz) define
it: independent Gaussian errors on the aim angle (degrees), on the cue speed (m/s) and on each
tip offset (mm). It acts on actions ``(theta, p, a, b)`` through the table's own conversion
(``cue_speed_max``, ``max_english``, ``ball_radius``), so the simulator itself stays exact and
deterministic: noise only changes which shot it is asked to play.

* ``theta' = theta + N(0, sigma_aim_deg)`` (in radians);
* ``V0' = clip(V0 + N(0, sigma_speed), 0, cue_speed_max)``, i.e. ``p' = V0' / cue_speed_max``
  (the cue cannot be struck harder than the table's maximum);
* the contact offset ``(a, b) * max_english * R`` moves by ``N(0, sigma_tip_mm)`` mm per axis
  and is projected back onto the disk of radius ``max_english * R`` (no miscue model).

Presets (:data:`NOISE_PRESETS`): ``none`` (the default: no draw is made and actions pass
through unchanged, bit for bit), ``fastfiz`` (0.125 deg, 0.075 m/s, 0.5 mm), ``fastfiz_x5``
(five times each) and ``variable`` (the tournaments' variable noise: each shot plays fastfiz's
sigmas times its own *level*, drawn uniformly from [0, 5] and told to the player before it
shoots). Pure NumPy; the random numbers come from the caller's generator.

Variable noise is a model with a ``level_range``: the env draws each shot's level
(:meth:`NoiseModel.draw_levels`, from its own noise generator, when it produces the observation
for that shot) and plays ``apply(actions, level * z)`` (:meth:`NoiseModel.perturb` with
``levels``): level 0 plays the commanded shot exactly, level 1 the model's sigmas.

The apps' ``noise`` config node (:class:`NoiseConfig`, ``conf/noise/<preset>.yaml``) is a preset
plus optional per-sigma overrides (``noise.aim_deg=0.3``), a multiplier of all sigmas
(``noise.scale=2``; 1 leaves the preset as it is, bit for bit) and, for variable noise, the
levels' range (``noise.level_range=[0,5]``), turned into a model by :func:`noise_from_config`
and recorded in result files by :func:`noise_record`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, List, Optional

import numpy as np

from .checks import ContractError, finite_number, real_array
from .params import DEFAULT_PARAMS, UPPER_BOUNDS, PhysicsParams


SIGMA_FIELDS = ("sigma_aim_deg", "sigma_speed", "sigma_tip_mm")
# The largest standard deviation of each error a model may play (its sigma times its top
# level): an aim error of a right angle, a speed error of the fastest cue any table allows
# (PhysicsParams' bound on cue_speed_max), a tip error of the largest ball's radius. Past these
# the shot played has nothing to do with the shot commanded (and 1e308 would overflow to inf).
SIGMA_CAPS = {
    "sigma_aim_deg": (90.0, "degrees: a right angle"),
    "sigma_speed": (UPPER_BOUNDS["cue_speed_max"], "m/s: the fastest cue speed any table allows"),
    "sigma_tip_mm": (1e3 * UPPER_BOUNDS["ball_radius"], "mm: the largest ball radius any table allows"),
}
MAX_LEVEL = 100.0  # the highest level (multiplier of the sigmas) a variable model may draw
# What an app's ``noise`` config node may ask for (:func:`noise_errors`), tighter than what a
# NoiseModel accepts: ``noise.scale`` at most MAX_SCALE, and each sigma (times the top level of
# variable noise) at most PRACTICAL_LEVEL times fastfiz's -- 1.25 degrees of aim, 0.75 m/s, 5 mm
# of tip. That is the bound match.py's observation tells a level up to (billiards.envs.sagu:
# MAX_NOISE_LEVEL, and its noise_cap_error, the same rule for the aim); the largest noise any
# result of the project plays is 5 times fastfiz's (noise=fastfiz_x5, noise.scale=5).
MAX_SCALE = 20.0
PRACTICAL_LEVEL = 10.0


def _is_level(value) -> bool:
    """A finite real number >= 0 (a standard deviation, a multiplier of one)."""
    return isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, (bool, np.bool_)) \
        and math.isfinite(value) and value >= 0


def sigma_cap_error(name: str, sigma: float, top: float = 1.0) -> str | None:
    """What is wrong with a sigma ``sigma`` of field ``name`` played up to level ``top`` (1 for
    fixed noise) if it passes its cap (:data:`SIGMA_CAPS`), else None."""
    cap, unit = SIGMA_CAPS[name]
    if sigma * top <= cap:
        return None
    levels = f" times the top level {top:g} of level_range" if top != 1 else ""
    return f"{name}{levels} must be at most {cap:g} ({unit}), got {sigma * top:g}"


@dataclasses.dataclass(frozen=True)
class NoiseModel:
    """Standard deviations of the execution errors, in physical units (0 = exact). With a
    ``level_range`` (low, high) the noise is *variable*: each shot plays these sigmas times its
    own level, drawn uniformly from [low, high] (:meth:`draw_levels`) and told to the player."""

    sigma_aim_deg: float = 0.0  # aim angle (degrees)
    sigma_speed: float = 0.0  # cue speed (m/s)
    sigma_tip_mm: float = 0.0  # each tip offset coordinate (mm)
    level_range: Optional[tuple[float, float]] = None  # variable noise: the per-shot level's range (None: fixed)
    # (preset, scale) a config's noise.scale made these sigmas of (noise_from_config): labels the
    # model (describe) and is recorded (noise_record); neither compared nor applied again
    origin: Optional[tuple[str, float]] = dataclasses.field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        for name in SIGMA_FIELDS:
            finite_number(getattr(self, name), f"NoiseModel.{name}", 0.0, SIGMA_CAPS[name][0],
                          what="a finite number >= 0", note=SIGMA_CAPS[name][1])
        top = 1.0
        if self.level_range is not None:
            levels = tuple(self.level_range) if isinstance(self.level_range, (tuple, list)) else ()
            if not (len(levels) == 2 and all(map(_is_level, levels)) and levels[0] <= levels[1] <= MAX_LEVEL):
                raise ContractError(f"NoiseModel.level_range must be (low, high), finite numbers with 0 <= low <= high "
                                    f"<= {MAX_LEVEL:g}, got {self.level_range!r}")
            object.__setattr__(self, "level_range", (float(levels[0]), float(levels[1])))
            top = self.level_range[1]
        for name in SIGMA_FIELDS:
            if err := sigma_cap_error(name, getattr(self, name), top):
                raise ContractError(f"NoiseModel.{err}")

    @property
    def is_variable(self) -> bool:
        """Whether each shot draws its own level (:attr:`level_range`)."""
        return self.level_range is not None

    @property
    def is_exact(self) -> bool:
        """Whether every shot is played as commanded (no sigma, or every level 0)."""
        no_sigma = self.sigma_aim_deg == 0 and self.sigma_speed == 0 and self.sigma_tip_mm == 0
        return no_sigma or (self.is_variable and self.level_range[1] == 0)

    def scaled(self, factor: float) -> "NoiseModel":
        """Every sigma times ``factor`` (a variable model keeps its levels' range)."""
        return NoiseModel(*(factor * getattr(self, name) for name in SIGMA_FIELDS), level_range=self.level_range)

    def describe(self) -> str:
        """The preset's name when the model is a preset's (``fastfiz*2`` for a preset scaled by
        ``noise.scale=2``), else the sigmas themselves (and the levels' range)."""
        if self.origin is not None:
            name, scale = self.origin
            base = NOISE_PRESETS.get(name)
            if base is not None and not base.is_exact and scale != 1 and base.scaled(scale) == self:
                return f"{name}*{scale:g}"
        for name, model in NOISE_PRESETS.items():
            if model == self:
                return name
        levels = f", levels={self.level_range[0]:g}-{self.level_range[1]:g}" if self.is_variable else ""
        return (f"custom(aim_deg={self.sigma_aim_deg:g}, speed={self.sigma_speed:g}, "
                f"tip_mm={self.sigma_tip_mm:g}{levels})")

    def draw_levels(self, shape, rng: np.random.Generator) -> np.ndarray:
        """Levels of the next shots (``shape``, float64) of a variable model: uniform on
        :attr:`level_range`, from ``rng``, each rounded to float32 (so that the level a float32
        observation tells is the level played) within the range."""
        if not self.is_variable:
            raise ValueError(f"noise {self.describe()} has no per-shot levels (it is not variable)")
        low, high = self.level_range
        return np.clip(rng.uniform(low, high, shape).astype(np.float32).astype(np.float64), low, high)

    def draw(self, shape, rng: np.random.Generator) -> np.ndarray:
        """Standard normal errors ``z`` (``shape`` + (4,): aim, speed, tip a, tip b) for
        :meth:`apply`, drawn in the order :meth:`perturb` has always drawn them."""
        shape = tuple(shape)
        z = np.empty(shape + (4,))
        z[..., 0] = rng.standard_normal(shape)
        z[..., 1] = rng.standard_normal(shape)
        z[..., 2:4] = rng.standard_normal(shape + (2,))
        return z

    def apply(self, actions, z, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
        """The played actions for commanded ``actions`` (..., 4) and standard normal errors
        ``z`` (..., 4) (aim, speed, tip a, tip b; random from :meth:`draw`, or chosen points
        such as sigma points): a new float64 array."""
        actions = np.array(actions, dtype=np.float64)
        z = np.broadcast_to(np.asarray(z, dtype=np.float64), actions.shape)
        played = actions.copy()
        played[..., 0] += np.radians(self.sigma_aim_deg) * z[..., 0]
        v0 = actions[..., 1] * params.cue_speed_max + self.sigma_speed * z[..., 1]
        played[..., 1] = np.clip(v0, 0.0, params.cue_speed_max) / params.cue_speed_max
        # tip offsets: from the action's unit disk to millimetres of contact offset and back
        mm_per_unit = 1e3 * params.max_english * params.ball_radius
        ab = actions[..., 2:4].copy()
        norm = np.linalg.norm(ab, axis=-1, keepdims=True)
        ab /= np.maximum(norm, 1.0)  # the simulator's own projection onto the unit disk
        if mm_per_unit > 0:
            ab += (self.sigma_tip_mm / mm_per_unit) * z[..., 2:4]
            norm = np.linalg.norm(ab, axis=-1, keepdims=True)
            ab /= np.maximum(norm, 1.0)
        played[..., 2:4] = ab
        return played

    def perturb(self, actions, rng: np.random.Generator, params: PhysicsParams = DEFAULT_PARAMS,
                levels=None) -> np.ndarray:
        """The played actions for commanded ``actions`` (..., 4): a new float64 array. With an
        exact model the actions come back unchanged and ``rng`` is not touched.

        ``levels`` (broadcast to ...), optional: each shot's multiplier of the sigmas (variable
        noise: the level the env drew and told); the errors are ``level * z``, and a shot at
        level 0 is played exactly as commanded. A variable model given no levels draws each
        shot's level after its errors (:meth:`draw_levels`: a shot whose level nobody was told)."""
        actions = np.array(actions, dtype=np.float64)
        if self.is_exact:
            return actions
        z = self.draw(actions.shape[:-1], rng)
        if levels is None and self.is_variable:
            levels = self.draw_levels(actions.shape[:-1], rng)
        if levels is None:
            return self.apply(actions, z, params)
        levels = np.broadcast_to(real_array(levels, "levels", finite=True, lo=0.0), actions.shape[:-1])
        played = self.apply(actions, z * levels[..., None], params)
        exact = levels == 0
        played[exact] = actions[exact]  # level 0: the commanded shot, bit for bit
        return played


NOISE_PRESETS: dict[str, NoiseModel] = {
    "none": NoiseModel(),
    "fastfiz": NoiseModel(sigma_aim_deg=0.125, sigma_speed=0.075, sigma_tip_mm=0.5),
    "fastfiz_x5": NoiseModel(sigma_aim_deg=0.625, sigma_speed=0.375, sigma_tip_mm=2.5),
    # the tournaments' variable noise: fastfiz's sigmas times a level drawn per shot from [0, 5]
    "variable": NoiseModel(sigma_aim_deg=0.125, sigma_speed=0.075, sigma_tip_mm=0.5, level_range=(0.0, 5.0)),
}


def noise_level(noise: NoiseModel) -> float:
    """The execution noise's aim sigma in units of fastfiz's (0 for exact play); of variable
    noise, that of its level 1 (a shot's level is this times the shot's multiplier)."""
    base = NOISE_PRESETS["fastfiz"].sigma_aim_deg
    return float(noise.sigma_aim_deg / base) if base else 0.0


def get_noise(noise=None) -> NoiseModel:
    """A NoiseModel from None (exact), a preset name, a NoiseModel or a dict of sigmas."""
    if noise is None:
        return NOISE_PRESETS["none"]
    if isinstance(noise, NoiseModel):
        return noise
    if isinstance(noise, str):
        if noise not in NOISE_PRESETS:
            raise ValueError(f"unknown noise preset {noise!r}; presets: {sorted(NOISE_PRESETS)}")
        return NOISE_PRESETS[noise]
    if isinstance(noise, dict):
        known = {*SIGMA_FIELDS, "level_range"}
        unknown = sorted(set(noise) - known)
        if unknown:
            raise ValueError(f"unknown noise field(s) {unknown}; known: {sorted(known)}")
        return NoiseModel(**noise)
    raise ValueError(f"noise must be a preset name, a NoiseModel or a dict, got {type(noise).__name__}")


# ----------------------------------------------------------------------------- the apps' config node

# NoiseConfig key -> NoiseModel field (the config's short names: noise.aim_deg=0.3)
CONFIG_FIELDS = {"aim_deg": "sigma_aim_deg", "speed": "sigma_speed", "tip_mm": "sigma_tip_mm"}


@dataclasses.dataclass
class NoiseConfig:
    """The ``noise`` node of ``train.py``, ``search.py`` and ``match.py``: a preset
    (``noise=fastfiz``) and optional overrides of its sigmas (null: the preset's value):
    ``noise.aim_deg`` (degrees), ``noise.speed`` (m/s), ``noise.tip_mm`` (mm); ``noise.scale``
    multiplies every sigma (after the overrides; 1, the default, leaves them as they are);
    ``noise.level_range`` ([low, high]; null: the preset's) makes the noise variable, each shot
    at its own level drawn from that range."""

    preset: str = "none"
    aim_deg: Optional[float] = None
    speed: Optional[float] = None
    tip_mm: Optional[float] = None
    scale: float = 1.0
    level_range: Optional[List[float]] = None


def noise_from_config(node: Any | None) -> NoiseModel:
    """The NoiseModel a ``noise`` config node describes (a DictConfig of :class:`NoiseConfig`,
    or a plain dict: a key it leaves out takes NoiseConfig's default, as a null does; None: the
    default, exact play, as :func:`billiards.physics.config.params_from_config` gives the
    default table). A saved config is read through :mod:`billiards.compat` first, which gives it
    its node."""
    if node is None:
        return NOISE_PRESETS[NoiseConfig.preset]
    preset = str(node["preset"])
    base = get_noise(preset)
    overrides = {field: node[key] for key, field in CONFIG_FIELDS.items() if node.get(key) is not None}
    if node.get("level_range") is not None:
        overrides["level_range"] = tuple(node["level_range"])
    model = dataclasses.replace(base, **overrides) if overrides else base
    scale = node.get("scale")
    if scale is not None and scale != 1:
        model = dataclasses.replace(model.scaled(scale), origin=(preset, float(scale)))
    return model


def noise_errors(node: Any) -> list[str]:
    """Problems of a ``noise`` config node, each naming its key (empty if it is valid)."""
    if node["preset"] not in NOISE_PRESETS:
        return [f"noise.preset={node['preset']!r} is not a noise preset; presets: {', '.join(NOISE_PRESETS)} "
                f"(choose one with noise=<name>)"]
    for key, field in CONFIG_FIELDS.items():
        value = node.get(key)
        if value is not None and not _is_level(value):
            return [f"noise.{key} must be a finite number >= 0 (a standard deviation), got {value!r}"]
        if value is not None and (err := sigma_cap_error(field, value)):
            return [f"noise.{key}: {err}"]
    scale = node.get("scale")
    if scale is not None and not _is_level(scale):
        return [f"noise.scale must be a finite number >= 0 (a multiplier of the preset's sigmas; 1 keeps them), "
                f"got {scale!r}"]
    if scale is not None and scale > MAX_SCALE:
        return [f"noise.scale must be at most {MAX_SCALE:g} (a multiplier of the preset's sigmas), got {scale!r}"]
    levels = node.get("level_range")
    if levels is not None:
        levels = list(levels)
        if not (len(levels) == 2 and all(map(_is_level, levels)) and levels[0] <= levels[1]):
            return [f"noise.level_range must be [low, high], finite numbers with 0 <= low <= high (each shot's "
                    f"multiplier of the sigmas is drawn uniformly from it), got {levels!r}"]
    try:  # the sigmas the preset, the overrides, the scale and the levels make together, within their caps
        model = noise_from_config(node)
    except ValueError as err:
        return [f"noise: {err}"]
    err = practical_noise_error(model)
    return [err] if err else []


def practical_noise_error(model: NoiseModel) -> str | None:
    """What is wrong with the noise an app's config asks for if a sigma, times the top level of
    variable noise, passes :data:`PRACTICAL_LEVEL` times fastfiz's (aim, then speed, then tip),
    else None."""
    base = NOISE_PRESETS["fastfiz"]
    top = model.level_range[1] if model.is_variable else 1.0
    for (key, field), what in zip(CONFIG_FIELDS.items(), ("aim", "speed", "tip")):
        times = getattr(model, field) / getattr(base, field) * top
        if times > PRACTICAL_LEVEL * (1 + 1e-9):
            return (f"noise: at most {PRACTICAL_LEVEL:g} times fastfiz's {what} sigma, got {times:g} (noise.{key} times "
                    f"noise.scale and the top level of variable noise; past it no shot is played as commanded)")
    return None


def noise_record(model: NoiseModel) -> dict:
    """What a result file records of its execution noise: ``{"noise": label, "noise_sigmas":
    {"aim_deg", "speed", "tip_mm"}, "noise_scale": the config's noise.scale}`` (the sigmas
    played, the scale already in them), and for variable noise ``"noise_levels": [low, high]``."""
    record = {"noise": model.describe(),
              "noise_sigmas": {key: getattr(model, field) for key, field in CONFIG_FIELDS.items()},
              "noise_scale": model.origin[1] if model.origin is not None else 1.0}
    if model.is_variable:
        record["noise_levels"] = list(model.level_range)
    return record


__all__ = ["CONFIG_FIELDS", "MAX_LEVEL", "MAX_SCALE", "NOISE_PRESETS", "PRACTICAL_LEVEL", "SIGMA_CAPS", "SIGMA_FIELDS",
           "NoiseConfig", "NoiseModel", "get_noise", "noise_errors", "noise_from_config", "noise_level", "noise_record",
           "practical_noise_error", "sigma_cap_error"]
