"""Pictures of shots and innings (matplotlib, Agg backend). Drawing only: of the package it
imports the simulator alone, never an env, a policy or a search (playing an inning for a
picture, and the command line, are :mod:`billiards.pictures`').

API:
* :func:`render_shot` -- PNG of one shot: table, balls in their colours at the start (faint)
  and at rest (solid), every ball's path from :func:`billiards.physics.trajectory`, the
  white's ball contacts (numbered rings) and cushion contacts (triangles), the aim, and the
  outcome (SCORE / FOUL / MISS) in the title;
* :func:`render_inning` -- animated GIF of a sequence of shots (Pillow writer);
* :func:`table_rgb_array` -- an RGB image of a table at rest (gymnasium's ``rgb_array``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib import animation
from matplotlib.patches import Circle, Rectangle

from billiards.physics import (
    BALL_NAMES,
    DEFAULT_PARAMS,
    EVENT_KINDS,
    PhysicsParams,
    ShotResult,
    simulate_shot,
    trajectory,
)

BALL_COLORS = ("#f7f7f2", "#f2c400", "#d7261e", "#9c0d2b")  # white, yellow, red1, red2 (darker)
# each path is drawn over a wider edge line: dark under the light balls' paths, white under the reds'
PATH_EDGES = ("#222222", "#222222", "#ffffff", "#ffffff")
CLOTH, RAIL, PATH_EDGE = "#1f6e43", "#5a3a1e", "#222222"
EV_BALL_BALL, EV_CUSHION = EVENT_KINDS.index("ball_ball"), EVENT_KINDS.index("cushion")


# ----------------------------------------------------------------------------- drawing blocks


def _figure(params: PhysicsParams, scale: float = 3.0, dpi: int = 100):
    """A portrait figure: the table, a title band above it and a legend band below."""
    w, l = params.table_width, params.table_length
    fig = plt.figure(figsize=(scale * (w + 0.3), scale * (l + 0.75)), dpi=dpi)
    ax = fig.add_axes((0.0, 0.2 / (l + 0.75), 1.0, (l + 0.3) / (l + 0.75)))
    return fig, ax


def draw_table(ax, params: PhysicsParams = DEFAULT_PARAMS) -> None:
    """Cloth inside the cushion nose lines [0, w] x [0, l], a rail around it and the diamonds."""
    w, l, rail = params.table_width, params.table_length, 0.12
    ax.add_patch(Rectangle((-rail, -rail), w + 2 * rail, l + 2 * rail, color=RAIL, zorder=0))
    ax.add_patch(Rectangle((0, 0), w, l, color=CLOTH, zorder=1))
    for k in range(1, 4):  # diamonds every w/4 and l/8
        for x in (-rail / 2, w + rail / 2):
            ax.plot(x, l * k / 4, "o", ms=2.5, color="#e8e0c8", zorder=2)
        for y in (-rail / 2, l + rail / 2):
            ax.plot(w * k / 4, y, "o", ms=2.5, color="#e8e0c8", zorder=2)
    for k in range(1, 8):
        for x in (-rail / 2, w + rail / 2):
            ax.plot(x, l * k / 8, "o", ms=1.5, color="#e8e0c8", zorder=2)
    ax.set_xlim(-rail - 0.03, w + rail + 0.03)
    ax.set_ylim(-rail - 0.03, l + rail + 0.03)
    ax.set_aspect("equal")
    ax.axis("off")


def draw_balls(ax, positions: np.ndarray, params: PhysicsParams = DEFAULT_PARAMS, alpha: float = 1.0, zorder: int = 6):
    """Circles of the true radius at positions (4, 2); returns the patches (for animation)."""
    patches = []
    for k in range(4):
        c = Circle(positions[k], params.ball_radius, facecolor=BALL_COLORS[k], edgecolor="black", lw=0.6, alpha=alpha, zorder=zorder)
        ax.add_patch(c)
        patches.append(c)
    return patches


def outcome_text(result) -> str:
    """'SCORE' / 'FOUL' / 'MISS' and the white's first contact and cushion count."""
    label = "SCORE" if result.score else ("FOUL" if result.foul else "MISS")
    first = BALL_NAMES[result.first_contact] if result.first_contact >= 0 else "none"
    return f"{label}  first contact: {first}, cushions: {result.cushions}"


def _white_contacts(result: ShotResult):
    """(balls, cushions): the white's ball contacts as (position, other ball) and its cushion
    contact positions, in order."""
    balls, cushions = [], []
    for e in range(result.event_time.size):
        kind, i, j = result.event_kind[e], result.event_ball[e], result.event_other[e]
        white_xy = result.event_state[e, 0, :2]
        if kind == EV_BALL_BALL and 0 in (i, j):
            balls.append((white_xy, j if i == 0 else i))
        elif kind == EV_CUSHION and i == 0:
            cushions.append(white_xy)
    return balls, cushions


def draw_shot(ax, positions, action, params: PhysicsParams = DEFAULT_PARAMS, dt: float = 1 / 120) -> ShotResult:
    """Draw one simulated shot (raw action theta, p, a, b) on ax; returns the ShotResult."""
    positions = np.asarray(positions, dtype=np.float64)
    action = np.asarray(action, dtype=np.float64)
    result = simulate_shot(positions, action, params)
    _, xy = trajectory(result, dt, params)
    draw_table(ax, params)
    for k in (1, 2, 3, 0):  # the white's path on top
        ax.plot(xy[:, k, 0], xy[:, k, 1], color=PATH_EDGES[k], lw=3.0, zorder=3, solid_capstyle="round")
        ax.plot(xy[:, k, 0], xy[:, k, 1], color=BALL_COLORS[k], lw=1.6, zorder=3, solid_capstyle="round")
    draw_balls(ax, positions, params, alpha=0.35, zorder=4)
    draw_balls(ax, result.positions, params, zorder=6)
    aim = 0.15 * np.array([math.cos(action[0]), math.sin(action[0])])
    ax.annotate("", positions[0] + aim, positions[0], arrowprops=dict(arrowstyle="->", color="white", lw=1.0), zorder=7)
    balls, cushions = _white_contacts(result)
    for n, (p, other) in enumerate(balls, start=1):
        ax.add_patch(Circle(p, 1.6 * params.ball_radius, fill=False, edgecolor=BALL_COLORS[other], lw=1.5, zorder=8))
        ax.annotate(str(n), p + 0.07, color="white", fontsize=7, ha="center", va="center", zorder=9)
    for p in cushions:
        ax.plot(*p, marker="^", ms=4, color="#ffdd88", markeredgecolor="black", mew=0.4, zorder=8)
    return result


def draw_legend(fig) -> None:
    """A one-line key under the table: the balls' colours, contacts and the aim."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], marker="o", ls="-", color=BALL_COLORS[k], markeredgecolor="black", lw=1.6, label=name)
               for k, name in enumerate(BALL_NAMES)]
    handles += [Line2D([], [], marker="o", ls="", mfc="none", mec="#d7261e", label="white's contact (n)"),
                Line2D([], [], marker="^", ls="", color="#ffdd88", mec="black", label="cushion")]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=7, frameon=False, handlelength=1.5,
               columnspacing=1.0, labelcolor="black")


# ----------------------------------------------------------------------------- one shot


def render_shot(
    positions,
    action,
    path: str | Path | None = None,
    *,
    params: PhysicsParams = DEFAULT_PARAMS,
    title: str | None = None,
    dpi: int = 100,
) -> ShotResult:
    """Draw one shot from ``positions`` (4, 2) with the raw ``action`` (theta, p, a, b).

    Saves a PNG to ``path`` if given. Returns the simulated :class:`ShotResult`.
    """
    fig, ax = _figure(params, dpi=dpi)
    result = draw_shot(ax, positions, action, params)
    draw_legend(fig)
    theta, p, a, b = np.asarray(action, dtype=np.float64)
    text = outcome_text(result) + f"\ntheta={math.degrees(theta) % 360:.1f}°  p={p:.2f}  a={a:+.2f}  b={b:+.2f}"
    fig.text(0.5, 0.995, (title + "\n" if title else "") + text, ha="center", va="top", fontsize=7)
    if path is not None:
        fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return result


def table_rgb_array(positions, params: PhysicsParams = DEFAULT_PARAMS, dpi: int = 60, last_shot=None) -> np.ndarray:
    """An (H, W, 3) uint8 image of the table with the balls at ``positions``; with
    ``last_shot = (positions_before, raw_action)`` the shot that led there, drawn as by
    :func:`draw_shot` (ball paths, the balls where they started, faint, and where they stopped)."""
    fig, ax = _figure(params, dpi=dpi)
    if last_shot is None:
        draw_table(ax, params)
        draw_balls(ax, np.asarray(positions, dtype=np.float64), params)
    else:
        draw_shot(ax, *last_shot, params=params)
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    return image


# ----------------------------------------------------------------------------- innings


def render_inning(
    shots: Sequence[tuple[np.ndarray, np.ndarray]],
    path: str | Path,
    *,
    params: PhysicsParams = DEFAULT_PARAMS,
    fps: int = 15,
    speed: float = 2.0,
    pause: float = 0.6,
    dpi: int = 80,
    title: str = "",
) -> int:
    """Animated GIF of a sequence of shots (positions, raw action); returns the frame count.

    ``speed`` is simulated seconds per wall-clock second; each shot holds ``pause`` seconds on
    its final table. Trails show the paths of the current shot.
    """
    frames = []  # (shot index, xy (4, 2), trail xy (t, 4, 2), caption)
    points = 0
    for n, (pos, act) in enumerate(shots):
        result = simulate_shot(pos, act, params)
        times, xy = trajectory(result, 1 / 240, params)
        grid = np.arange(0.0, result.duration + 1e-12, speed / fps)
        xy_grid = np.empty((grid.size, 4, 2))
        for k in range(4):
            for c in range(2):
                xy_grid[:, k, c] = np.interp(grid, times, xy[:, k, c])
        xy_grid[-1] = result.positions
        points += int(result.score)
        caption = f"{title}shot {n + 1}/{len(shots)}: {outcome_text(result).split('  ')[0]}  points {points}"
        pending = f"{title}shot {n + 1}/{len(shots)}  points {points - int(result.score)}"
        for t in range(len(grid)):
            frames.append((xy_grid[t], xy_grid[: t + 1], pending))
        frames += [(xy_grid[-1], xy_grid, caption)] * max(1, int(pause * fps))

    fig, ax = _figure(params, dpi=dpi)
    draw_table(ax, params)
    draw_legend(fig)
    trails = [ax.plot([], [], color=BALL_COLORS[k], lw=1.0, alpha=0.8, zorder=3)[0] for k in range(4)]
    balls = draw_balls(ax, shots[0][0], params)
    text = fig.text(0.5, 0.99, "", ha="center", va="top", fontsize=8)

    def update(i):
        xy, trail, caption = frames[i]
        for k in range(4):
            balls[k].center = tuple(xy[k])
            trails[k].set_data(trail[:, k, 0], trail[:, k, 1])
        text.set_text(caption)
        return [*balls, *trails, text]

    anim = animation.FuncAnimation(fig, update, frames=len(frames), blit=False)
    anim.save(str(path), writer=animation.PillowWriter(fps=fps), dpi=dpi)
    plt.close(fig)
    return len(frames)


if __name__ == "__main__":
    raise SystemExit("the picture command line is python -m billiards.pictures (shot | inning ...); "
                     "billiards.render only draws")
