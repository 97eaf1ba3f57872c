"""Public simulator API: validated inputs in, NumPy results out.

Action convention (one shot): ``(theta, p, a, b)``
* ``theta``: aim angle in radians, any finite real, wrapped mod 2*pi; 0 along +x,
  counter-clockwise (pi/2 is along +y, towards the far short cushion).
* ``p``: power in [0, 1]; the cue speed is ``V0 = p * params.cue_speed_max`` (4.5 m/s on the
  default ``korean_medium`` table, so the cue ball leaves at up to 2/(1 + 0.21/0.55) * 4.5 =
  6.51 m/s for a centre hit; 6 m/s on ``international``).
* ``a, b``: tip offsets in [-1, 1]; (a, b) is projected onto the unit disk (divided by its
  norm if that exceeds 1) and scaled by ``params.max_english`` (1.0 on ``korean_medium``,
  0.6 on ``international``) to give the
  contact point as a fraction of R, in pooltool's convention: a > 0 is left english
  (clockwise spin seen from above), b > 0 is above centre (topspin).

Anything else (NaN/inf, p outside [0, 1], a or b outside [-1, 1], wrong shapes, balls off the
table or overlapping by more than ``POSITION_TOL``; booleans, complex numbers, strings or
masked arrays in place of real numbers) raises :class:`ValueError`; nothing is clamped or
dropped silently. The arguments' types, shapes and ranges are checked by
:mod:`billiards.physics.checks`, the envs' checks too.

Every state this accepts is one the simulator keeps its invariants from: a shot from it ends
with every ball on the table and no two overlapping beyond ``POSITION_TOL``, so its rest
positions are a valid start for the next shot (``benchmarks/fuzz.py`` checks this over 10^6
natural and adversarial shots). A shot the event loop cannot finish (``params.max_events``
reached, e.g. a ball pressed against a rail or a wedged cluster by its own friction, which an
impulse model can only answer with ever more collisions) is stopped where it is and flagged
``truncated``.

The first use on a machine compiles the kernels (numba; cached afterwards): before a kernel's
first call in a process that will compile it, one line on stderr says so with the expected
time (:mod:`billiards.physics.first_use`).
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import NamedTuple

import numpy as np

from . import core, first_use
from .checks import ContractError, finite_number, generator, integer, real_array
from .params import DEFAULT_PARAMS, PhysicsParams, get_params
from .rules import carom_outcome

PARALLEL_MIN_BATCH = 64  # smaller batches run on the calling thread (same kernel, same bits)
POSITION_TOL = 1e-6  # metres a state may sit outside the table or overlap and still be accepted
BALL_NAMES = ("white", "yellow", "red1", "red2")
EVENT_KINDS = ("strike", "transition", "ball_ball", "cushion", "stop")
CUSHION_NAMES = ("x=0", "x=w", "y=0", "y=l")
MOTION_LABELS = ("stationary", "spinning", "sliding", "rolling")


class ShotResult:
    """One simulated shot (see :func:`simulate_shot`).

    Fields are read-only attributes, each computed from the kernel's raw output the first time
    it is read (so a caller pays only for what it uses):

    * ``positions`` (4, 2) centres at rest;
    * ``score``, ``foul``, ``miss``: the carom outcome (:mod:`billiards.physics.rules`);
    * ``first_contact``: the first ball the white hit (1, 2, 3), or -1;
    * ``hits`` (3,) bool: the white touched yellow, red1, red2;
    * ``closest`` (2,): the white's closest surface gap to red1, red2 (m; 0 if hit);
    * ``second_red``: the red (2 or 3) the white touched second, -1 unless it touched both
      (the leave-position bonus measures the white's rest position from it);
    * ``cushions``: cushion contacts of the white; ``n_events``: physical events (strike
      excluded); ``duration``: simulated seconds until every ball rests (at most
      ``params.max_time``); ``timed_out``: stopped at ``params.max_time`` (every ball then
      rests where it is, the paper's rule); ``truncated``: stopped by ``params.max_events``;
    * the event log: ``event_time`` (E,) (event 0 is the strike at t = 0), ``event_kind`` (E,)
      index into EVENT_KINDS, ``event_ball`` (E,), ``event_other`` (E,) (other ball for
      ball_ball, cushion id for cushion, new motion label for transition), ``event_state``
      (E, 4, 8) every ball's x, y, vx, vy, wx, wy, wz, label after the event.
    """

    def __init__(self, st, out_int, out_float, ev_time, ev_info, ev_state):
        self._st, self._oi, self._of = st, out_int, out_float
        self.event_time, self.event_state, self._ev_info = ev_time, ev_state, ev_info

    @cached_property
    def positions(self) -> np.ndarray:
        return self._st[:, core.X:core.Y + 1].copy()

    @cached_property
    def hits(self) -> np.ndarray:
        return self._oi[core.O_HIT1:core.O_HIT3 + 1] != 0

    @cached_property
    def _outcome(self):
        h = self.hits
        return tuple(bool(x) for x in carom_outcome(h[0], h[1], h[2]))

    score = property(lambda self: self._outcome[0], doc="the white hit both reds and never the yellow")
    foul = property(lambda self: self._outcome[1], doc="the white hit the yellow")
    miss = property(lambda self: self._outcome[2], doc="neither score nor foul")
    first_contact = property(lambda self: int(self._oi[core.O_FIRST]))
    cushions = property(lambda self: int(self._oi[core.O_CUSHIONS]))
    n_events = property(lambda self: int(self._oi[core.O_NEVENTS]))
    truncated = property(lambda self: bool(self._oi[core.O_TRUNC]))
    timed_out = property(lambda self: bool(self._oi[core.O_TIMEOUT]))
    second_red = property(lambda self: int(self._oi[core.O_SECOND_RED]))
    duration = property(lambda self: float(self._of[core.OF_TIME]))
    closest = property(lambda self: self._of[core.OF_CLOSE2:core.OF_CLOSE3 + 1])
    event_kind = property(lambda self: self._ev_info[:, core.INFO_KIND])
    event_ball = property(lambda self: self._ev_info[:, core.INFO_BALL])
    event_other = property(lambda self: self._ev_info[:, core.INFO_OTHER])

    def events(self) -> list[tuple[float, str, int, int]]:
        """The ordered event log as (time, kind, ball, other) tuples."""
        return [
            (float(t), EVENT_KINDS[k], int(i), int(j))
            for t, k, i, j in zip(self.event_time, self.event_kind, self.event_ball, self.event_other)
        ]

    def __repr__(self) -> str:
        outcome = "score" if self.score else "foul" if self.foul else "miss"
        return f"ShotResult({outcome}, first_contact={self.first_contact}, n_events={self.n_events}, duration={self.duration:.3f} s)"


class BatchResult(NamedTuple):
    """N simulated shots (see :func:`simulate_batch`); every field has leading dimension N."""

    positions: np.ndarray  # (N, 4, 2)
    score: np.ndarray  # (N,) bool
    foul: np.ndarray  # (N,) bool
    miss: np.ndarray  # (N,) bool
    first_contact: np.ndarray  # (N,) int64, -1 for none
    hits: np.ndarray  # (N, 3) bool: yellow, red1, red2
    closest: np.ndarray  # (N, 2) closest surface gap to red1, red2 (m)
    cushions: np.ndarray  # (N,) int64
    n_events: np.ndarray  # (N,) int64
    duration: np.ndarray  # (N,) float64
    truncated: np.ndarray  # (N,) bool
    second_red: np.ndarray  # (N,) int64: the red (2, 3) the white touched second, -1 unless both
    timed_out: np.ndarray  # (N,) bool: stopped at params.max_time


# ----------------------------------------------------------------------------- validation


ACTION_NOTE = " = (theta, p, a, b)"
POSITIONS_NOTE = " (white, yellow, red1, red2 × x, y)"


def check_actions(actions, name: str = "action") -> None:
    """Raise ValueError unless actions is one action (4,) or N actions (N, 4) of finite
    (theta, p, a, b) inside the convention (real numbers: see :func:`checks.real_array`)."""
    actions = real_array(actions, name, [(4,), (None, 4)], note=ACTION_NOTE)
    if actions.ndim == 1:
        actions = actions[None]
    code, n, k = core.check_actions(np.ascontiguousarray(actions, dtype=np.float64))
    if code == core.ERR_OK:
        return
    where = f"{name}[{n}]" if actions.shape[0] > 1 else name
    field = ("theta", "p", "a", "b")[k]
    if code == core.ERR_ACTION_NONFINITE:
        raise ValueError(f"{where} has a non-finite {field}: {actions[n].tolist()}")
    if code == core.ERR_POWER:
        raise ValueError(f"{where}: power p = {float(actions[n, 1])!r} is outside [0, 1]")
    raise ValueError(f"{where}: tip offset {field} = {float(actions[n, k])!r} is outside [-1, 1]")


def check_positions(positions: np.ndarray, params: PhysicsParams = DEFAULT_PARAMS, name: str = "positions") -> None:
    """Raise ValueError unless positions is one rack (4, 2) or N racks (N, 4, 2) of finite,
    on-table, non-overlapping balls."""
    params = get_params(params)  # a preset's name is accepted wherever parameters are
    positions = real_array(positions, name, [(4, 2), (None, 4, 2)], note=POSITIONS_NOTE)
    if positions.ndim == 2:
        positions = positions[None]
    code, n, k, j = core.check_positions(np.ascontiguousarray(positions, dtype=np.float64), params.array, POSITION_TOL)
    if code == core.ERR_OK:
        return
    where = f"{name}[{n}]" if positions.shape[0] > 1 else name
    ball = f"ball {k} ({BALL_NAMES[k]}) at {positions[n, k].tolist()}"
    if code == core.ERR_NONFINITE:
        raise ValueError(f"{where}: {ball} is not finite")
    if code == core.ERR_OFF_TABLE:
        R = params.ball_radius
        raise ValueError(
            f"{where}: {ball} is off the table: centres must lie in "
            f"[{R}, {params.table_width - R}] x [{R}, {params.table_length - R}]"
        )
    d = float(np.hypot(*(positions[n, j] - positions[n, k])))
    raise ValueError(
        f"{where}: {ball} overlaps ball {j} ({BALL_NAMES[j]}) at {positions[n, j].tolist()}: "
        f"centre distance {d:.6g} m < 2R = {2 * params.ball_radius} m"
    )


# ----------------------------------------------------------------------------- conversions


def action_to_cue(action, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """Map actions (theta, p, a, b) to cue parameters (V0 m/s, phi rad in [0, 2pi), a, b).

    a and b come out as contact-point offsets in fractions of R (pooltool's convention).
    Accepts (4,) or (N, 4) and returns the same shape. Validates as described in the module.
    """
    params = get_params(params)  # a preset's name is accepted wherever parameters are
    arr = real_array(action, "action", [(4,), (None, 4)], note=ACTION_NOTE)
    single = arr.ndim == 1
    actions = np.ascontiguousarray(arr.reshape(1, -1) if single else arr)
    check_actions(actions)
    cue = core.actions_to_cue(actions, params.array)
    return cue[0] if single else cue


# ----------------------------------------------------------------------------- racks


def canonical_rack(params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """The opening rack of ``params``'s table (its ``rack`` field), (4, 2). W is the width
    (short side), L the length, R the ball radius:

    * ``"korean"`` (the paper's, ``korean_medium``): yellow, red1 and red2 on the long centre
      line x = W/2 at y = L/8, 2L/8 and 6L/8; the white beside red2 at (W/2 + 4R, 6L/8), two
      ball diameters centre to centre. On the 1.27 x 2.54 m table: white (0.766, 1.905),
      yellow (0.635, 0.3175), red1 (0.635, 0.635), red2 (0.635, 1.905).
    * ``"spots"`` (``international``): reds on the head spot (W/2, L/4) and the foot spot
      (W/2, 3L/4); white at (W - 0.2, L/4) and yellow at (0.2, L/4). On the 2.84 x 1.42 m
      table: white (1.22, 0.71), yellow (0.20, 0.71), red1 (0.71, 0.71), red2 (0.71, 2.13).

    A layout that does not fit its table is refused when the PhysicsParams is built.
    """
    params = get_params(params)  # a preset's name is accepted wherever parameters are
    return params.opening_rack()


def random_rack(rng: np.random.Generator, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """A uniform random rack, (4, 2) (see :func:`random_racks`)."""
    generator(rng, "rng")
    params = get_params(params)  # a preset's name is accepted wherever parameters are
    return random_racks(rng, 1, params)[0]


RACK_ATTEMPTS = 1000  # rejection rounds of random_racks before it gives up with an error


def random_racks(rng: np.random.Generator, n: int, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """n independent uniform racks, (n, 4, 2): each centre uniform in
    [R + m, W - R - m] x [R + m, L - R - m] with m = ``params.rack_margin``, the whole rack
    redrawn until every pair of centres is at least 2R + ``params.rack_clearance`` apart
    (the paper's sampling on ``korean_medium``: m = 5 mm, clearance 2 mm; 0 and 0 on
    ``international``). Raises ValueError if some rack is still not placed after
    ``RACK_ATTEMPTS`` rounds (a table barely larger than four balls)."""
    generator(rng, "rng")
    n = integer(n, "n", lo=0, what="an integer >= 0 (the number of racks)")
    return _place_racks(lambda todo: rng.random((todo.size, 4, 2)), n, params)


def random_racks_each(rngs, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """One rack per generator of ``rngs``, (len(rngs), 4, 2): row i is ``random_racks(rngs[i], 1,
    params)[0]`` bit for bit (the same draws from each generator, which it advances alike),
    with the rejection test run on all the racks at once."""
    for i, rng in enumerate(rngs):
        generator(rng, f"rngs[{i}]")
    return _place_racks(lambda todo: np.stack([rngs[i].random((4, 2)) for i in todo]), len(rngs), params)


def _place_racks(draw, n: int, params: PhysicsParams) -> np.ndarray:
    """:func:`random_racks` with the uniform draws of the racks still to place, (todo.size, 4, 2)
    in [0, 1), from ``draw(todo)``."""
    params = get_params(params)  # a preset's name is accepted wherever parameters are
    R, m = params.ball_radius, params.rack_margin
    lo = np.array([R + m, R + m])
    hi = np.array([params.table_width - R - m, params.table_length - R - m])
    min_gap = 2 * R + params.rack_clearance
    out = np.empty((n, 4, 2))
    todo = np.arange(n)
    for _ in range(RACK_ATTEMPTS):
        if not todo.size:
            return out
        cand = lo + (hi - lo) * draw(todo)
        d = np.linalg.norm(cand[:, :, None, :] - cand[:, None, :, :], axis=-1)
        d[:, np.arange(4), np.arange(4)] = np.inf
        ok = d.min(axis=(1, 2)) >= min_gap
        out[todo[ok]] = cand[ok]
        todo = todo[~ok]
    if not todo.size:
        return out
    raise ValueError(
        f"random_racks: {todo.size} of {n} racks could not be placed in {RACK_ATTEMPTS} rounds on a "
        f"{params.table_width} x {params.table_length} m table (R = {R} m, margin {m} m, clearance "
        f"{params.rack_clearance} m): the table is too small for random racks"
    )


# ----------------------------------------------------------------------------- simulation


def _prepare_batch(positions, actions, params: PhysicsParams):
    pos = np.ascontiguousarray(real_array(positions, "positions", (None, 4, 2), note=POSITIONS_NOTE))
    act = np.ascontiguousarray(real_array(actions, "actions", (None, 4), note=ACTION_NOTE))
    if pos.shape[0] != act.shape[0]:
        raise ValueError(
            f"simulate_batch needs positions (N, 4, 2) and actions (N, 4) with the same N; "
            f"got {pos.shape} and {act.shape}"
        )
    check_actions(act, "actions")
    check_positions(pos, params)
    return pos, act


def simulate_shot(positions, action, params: PhysicsParams = DEFAULT_PARAMS) -> ShotResult:
    """Simulate one shot of the white (ball 0) from a table at rest.

    positions: (4, 2) centres (white, yellow, red1, red2); action: (theta, p, a, b).
    Returns a :class:`ShotResult` with the rest positions, the carom outcome, and the
    ordered event log with every ball's state after each event (what
    :func:`billiards.physics.trajectory` needs to draw the paths).
    """
    params = get_params(params)  # a preset's name is accepted wherever parameters are
    pos = real_array(positions, "positions", (4, 2), note=POSITIONS_NOTE)
    act = real_array(action, "action", (4,), note=ACTION_NOTE)
    args = (np.ascontiguousarray(pos), np.ascontiguousarray(act), params.array, POSITION_TOL)
    if core.checked_shot not in first_use.CHECKED:  # its first call here: say so if it compiles
        first_use.before_first_call(core.checked_shot, *args)
    ok, raw = core.checked_shot(*args)
    if not ok:
        check_actions(act[None])  # raise with the message
        check_positions(pos[None], params)
    return ShotResult(*raw)


def simulate_batch(positions, actions, params: PhysicsParams = DEFAULT_PARAMS) -> BatchResult:
    """Simulate N independent shots at once, in parallel over numba's threads.

    positions (N, 4, 2), actions (N, 4). Bit-identical to N calls of :func:`simulate_shot`.
    The thread count is numba's (``numba.set_num_threads`` or ``NUMBA_NUM_THREADS``); batches
    smaller than ``PARALLEL_MIN_BATCH`` run on the calling thread.
    """
    params = get_params(params)  # a preset's name is accepted wherever parameters are
    pos, act = _prepare_batch(positions, actions, params)
    n = pos.shape[0]
    out_pos = np.empty((n, 4, 2))
    out_int = np.empty((n, core.N_OUT_INT), dtype=np.int64)
    out_float = np.empty((n, core.N_OUT_FLOAT))
    if n:
        kernel = core.run_batch if n >= PARALLEL_MIN_BATCH else core.run_batch_serial
        args = (pos, act, params.array, out_pos, out_int, out_float)
        if kernel not in first_use.CHECKED:  # its first call here: say so if it compiles
            first_use.before_first_call(kernel, *args)
        kernel(*args)
    hits = out_int[:, core.O_HIT1:core.O_HIT3 + 1] != 0
    score, foul, miss = carom_outcome(hits[:, 0], hits[:, 1], hits[:, 2])
    return BatchResult(
        positions=out_pos,
        score=score,
        foul=foul,
        miss=miss,
        first_contact=out_int[:, core.O_FIRST],
        hits=hits,
        closest=out_float[:, core.OF_CLOSE2:core.OF_CLOSE3 + 1],
        cushions=out_int[:, core.O_CUSHIONS],
        n_events=out_int[:, core.O_NEVENTS],
        duration=out_float[:, core.OF_TIME],
        truncated=out_int[:, core.O_TRUNC].astype(bool),
        second_red=out_int[:, core.O_SECOND_RED],
        timed_out=out_int[:, core.O_TIMEOUT].astype(bool),
    )


MIN_DT = 1e-4  # seconds: trajectory's finest time step
MAX_FRAMES = 1_000_000  # trajectory's most samples of one shot (32 bytes per ball each)


def trajectory(result: ShotResult, dt: float = 1.0 / 60.0, params: PhysicsParams = DEFAULT_PARAMS):
    """Sample every ball's centre along a simulated shot for drawing.

    Returns (times (T,), xy (T, 4, 2)): a uniform grid of step dt plus every event time, each
    position evolved with the closed forms from the last event before it. ``dt`` is a number
    of seconds, at least ``MIN_DT`` (0.1 ms), and the shot's grid at most ``MAX_FRAMES``
    samples long; anything else raises ValueError.
    """
    params = get_params(params)  # a preset's name is accepted wherever parameters are
    if not isinstance(result, ShotResult):
        raise ContractError(f"result must be a ShotResult (what simulate_shot returns), got {type(result).__name__}")
    dt = finite_number(dt, "dt", MIN_DT, what=f"a finite time step of at least {MIN_DT:g} s")
    frames = math.ceil(result.duration / dt) + result.event_time.size + 1
    if frames > MAX_FRAMES:
        raise ContractError(f"dt must be at least {result.duration / MAX_FRAMES:.3g} s for this {result.duration:.3g} s "
                            f"shot (at most {MAX_FRAMES:,} frames), got {dt!r}")
    grid = np.arange(0.0, result.duration, dt)
    times = np.unique(np.concatenate([grid, result.event_time, [result.duration]]))
    seg = np.searchsorted(result.event_time, times, side="right") - 1
    xy = np.empty((times.size, 4, 2))
    p = params.array
    for n, (t, s) in enumerate(zip(times, seg)):
        st = result.event_state[s, :, :core.N_STATE].copy()
        lab = result.event_state[s, :, core.LABEL].astype(np.int64)
        for k in range(core.N_BALLS):
            core.evolve_ball(st, lab, k, t - result.event_time[s], p)
        xy[n] = st[:, core.X:core.Y + 1]
    return times, xy
