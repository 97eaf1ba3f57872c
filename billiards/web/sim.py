"""One shot for the page: the exact simulation, its execution noise, its sampled paths and its
outcome, as plain JSON-able values.

Either cue ball can shoot (``shooter`` 0: white, 1: yellow): a yellow shot is simulated on the
table with the cue balls' slots exchanged and exchanged back (:func:`billiards.envs.sagu.shooter_view`,
as the two-player env does), so the positions, paths and events come back in the table's own
ball order (0 white, 1 yellow, 2 red1, 3 red2) and a white shot is exactly
:func:`billiards.physics.simulate_shot`'s.
"""

from __future__ import annotations

import math

import numpy as np

from billiards.envs.sagu import SWAP, shooter_view
from billiards.physics import BALL_NAMES, CUSHION_NAMES, DEFAULT_PRESET, EVENT_KINDS, PRESETS, get_params, simulate_shot, trajectory
from billiards.physics.noise import NOISE_PRESETS, get_noise

DEFAULT_DT = 1.0 / 60.0  # seconds between path samples (the page interpolates between them)
MAX_FRAMES = 2400  # a shot's path samples at most (a longer shot is sampled more coarsely)
PATH_DECIMALS = 5  # path samples are rounded to 0.01 mm (drawing only: `final` is exact)
EV_BALL_BALL, EV_CUSHION = EVENT_KINDS.index("ball_ball"), EVENT_KINDS.index("cushion")


def table_info(name: str) -> dict:
    """What the page needs to draw a physics preset's table: its size, the ball radius and the
    opening rack (metres), the cue's limits."""
    p = get_params(name)
    return {"name": name, "table_width": p.table_width, "table_length": p.table_length, "ball_radius": p.ball_radius,
            "opening_rack": p.opening_rack().tolist(), "cue_speed_max": p.cue_speed_max, "max_english": p.max_english,
            "max_time": None if math.isinf(p.max_time) else p.max_time}


def noise_info(name: str) -> dict:
    n = NOISE_PRESETS[name]
    return {"name": name, "aim_deg": n.sigma_aim_deg, "speed": n.sigma_speed, "tip_mm": n.sigma_tip_mm,
            "variable": n.is_variable, "level_range": list(n.level_range) if n.is_variable else None}


def presets() -> dict:
    return {"physics": {name: table_info(name) for name in PRESETS}, "noise": {name: noise_info(name) for name in NOISE_PRESETS}}


def played_action(action, noise_name: str, seed: int, params, level: float | None = None) -> tuple[np.ndarray, float | None]:
    """The shot played for the commanded ``action`` under the noise preset ``noise_name``, its
    errors drawn from ``numpy.random.default_rng(seed)``; under variable noise at ``level`` (None:
    the level is drawn first from the same generator). Exact play returns the action unchanged."""
    noise = get_noise(noise_name)
    action = np.asarray(action, dtype=np.float64)
    if noise.is_exact:
        return action.copy(), None
    rng = np.random.default_rng(seed)
    if noise.is_variable:
        if level is None:
            level = float(noise.draw_levels((1,), rng)[0])
        return noise.perturb(action[None], rng, params, levels=np.array([level]))[0], level
    return noise.perturb(action[None], rng, params)[0], None


def outcome(result, shooter: int = 0) -> dict:
    """The carom outcome of a shot, named from the shooter's side (its cue ball struck, the
    other cue ball its foul ball)."""
    names = [BALL_NAMES[SWAP[k]] if shooter else BALL_NAMES[k] for k in range(4)]
    first = int(result.first_contact)
    return {"score": bool(result.score), "foul": bool(result.foul), "miss": bool(result.miss),
            "label": "score" if result.score else "foul" if result.foul else "miss",
            "first_contact": names[first] if first >= 0 else None,
            "hits": {names[k + 1]: bool(h) for k, h in enumerate(result.hits)},
            "cushions": int(result.cushions), "duration": float(result.duration), "n_events": int(result.n_events),
            "truncated": bool(result.truncated), "timed_out": bool(result.timed_out)}


def events(result, shooter: int = 0) -> list[dict]:
    """Ball-ball and cushion events, in the table's ball order: time, kind, ball, other (a ball
    or a cushion's name) and where the ball was."""
    out = []
    relabel = SWAP if shooter else np.arange(4)
    for e in range(result.event_time.size):
        kind = int(result.event_kind[e])
        if kind not in (EV_BALL_BALL, EV_CUSHION):
            continue
        i, j = int(result.event_ball[e]), int(result.event_other[e])
        xy = result.event_state[e, i, :2]
        out.append({"t": float(result.event_time[e]), "kind": EVENT_KINDS[kind], "ball": int(relabel[i]),
                    "other": int(relabel[j]) if kind == EV_BALL_BALL else CUSHION_NAMES[j],
                    "xy": [round(float(xy[0]), PATH_DECIMALS), round(float(xy[1]), PATH_DECIMALS)]})
    return out


def paths(result, params, dt: float = DEFAULT_DT) -> dict:
    """Every ball's sampled path (``t`` (T,), ``xy`` (T, 4, 2), in the simulator's ball order),
    at most :data:`MAX_FRAMES` samples."""
    dt = max(dt, result.duration / MAX_FRAMES)
    times, xy = trajectory(result, dt, params)
    return {"dt": dt, "t": np.round(times, 6).tolist(), "xy": np.round(xy, PATH_DECIMALS).tolist()}


def shot(positions, action, *, physics: str = DEFAULT_PRESET, noise: str = "none", seed: int = 0,
         level: float | None = None, shooter: int = 0, dt: float = DEFAULT_DT, with_paths: bool = True) -> dict:
    """One shot as the API answers it (see the module docstring): the commanded and played
    actions, ``final`` (4, 2) exact, ``result``, ``events`` and ``paths``. Bad positions or
    actions raise the simulator's ValueError."""
    params = get_params(physics)
    positions = np.asarray(positions, dtype=np.float64)
    action = np.asarray(action, dtype=np.float64)
    from billiards.physics import check_actions, check_positions

    check_actions(action)
    check_positions(positions, params)
    played, level = played_action(action, noise, seed, params, level)
    view = shooter_view(positions, shooter)
    result = simulate_shot(view, played, params)
    final = shooter_view(result.positions, shooter)
    out = {"shooter": shooter, "commanded": action.tolist(), "played": played.tolist(), "noise": noise, "level": level,
           "seed": seed, "physics": physics, "positions": positions.tolist(), "final": final.tolist(),
           "result": outcome(result, shooter), "events": events(result, shooter)}
    if with_paths:
        p = paths(result, params, dt)
        if shooter:
            p["xy"] = [[frame[k] for k in SWAP] for frame in p["xy"]]
        out["paths"] = p
    return out


def replay_played(positions, played, *, physics: str, shooter: int = 0, dt: float = DEFAULT_DT) -> dict:
    """A recorded shot played again exactly (its played action, no new noise)."""
    return shot(positions, played, physics=physics, noise="none", shooter=shooter, dt=dt)


__all__ = ["DEFAULT_DT", "MAX_FRAMES", "events", "noise_info", "outcome", "paths", "played_action", "presets",
           "replay_played", "shot", "table_info"]
