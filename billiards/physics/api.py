"""Public simulator API: validated inputs in, NumPy results out.

Action convention (one shot): ``(theta, p, a, b)``
* ``theta``: aim angle in radians, any finite real, wrapped mod 2*pi; 0 along +x,
  counter-clockwise (pi/2 is along +y, towards the far short cushion).
* ``p``: power in [0, 1]; the cue speed is ``V0 = p * params.cue_speed_max`` (default 6 m/s,
  so the cue ball leaves at up to 1.4595 * 6 = 8.76 m/s for a centre hit).
* ``a, b``: tip offsets in [-1, 1]; (a, b) is projected onto the unit disk (divided by its
  norm if that exceeds 1) and scaled by ``params.max_english`` (default 0.6) to give the
  contact point as a fraction of R, in pooltool's convention: a > 0 is left english
  (clockwise spin seen from above), b > 0 is above centre (topspin).

Anything else (NaN/inf, p outside [0, 1], a or b outside [-1, 1], wrong shapes, balls off the
table or overlapping by more than ``POSITION_TOL``) raises :class:`ValueError`; nothing is
clamped silently.
"""

from __future__ import annotations

from functools import cached_property
from typing import NamedTuple

import numpy as np

from . import core
from .params import DEFAULT_PARAMS, PhysicsParams
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
    * ``cushions``: cushion contacts of the white; ``n_events``: physical events (strike
      excluded); ``duration``: simulated seconds until every ball rests; ``truncated``:
      stopped by ``params.max_events``;
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
        return self._st[:, :2].copy()

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
    duration = property(lambda self: float(self._of[core.OF_TIME]))
    closest = property(lambda self: self._of[core.OF_CLOSE2:core.OF_CLOSE3 + 1])
    event_kind = property(lambda self: self._ev_info[:, 0])
    event_ball = property(lambda self: self._ev_info[:, 1])
    event_other = property(lambda self: self._ev_info[:, 2])

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


# ----------------------------------------------------------------------------- validation


def _as_float_array(x, name: str) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be numeric, got {type(x).__name__}: {err}") from None
    return arr


def check_actions(actions: np.ndarray, name: str = "action") -> None:
    """Raise ValueError unless actions is (N, 4) of finite (theta, p, a, b) inside the convention."""
    if actions.ndim != 2 or actions.shape[1] != 4:
        raise ValueError(f"{name} must have shape (4,) or (N, 4) = (theta, p, a, b); got shape {actions.shape}")
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
    """Raise ValueError unless positions is (N, 4, 2) of finite, on-table, non-overlapping balls."""
    if positions.ndim != 3 or positions.shape[1:] != (4, 2):
        raise ValueError(f"{name} must have shape (4, 2) or (N, 4, 2) (white, yellow, red1, red2 × x, y); got {positions.shape}")
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
    arr = _as_float_array(action, "action")
    single = arr.ndim == 1
    actions = np.ascontiguousarray(arr.reshape(1, -1) if single else arr)
    check_actions(actions)
    cue = core.actions_to_cue(actions, params.array)
    return cue[0] if single else cue


# ----------------------------------------------------------------------------- racks


def canonical_rack(params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """The fixed starting rack, (4, 2).

    Reds on the head spot (w/2, l/4) and the foot spot (w/2, 3l/4); the two cue balls on the
    head string y = l/4, 0.2 m from the side cushions' nose lines: white at (w - 0.2, l/4)
    and yellow at (0.2, l/4). With the default 2.84 x 1.42 m table: white (1.22, 0.71),
    yellow (0.20, 0.71), red1 (0.71, 0.71), red2 (0.71, 2.13).
    """
    w, l = params.table_width, params.table_length
    return np.array([[w - 0.2, l / 4], [0.2, l / 4], [w / 2, l / 4], [w / 2, 3 * l / 4]], dtype=np.float64)


def random_rack(rng: np.random.Generator, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """A uniform random rack, (4, 2): each centre uniform in [R, w-R] x [R, l-R], the whole
    rack redrawn until no two balls overlap (centre distance >= 2R)."""
    return random_racks(rng, 1, params)[0]


def random_racks(rng: np.random.Generator, n: int, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """n independent uniform non-overlapping racks, (n, 4, 2) (see :func:`random_rack`)."""
    R = params.ball_radius
    lo = np.array([R, R])
    hi = np.array([params.table_width - R, params.table_length - R])
    out = np.empty((n, 4, 2))
    todo = np.arange(n)
    while todo.size:
        cand = lo + (hi - lo) * rng.random((todo.size, 4, 2))
        d = np.linalg.norm(cand[:, :, None, :] - cand[:, None, :, :], axis=-1)
        d[:, np.arange(4), np.arange(4)] = np.inf
        ok = d.min(axis=(1, 2)) >= 2 * R
        out[todo[ok]] = cand[ok]
        todo = todo[~ok]
    return out


# ----------------------------------------------------------------------------- simulation


def _prepare_batch(positions, actions, params: PhysicsParams):
    pos = np.ascontiguousarray(_as_float_array(positions, "positions"))
    act = np.ascontiguousarray(_as_float_array(actions, "actions"))
    if pos.ndim != 3 or act.ndim != 2 or pos.shape[0] != act.shape[0]:
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
    pos = _as_float_array(positions, "positions")
    act = _as_float_array(action, "action")
    if pos.shape != (4, 2):
        raise ValueError(f"positions must have shape (4, 2) (white, yellow, red1, red2 × x, y); got {pos.shape}")
    if act.shape != (4,):
        raise ValueError(f"action must have shape (4,) = (theta, p, a, b); got {act.shape}")
    ok, raw = core.checked_shot(np.ascontiguousarray(pos), np.ascontiguousarray(act), params.array, POSITION_TOL)
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
    pos, act = _prepare_batch(positions, actions, params)
    n = pos.shape[0]
    out_pos = np.empty((n, 4, 2))
    out_int = np.empty((n, core.N_OUT_INT), dtype=np.int64)
    out_float = np.empty((n, core.N_OUT_FLOAT))
    if n >= PARALLEL_MIN_BATCH:
        core.run_batch(pos, act, params.array, out_pos, out_int, out_float)
    elif n:
        core.run_batch_serial(pos, act, params.array, out_pos, out_int, out_float)
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
    )


def trajectory(result: ShotResult, dt: float = 1.0 / 60.0, params: PhysicsParams = DEFAULT_PARAMS):
    """Sample every ball's centre along a simulated shot for drawing.

    Returns (times (T,), xy (T, 4, 2)): a uniform grid of step dt plus every event time, each
    position evolved with the closed forms from the last event before it.
    """
    grid = np.arange(0.0, result.duration, dt)
    times = np.unique(np.concatenate([grid, result.event_time, [result.duration]]))
    seg = np.searchsorted(result.event_time, times, side="right") - 1
    xy = np.empty((times.size, 4, 2))
    p = params.array
    for n, (t, s) in enumerate(zip(times, seg)):
        st = result.event_state[s, :, :7].copy()
        lab = result.event_state[s, :, 7].astype(np.int64)
        for k in range(4):
            core.evolve_ball(st, lab, k, t - result.event_time[s], p)
        xy[n] = st[:, :2]
    return times, xy
