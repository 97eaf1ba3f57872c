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
through unchanged, bit for bit), ``fastfiz`` (0.125 deg, 0.075 m/s, 0.5 mm) and ``fastfiz_x5``
(five times each). Pure NumPy; the random numbers come from the caller's generator.

The apps' ``noise`` config node (:class:`NoiseConfig`, ``conf/noise/<preset>.yaml``) is a preset
plus optional per-sigma overrides (``noise.aim_deg=0.3``), turned into a model by
:func:`noise_from_config` and recorded in result files by :func:`noise_record`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Optional

import numpy as np

from .params import DEFAULT_PARAMS, PhysicsParams


@dataclasses.dataclass(frozen=True)
class NoiseModel:
    """Standard deviations of the execution errors, in physical units (0 = exact)."""

    sigma_aim_deg: float = 0.0  # aim angle (degrees)
    sigma_speed: float = 0.0  # cue speed (m/s)
    sigma_tip_mm: float = 0.0  # each tip offset coordinate (mm)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"NoiseModel.{f.name} must be a finite number >= 0, got {value!r}")

    @property
    def is_exact(self) -> bool:
        return self.sigma_aim_deg == 0 and self.sigma_speed == 0 and self.sigma_tip_mm == 0

    def scaled(self, factor: float) -> "NoiseModel":
        return NoiseModel(*(factor * getattr(self, f.name) for f in dataclasses.fields(self)))

    def describe(self) -> str:
        """The preset's name when the sigmas are a preset's, else the sigmas themselves."""
        for name, model in NOISE_PRESETS.items():
            if model == self:
                return name
        return f"custom(aim_deg={self.sigma_aim_deg:g}, speed={self.sigma_speed:g}, tip_mm={self.sigma_tip_mm:g})"

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

    def perturb(self, actions, rng: np.random.Generator, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
        """The played actions for commanded ``actions`` (..., 4): a new float64 array. With an
        exact model the actions come back unchanged and ``rng`` is not touched."""
        actions = np.array(actions, dtype=np.float64)
        if self.is_exact:
            return actions
        return self.apply(actions, self.draw(actions.shape[:-1], rng), params)


NOISE_PRESETS: dict[str, NoiseModel] = {
    "none": NoiseModel(),
    "fastfiz": NoiseModel(sigma_aim_deg=0.125, sigma_speed=0.075, sigma_tip_mm=0.5),
    "fastfiz_x5": NoiseModel(sigma_aim_deg=0.625, sigma_speed=0.375, sigma_tip_mm=2.5),
}


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
        known = {f.name for f in dataclasses.fields(NoiseModel)}
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
    """The ``noise`` node of ``train.py`` and ``search.py``: a preset (``noise=fastfiz``) and
    optional overrides of its sigmas (null: the preset's value): ``noise.aim_deg`` (degrees),
    ``noise.speed`` (m/s), ``noise.tip_mm`` (mm)."""

    preset: str = "none"
    aim_deg: Optional[float] = None
    speed: Optional[float] = None
    tip_mm: Optional[float] = None


def noise_from_config(node: Any | None) -> NoiseModel:
    """The NoiseModel a ``noise`` config node describes (None, e.g. a config saved before the
    node existed: exact play)."""
    if node is None:
        return NOISE_PRESETS["none"]
    base = get_noise(str(node["preset"]))
    overrides = {field: node[key] for key, field in CONFIG_FIELDS.items() if node.get(key) is not None}
    return dataclasses.replace(base, **overrides) if overrides else base


def noise_errors(node: Any) -> list[str]:
    """Problems of a ``noise`` config node, each naming its key (empty if it is valid)."""
    if node["preset"] not in NOISE_PRESETS:
        return [f"noise.preset={node['preset']!r} is not a noise preset; presets: {', '.join(NOISE_PRESETS)} "
                f"(choose one with noise=<name>)"]
    for key, field in CONFIG_FIELDS.items():
        value = node.get(key)
        if value is not None and not (math.isfinite(value) and value >= 0):
            return [f"noise.{key} must be a finite number >= 0 (a standard deviation), got {value!r}"]
    return []


def noise_record(model: NoiseModel) -> dict:
    """What a result file records of its execution noise: ``{"noise": label, "noise_sigmas":
    {"aim_deg", "speed", "tip_mm"}}``."""
    return {"noise": model.describe(),
            "noise_sigmas": {key: getattr(model, field) for key, field in CONFIG_FIELDS.items()}}


__all__ = ["CONFIG_FIELDS", "NOISE_PRESETS", "NoiseConfig", "NoiseModel", "get_noise", "noise_errors",
           "noise_from_config", "noise_record"]
