"""``Billiards4Ball-v0`` as a native gymnasium vector env: B innings, one ``simulate_batch`` call per step.

``gymnasium.make_vec("Billiards4Ball-v0", num_envs=B)`` builds it (the id's ``vector_entry_point``;
``vectorization_mode="sync"`` or ``"async"`` still give gymnasium's wrappers of B single envs).
gymnasium's ``SyncVectorEnv`` steps its B envs one by one, each a Python call that simulates
one shot; here the B shots go through :func:`~billiards.envs._common.play_shots` together, as in
the TorchRL env.

Its outputs are, bit for bit, those of ``SyncVectorEnv`` over B
:class:`~billiards.envs.gym_env.Billiards4BallInningEnv` with the same options (its default
next-step autoreset): the same observations, rewards, flags and info (each key of
:data:`~billiards.envs.gym_env.INFO_KEYS` stacked, with its ``_key`` mask), the same seeding
(``reset(seed=s)`` seeds inning i's generator with s + i, as gymnasium seeds env i), each
inning's racks and execution noise drawn from its own generator. ``reset(options=...)`` takes
``positions`` (every inning starts from that table) and ``reset_mask`` (reset only the innings
it marks). Not supported: render modes (use ``vectorization_mode="sync"``) and other autoreset
modes; an action is checked only for the innings that play it (an inning being reset ignores
its row, as the sync env does).
"""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from billiards import domain
from billiards.physics.api import random_racks_each
from billiards.physics.checks import integer, real_array

from ._common import check_aim_offset, initial_racks, next_levels, play_shots, unnormalize_checked, validate_action
from .gym_env import INFO_KEYS, RESET_OPTIONS, Billiards4BallInningEnv, reset_positions


class Billiards4BallVectorEnv(VectorEnv):
    """``num_envs`` innings of :class:`~billiards.envs.gym_env.Billiards4BallInningEnv` stepped
    together (see the module docstring); every other argument is that env's, with the same
    meaning and checks."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int, render_mode: str | None = None, **kwargs):
        num_envs = integer(num_envs, "num_envs", 1)
        if render_mode is not None:
            raise ValueError(f'the batched vector env does not render; use gymnasium.make_vec(..., '
                             f'vectorization_mode="sync") for render_mode={render_mode!r}')
        self.one = one = Billiards4BallInningEnv(**kwargs)  # checks the options once; the template inning
        self.num_envs, self.render_mode = int(num_envs), None
        self.single_observation_space, self.single_action_space = one.observation_space, one.action_space
        self.observation_space = batch_space(one.observation_space, self.num_envs)
        self.action_space = batch_space(one.action_space, self.num_envs)
        B = self.num_envs
        self._rngs: list[np.random.Generator | None] = [None] * B  # each inning's np_random, as env i's
        self._positions = np.broadcast_to(one.positions, (B, 4, 2)).copy()
        self._shot = np.zeros(B, dtype=np.int64)
        self._autoreset = np.zeros(B, dtype=bool)
        self._levels = np.zeros(B) if one.noise.is_variable else None  # variable noise: each inning's next level
        self._obs = one.observe(self._positions, self._levels)

    def _rng(self, i: int) -> np.random.Generator:
        if self._rngs[i] is None:  # gymnasium's Env.np_random: seeded from entropy on first use
            self._rngs[i], _ = seeding.np_random()
        return self._rngs[i]

    def _start(self, rows: np.ndarray, positions) -> None:
        """New innings in ``rows``: the given table, or racks drawn from each inning's generator."""
        if positions is not None:
            self._positions[rows] = positions
        elif self.one.start == "random":
            self._positions[rows] = random_racks_each([self._rng(i) for i in rows], self.one.params)
        else:
            self._positions[rows] = initial_racks(None, "canonical", rows.size, self.one.params)
        self._next_levels(rows)
        self._shot[rows] = 0
        self._obs[rows] = self.one.observe(self._positions[rows], self._level_rows(rows))

    def _next_levels(self, rows: np.ndarray) -> None:
        """Under variable noise the next shot's level of the innings in ``rows``, each from its own
        generator (as each single env draws it)."""
        if self._levels is not None:
            self._levels[rows] = next_levels(self.one.noise, [self._rng(i) for i in rows], rows.size)

    def _level_rows(self, rows: np.ndarray) -> np.ndarray | None:
        return None if self._levels is None else self._levels[rows]

    def reset(self, *, seed: int | list | None = None, options: dict | None = None):
        B = self.num_envs
        seeds = [None] * B if seed is None else [seed + i for i in range(B)] if isinstance(seed, int) else list(seed)
        if len(seeds) != B:
            raise ValueError(f"If seeds are passed as a list the length must match num_envs={B} but got length={len(seeds)}.")
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            mask = np.ones(B, dtype=bool)
        elif not (isinstance(mask, np.ndarray) and mask.shape == (B,) and mask.dtype == np.bool_ and mask.any()):
            raise ValueError(f'options["reset_mask"] must be a bool array of shape ({B},) with a True value')
        if set(options) - RESET_OPTIONS:
            unknown = sorted(map(repr, set(options) - RESET_OPTIONS))
            raise ValueError(f"reset options may only be {sorted(RESET_OPTIONS)} (and reset_mask); got {', '.join(unknown)}")
        positions = options.get("positions")
        if positions is not None:
            positions = reset_positions(positions, self.one.params)
        rows = np.flatnonzero(mask)
        for i in rows:
            if seeds[i] is not None:
                self._rngs[i], _ = seeding.np_random(seeds[i])
        self._start(rows, positions)
        self._autoreset[rows] = False
        return self._obs.copy(), self._infos(mask, rows, None, None)

    def step(self, actions):
        B, one = self.num_envs, self.one
        resetting = self._autoreset
        rows = np.flatnonzero(~resetting)
        rewards, terminated, truncated = np.zeros(B), np.zeros(B, dtype=bool), np.zeros(B, dtype=bool)
        shots = commanded = None
        if rows.size:
            act = real_array(actions, '"action"')  # real numbers (the shape is checked on the rows played)
            act = validate_action(act[rows] if act.shape[:1] == (B,) else act, (rows.size, domain.ACTION_DIM))
            if one.normalize_actions:
                act = unnormalize_checked(act, one.constrain_aim)
            elif one.constrain_aim:
                check_aim_offset(act)
            commanded = domain.raw_action(act, self._positions[rows], one.params.ball_radius, one.constrain_aim)
            rng = None if one.noise.is_exact else [self._rng(i) for i in rows]  # each inning's own noise
            shots = play_shots(self._positions[rows], commanded, self._shot[rows], params=one.params, noise=one.noise,
                               rng=rng, on_miss=one.on_miss, max_shots=one.max_shots, levels=self._level_rows(rows))
            self._next_levels(rows)
            self._positions[rows] = shots.result.positions
            self._shot[rows] = shots.shot
            self._obs[rows] = one.observe(shots.result.positions, self._level_rows(rows))
            rewards[rows] = one.shaping.reward(shots)
            terminated[rows], truncated[rows] = shots.terminated, shots.truncated
        started = np.flatnonzero(resetting)
        if started.size:
            self._start(started, None)
        self._autoreset = terminated | truncated
        return self._obs.copy(), rewards, terminated, truncated, self._infos(np.ones(B, dtype=bool), rows, shots, commanded)

    def _infos(self, mask: np.ndarray, played: np.ndarray, shots, commanded) -> dict:
        """The stacked info of the innings in ``mask`` (``SyncVectorEnv``'s layout: each key, then
        its ``_key`` mask): the shot's outcome for the rows ``played`` (``shots``), "no shot yet"
        for the others, as a single env's ``_info`` reads."""
        B = self.num_envs
        info = {
            "score": np.zeros(B, dtype=bool), "foul": np.zeros(B, dtype=bool), "miss": np.zeros(B, dtype=bool),
            "first_contact": np.zeros(B, dtype=np.int64), "second_red": np.zeros(B, dtype=np.int64),
            "hits": np.zeros((B, 3), dtype=bool), "closest": np.zeros((B, 2)), "cushions": np.zeros(B, dtype=np.int64),
            "n_events": np.zeros(B, dtype=np.int64), "shot": np.zeros(B, dtype=np.int64), "positions": np.zeros((B, 4, 2)),
            "theta": np.zeros(B), "raw_action": np.zeros((B, domain.ACTION_DIM)),
            "commanded_action": np.zeros((B, domain.ACTION_DIM)),
        }
        info["first_contact"][mask] = info["second_red"][mask] = -1
        info["shot"][mask], info["positions"][mask] = self._shot[mask], self._positions[mask]
        if shots is not None:
            res = shots.result
            for key, value in (("score", res.score), ("foul", res.foul), ("miss", res.miss),
                               ("first_contact", res.first_contact), ("second_red", res.second_red), ("hits", res.hits),
                               ("closest", res.closest), ("cushions", res.cushions), ("n_events", res.n_events),
                               ("theta", shots.played[:, 0]), ("raw_action", shots.played),
                               ("commanded_action", commanded)):
                info[key][played] = value
        assert tuple(info) == INFO_KEYS
        return {k: v for key, value in info.items() for k, v in ((key, value), (f"_{key}", mask.copy()))}


__all__ = ["Billiards4BallVectorEnv"]
