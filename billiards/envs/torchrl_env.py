"""TorchRL environment: B independent innings stepped by one ``simulate_batch`` call.

One env step is one shot in every one of the B innings. The env is *stateless* in TorchRL's
sense (like ``PendulumEnv``): the table state lives in the tensordict as ``"positions"``
(float64, exact) and ``"shot"`` (shots played in the inning), both declared in
``state_spec``. ``step`` simulates from whatever positions the input carries, which is what
makes exact snapshots and search cheap; ``reset`` draws new racks, or starts from given
positions.

Keys (B = batch size; every entry has leading dim B):

=================  ===========  ===========================================================
key                shape dtype  meaning
=================  ===========  ===========================================================
action             (4,) f32     (theta, p, a, b); spec Bounded([0,0,-1,-1], [2pi,1,1,1])
observation        (28,) f32    4 balls x (x, y, vx, vy, wx, wy, wz), ball order; at rest the
                                velocity/spin slots are 0 (:func:`billiards.domain.rest_observation`)
positions          (4, 2) f64   exact ball centres (white, yellow, red1, red2); state
positions_bits     (4, 2) i64   the same table's float64 bit pattern; state (see below)
shot               (1,) i64     shots played in the current inning; state
reward             (1,) f32     the carom score in {0, 1} (transforms may add shaping)
done/terminated/   (1,) bool    terminated: a miss or foul under ``on_miss="reset"``;
truncated                       truncated: ``shot == max_shots`` and not terminated
score/foul/miss    (1,) bool    the shot's carom outcome (exactly one is true after a shot)
first_contact      (1,) i64     first ball the white touched (1, 2, 3) or -1
second_red         (1,) i64     the red (2, 3) the white touched second, -1 unless it touched both
hits               (3,) bool    the white touched (yellow, red1, red2)
closest            (2,) f32     the white's closest surface gap to red1, red2 (m), 0 if hit
n_events           (1,) i64     physical events of the shot
played_action      (4,) f64     under execution noise: the shot the simulator played
noise_level        (1,) f32     under variable noise: the next shot's level (its multiplier of
                                the noise's sigmas), drawn as the observation is made; state
=================  ===========  ===========================================================

After a reset the per-shot entries are "no shot yet": False, first_contact -1, zeros.

Why ``positions_bits``: dtype-casting transforms (TorchRL's ``DoubleToFloat``, which the usual
SAC recipes append) turn every float64 entry of the specs into float32, and would hand the env
a rounded table. The bit pattern, stored as int64, is out of their reach, so the env and the
transforms read the table through :func:`exact_positions`, which restores the exact table when
``"positions"`` is only a rounded copy of it; a table given as anything but float64 without
its exact bits is refused.
"""

from __future__ import annotations

from collections.abc import Sequence

import weakref

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from billiards.device import start_numba_threads
from billiards.domain import ACTION_DIM, OBS_DIM, action_bounds, observation
from billiards.physics import DEFAULT_PARAMS, PhysicsParams, check_positions, get_params
from billiards.physics.checks import ContractError, integer, real_array
from billiards.physics.noise import NoiseModel, get_noise

from ._common import check_inning_options, initial_racks, next_levels, play_shots, validate_action

BITS_KEY = "positions_bits"
INFO_KEYS = ("score", "foul", "miss", "first_contact", "second_red", "hits", "closest", "n_events")


_EXACT_CACHE: list = []  # the last tables exact_positions built: [(positions tensor ref, version, bits ref, version, table)]


def exact_positions(tensordict: TensorDictBase) -> np.ndarray | None:
    """The exact float64 table (..., 4, 2) of a tensordict, or None without ``"positions"``.

    ``"positions"`` is the table, except where it is only a rounded copy of the exact one
    carried as ``"positions_bits"``: equal to it rounded to float32 (what ``DoubleToFloat``
    and back makes of it) or to the dtype ``"positions"`` arrives in; those rows take the exact
    table. A table that is not float64 and has no such exact copy raises ValueError (it would
    be simulated rounded). A new table written into ``"positions"`` wins over stale bits.
    """
    pos_t = tensordict.get("positions", None)
    if pos_t is None:
        return None
    bits_t = tensordict.get(BITS_KEY, None)
    # one step asks for the same table several times (the env, the aim constraint, the features,
    # each shaping term): the table of the very same tensors at the same versions is reused (the
    # tensors are held by weak reference: a new tensor never matches a dead one's entry)
    for ref, version, bits_ref, bits_version, table in _EXACT_CACHE:
        if (ref() is pos_t and pos_t._version == version
                and (bits_t is None and bits_ref is None
                     or bits_ref is not None and bits_ref() is bits_t and bits_t._version == bits_version)):
            return table
    table = _exact_positions(pos_t, bits_t)
    table.setflags(write=False)  # shared by the callers of this step: read-only
    entry = (weakref.ref(pos_t), pos_t._version, None if bits_t is None else weakref.ref(bits_t),
             None if bits_t is None else bits_t._version, table)
    _EXACT_CACHE[:] = [entry, *_EXACT_CACHE[:1]]
    return table


def _exact_positions(pos_t: torch.Tensor, bits) -> np.ndarray:
    pos = real_array(pos_t, '"positions"')  # real numbers (not complex, boolean or on the meta device), float64
    pos_t = pos_t.detach().cpu()
    use_exact = np.zeros(pos.shape[:-2], dtype=bool)
    if bits is not None and bits.shape == pos_t.shape and bits.dtype == torch.int64:
        exact = np.ascontiguousarray(bits.detach().cpu().numpy()).view(np.float64)
        low = pos_t.dtype if pos_t.dtype.is_floating_point and pos_t.dtype != torch.float64 else torch.float32
        rounded = torch.from_numpy(exact).to(low).to(torch.float64).numpy()
        use_exact = ((pos == exact) | (pos == rounded)).all(axis=(-2, -1))
        pos = np.where(use_exact[..., None, None], exact, pos)
    if pos_t.dtype != torch.float64 and not use_exact.all():
        raise ValueError(
            f'"positions" must be the exact float64 table; got {pos_t.dtype} without its exact copy '
            f'"{BITS_KEY}" (a dtype-casting transform such as DoubleToFloat rounded it: leave "positions" out of its keys)'
        )
    return pos


def check_batch_size(batch_size) -> torch.Size:
    """``batch_size`` as ``torch.Size([B])``: B an integer >= 1 (a Python or NumPy integer, not
    a boolean or a float), alone or as the only entry of a list, tuple or ``torch.Size``."""
    what = "an integer B >= 1 or [B] (one batch dimension)"
    if isinstance(batch_size, (list, tuple)):  # torch.Size is a tuple
        if len(batch_size) != 1:
            raise ContractError(f"batch_size must be {what}, got {list(batch_size)!r}")
        batch_size = batch_size[0]
    return torch.Size([integer(batch_size, "batch_size", 1, what=what)])


def _bool_spec(shape) -> Categorical:
    return Categorical(2, shape=shape, dtype=torch.bool)


class BilliardsEnv(EnvBase):
    """Korean 4-ball innings as a batched TorchRL env (one env, ``batch_size=[B]``).

    Args:
        batch_size: B, the number of innings played side by side (int or ``[B]``).
        start: ``"random"`` (uniform non-overlapping rack per inning) or ``"canonical"``.
        on_miss: ``"continue"`` (the inning always runs ``max_shots`` shots from whatever
            table each shot leaves) or ``"reset"`` (a miss or a foul terminates the inning).
        max_shots: shot budget of an inning (truncation), default 10.
        params: simulator parameters.
        seed: seed of the numpy Generator that draws racks (see :meth:`set_seed`).
        noise: execution noise (:func:`billiards.physics.noise.get_noise`: None or ``"none"``,
            the default, plays the commanded shot exactly; ``"fastfiz"``, ``"fastfiz_x5"``, a
            NoiseModel or a dict of sigmas perturb it). With noise the output also holds
            ``"played_action"`` (4,) float64, the shot the simulator played; its random draws
            come from a generator of their own, seeded with the rack seed (racks are unchanged).
            Under variable noise (``"variable"``) each inning's next shot plays at its own level,
            drawn from that generator on reset and after each step and carried as
            ``"noise_level"`` (B, 1) float32: a step plays the level its input holds (the
            env is stateless; a level of 0 plays the commanded shot exactly).

    Reset to a given table (``set_state=True`` is TorchRL's explicit form; without it
    TorchRL 0.14 still honours the state with a FutureWarning)::

        td = env.reset(TensorDict({"positions": pos}, batch_size=[B]), set_state=True)

    Partial resets follow TorchRL: a boolean ``"_reset"`` of shape (B, 1) resets only the
    marked innings. Bad actions (wrong shape, NaN/inf, p or a, b out of range) raise
    ``ValueError`` naming ``"action"``.
    """

    batch_locked = True
    _supports_set_state = True

    def __init__(
        self,
        batch_size: int | Sequence[int] = 1,
        *,
        start: str = "random",
        on_miss: str = "continue",
        max_shots: int = 10,
        params: PhysicsParams = DEFAULT_PARAMS,
        seed: int | None = None,
        noise: NoiseModel | str | dict | None = None,
    ):
        self.noise = get_noise(noise)
        batch_size = check_batch_size(batch_size)
        super().__init__(device="cpu", batch_size=batch_size)
        self.max_shots = check_inning_options(start, on_miss, max_shots)
        # numba's pool now, not on the first parallel batch, whose start would reset torch's thread count
        start_numba_threads()
        self.start, self.on_miss, self.params = start, on_miss, get_params(params)  # a preset's name too
        self._make_specs()
        self._set_seed(seed)

    # ------------------------------------------------------------------ specs

    def _make_specs(self) -> None:
        B = self.batch_size
        w, l = self.params.table_width, self.params.table_length
        pos_high = torch.tensor([w, l], dtype=torch.float64).expand(*B, 4, 2)
        positions = Bounded(torch.zeros_like(pos_high), pos_high, shape=(*B, 4, 2), dtype=torch.float64)
        shot = Bounded(0, self.max_shots, shape=(*B, 1), dtype=torch.int64)
        bits = Unbounded(shape=(*B, 4, 2), dtype=torch.int64)
        self.observation_spec = Composite(
            observation=Unbounded(shape=(*B, OBS_DIM), dtype=torch.float32),
            positions=positions,
            positions_bits=bits,
            shot=shot,
            score=_bool_spec((*B, 1)),
            foul=_bool_spec((*B, 1)),
            miss=_bool_spec((*B, 1)),
            first_contact=Bounded(-1, 3, shape=(*B, 1), dtype=torch.int64),
            second_red=Bounded(-1, 3, shape=(*B, 1), dtype=torch.int64),
            hits=_bool_spec((*B, 3)),
            closest=Unbounded(shape=(*B, 2), dtype=torch.float32),
            n_events=Unbounded(shape=(*B, 1), dtype=torch.int64),
            shape=B,
        )
        if not self.noise.is_exact:
            self.observation_spec["played_action"] = Unbounded(shape=(*B, ACTION_DIM), dtype=torch.float64)
        self.state_spec = Composite(positions=positions.clone(), positions_bits=bits.clone(), shot=shot.clone(), shape=B)
        if self.noise.is_variable:  # the next shot's noise level: an output, and the input of the step that plays it
            low, high = self.noise.level_range
            level = Bounded(low, high, shape=(*B, 1), dtype=torch.float32)
            self.observation_spec["noise_level"], self.state_spec["noise_level"] = level, level.clone()
        low, high = action_bounds()
        self.action_spec = Bounded(
            torch.as_tensor(low, dtype=torch.float32).expand(*B, ACTION_DIM),
            torch.as_tensor(high, dtype=torch.float32).expand(*B, ACTION_DIM),
            shape=(*B, ACTION_DIM),
            dtype=torch.float32,
        )
        self.reward_spec = Unbounded(shape=(*B, 1), dtype=torch.float32)
        self.full_done_spec = Composite(
            done=_bool_spec((*B, 1)), terminated=_bool_spec((*B, 1)), truncated=_bool_spec((*B, 1)), shape=B
        )

    # ------------------------------------------------------------------ seeding

    def _set_seed(self, seed: int | None) -> None:
        """Racks are drawn from ``numpy.random.default_rng(seed)``; same seed, same racks. The
        execution noise draws from ``default_rng([seed, 1])``, so it never shifts the racks."""
        self.rng = np.random.default_rng(seed)
        self.noise_rng = np.random.default_rng(None if seed is None else [seed, 1])

    # ------------------------------------------------------------------ step

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        B = self.batch_size[0]
        action = validate_action(tensordict.get("action", None), (B, ACTION_DIM))
        positions = exact_positions(tensordict)
        shot = tensordict.get("shot", None)
        if positions is None or shot is None:
            raise KeyError('BilliardsEnv.step needs "positions" and "shot" in the input: call env.reset() first')
        shot = real_array(shot, '"shot"', [(B, 1), (B,)], integer=True, note=" (shots played in each inning)").reshape(B)
        ended = (shot < 0) | (shot >= self.max_shots)
        if ended.any():
            bad = np.flatnonzero(ended)[:8].tolist()
            raise ValueError(f'"shot" must lie in [0, max_shots - 1 = {self.max_shots - 1}] (an inning that has not '
                             f'ended); innings {bad} have {shot[bad].tolist()}: call env.reset() (or reset those innings)')
        levels = self._input_levels(tensordict)
        shots = play_shots(positions, action, shot, params=self.params, noise=self.noise,
                           rng=self.noise_rng, on_miss=self.on_miss, max_shots=self.max_shots, levels=levels)
        result = shots.result
        noisy = {} if self.noise.is_exact else {"played_action": shots.played}
        if levels is not None:
            noisy["noise_level"] = next_levels(self.noise, self.noise_rng, B).astype(np.float32)
        return self._output(
            positions=result.positions,
            shot=shots.shot,
            reward=result.score.astype(np.float32),
            terminated=shots.terminated,
            truncated=shots.truncated,
            score=result.score,
            foul=result.foul,
            miss=result.miss,
            first_contact=result.first_contact,
            second_red=result.second_red,
            hits=result.hits,
            closest=result.closest.astype(np.float32),
            n_events=result.n_events,
            **noisy,
        )

    def _input_levels(self, tensordict: TensorDictBase) -> np.ndarray | None:
        """Under variable noise the levels (B,) float64 the input's shots play at (``"noise_level"``)."""
        if not self.noise.is_variable:
            return None
        levels = tensordict.get("noise_level", None)
        if levels is None:
            raise KeyError('BilliardsEnv.step under variable noise needs "noise_level" in the input (the level '
                           'env.reset() or the last step drew for each inning)')
        B, high = self.batch_size[0], self.noise.level_range[1]
        # a level up to the top of the noise's range (as the float32 the env told it rounds it); 0 plays exactly
        top = max(high, float(np.float32(high)))
        return real_array(levels, '"noise_level"', [(B, 1), (B,)], finite=True, lo=0.0, hi=top).reshape(B)

    def _output(self, *, positions, shot, reward=None, terminated, truncated, **info) -> TensorDictBase:
        B = self.batch_size[0]
        col = lambda x: torch.from_numpy(np.ascontiguousarray(x)).reshape(B, -1)
        positions = np.ascontiguousarray(positions, dtype=np.float64)
        data = {
            "observation": torch.from_numpy(observation(positions)),
            "positions": torch.from_numpy(positions),
            BITS_KEY: torch.from_numpy(positions.view(np.int64).copy()),
            "shot": col(shot.astype(np.int64)),
            "done": col(terminated | truncated),
            "terminated": col(terminated),
            "truncated": col(truncated),
        }
        if reward is not None:
            data["reward"] = col(reward)
        data.update({k: col(v) for k, v in info.items()})
        return TensorDict(data, batch_size=self.batch_size, device=self.device)

    # ------------------------------------------------------------------ reset

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        B = self.batch_size[0]
        mask = np.ones(B, dtype=bool)
        if tensordict is not None and "_reset" in tensordict:
            mask = tensordict.get("_reset").detach().numpy().reshape(B).astype(bool)
        given = exact_positions(tensordict) if tensordict is not None else None
        if given is not None and given.shape != (B, 4, 2):
            raise ValueError(f'"positions" must have shape ({B}, 4, 2) (white, yellow, red1, red2 x (x, y)); got {given.shape}')

        # Rows outside the mask keep the input's table (TorchRL merges only the masked rows back;
        # without an input table they hold a placeholder that is never used).
        positions = given.copy() if given is not None else initial_racks(self.rng, "canonical", B, self.params)
        if kwargs.get("set_state") and given is not None:
            check_positions(given[mask], self.params, name="positions")
        elif mask.any():
            positions[mask] = initial_racks(self.rng, self.start, int(mask.sum()), self.params)

        no = np.zeros(B, dtype=bool)
        noisy = {} if self.noise.is_exact else {"played_action": np.zeros((B, ACTION_DIM))}
        if self.noise.is_variable:  # rows outside the mask: a placeholder, as for the table
            levels = np.zeros(B, dtype=np.float32)
            levels[mask] = next_levels(self.noise, self.noise_rng, int(mask.sum()))
            noisy["noise_level"] = levels
        return self._output(
            positions=positions,
            shot=np.zeros(B, dtype=np.int64),
            terminated=no,
            truncated=no,
            score=no,
            foul=no,
            miss=no,
            first_contact=np.full(B, -1, dtype=np.int64),
            second_red=np.full(B, -1, dtype=np.int64),
            hits=np.zeros((B, 3), dtype=bool),
            closest=np.zeros((B, 2), dtype=np.float32),
            n_events=np.zeros(B, dtype=np.int64),
            **noisy,
        )


def reset_to(env: EnvBase, positions) -> TensorDictBase:
    """Start fresh innings from the given table states, exactly: ``positions`` (B, 4, 2).

    Works on a bare :class:`BilliardsEnv` and on a ``TransformedEnv`` around it (the
    transforms see the reset). Shorthand for ``env.reset(TensorDict(positions=...),
    set_state=True)``.
    """
    positions = torch.as_tensor(real_array(positions, "positions", [(4, 2), (*env.batch_size, 4, 2)]))
    if positions.ndim == 2:
        positions = positions.expand(*env.batch_size, 4, 2).clone()
    return env.reset(TensorDict({"positions": positions}, batch_size=env.batch_size), set_state=True)


__all__ = ["BITS_KEY", "INFO_KEYS", "BilliardsEnv", "check_batch_size", "exact_positions", "reset_to"]
