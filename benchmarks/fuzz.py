"""Fuzz the simulator's invariants: no shot may end with a ball off the table, two balls
overlapping, or a non-finite coordinate, whatever valid state and action it starts from.

    NUMBA_NUM_THREADS=1 python benchmarks/fuzz.py --shots 1000000 --out results/fuzz.json

Shots come in families, each run with ``simulate_batch`` (the public, validated path):

* ``natural``: uniform random racks and uniform actions;
* ``contacts``: racks built from exactly touching balls (clusters, chains, axis-aligned and
  diagonal contacts, gaps and overlaps within ``POSITION_TOL``);
* ``rails``: balls exactly on, or within ``POSITION_TOL`` of, the cushions' nose lines and
  corners, often touching each other along a rail;
* ``chained``: innings: every shot starts from the previous shot's rest positions;
* ``frozen``: every ball touching another (clusters of four frozen together, chains, pairs on
  a rail), each gap drawn from 0 to 1e-6 m (0, log-uniform 1e-15 ... 1e-6, 1e-6);
* ``corners``: balls jammed into the corners (on both nose lines, a gap of 0 to 1e-6 m), the
  others frozen to them;

and the last two play adversarial actions: power exactly 0 or 1 (or uniform), tip offsets on
the unit circle (or uniform), aims at a ball's centre, grazing it, or along an axis.

Every family mixes natural actions with extreme ones: power 1, tip offsets on the unit
circle, aims along the axes (straight into or along a rail), at a ball's centre, and grazes
that meet a ball at a cut of (almost) 90 degrees. A rest state is a violation if a ball is
off the table or two balls overlap beyond ``POSITION_TOL``, or a coordinate is not finite; a
shot the simulator had to flag (``truncated``) is counted apart, as is a rest state that
validation would refuse as the next shot's start (the union of the first three).

Prints shots, violations by kind and family, and the time; ``--out`` writes the figures as
JSON with the command and the git commit. ``--physics`` picks the parameters by preset name
(``billiards.physics.PRESETS``; the default preset if omitted), ``--max-english`` overrides
the largest tip offset. Shots stopped at the preset's ``max_time`` are counted (``timed_out``)
but are no violation: every ball then rests where it is, a valid state.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numba
import numpy as np

# This checkout's benchmarks and package first, so the figures come from the code (and the
# commit) of the checkout the script lives in, not from another installed copy of billiards.
HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]
from _shots import git_commit, write_json  # noqa: E402

from billiards import numerics  # noqa: E402  (the C library's functions: the same inputs on every CPU)
from billiards.physics import (  # noqa: E402
    DEFAULT_PRESET, POSITION_TOL, PRESETS, PhysicsParams, check_positions, random_racks, simulate_batch,
)

FAMILIES = ("natural", "contacts", "rails", "chained")  # (benchmarks/kernel_fingerprint.py plays these too)
ADVERSARIAL = ("frozen", "corners")
ALL_FAMILIES = FAMILIES + ADVERSARIAL
KINDS = ("off_table", "overlap", "non_finite", "truncated", "refused_next")


# ----------------------------------------------------------------------------- racks


def _valid(racks: np.ndarray, params: PhysicsParams) -> np.ndarray:
    """(N,) mask of the racks the simulator accepts (the same rule as check_positions)."""
    R, W, L, tol = params.ball_radius, params.table_width, params.table_length, POSITION_TOL
    x, y = racks[..., 0], racks[..., 1]
    inside = (x >= R - tol) & (x <= W - R + tol) & (y >= R - tol) & (y <= L - R + tol)
    d = np.linalg.norm(racks[:, :, None] - racks[:, None], axis=-1)
    d[:, range(4), range(4)] = np.inf
    return np.isfinite(racks).all(axis=(1, 2)) & inside.all(axis=1) & (d.min(axis=(1, 2)) >= 2 * R - tol)


def _near(rng: np.random.Generator, shape) -> np.ndarray:
    """Offsets of a rail or contact distance from exact: 0, an ulp-sized nudge, or up to the
    tolerance either way (the edges of what validation accepts)."""
    tol = POSITION_TOL
    choice = rng.integers(0, 5, shape)
    out = np.zeros(shape)
    out = np.where(choice == 1, rng.choice([-1e-15, 1e-15, -1e-12, 1e-12], shape), out)
    out = np.where(choice == 2, rng.uniform(-tol, tol, shape), out)
    out = np.where(choice == 3, rng.choice([-tol, tol], shape) * 0.9999999, out)
    return out


def _angles(rng: np.random.Generator, n: int) -> np.ndarray:
    """Directions: uniform, or exact multiples of pi/4 (axis-aligned and diagonal contacts)."""
    exact = rng.integers(0, 8, n) * (np.pi / 4)
    return np.where(rng.random(n) < 0.4, exact, rng.uniform(0, 2 * np.pi, n))


def _snap_to_rails(rng: np.random.Generator, xy: np.ndarray, params: PhysicsParams) -> np.ndarray:
    """Move points onto a nose line (x, y or both: corners), each within _near of it."""
    R, W, L = params.ball_radius, params.table_width, params.table_length
    n = xy.shape[0]
    out = xy.copy()
    which = rng.integers(0, 3, n)  # 0: an x rail, 1: a y rail, 2: a corner
    xr = np.where(rng.random(n) < 0.5, R, W - R) + _near(rng, n)
    yr = np.where(rng.random(n) < 0.5, R, L - R) + _near(rng, n)
    out[:, 0] = np.where(which != 1, xr, out[:, 0])
    out[:, 1] = np.where(which != 0, yr, out[:, 1])
    return out


def _build(rng: np.random.Generator, n: int, params: PhysicsParams, p_rail: float, p_touch: float) -> np.ndarray:
    """n valid racks whose balls are, each with the given odds, on a rail or touching an
    earlier ball (along a rail if that ball is on one); redrawn until valid."""
    R, W, L = params.ball_radius, params.table_width, params.table_length
    out = np.empty((n, 4, 2))
    todo = np.arange(n)
    while todo.size:
        m = todo.size
        rack = np.column_stack([rng.uniform(R, W - R, (m, 4)), rng.uniform(R, L - R, (m, 4))]).reshape(m, 2, 4)
        rack = rack.transpose(0, 2, 1).copy()
        for k in range(4):
            u = rng.random(m)
            on_rail = u < p_rail
            rack[on_rail, k] = _snap_to_rails(rng, rack[on_rail, k], params)
            touch = (u >= p_rail) & (u < p_rail + p_touch) & (k > 0)
            if touch.any():
                idx = np.flatnonzero(touch)
                base = rack[idx, rng.integers(0, k, idx.size)]
                ang = _angles(rng, idx.size)
                dist = 2 * R + _near(rng, idx.size)
                rack[idx, k, 0] = base[:, 0] + dist * numerics.cos(ang)
                rack[idx, k, 1] = base[:, 1] + dist * numerics.sin(ang)
                # exact axis steps (no cos/sin rounding) for a third of them
                axis = rng.random(idx.size) < 0.33
                step = rng.integers(0, 4, idx.size)
                dx = np.array([1.0, -1.0, 0.0, 0.0])[step] * dist
                dy = np.array([0.0, 0.0, 1.0, -1.0])[step] * dist
                rack[idx[axis], k, 0] = base[axis, 0] + dx[axis]
                rack[idx[axis], k, 1] = base[axis, 1] + dy[axis]
        ok = _valid(rack, params)
        out[todo[ok]] = rack[ok]
        todo = todo[~ok]
    return out


def _gap(rng: np.random.Generator, shape) -> np.ndarray:
    """Gaps from 0 to 1e-6 m: exactly 0, exactly 1e-6, or log-uniform in between."""
    choice = rng.integers(0, 4, shape)
    return np.where(choice == 0, 0.0, np.where(choice == 1, 1e-6, 10.0 ** rng.uniform(-15, -6, shape)))


def _frozen(rng: np.random.Generator, n: int, params: PhysicsParams, corner_share: float) -> np.ndarray:
    """n valid racks of balls frozen together: ball 0 in a corner (``corner_share`` of the balls
    after it too, each in a corner of its own) or anywhere, every other ball touching an
    earlier one at a gap of 0 to 1e-6 m (axis-aligned, diagonal or any direction)."""
    R, W, L = params.ball_radius, params.table_width, params.table_length
    out = np.empty((n, 4, 2))
    todo = np.arange(n)
    while todo.size:
        m = todo.size
        rack = np.empty((m, 4, 2))
        cx, cy = np.where(rng.random(m) < 0.5, R, W - R), np.where(rng.random(m) < 0.5, R, L - R)
        inward = lambda c, lo, hi: np.where(c == lo, c + _gap(rng, m), c - _gap(rng, m))
        anywhere = np.column_stack([rng.uniform(R, W - R, m), rng.uniform(R, L - R, m)])
        first_corner = rng.random(m) < max(corner_share, 0.5)
        rack[:, 0] = np.where(first_corner[:, None], np.column_stack([inward(cx, R, W - R), inward(cy, R, L - R)]), anywhere)
        for k in range(1, 4):
            base = rack[np.arange(m), rng.integers(0, k, m)]
            ang = _angles(rng, m)
            dist = 2 * R + _gap(rng, m)
            step = rng.integers(0, 4, m)
            axis = rng.random(m) < 0.4
            dx = np.where(axis, np.array([1.0, -1.0, 0.0, 0.0])[step] * dist, dist * numerics.cos(ang))
            dy = np.where(axis, np.array([0.0, 0.0, 1.0, -1.0])[step] * dist, dist * numerics.sin(ang))
            rack[:, k] = base + np.column_stack([dx, dy])
            corner = rng.random(m) < corner_share
            kx, ky = np.where(rng.random(m) < 0.5, R, W - R), np.where(rng.random(m) < 0.5, R, L - R)
            rack[corner, k] = np.column_stack([inward(kx, R, W - R), inward(ky, R, L - R)])[corner]
        ok = _valid(rack, params)
        out[todo[ok]] = rack[ok]
        todo = todo[~ok]
    return out


def adversarial_actions(rng: np.random.Generator, racks: np.ndarray, params: PhysicsParams) -> np.ndarray:
    """:func:`make_actions`' aims, with power exactly 0 or 1 (or uniform) and tip offsets on the
    unit circle (or uniform)."""
    acts = make_actions(rng, racks, params)
    n = acts.shape[0]
    u = rng.random(n)
    acts[:, 1] = np.where(u < 0.3, 0.0, np.where(u < 0.6, 1.0, acts[:, 1]))
    ang = rng.uniform(0, 2 * np.pi, n)
    rim = rng.random(n) < 0.6
    acts[rim, 2], acts[rim, 3] = np.clip(numerics.cos(ang[rim]), -1, 1), np.clip(numerics.sin(ang[rim]), -1, 1)
    return acts


def make_racks(rng: np.random.Generator, family: str, n: int, params: PhysicsParams) -> np.ndarray:
    if family == "frozen":
        return _frozen(rng, n, params, corner_share=0.1)
    if family == "corners":
        return _frozen(rng, n, params, corner_share=0.6)
    if family == "natural":
        return random_racks(rng, n, params)
    if family == "contacts":
        return _build(rng, n, params, p_rail=0.15, p_touch=0.75)
    if family == "rails":
        return _build(rng, n, params, p_rail=0.6, p_touch=0.3)
    # chained innings start from a mix of the three
    parts = [make_racks(rng, f, m, params) for f, m in zip(FAMILIES[:3], np.diff(np.linspace(0, n, 4).astype(int)))]
    return np.concatenate(parts)[rng.permutation(n)]


# ----------------------------------------------------------------------------- actions


def make_actions(rng: np.random.Generator, racks: np.ndarray, params: PhysicsParams) -> np.ndarray:
    """One action per rack: uniform, or extreme in aim, power and tip (see the module doc)."""
    n = racks.shape[0]
    R = params.ball_radius
    theta = rng.uniform(0, 2 * np.pi, n)
    aim = rng.integers(0, 4, n)  # 0 uniform, 1 axis, 2 at a ball's centre, 3 graze a ball
    axis = rng.integers(0, 4, n) * (np.pi / 2) + rng.choice([0.0, 0.0, 1e-12, -1e-12, 1e-6], n)
    theta = np.where(aim == 1, axis, theta)
    target = racks[np.arange(n), rng.integers(1, 4, n)]
    d = target - racks[:, 0]
    centre = numerics.atan2(d[:, 1], d[:, 0])
    dist = np.maximum(np.linalg.norm(d, axis=1), 2 * R)
    cut = numerics.asin(np.clip(2 * R / dist * (1 - rng.choice([0.0, 1e-15, 1e-12, 1e-9, 1e-6, -1e-9], n)), -1, 1))
    graze = centre + rng.choice([-1.0, 1.0], n) * cut
    theta = np.where(aim == 2, centre, np.where(aim == 3, graze, theta))
    power = np.where(rng.random(n) < 0.4, 1.0, rng.uniform(0, 1, n))
    tip = rng.random(n)
    ang = rng.uniform(0, 2 * np.pi, n)
    a = np.where(tip < 0.4, numerics.cos(ang), rng.uniform(-1, 1, n))
    b = np.where(tip < 0.4, numerics.sin(ang), rng.uniform(-1, 1, n))
    axis_tip = tip > 0.9  # pure side spin or pure draw/follow at the rim
    a = np.where(axis_tip, np.round(a), a)
    b = np.where(axis_tip, np.where(np.round(a) == 0, np.sign(b), 0.0), b)
    return np.column_stack([theta, power, np.clip(a, -1, 1), np.clip(b, -1, 1)])


def uniform_actions(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack([rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)])


# ----------------------------------------------------------------------------- checks


def violations(pos: np.ndarray, truncated: np.ndarray, params: PhysicsParams) -> dict[str, np.ndarray]:
    """Per-shot masks of each violation kind of the rest positions pos (N, 4, 2)."""
    R, W, L, tol = params.ball_radius, params.table_width, params.table_length, POSITION_TOL
    finite = np.isfinite(pos).all(axis=(1, 2))
    with np.errstate(invalid="ignore"):
        x, y = pos[..., 0], pos[..., 1]
        off = ((x < R - tol) | (x > W - R + tol) | (y < R - tol) | (y > L - R + tol)).any(axis=1)
        d = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1)
        d[:, range(4), range(4)] = np.inf
        over = d.min(axis=(1, 2)) < 2 * R - tol
    return {"off_table": off & finite, "overlap": over & finite, "non_finite": ~finite,
            "truncated": truncated.copy(), "refused_next": ~_valid(pos, params)}


def worst(pos: np.ndarray, params: PhysicsParams) -> tuple[float, float]:
    """The largest distance (m) a ball centre lies outside the table, and the deepest overlap."""
    R, W, L = params.ball_radius, params.table_width, params.table_length
    x, y = pos[..., 0], pos[..., 1]
    out = np.maximum.reduce([R - x, x - (W - R), R - y, y - (L - R)])
    d = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1)
    d[:, range(4), range(4)] = np.inf
    return float(np.nanmax(out, initial=-np.inf)), float(np.nanmax(2 * R - d.min(axis=(1, 2)), initial=-np.inf))


class Tally:
    """Counts of shots and violations per family, plus the worst excursions and examples."""

    def __init__(self, params: PhysicsParams):
        self.params = params
        self.counts = {f: dict(shots=0, timed_out=0, **{k: 0 for k in KINDS}) for f in ALL_FAMILIES}
        self.worst_off, self.worst_overlap = -np.inf, -np.inf
        self.examples: list[dict] = []

    def add(self, family: str, racks: np.ndarray, actions: np.ndarray, result) -> np.ndarray:
        """Record one batch; return the mask of shots whose rest state is invalid."""
        v = violations(result.positions, result.truncated, self.params)
        c = self.counts[family]
        c["shots"] += racks.shape[0]
        c["timed_out"] += int(result.timed_out.sum())
        for k in KINDS:
            c[k] += int(v[k].sum())
        finite = np.isfinite(result.positions).all(axis=(1, 2))
        off, over = worst(result.positions[finite], self.params)
        self.worst_off, self.worst_overlap = max(self.worst_off, off), max(self.worst_overlap, over)
        bad = v["refused_next"] | v["truncated"]
        for n in np.flatnonzero(bad)[: max(0, 5 - len(self.examples))]:
            kinds = [k for k in KINDS if v[k][n]]
            self.examples.append({"family": family, "kinds": kinds, "rack": racks[n].tolist(), "action": actions[n].tolist()})
        return v["refused_next"]


# ----------------------------------------------------------------------------- run


def run(shots: int, seed: int, params: PhysicsParams, batch: int, chain: int) -> tuple[Tally, float]:
    """Fuzz `shots` shots split evenly over the families; return the tally and the seconds."""
    rng = np.random.default_rng(seed)
    tally = Tally(params)
    per = np.diff(np.linspace(0, shots, len(ALL_FAMILIES) + 1).astype(int))
    t0 = time.perf_counter()
    for family, total in zip(ALL_FAMILIES, per):
        done = 0
        while done < total:
            if family == "chained":
                lanes = max(1, min(batch, total - done) // chain)
                racks = make_racks(rng, family, lanes, params)
                for _ in range(min(chain, total - done)):
                    acts = make_actions(rng, racks, params) if rng.random() < 0.5 else uniform_actions(rng, lanes)
                    res = simulate_batch(racks, acts, params)
                    bad = tally.add(family, racks, acts, res)
                    done += lanes
                    racks = res.positions
                    if bad.any():  # an invalid state cannot be played on: restart those innings
                        racks[bad] = make_racks(rng, family, int(bad.sum()), params)
                    if done >= total:
                        break
            else:
                m = min(batch, total - done)
                racks = make_racks(rng, family, m, params)
                acts = (uniform_actions(rng, m) if family == "natural" else adversarial_actions(rng, racks, params)
                        if family in ADVERSARIAL else make_actions(rng, racks, params))
                check_positions(racks, params)  # the generators only build accepted states
                tally.add(family, racks, acts, simulate_batch(racks, acts, params))
                done += m
    return tally, time.perf_counter() - t0


def physics_from_args(args) -> PhysicsParams:
    if args.physics not in PRESETS:
        raise SystemExit(f"--physics must be one of {sorted(PRESETS)}, got {args.physics!r}")
    params = PRESETS[args.physics]
    if args.max_english is not None:
        try:
            params = dataclasses.replace(params, max_english=args.max_english)
        except ValueError as err:
            raise SystemExit(f"--max-english: {err}") from None
    return params


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shots", type=int, default=1_000_000, help="total shots over all families")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--physics", default=DEFAULT_PRESET, help=f"physics preset, one of {sorted(PRESETS)}")
    ap.add_argument("--max-english", type=float, default=None, help="override max_english (tip offsets up to this fraction of R)")
    ap.add_argument("--batch", type=int, default=20000, help="shots per simulate_batch call")
    ap.add_argument("--chain", type=int, default=20, help="shots per chained inning")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.shots < 1 or args.batch < 1 or args.chain < 1:
        raise SystemExit("--shots, --batch and --chain must be >= 1")
    params = physics_from_args(args)

    tally, seconds = run(args.shots, args.seed, params, args.batch, args.chain)
    total = {k: sum(c[k] for c in tally.counts.values()) for k in ("shots", "timed_out") + KINDS}
    print(f"physics={params.describe()} seed={args.seed} threads={numba.get_num_threads()}")
    print(f"{'family':10s} {'shots':>9s} " + " ".join(f"{k:>12s}" for k in KINDS))
    for f, c in list(tally.counts.items()) + [("total", total)]:
        print(f"{f:10s} {c['shots']:9d} " + " ".join(f"{c[k]:12d}" for k in KINDS))
    print(f"worst excursion off the table {tally.worst_off:.3g} m, deepest overlap {tally.worst_overlap:.3g} m "
          f"(tolerance {POSITION_TOL:g} m; negative: none at all)")
    print(f"time {seconds:.1f} s ({total['shots'] / seconds:.0f} shots/s); {total['timed_out']} shots stopped at "
          f"max_time = {params.max_time} s (no violation)")
    for ex in tally.examples:
        print("example", ex)
    if args.out:
        summary = {"command": " ".join(["python", "benchmarks/fuzz.py"] + (argv if argv is not None else sys.argv[1:])),
                   "commit": git_commit(), "physics": params.describe(), "params": params.to_dict(),
                   "seed": args.seed, "threads": numba.get_num_threads(), "seconds": seconds,
                   "total": total, "families": tally.counts, "worst_off_table_m": tally.worst_off,
                   "worst_overlap_m": tally.worst_overlap, "examples": tally.examples}
        write_json(args.out, summary)


if __name__ == "__main__":
    main()
