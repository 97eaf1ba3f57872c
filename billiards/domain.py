"""Domain knowledge for Korean 4-ball, in one place: pure NumPy, no torch.

Every formula the environments and transforms use lives here exactly once; the gymnasium env,
the TorchRL transforms, the baselines and the search code all call these functions. Every
function is batched over arbitrary leading axes ``...``.

Conventions (see :mod:`billiards.physics`): ball order 0 white (the cue ball), 1 yellow,
2 red1, 3 red2; ``positions`` is ``(..., 4, 2)`` centres in metres in the table frame (x
across the width, y along the length); angles are radians, counter-clockwise from +x, the
same convention as the action's aim ``theta``.

Contents
--------
* the observation: :func:`observation` (the 28 floats of :func:`rest_observation`, then with
  the carom features the 4 of :func:`feature_observation`), its bounds,
  :func:`observation_bounds`, and the table it holds, :func:`observed_positions`;
* the action a policy emits and its bounds (:func:`action_bounds`), the normalised action
  [-1, 1]^4 and its map to the raw shot (:func:`unnormalize_action`), and the whole map from a
  policy's action to the shot the simulator plays, :func:`raw_action`, and back,
  :func:`normalized_aim_action`;
* the aim constraint: :func:`nearest_red`, :func:`aim_window`, :func:`constrained_theta`,
  :func:`aim_action`;
* the carom features: :func:`carom_features`;
* reward shaping: :func:`foul_penalty`, :func:`gentle_bonus` (the paper's leave-position
  bonus) or :func:`gentle_power_bonus` (a power-based alternative), :func:`near_miss_bonus`,
  summed by :func:`shaped_reward`; :func:`check_coefficient` checks their coefficients.

The constants are the paper's as its authors configured them (``docs/physics.md`` §10):
the aim window capped at 80 degrees, the gentle bonus 0.2 exp(-(d - 0.2)^2 / (2 0.1^2)), the
near-miss bonus 0.05 exp(-gap / 0.03).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from billiards import numerics
from billiards.physics import DEFAULT_PARAMS, unhit_red_gap
from billiards.physics.checks import finite_number
from billiards.physics.core import N_BALLS, RED1, RED2, WHITE, YELLOW  # noqa: F401  (the simulator's ball order)
from billiards.physics.core import N_STATE as BALL_STATE_DIM  # x, y, vx, vy, wx, wy, wz
OBS_DIM = N_BALLS * BALL_STATE_DIM  # 28
N_CAROM_FEATURES = 4  # d1, d2, sin(phi), cos(phi)
ACTION_DIM = 4  # theta, p, a, b
# Documented bounds of the raw action (theta, p, a, b). theta is in fact accepted as any real
# (the simulator wraps it mod 2*pi); the bound [0, 2*pi] is what specs and policies see.
ACTION_LOW = np.array([0.0, 0.0, -1.0, -1.0])
ACTION_HIGH = np.array([2.0 * math.pi, 1.0, 1.0, 1.0])
AIM_MAX_HALF_WIDTH = math.radians(80.0)  # the aim window's half-width cap (the paper's 80 degrees)
NEAR_MISS_SIGMA = 0.03  # length scale (m) of the near-miss bonus (the paper's; its weight is 0.05)
GENTLE_CENTER = 0.2  # the leave-position bonus peaks when the white rests this far (m) from the second red
GENTLE_WIDTH = 0.1  # ... with this Gaussian width (m)
GENTLE_KINDS = ("leave", "power")  # the paper's leave-position bonus; the power-based alternative


# ----------------------------------------------------------------------------- observation


def rest_observation(positions: np.ndarray) -> np.ndarray:
    """The paper's 28-float observation of a table at rest, float32.

    ``obs[..., 7*k : 7*k + 7] = (x_k, y_k, vx_k, vy_k, wx_k, wy_k, wz_k)`` for ball k in the
    ball order. Between shots every ball is at rest, so the velocity and spin slots are 0; they
    are kept for fidelity with the paper's observation layout.
    """
    positions = np.asarray(positions)
    obs = np.zeros(positions.shape[:-2] + (N_BALLS, BALL_STATE_DIM), dtype=np.float32)
    obs[..., :2] = positions
    return obs.reshape(positions.shape[:-2] + (OBS_DIM,))


def observed_positions(obs: np.ndarray) -> np.ndarray:
    """The ball centres an observation holds: the inverse of :func:`rest_observation` (to
    float32's precision). obs (..., D >= 28) -> positions (..., 4, 2) float64; what an agent that
    sees only the gymnasium observation knows of the table."""
    obs = np.asarray(obs)
    if obs.shape[-1] < OBS_DIM:
        raise ValueError(f"observed_positions: an observation has at least {OBS_DIM} floats, got shape {obs.shape}")
    balls = obs[..., :OBS_DIM].reshape(obs.shape[:-1] + (N_BALLS, BALL_STATE_DIM))
    return balls[..., :2].astype(np.float64)


def feature_observation(positions: np.ndarray) -> np.ndarray:
    """The observation slots of the carom features: :func:`carom_features` as float32,
    (..., 4), what the ``extra_features`` layer appends after the 28 rest floats."""
    return carom_features(positions).astype(np.float32)


def observation(positions: np.ndarray, extra_features: bool = False) -> np.ndarray:
    """THE observation of a table at rest, float32 (..., 28), or (..., 32) with the carom
    features: :func:`rest_observation`, then :func:`feature_observation`. The gymnasium env
    returns it; the TorchRL env returns the 28 floats and its ``CaromFeatures`` transform
    appends the 4 features (the same floats)."""
    obs = rest_observation(positions)
    if extra_features:
        obs = np.concatenate([obs, feature_observation(positions)], axis=-1)
    return obs


def observation_bounds(params=DEFAULT_PARAMS, extra_features: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) float32 bounds of :func:`observation` on the table of ``params``.

    Centres lie on the table; the velocity and spin slots (0 between shots) get a physical
    envelope: the fastest cue-ball launch v_max = 2 V0_max / (1 + m/M) and spin 2.5 v_max / R.
    The carom features: distances up to the table's diagonal, sin and cos in [-1, 1].
    """
    w, l = params.table_width, params.table_length
    v_max = 2.0 * params.cue_speed_max / (1.0 + params.ball_mass / params.cue_mass)
    w_max = 2.5 * v_max / params.ball_radius
    ball_high = np.array([w, l, v_max, v_max, w_max, w_max, w_max])
    ball_low = np.concatenate([[0.0, 0.0], -ball_high[2:]])
    low, high = np.tile(ball_low, N_BALLS), np.tile(ball_high, N_BALLS)
    if extra_features:
        diag = float(np.hypot(w, l))
        low = np.concatenate([low, [0.0, 0.0, -1.0, -1.0]])
        high = np.concatenate([high, [diag, diag, 1.0, 1.0]])
    return low.astype(np.float32), high.astype(np.float32)


# ----------------------------------------------------------------------------- normalised action


def action_bounds(constrain_aim: bool = False, normalized: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of the action a policy emits, fresh float64 arrays of shape (4,): the raw
    action (theta, p, a, b) = ACTION_LOW/HIGH, or with the aim constraint (u, p, a, b) with u
    in [-1, 1]; ``normalized``: [-1, 1]^4 either way (see :func:`unnormalize_action`). Every
    action space and spec of the envs and transforms is built from it."""
    if normalized:
        return -np.ones(ACTION_DIM), np.ones(ACTION_DIM)
    low, high = ACTION_LOW.copy(), ACTION_HIGH.copy()
    if constrain_aim:
        low[0], high[0] = -1.0, 1.0
    return low, high


def unnormalize_action(x: np.ndarray, constrain_aim: bool = False) -> np.ndarray:
    """The normalised action ``x in [-1, 1]^4`` as the raw action the simulator plays.

    This is THE map between the two (the gymnasium env's default action space, and the
    TorchRL ``NormalizedActions`` transform): each coordinate goes affinely from [-1, 1]
    onto its raw bounds (:func:`action_bounds`)::

        theta = pi * (x0 + 1)     in [0, 2 pi]   (with the aim constraint: u = x0 in [-1, 1])
        p     = (x1 + 1) / 2      in [0, 1]
        a     = x2,  b = x3       in [-1, 1]

    Why: Gaussian policies (SB3's PPO, ...) sample around 0 and clip to the box; on the raw
    box half their shots would have p clipped to 0. x (..., 4) -> (..., 4) float64.
    """
    low, high = action_bounds(constrain_aim)
    return low + (np.asarray(x, dtype=np.float64) + 1.0) * 0.5 * (high - low)


def normalize_action(action: np.ndarray, constrain_aim: bool = False) -> np.ndarray:
    """The inverse of :func:`unnormalize_action`: raw (theta | u, p, a, b) -> x in [-1, 1]^4
    (for theta in [0, 2 pi]). (..., 4) float64."""
    low, high = action_bounds(constrain_aim)
    return 2.0 * (np.asarray(action, dtype=np.float64) - low) / (high - low) - 1.0


# ----------------------------------------------------------------------------- aim constraint


def nearest_red(positions: np.ndarray) -> np.ndarray:
    """Ball index (2 or 3) of the red whose centre is nearest the white's; ties go to red1 (2).

    positions (..., 4, 2) -> (...,) int64.
    """
    pos = _rows(positions)
    return nearest_red_rows(pos).reshape(np.shape(positions)[:-2])


def _take_ball(positions: np.ndarray, index: np.ndarray) -> np.ndarray:
    """positions[..., index[...], :] for a per-row ball index."""
    return np.take_along_axis(positions, index[..., None, None], axis=-2)[..., 0, :]


def aim_window(positions: np.ndarray, R: float = DEFAULT_PARAMS.ball_radius,
               max_half_width: float = AIM_MAX_HALF_WIDTH, red: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The cone of aim angles whose straight path makes the white hit the nearest red (or the
    ball ``red`` (...,) names, e.g. the farther red ``RED1 + RED2 - nearest_red(positions)``).

    With ``delta = c_red - c_white`` (nearest red) and ``d = |delta|``:

        theta_target = atan2(delta_y, delta_x)
        half_width   = asin(min(2R / d, sin(max_half_width)))

    (the paper caps the half-width at 80 degrees, reached only when the balls nearly touch).

    A ball of radius R travelling along direction theta touches a resting ball of radius R
    whose centre lies at distance d iff the perpendicular offset ``d * |sin(theta -
    theta_target)|`` is below 2R (and the red is ahead), i.e. iff
    ``|theta - theta_target| < half_width``. The white's path is straight until its first
    collision (a level cue without squirt launches it along theta and no spin bends it), so
    every theta strictly inside the window makes the nearest red the first contact, unless
    another ball blocks the path first or the shot is too weak to get there.

    Returns ``(theta_target, half_width)``, each (...,) float64, theta_target in (-pi, pi].
    """
    pos = _rows(positions)
    lead = np.shape(positions)[:-2]
    reds = (nearest_red_rows(pos) if red is None
            else np.ascontiguousarray(np.broadcast_to(np.asarray(red, dtype=np.int64), lead)).reshape(-1))
    # one compiled pass (the C library's atan2 and asin, not NumPy's CPU-dependent loops)
    theta_target, half_width = aim_window_rows(pos, reds, 2.0 * R, math.sin(max_half_width))
    return theta_target.reshape(lead)[()], half_width.reshape(lead)[()]  # one table: two float64 scalars


def constrained_theta(positions: np.ndarray, u: np.ndarray, R: float = DEFAULT_PARAMS.ball_radius) -> np.ndarray:
    """The aim constraint: ``theta = theta_target + u * half_width`` (see :func:`aim_window`).

    u in [-1, 1] chooses where inside the guaranteed-contact cone to aim (u = 0 is a full-ball
    hit on the nearest red's centre, u = +-1 a graze on either side); |u| > 1 aims outside it.
    positions (..., 4, 2), u (...,) -> theta (...,) float64 (not wrapped; the simulator wraps).
    """
    theta_target, half_width = aim_window(positions, R)
    return theta_target + np.asarray(u, dtype=np.float64) * half_width


def aim_action(action: np.ndarray, positions: np.ndarray, R: float = DEFAULT_PARAMS.ball_radius) -> np.ndarray:
    """The aim-constrained action (u, p, a, b) (..., 4) as the raw (theta, p, a, b) on the
    tables ``positions`` (..., 4, 2): theta = :func:`constrained_theta` of u; p, a, b pass
    through. A new float64 array."""
    raw = np.array(action, dtype=np.float64)
    raw[..., 0] = constrained_theta(positions, raw[..., 0], R)
    return raw


def raw_action(action: np.ndarray, positions: np.ndarray, R: float = DEFAULT_PARAMS.ball_radius,
               constrain_aim: bool = False, normalized: bool = False) -> np.ndarray:
    """THE map from a policy's action (..., 4) to the raw shot (theta, p, a, b) the simulator
    plays on the tables ``positions`` (..., 4, 2): :func:`unnormalize_action` if the action is
    ``normalized``, then :func:`aim_action` with ``constrain_aim``. The gymnasium env plays it
    on a batch of one; the TorchRL ``NormalizedActions`` and ``AimConstraint`` transforms are
    its two stages, in that order. A new float64 array."""
    raw = unnormalize_action(action, constrain_aim) if normalized else np.array(action, dtype=np.float64)
    return aim_action(raw, positions, R) if constrain_aim else raw


def normalized_aim_action(positions: np.ndarray, actions: np.ndarray, R: float = DEFAULT_PARAMS.ball_radius) -> np.ndarray:
    """The inverse of :func:`raw_action` with the aim constraint and the normalised box: raw
    shots (..., 4) on the tables ``positions`` (..., 4, 2) as the aim-constrained policy's
    normalised action (u, 2p - 1, a, b), u the shot's angle inside the nearest red's window
    (:func:`aim_window`; the angle's difference taken within half a turn, so |u| > 1 for a shot
    aimed outside the window). (..., 4) float64."""
    target, half = aim_window(positions, R)
    actions = np.asarray(actions, dtype=np.float64)
    u = (np.mod(actions[..., 0] - target + math.pi, 2.0 * math.pi) - math.pi) / half
    return normalize_action(np.stack([u, actions[..., 1], actions[..., 2], actions[..., 3]], axis=-1), constrain_aim=True)


# ----------------------------------------------------------------------------- carom features


def carom_features(positions: np.ndarray) -> np.ndarray:
    """Four carom-geometry features, all measured from the red nearest the white.

    With w the white's centre, n the nearest red's (:func:`nearest_red`) and o the other red's,
    u1 = n - w and u2 = o - n:

        d1     = |u1|                            white -> nearest red centre distance (m)
        d2     = |o - w|                         white -> other red centre distance (m)
        sin_phi = (u1 x u2) / (|u1| |u2|)        u1 x u2 = u1_x u2_y - u1_y u2_x
        cos_phi = (u1 . u2) / (|u1| |u2|)

    phi in (-pi, pi] is the signed angle that turns the white->nearest-red direction onto the
    nearest-red->other-red direction, counter-clockwise positive in the table frame: phi = 0
    when the other red lies straight on beyond the nearest one, |phi| = pi when it lies back
    towards the white. Returns (..., 4) float64 = (d1, d2, sin_phi, cos_phi). Balls never
    overlap, so |u1|, |u2| >= 2R > 0.
    """
    pos = _rows(positions)
    return carom_features_rows(pos).reshape(np.shape(positions)[:-2] + (N_CAROM_FEATURES,))


# The three functions above as compiled passes over (N, 4, 2) rows: the same IEEE operations in
# the same order as their NumPy formulas (|v| = sqrt(vx*vx + vy*vy) where NumPy's norm sums two
# squares, hypot where it calls hypot), so the same bits, without a dozen temporary arrays.


def _rows(positions) -> np.ndarray:
    pos = np.asarray(positions, dtype=np.float64)
    if pos.shape[-2:] != (N_BALLS, 2):
        raise ValueError(f"positions must have shape (..., {N_BALLS}, 2); got {pos.shape}")
    return np.ascontiguousarray(pos.reshape(-1, N_BALLS, 2))


@numba.njit(cache=True, nogil=True)
def nearest_red_rows(pos):
    out = np.empty(pos.shape[0], dtype=np.int64)
    for i in range(pos.shape[0]):
        ax, ay = pos[i, RED1, 0] - pos[i, WHITE, 0], pos[i, RED1, 1] - pos[i, WHITE, 1]
        bx, by = pos[i, RED2, 0] - pos[i, WHITE, 0], pos[i, RED2, 1] - pos[i, WHITE, 1]
        out[i] = RED2 if math.sqrt(bx * bx + by * by) < math.sqrt(ax * ax + ay * ay) else RED1
    return out


@numba.njit(cache=True, nogil=True)
def aim_window_rows(pos, reds, two_r, cap):
    n = pos.shape[0]
    theta, half = np.empty(n), np.empty(n)
    for i in range(n):
        dx, dy = pos[i, reds[i], 0] - pos[i, WHITE, 0], pos[i, reds[i], 1] - pos[i, WHITE, 1]
        theta[i] = math.atan2(dy, dx)
        half[i] = math.asin(min(two_r / math.hypot(dx, dy), cap))
    return theta, half


@numba.njit(cache=True, nogil=True)
def carom_features_rows(pos):
    near = nearest_red_rows(pos)
    out = np.empty((pos.shape[0], 4))
    for i in range(pos.shape[0]):
        k, m = near[i], RED1 + RED2 - near[i]
        wx, wy = pos[i, WHITE, 0], pos[i, WHITE, 1]
        u1x, u1y = pos[i, k, 0] - wx, pos[i, k, 1] - wy
        u2x, u2y = pos[i, m, 0] - pos[i, k, 0], pos[i, m, 1] - pos[i, k, 1]
        ox, oy = pos[i, m, 0] - wx, pos[i, m, 1] - wy
        d1 = math.hypot(u1x, u1y)
        norm = d1 * math.hypot(u2x, u2y)
        out[i, 0] = d1
        out[i, 1] = math.sqrt(ox * ox + oy * oy)
        out[i, 2] = (u1x * u2y - u1y * u2x) / norm
        out[i, 3] = (u1x * u2x + u1y * u2y) / norm
    return out


# ----------------------------------------------------------------------------- reward shaping


def check_coefficient(name: str, value: float, strict: bool = False) -> float:
    """A shaping coefficient as a float, or a ValueError naming it if it is not a number, NaN,
    inf or negative (or zero when ``strict``, for length scales). Every shaping entry point --
    the functions below, make_env, the gymnasium env and the transforms -- checks with it, so
    no such value reaches a reward (:func:`billiards.physics.checks.finite_number`: a real
    number, not a boolean or a string)."""
    return finite_number(value, name, 0.0, lo_open=strict)


def foul_penalty(foul: np.ndarray, c: float) -> np.ndarray:
    """Foul penalty term: ``-c * foul`` (foul in {0, 1})."""
    return -check_coefficient("foul penalty c", c) * np.asarray(foul, dtype=np.float64)


def shot_reward(score: np.ndarray, foul: np.ndarray, c: float) -> np.ndarray:
    """The searches' reward of shots: ``score - c * foul`` (score and foul in {0, 1}, or their
    rates over replays), in float64: what the verifier, the league players and the protocols'
    predictions all score a shot by."""
    return np.asarray(score, dtype=np.float64) + foul_penalty(foul, c)


def gentle_bonus(
    score: np.ndarray,
    positions: np.ndarray,
    second_red: np.ndarray,
    beta: float,
    center: float = GENTLE_CENTER,
    width: float = GENTLE_WIDTH,
) -> np.ndarray:
    """The paper's gentle-shot bonus, a leave-position bonus: on a scoring shot,

        beta * exp(-(d - center)^2 / (2 width^2)),

    d (m) the distance from the white at rest to the second red it contacted (``positions``
    (..., 4, 2) the table after the shot, ``second_red`` (...,) that red's ball index 2 or 3,
    as the simulator reports it). It favours soft shots because a hard shot carries the white
    far from that red; a score is never a foul, so no foul check is needed. The paper uses
    beta = 0.2, center 0.2 m, width 0.1 m.
    """
    beta = check_coefficient("gentle beta", beta)
    score = np.asarray(score, dtype=bool)
    positions = np.asarray(positions, dtype=np.float64)
    red = np.where(np.asarray(second_red) >= RED1, second_red, RED1).astype(np.int64)
    d = np.linalg.norm(_take_ball(positions, red) - positions[..., WHITE, :], axis=-1)
    return np.where(score, beta * numerics.exp(-((d - center) ** 2) / (2.0 * width * width)), 0.0)


def gentle_power_bonus(score: np.ndarray, power: np.ndarray, beta: float) -> np.ndarray:
    """A power-based alternative to :func:`gentle_bonus`: ``beta * score * (1 - p)``, p in
    [0, 1] the shot's power (``shaping.gentle_kind=power``; the project's gentle bonus before
    the paper's constants were adopted)."""
    beta = check_coefficient("gentle beta", beta)
    return beta * np.asarray(score, dtype=np.float64) * (1.0 - np.asarray(power, dtype=np.float64))




def near_miss_bonus(
    score: np.ndarray,
    foul: np.ndarray,
    hits: np.ndarray,
    closest: np.ndarray,
    beta: float,
    sigma: float = NEAR_MISS_SIGMA,
) -> np.ndarray:
    """Near-miss bonus for nearly completing the carom:

        beta * exp(-gap / sigma)   if the white hit exactly one red and the shot is neither
                                   a score nor a foul,
        0                          otherwise,

    where gap (m) is the white's closest surface gap to the red it did not touch during the
    shot (:func:`billiards.physics.unhit_red_gap`; the simulator measures it over the whole
    shot). The bonus is beta for a hair's-breadth miss and decays with length scale sigma
    (the paper: beta = 0.05, sigma = 0.03 m). hits (..., 3) = (yellow, red1, red2), closest
    (..., 2) gaps to red1, red2.
    """
    beta = check_coefficient("near-miss beta", beta)
    sigma = check_coefficient("near-miss sigma", sigma, strict=True)
    hits = np.asarray(hits, dtype=bool)
    one_red = hits[..., 1] ^ hits[..., 2]
    eligible = one_red & ~np.asarray(score, dtype=bool) & ~np.asarray(foul, dtype=bool)
    gap = unhit_red_gap(hits, closest)
    return np.where(eligible, beta * numerics.exp(-gap / sigma), 0.0)


def shaped_reward(
    score: np.ndarray,
    foul: np.ndarray,
    power: np.ndarray,
    hits: np.ndarray,
    closest: np.ndarray,
    positions: np.ndarray | None = None,
    second_red: np.ndarray | None = None,
    foul_c: float = 0.0,
    gentle_beta: float = 0.0,
    gentle_kind: str = "leave",
    near_miss_beta: float = 0.0,
    near_miss_sigma: float = NEAR_MISS_SIGMA,
) -> np.ndarray:
    """Total reward: ``score + foul_penalty + gentle + near_miss_bonus`` (terms with a zero
    coefficient are skipped). With all coefficients 0 this is the raw carom score. The
    leave-position gentle bonus needs the rest ``positions`` and ``second_red`` of the shot.
    Coefficients must be finite and >= 0, sigma > 0 (:func:`check_coefficient`)."""
    foul_c = check_coefficient("foul penalty c", foul_c)
    gentle_beta = check_coefficient("gentle beta", gentle_beta)
    near_miss_beta = check_coefficient("near-miss beta", near_miss_beta)
    near_miss_sigma = check_coefficient("near-miss sigma", near_miss_sigma, strict=True)
    reward = np.asarray(score, dtype=np.float64).copy()
    if foul_c:
        reward += foul_penalty(foul, foul_c)
    if gentle_beta:
        if gentle_kind == "leave":
            reward += gentle_bonus(score, positions, second_red, gentle_beta)
        elif gentle_kind == "power":
            reward += gentle_power_bonus(score, power, gentle_beta)
        else:
            raise ValueError(f"gentle_kind must be one of {GENTLE_KINDS}, got {gentle_kind!r}")
    if near_miss_beta:
        reward += near_miss_bonus(score, foul, hits, closest, near_miss_beta, near_miss_sigma)
    return reward
