"""Gymnasium environment: one Korean 4-ball inning, one step per shot.

Registered as ``Billiards4Ball-v0`` when :mod:`billiards` is imported (``gym.make("billiards:Billiards4Ball-v0")``
imports it)::

    import gymnasium as gym, billiards
    env = gym.make("Billiards4Ball-v0", start="random", on_miss="continue", max_shots=10)
    env = gym.make("Billiards4Ball-v0", physics="international")   # another table (default korean_medium)

A thin layer over the step code the TorchRL env and its transforms run (``_common``:
:func:`~billiards.envs._common.play_shots`, :class:`~billiards.envs._common.Shaping`; and
:mod:`billiards.domain`: :func:`~billiards.domain.raw_action`,
:func:`~billiards.domain.observation`, :func:`~billiards.domain.action_bounds`), on a batch of
one, so ``constrain_aim``, ``extra_features`` and the shaping coefficients mean exactly what
they mean in :func:`billiards.envs.make_env`, and give the same shots. ``gymnasium.make_vec``
steps B of them as one batch (:mod:`billiards.envs.gym_vector`).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import gymnasium as gym
import numpy as np

from billiards import domain
from billiards.physics import PhysicsParams, check_positions, get_params
from billiards.physics.checks import one_of, real_array
from billiards.physics.noise import NoiseModel, get_noise

from ._common import (
    Shaping,
    check_aim_offset,
    check_flag,
    check_inning_options,
    initial_racks,
    next_levels,
    play_shots,
    unnormalize_checked,
    validate_action,
    with_levels,
)


INFO_KEYS = ("score", "foul", "miss", "first_contact", "second_red", "hits", "closest", "cushions",
             "n_events", "shot", "positions", "theta", "raw_action", "commanded_action")


RESET_OPTIONS = {"positions"}  # reset(options=...) keys: a typo is an error, not a random rack


def _has_pygame() -> bool:
    """Whether the optional human renderer can be imported (without importing it)."""
    import importlib.util

    return importlib.util.find_spec("pygame") is not None


class Billiards4BallInningEnv(gym.Env):
    """One inning of Korean 4-ball as a gymnasium env.

    Observation (float32): the 28 floats of :func:`billiards.domain.rest_observation`
    (4 balls x (x, y, vx, vy, wx, wy, wz) in ball order white, yellow, red1, red2; the velocity
    and spin slots are 0 at rest), then with ``extra_features`` the 4 carom features
    (d1, d2, sin phi, cos phi) of :func:`billiards.domain.carom_features` (32 floats), then
    under variable noise (``noise="variable"``) the next shot's noise level, last (29 or 33
    floats).

    Action (float32, 4): by default (``normalize_actions=True``) the normalised x in [-1, 1]^4,
    played as theta = pi (x0 + 1), p = (x1 + 1) / 2, a = x2, b = x3
    (:func:`billiards.domain.unnormalize_action`, the one definition of that map); with the aim
    constraint the first coordinate is u = x0 as below. With ``normalize_actions=False`` the
    paper's raw box (theta, p, a, b): theta in [0, 2pi] (any real is accepted and wrapped),
    power p in [0, 1], tip offsets a, b in [-1, 1]. With ``constrain_aim`` the first
    coordinate is u in [-1, 1] and theta = theta_target + u * asin(min(1, 2R/d))
    (:func:`billiards.domain.constrained_theta`); a u outside [-1, 1] is refused.

    Reward: the carom score in {0, 1}, plus the shaping terms whose coefficient is non-zero
    (:func:`billiards.domain.shaped_reward`): ``-foul_penalty * foul``,
    the gentle bonus (``gentle_kind="leave"``, the paper's: on a score ``gentle * exp(-(d -
    0.2)^2 / (2 0.1^2))``, d the white's rest distance to the second red it hit; ``"power"``:
    ``gentle * score * (1 - p)``), ``near_miss * exp(-gap / near_miss_sigma)``.

    Physics: ``physics`` is a preset name (``"korean_medium"``, the default, the paper's table;
    ``"international"``), a :class:`~billiards.physics.PhysicsParams` or a dict of fields
    (:func:`billiards.physics.get_params`); ``params`` is the same argument under the name
    :func:`billiards.envs.make_env` and :class:`~billiards.envs.BilliardsEnv` give it.

    Inning: at most ``max_shots`` shots (then ``truncated``); under ``on_miss="reset"`` a miss
    or a foul ends it (``terminated``); under ``"continue"`` it always runs ``max_shots`` shots
    from whatever table each shot leaves. ``start`` chooses the rack at reset: ``"random"``
    (drawn from the env's ``np_random``, so ``reset(seed=s)`` is reproducible) or
    ``"canonical"``. ``reset(options={"positions": (4, 2) array})`` starts from a given table.

    ``info``: the same keys after a reset and after a step (:data:`INFO_KEYS`), numpy values,
    so TorchRL's ``GymEnv(...).auto_register_info_dict()`` can read them: score, foul, miss
    (0-d bool arrays: gymnasium's vector envs stack np.bool_ scalars as object arrays),
    first_contact, second_red (int64; -1 for none), hits (3,) bool (yellow, red1, red2),
    closest (2,) float64 (gap to red1, red2 in m), cushions, n_events, shot (shots played)
    (int64), positions (4, 2) float64 (the exact table), theta (float64, the aim actually
    played) and raw_action (4,) float64 (the (theta, p, a, b) the simulator played), and
    commanded_action (4,) float64 (the raw shot the agent asked for: raw_action unless execution
    noise perturbed it). After a reset the per-shot entries read "no shot yet": False, -1 and zeros.

    Execution noise: ``noise`` is a preset name (``"none"``, the default, ``"fastfiz"``,
    ``"fastfiz_x5"``), a :class:`~billiards.physics.noise.NoiseModel` or a dict of sigmas
    (:func:`billiards.physics.noise.get_noise`); the played shot is the commanded one perturbed
    by it, drawn from the env's ``np_random`` (``reset(seed=s)`` replays the same noisy inning).
    Under variable noise (``"variable"``: fastfiz's sigmas times a level drawn per shot from
    [0, 5]) the level of the next shot is drawn from ``np_random`` as its observation is made
    (on reset, after the rack, and after each step) and told as the observation's last entry
    (also :attr:`noise_level`); the shot is played at that level.
    """

    # "human" is listed only where its optional renderer (pygame, the [render] extra) is installed,
    # so that gymnasium's checker, which opens one env per listed mode, passes on the default install
    metadata: ClassVar[dict] = {"render_modes": ["rgb_array", *(["human"] if _has_pygame() else [])], "render_fps": 2}
    _spec: gym.envs.registration.EnvSpec | None = None

    def __init__(
        self,
        start: str = "random",
        on_miss: str = "continue",
        max_shots: int = 10,
        *,
        constrain_aim: bool = False,
        extra_features: bool = False,
        foul_penalty: float = 0.0,
        gentle: float = 0.0,
        gentle_kind: str = "leave",
        near_miss: float = 0.0,
        near_miss_sigma: float = domain.NEAR_MISS_SIGMA,
        normalize_actions: bool = True,
        physics: PhysicsParams | str | dict | None = None,
        params: PhysicsParams | str | dict | None = None,
        render_mode: str | None = None,
        noise: NoiseModel | str | dict | None = None,
    ):
        self.noise = get_noise(noise)
        if physics is not None and params is not None:
            raise ValueError("give the physics once: physics= or params= (the same argument), not both")
        params = get_params(physics if physics is not None else params)
        self.max_shots = check_inning_options(start, on_miss, max_shots)
        render_mode = one_of(render_mode, "render_mode", (None, "rgb_array", "human"))
        self._window = _open_window() if render_mode == "human" else None
        self._last_shot = None
        self.start, self.on_miss, self.params, self.render_mode = start, on_miss, params, render_mode
        self.constrain_aim, self.extra_features = check_flag("constrain_aim", constrain_aim), check_flag("extra_features", extra_features)
        self.normalize_actions = check_flag("normalize_actions", normalize_actions)
        self.shaping = Shaping(foul_penalty=foul_penalty, gentle=gentle, gentle_kind=gentle_kind, near_miss=near_miss,
                               near_miss_sigma=near_miss_sigma)

        low, high = domain.action_bounds(self.constrain_aim, self.normalize_actions)
        self.action_space = gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        low, high = domain.observation_bounds(params, self.extra_features)
        if self.noise.is_variable:  # the next shot's noise level, last
            low, high = (np.append(b, np.float32(v)) for b, v in zip((low, high), self.noise.level_range))
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)

        self._positions = initial_racks(np.random.default_rng(0), "canonical", 1, params)[0]
        self._levels = np.zeros(1) if self.noise.is_variable else None  # variable noise: the next shot's level
        self._shot = 0
        self._finished = False  # the inning ended (terminated or truncated): step needs a reset first

    # ------------------------------------------------------------------ helpers

    def observe(self, positions: np.ndarray, levels: np.ndarray | None) -> np.ndarray:
        """Observations (N, obs dim) float32 of tables (N, 4, 2) whose next shots play at noise
        ``levels`` (N,) (variable noise; None otherwise)."""
        return with_levels(domain.observation(positions, self.extra_features), levels)

    def _obs(self) -> np.ndarray:
        return self.observe(self._positions[None], self._levels)[0]

    @property
    def noise_level(self) -> float | None:
        """Under variable noise the level of the next shot (its multiplier of the noise's sigmas,
        the observation's last entry); None otherwise."""
        return None if self._levels is None else float(self._levels[0])

    @property
    def spec(self):
        """The EnvSpec ``gym.make`` set, with the physics in JSON-able form (a preset's name, or
        the dict of all fields), so that ``EnvSpec.to_json()`` and ``gym.make(spec)`` work for
        any physics."""
        return self._spec

    @spec.setter
    def spec(self, spec) -> None:
        if spec is not None and ("physics" in spec.kwargs or "params" in spec.kwargs):
            kwargs = {k: v for k, v in spec.kwargs.items() if k != "params"}
            kwargs["physics"] = self.params.preset_name() or self.params.to_dict()
            spec = dataclasses.replace(spec, kwargs=kwargs)
        self._spec = spec

    @property
    def positions(self) -> np.ndarray:
        """The current table, (4, 2) float64 (a copy)."""
        return self._positions.copy()

    # ------------------------------------------------------------------ gymnasium API

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = {} if options is None else options
        if not isinstance(options, dict) or set(options) - RESET_OPTIONS:
            unknown = sorted(map(repr, set(options) - RESET_OPTIONS)) if isinstance(options, dict) else [repr(options)]
            raise ValueError(f"reset options may only be {sorted(RESET_OPTIONS)}; got {', '.join(unknown)}")
        if options.get("positions") is not None:
            pos = reset_positions(options["positions"], self.params)
            self._positions = pos.copy()
        else:
            self._positions = initial_racks(self.np_random, self.start, 1, self.params)[0]
        self._levels = next_levels(self.noise, self.np_random, 1)
        self._shot, self._last_shot, self._finished = 0, None, False
        if self.render_mode == "human":
            self.render()
        return self._obs(), self._info()

    def _raw_action(self, action) -> np.ndarray:
        """The commanded (theta, p, a, b) of the agent's action (see the class docstring), (1, 4)."""
        act = validate_action(action, (domain.ACTION_DIM,))[None]
        if self.normalize_actions:
            act = unnormalize_checked(act, self.constrain_aim)
        elif self.constrain_aim:
            check_aim_offset(act)
        return domain.raw_action(act, self._positions[None], self.params.ball_radius, self.constrain_aim)

    def _info(self, shots=None, commanded=None) -> dict:
        """The info dict: the same keys and dtypes after reset (shots None: "no shot yet") and
        step. The flags are 0-d bool arrays, not np.bool_, which is no np.number: gymnasium's
        vector envs would stack it into an object array."""
        if shots is None:
            return {
                "score": np.array(False), "foul": np.array(False), "miss": np.array(False),
                "first_contact": np.int64(-1), "second_red": np.int64(-1),
                "hits": np.zeros(3, dtype=bool), "closest": np.zeros(2), "cushions": np.int64(0),
                "n_events": np.int64(0), "shot": np.int64(self._shot), "positions": self.positions,
                "theta": np.float64(0.0), "raw_action": np.zeros(domain.ACTION_DIM),
                "commanded_action": np.zeros(domain.ACTION_DIM),
            }
        res, act = shots.result, shots.played[0]
        return {
            "score": np.array(bool(res.score[0])),
            "foul": np.array(bool(res.foul[0])),
            "miss": np.array(bool(res.miss[0])),
            "first_contact": np.int64(res.first_contact[0]),
            "second_red": np.int64(res.second_red[0]),
            "hits": res.hits[0].astype(bool),
            "closest": res.closest[0].astype(np.float64),
            "cushions": np.int64(res.cushions[0]),
            "n_events": np.int64(res.n_events[0]),
            "shot": np.int64(self._shot),
            "positions": self.positions,
            "theta": np.float64(act[0]),
            "raw_action": act.astype(np.float64),
            "commanded_action": commanded[0].astype(np.float64),
        }

    def step(self, action):
        if self._finished:
            raise gym.error.ResetNeeded("the inning has ended (terminated or truncated): call reset() before step()")
        commanded = self._raw_action(action)
        shots = play_shots(self._positions[None], commanded, np.array([self._shot]), params=self.params,
                           noise=self.noise, rng=self.np_random, on_miss=self.on_miss, max_shots=self.max_shots,
                           levels=self._levels)
        self._levels = next_levels(self.noise, self.np_random, 1)
        self._last_shot = (self._positions, shots.played[0])
        self._positions = shots.result.positions[0]
        self._shot = int(shots.shot[0])
        reward = self.shaping.reward(shots)
        terminated, truncated = bool(shots.terminated[0]), bool(shots.truncated[0])
        self._finished = terminated or truncated
        return self._obs(), float(reward[0]), terminated, truncated, self._info(shots, commanded)

    def render(self):
        """``rgb_array``: an (H, W, 3) uint8 frame of the table, with the last shot's ball paths
        after a step; ``human``: the same frame in a pygame window (drawn on reset and step)."""
        if self.render_mode is None:
            return None
        from billiards.render import table_rgb_array

        frame = table_rgb_array(self._positions, self.params, last_shot=self._last_shot)
        if self.render_mode == "rgb_array":
            return frame
        self._window.show(frame)
        return None

    def close(self):
        if getattr(self, "_window", None) is not None:
            self._window.close()
            self._window = None
        super().close()


def reset_positions(positions, params: PhysicsParams) -> np.ndarray:
    """``reset(options={"positions": ...})``'s table as a (4, 2) float64 array, or a ValueError
    naming it (real numbers of that shape, every ball on the table and apart)."""
    pos = real_array(positions, 'options["positions"]', (4, 2), note=" (white, yellow, red1, red2 × x, y)")
    check_positions(pos[None], params, name="positions")
    return pos


class _Window:
    """A pygame window showing rgb frames (``render_mode="human"``)."""

    def __init__(self, pygame):
        self.pygame, self.screen = pygame, None

    def show(self, frame: np.ndarray) -> None:
        pg = self.pygame
        if self.screen is None:
            pg.display.init()
            pg.display.set_caption("Billiards4Ball-v0")
            self.screen = pg.display.set_mode((frame.shape[1], frame.shape[0]))
        pg.event.pump()
        self.screen.blit(pg.surfarray.make_surface(frame.swapaxes(0, 1)), (0, 0))
        pg.display.flip()

    def close(self) -> None:
        if self.screen is not None:
            self.pygame.display.quit()
            self.screen = None


def _open_window() -> "_Window":
    """The human-render window, or an error naming the optional dependency it needs."""
    try:
        import pygame
    except ImportError:
        raise gym.error.DependencyNotInstalled(
            'render_mode="human" needs pygame, an optional dependency: pip install "billiards[render]" '
            '(or pip install pygame); render_mode="rgb_array" needs nothing more'
        ) from None
    return _Window(pygame)
