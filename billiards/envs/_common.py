"""The step code shared by the gymnasium and the TorchRL environment: pure NumPy, no torch.

Both envs are thin layers over these functions (the gymnasium env calls them on a batch of
one, the TorchRL env and its transforms on B innings), and over the domain math of
:mod:`billiards.domain` (observation, action maps, shaping terms):

* the inning options: :func:`check_inning_options`, :func:`resolve_paradigm`,
  :func:`initial_racks`, :func:`terminated_truncated`;
* the action a policy emits: :func:`validate_action`, :func:`unnormalize_checked`;
* one step of B innings: :func:`play_shots` (execution noise, simulation, inning end);
* the reward shaping's coefficients, checked once: :class:`Shaping` (of the one schema,
  :class:`billiards.shaping.ShapingOptions`, which :class:`EnvOptions` extends too).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from billiards import domain
from billiards.physics import (
    DEFAULT_PARAMS,
    BatchResult,
    PhysicsParams,
    canonical_rack,
    random_racks,
    simulate_batch,
)
from billiards.physics.checks import boolean, integer, one_of, real_array
from billiards.physics.noise import NoiseModel
from billiards.shaping import ShapingOptions

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


MAX_SHOTS = 10**9  # the longest inning an env plays (the shot counter's specs are int64)


def check_inning_options(start: str, on_miss: str, max_shots: int) -> int:
    """Validate the inning options; returns max_shots as an int (an integer, not a boolean or
    a float, in [1, MAX_SHOTS])."""
    one_of(start, "start", STARTS)
    one_of(on_miss, "on_miss", ON_MISS)
    return integer(max_shots, "max_shots", 1, MAX_SHOTS)


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


def next_levels(noise: NoiseModel, rng, n: int) -> np.ndarray | None:
    """The noise levels of the next shots of ``n`` innings (n,) float64 under variable noise,
    drawn from ``rng`` (a Generator, or a sequence of n of them, one per inning); None for
    fixed noise (nothing is drawn)."""
    if not noise.is_variable:
        return None
    if isinstance(rng, np.random.Generator):
        return noise.draw_levels((n,), rng)
    return np.concatenate([noise.draw_levels((1,), r) for r in rng]) if n else np.zeros(0)


def with_levels(obs: np.ndarray, levels: np.ndarray | None) -> np.ndarray:
    """Observations (..., n) with each shot's noise level appended last (variable noise): (..., n
    + 1) float32; unchanged without levels."""
    if levels is None:
        return obs
    return np.concatenate([obs, np.asarray(levels, dtype=np.float32)[..., None]], axis=-1)


def check_flag(name: str, value) -> bool:
    """A boolean option as a bool, or a TypeError (:func:`billiards.physics.checks.boolean`):
    ``constrain_aim="no"`` is not a boolean (``bool("no")`` would be True)."""
    return boolean(value, name)


def validate_action(action, expected_shape: tuple[int, ...]) -> np.ndarray:
    """The action as a float64 array of exactly ``expected_shape``, or a ValueError that names
    the key ``"action"`` and the expected shape (:func:`billiards.physics.checks.real_array`:
    real numbers, no masked array, a tensor's values). Checks type, shape and finiteness here;
    the simulator then checks the ranges of p, a and b (also naming ``action``), and
    :func:`check_aim_offset` the u of the aim constraint."""
    if action is None:
        raise ValueError(f'missing "action": expected a tensor of shape {expected_shape} = (theta, p, a, b) per shot')
    return real_array(action, '"action"', tuple(expected_shape), finite=True, note=" = (theta, p, a, b) per shot")


def check_aim_offset(action: np.ndarray) -> np.ndarray:
    """``action`` (..., 4) whose first coordinate is the aim constraint's u, or a ValueError
    naming ``"action"`` if some u lies outside [-1, 1]: u chooses an aim inside the window
    where the nearest red is hit first (:func:`billiards.domain.constrained_theta`), and the
    action space says so. Every env that takes u checks it here (the gymnasium envs, the
    two-player env and the TorchRL ``AimConstraint``)."""
    u = action[..., 0]
    if not (np.abs(u) <= 1.0).all():
        bad = np.flatnonzero(~(np.abs(u.reshape(-1)) <= 1.0))
        raise ValueError(f'"action" has the aim constraint: u = action[..., 0] must lie in [-1, 1] (the aim window of '
                         f'the nearest red), got {u.reshape(-1)[bad[0]].item()!r}'
                         + (f" in row {bad[0]}" if u.size > 1 else ""))
    return action


def unnormalize_checked(x: np.ndarray, constrain_aim: bool = False) -> np.ndarray:
    """The normalised action x (..., 4) as the raw one (:func:`billiards.domain.unnormalize_action`),
    or a ValueError naming ``"action"`` if a power or tip coordinate x1, x2, x3 lies outside
    [-1, 1], or, with the aim constraint, the aim coordinate u = x0 (:func:`check_aim_offset`;
    without it x0 may: theta wraps)."""
    x = np.asarray(x, dtype=np.float64)
    if np.any(np.abs(x[..., 1:]) > 1.0):
        bad = x.reshape(-1, x.shape[-1])
        row = bad[np.any(np.abs(bad[:, 1:]) > 1.0, axis=1)][0]
        raise ValueError(f'"action" is normalised: x1, x2, x3 (power, tip offsets) must lie in [-1, 1]; got {row.tolist()}')
    if constrain_aim:
        check_aim_offset(x)
    return domain.unnormalize_action(x, constrain_aim)


class Shots(NamedTuple):
    """What :func:`play_shots` returns for B innings (every field has leading dim B)."""

    played: np.ndarray  # (B, 4) float64: the raw shots simulated (the commanded ones, perturbed by the noise)
    result: BatchResult  # the simulator's outcome, rest positions included
    shot: np.ndarray  # (B,) int64: shots played in each inning, this one included
    terminated: np.ndarray  # (B,) bool
    truncated: np.ndarray  # (B,) bool
    commanded: np.ndarray  # (B, 4) float64: the raw shots asked for (``played`` without the noise)


def play_shots(positions: np.ndarray, commanded: np.ndarray, shots_before: np.ndarray, *, params: PhysicsParams,
               noise: NoiseModel, rng, on_miss: str, max_shots: int, levels: np.ndarray | None = None) -> Shots:
    """One step of B innings, the step of both envs: the commanded raw shots (B, 4) perturbed
    by the execution noise (its draws from ``rng``, a Generator, or a sequence of B of them,
    one per inning, each perturbing its own shot as a batch of one; an exact model draws
    nothing and plays them bit for bit; ``levels`` (B,): each shot's noise level under
    variable noise, :meth:`~billiards.physics.noise.NoiseModel.perturb`), simulated from the
    tables ``positions`` (B, 4, 2) in one ``simulate_batch`` call, and each inning's end
    (:func:`terminated_truncated`) after it."""
    if noise.is_exact or isinstance(rng, np.random.Generator):
        played = noise.perturb(commanded, rng, params, levels=levels)
    else:
        each = [None] * len(commanded) if levels is None else np.asarray(levels)[:, None]
        played = np.concatenate([noise.perturb(shot[None], r, params, levels=lv)
                                 for shot, r, lv in zip(commanded, rng, each, strict=True)])
    result = simulate_batch(positions, played, params)
    shot = np.asarray(shots_before) + 1
    terminated, truncated = terminated_truncated(result.score, shot, on_miss, max_shots)
    return Shots(played, result, shot, terminated, truncated, np.asarray(commanded, dtype=np.float64))


class _ReadOnly:
    """What ``dataclass(frozen=True)`` gives, for a dataclass derived from the mutable shaping
    schema (:class:`billiards.shaping.ShapingOptions`, mutable because the training config's
    Hydra schema derives from it too; a frozen dataclass cannot derive from a mutable one):
    ``__init__`` sets each field once; assigning or deleting one afterwards raises
    ``dataclasses.FrozenInstanceError``. With ``unsafe_hash=True`` the instances hash by value,
    as frozen ones do."""

    def __setattr__(self, name: str, value) -> None:
        if name in self.__dict__ or name not in self.__dataclass_fields__:
            raise dataclasses.FrozenInstanceError(f"cannot assign to field {name!r}")
        object.__setattr__(self, name, value)

    def __delattr__(self, name: str) -> None:
        raise dataclasses.FrozenInstanceError(f"cannot delete field {name!r}")


@dataclasses.dataclass(unsafe_hash=True, kw_only=True)
class Shaping(_ReadOnly, ShapingOptions):
    """The reward-shaping coefficients of an env (:class:`~billiards.shaping.ShapingOptions`,
    the one schema), checked once where they enter (a ValueError names the field as passed: NaN,
    inf or negative, ``near_miss_sigma`` <= 0, or an unknown ``gentle_kind``); read-only. The
    terms are :func:`billiards.domain.shaped_reward`'s (the TorchRL transforms add them one by
    one; the reward model's, ``rm``, only they)."""

    def __post_init__(self) -> None:
        for name in ("foul_penalty", "gentle", "near_miss"):
            object.__setattr__(self, name, domain.check_coefficient(name, getattr(self, name)))
        object.__setattr__(self, "near_miss_sigma", domain.check_coefficient("near_miss_sigma", self.near_miss_sigma, strict=True))
        if self.gentle_kind not in domain.GENTLE_KINDS:
            raise ValueError(f"gentle_kind must be one of {domain.GENTLE_KINDS}, got {self.gentle_kind!r}")
        object.__setattr__(self, "rm", domain.check_coefficient("rm", self.rm))

    @classmethod
    def of(cls, options: ShapingOptions) -> Shaping:
        """The shaping fields of ``options`` (an :class:`EnvOptions`, any ShapingOptions), checked."""
        return cls(**{f.name: getattr(options, f.name) for f in dataclasses.fields(ShapingOptions)})

    def reward(self, shots: Shots) -> np.ndarray:
        """(B,) float64: the carom score plus every enabled term but the reward model's, for
        the shots played. The power-based gentle bonus reads the *commanded* power (the agent's
        choice, as the TorchRL transform does): under execution noise the played power differs
        from it."""
        res = shots.result
        return domain.shaped_reward(res.score, res.foul, shots.commanded[..., 1], res.hits, res.closest, res.positions,
                                    res.second_red, foul_c=self.foul_penalty, gentle_beta=self.gentle,
                                    gentle_kind=self.gentle_kind, near_miss_beta=self.near_miss,
                                    near_miss_sigma=self.near_miss_sigma)


@dataclasses.dataclass(unsafe_hash=True, kw_only=True)
class EnvOptions(_ReadOnly, ShapingOptions):
    """Everything :func:`billiards.envs.make_env` builds an env from but its batch size and seed,
    as one object: what a training config means for its env
    (:func:`billiards.rl.config.env_options`), passed whole (``make_env(B, options, seed=s)``).
    The fields are ``make_env``'s keyword arguments, with the same defaults and meaning: the
    shaping's (:class:`~billiards.shaping.ShapingOptions`, the one schema) and the ones below;
    they are checked when the env is built. Read-only, keywords only."""

    start: str | None = None
    on_miss: str | None = None
    paradigm: str | None = None
    max_shots: int = 10
    constrain_aim: bool = False
    normalize_actions: bool = False
    extra_features: bool = False
    params: object = None
    noise: object = None
