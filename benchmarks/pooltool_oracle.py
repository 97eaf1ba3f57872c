#!/usr/bin/env python
"""Run 4-ball carom shots in pooltool-billiards 0.6.0, used as a reference oracle.

Runs INSIDE the separate venv made by benchmarks/setup_pooltool.sh (never in the project's
environment, and never imported by the project):

    .venv-pooltool/bin/python benchmarks/pooltool_oracle.py IN.npz OUT.npz [--threads 1] [--physics P.json]
    .venv-pooltool/bin/python benchmarks/pooltool_oracle.py --selfcheck [--physics P.json]
    .venv-pooltool/bin/python benchmarks/pooltool_oracle.py --make-random 200 --seed 0 IN.npz

Physics (the paper's stack, passed explicitly, the YAML in ~/.config is never consulted):
a pocketless table built from BilliardTableSpecs(l, w, cushion_height) (nose lines x=0, x=w,
y=0, y=l), the same BallParams on all four balls, CueSpecs with the given mass M,
InstantaneousPoint stick-ball with squirt_throttle 0 and english_throttle 1, Han2005Linear
cushions (the corrected 0.6.0 form), FrictionalInelastic ball-ball with
AverageBallBallFriction and u_b = 1e-12 on every ball (pooltool rejects 0; this is the
equal-mass restitution exchange with e_b and no tangential friction).

The numbers come from --physics P.json, a JSON object with exactly the keys of BILLIARD below
(table_w, table_l, cushion_height, R, m, u_s, u_r, u_sp_proportionality = mu_sp / R, e_b,
e_c, f_c, g, cue_M); without it, pooltool's own BILLIARD table, BILLIARD_GENERIC balls and
default cue (the project's `international` preset). The file is read with json, never run.

Tip offsets: pooltool's strike evaluates sqrt(1 - a^2 - b^2), NaN when a^2 + b^2 rounds above
1, and it has no miscue check. An offset with 1 - OFFSET_HAIR < sqrt(a^2 + b^2) <= 1 + 1e-9
(the rim of the disk, give or take rounding) is pulled in to 1 - OFFSET_HAIR (changes the
ball speed by ~1e-11 relative); larger offsets are simulated as given (and fail).

Input npz:
    positions (N,4,2) float64  ball centres, table frame: x across the width [0, table_w],
                               y along the length [0, table_l]; order 0 = white cue ball,
                               1 = yellow, 2, 3 = reds. All balls start at rest.
    V0        (N,)            cue speed, m/s
    phi_deg   (N,)            aim angle, degrees, 0 = +x, counter-clockwise
    a, b      (N,)            contact point on the ball / R, pooltool convention
                              (a > 0 left english, b > 0 top spin); level cue (theta = 0)
Output npz (one row per shot; a failed shot has ok = False and NaN / -1 / 0 fields):
    final_positions (N,4,2)   ball centres when every ball has stopped
    n_events        (N,)      len(system.events) - 2: every event between the leading and
                              trailing null events, i.e. the stick-ball strike, all motion
                              transitions and all collisions
    n_ball_ball     (N,)      ball-ball collisions (any pair)
    n_cushion       (N,)      ball-cushion collisions (any ball)
    cue_cushions    (N,)      cushion collisions of ball 0
    seconds         (N,)      wall time of pt.simulate() alone (time.perf_counter), after
                              warm-up shots, so numba compilation is excluded (min over
                              --repeat runs)
    sim_time        (N,)      simulated duration of the shot, s
    ok              (N,) bool False if pooltool raised, hit --timeout, or ended in a
                              non-finite state (pooltool has no miscue check)
    first_contact   (N,)      first ball (1, 2, 3) that ball 0 touched, -1 if none
    cue_hits        (N,3) bool ball 0 touched ball 1 / 2 / 3
    cue_ball_seq    (N,8)     the balls ball 0 touched, in order (repeats kept), -1 padded
    offset_pulled_in (N,) bool the tip offset was pulled in from the rim (see above)
    error           (N,) str  exception text of failed shots
    physics         () str    the physics JSON the shots ran with
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time

SEQ_LEN = 8
OFFSET_HAIR = 1e-12  # how far inside the unit disk a rim tip offset is pulled (see above)

# pooltool's BILLIARD table (BILLIARD_WIP), BILLIARD_GENERIC balls and default cue: the physics
# used without --physics, and the list of keys a --physics file must have.
BILLIARD = dict(table_w=1.42, table_l=2.84, cushion_height=0.037, R=0.0615 / 2, m=0.21, u_s=0.2,
                u_r=0.01, u_sp_proportionality=10 * 2 / 5 / 9, e_b=0.95, e_c=0.85, f_c=0.15,
                g=9.81, cue_M=0.567)


def load_physics(path) -> dict:
    """The --physics JSON (see the module docstring), checked: exactly BILLIARD's keys, each a
    finite number > 0 (restitutions at most 1). Raises SystemExit naming what is wrong."""
    if path is None:
        return dict(BILLIARD)
    try:
        with open(path) as f:
            phys = json.load(f)
    except (OSError, ValueError) as exc:
        raise SystemExit(f"--physics {path}: cannot read a JSON object: {exc}")
    if not isinstance(phys, dict):
        raise SystemExit(f"--physics {path}: expected a JSON object, got {type(phys).__name__}")
    missing, unknown = sorted(set(BILLIARD) - set(phys)), sorted(set(phys) - set(BILLIARD))
    if missing or unknown:
        raise SystemExit(f"--physics {path}: missing keys {missing}, unknown keys {unknown}; "
                         f"expected {sorted(BILLIARD)}")
    for k, v in phys.items():
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0
        if not ok or (k in ("e_b", "e_c") and v > 1):
            raise SystemExit(f"--physics {path}: {k} must be a finite number > 0"
                             f"{' and <= 1' if k in ('e_b', 'e_c') else ''}, got {v!r}")
    return {k: float(v) for k, v in phys.items()}


def _parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("inp", nargs="?", help="input .npz (or output path with --make-random)")
    p.add_argument("out", nargs="?", help="output .npz")
    p.add_argument("--threads", type=int, default=1,
                   help="thread count for numba/BLAS/OpenMP (default 1: single-core timing)")
    p.add_argument("--pin-cpu", type=int, default=None,
                   help="also pin this process to this CPU index (sched_setaffinity)")
    p.add_argument("--selfcheck", action="store_true",
                   help="run hand-computed physics sanity shots and exit non-zero on failure")
    p.add_argument("--make-random", type=int, default=None, metavar="N",
                   help="write N random shots to INP (no simulation)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--vmax", type=float, default=6.0, help="--make-random: max V0 (m/s)")
    p.add_argument("--vmin", type=float, default=0.5, help="--make-random: min V0 (m/s)")
    p.add_argument("--max-english", type=float, default=0.6,
                   help="--make-random: max sqrt(a^2+b^2)")
    p.add_argument("--max-events", type=int, default=0,
                   help="pooltool's max_events (0 = unlimited, the default)")
    p.add_argument("--timeout", type=float, default=30.0,
                   help="per-shot wall-clock limit in seconds (0 = none); a shot over it is "
                        "marked ok = False")
    p.add_argument("--repeat", type=int, default=1,
                   help="simulate each shot this many times and report the fastest wall time "
                        "(less noise on a shared machine; results are deterministic)")
    p.add_argument("--physics", default=None, metavar="P.json",
                   help="table, ball and cue values (see the module docstring); default: "
                        "pooltool's BILLIARD table, BILLIARD_GENERIC balls, default cue")
    p.add_argument("--quiet", action="store_true")
    args = p.parse_args(argv)
    if args.make_random is None and not args.selfcheck and (args.inp is None or args.out is None):
        p.error("IN.npz and OUT.npz are required (or use --selfcheck / --make-random)")
    if args.make_random is not None and args.inp is None:
        p.error("--make-random N needs the output path as the first positional argument")
    return args


ARGS = _parse_args() if __name__ == "__main__" else None

# --- environment, before numpy / numba / pooltool are imported ------------------------
if ARGS is not None:
    _n = str(max(1, ARGS.threads))
    for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                 "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
        os.environ[_var] = _n
    if ARGS.pin_cpu is not None:
        os.sched_setaffinity(0, {ARGS.pin_cpu})
# `import pooltool` creates ~/.config/pooltool/{general.yaml,physics/resolver.yaml}; keep it
# out of the real home. (The numba on-disk cache lives in the venv's site-packages.)
_TMP_HOME = tempfile.mkdtemp(prefix="pooltool_home_")
os.environ["HOME"] = _TMP_HOME

import numpy as np  # noqa: E402


# --- random input generation (numpy only) ---------------------------------------------
def make_random_shots(n: int, seed: int = 0, vmin: float = 0.5, vmax: float = 6.0,
                      max_english: float = 0.6, phys: dict = BILLIARD) -> dict:
    """N random 4-ball layouts on phys's table (uniform, non-overlapping with 1 mm margin, at
    least 1 mm from every cushion) and random strokes: V0 ~ U[vmin, vmax], phi ~ U[0, 360),
    (a, b) uniform on the disk of radius max_english."""
    rng = np.random.default_rng(seed)
    margin, R = 1e-3, phys["R"]
    pos = np.empty((n, 4, 2))
    for i in range(n):
        k = 0
        while k < 4:
            p = np.array([rng.uniform(R + margin, phys["table_w"] - R - margin),
                          rng.uniform(R + margin, phys["table_l"] - R - margin)])
            if all(np.hypot(*(p - pos[i, j])) > 2 * R + margin for j in range(k)):
                pos[i, k] = p
                k += 1
    r = max_english * np.sqrt(rng.uniform(0, 1, n))
    ang = rng.uniform(0, 2 * np.pi, n)
    return dict(positions=pos, V0=rng.uniform(vmin, vmax, n),
                phi_deg=rng.uniform(0, 360, n), a=r * np.cos(ang), b=r * np.sin(ang))


# --- pooltool -------------------------------------------------------------------------
def _import_pooltool():
    import pooltool as pt  # noqa: F401  (writes only under the temp HOME)

    return pt


def make_engine(pt):
    """The paper's stack as an explicit PhysicsEngine (nothing read from YAML)."""
    from pooltool.physics.engine import PhysicsEngine
    from pooltool.physics.resolve.ball_ball.friction import AverageBallBallFriction
    from pooltool.physics.resolve.ball_ball.frictional_inelastic import FrictionalInelastic
    from pooltool.physics.resolve.ball_cushion.han_2005.model import (
        Han2005Circular,
        Han2005Linear,
    )
    from pooltool.physics.resolve.ball_pocket import CanonicalBallPocket
    from pooltool.physics.resolve.resolver import VERSION, Resolver
    from pooltool.physics.resolve.stick_ball.instantaneous_point import InstantaneousPoint
    from pooltool.physics.resolve.transition import CanonicalTransition

    resolver = Resolver(
        ball_ball=FrictionalInelastic(friction=AverageBallBallFriction()),
        ball_linear_cushion=Han2005Linear(),
        ball_circular_cushion=Han2005Circular(),  # unused: the carom table has none
        ball_pocket=CanonicalBallPocket(),  # unused: no pockets
        stick_ball=InstantaneousPoint(english_throttle=1.0, squirt_throttle=0.0),
        transition=CanonicalTransition(),
        version=VERSION,
    )
    return PhysicsEngine(resolver=resolver)


U_B = 1e-12  # pooltool requires u_b > 0


def make_ball_params(pt, phys: dict):
    """phys's ball values with u_b = 1e-12, shared by all four balls (without --physics:
    BILLIARD_GENERIC, m 0.21, R 0.03075, u_s 0.2, u_r 0.01, u_sp (4/9)R, e_c 0.85, f_c 0.15,
    e_b 0.95, g 9.81)."""
    from pooltool.objects.ball.params import BallParams

    keys = ("m", "R", "u_s", "u_r", "u_sp_proportionality", "e_b", "e_c", "f_c", "g")
    return BallParams(u_b=U_B, **{k: phys[k] for k in keys})


def make_table(pt, phys: dict):
    """The pocketless table of phys's size and nose height (without --physics: BILLIARD_WIP)."""
    from pooltool.objects.table.specs import BilliardTableSpecs

    specs = BilliardTableSpecs(l=phys["table_l"], w=phys["table_w"],
                               cushion_height=phys["cushion_height"])
    return pt.Table.from_table_specs(specs)


def make_cue_specs(pt, phys: dict):
    """pooltool's default cue with phys's mass (end_mass and tip radius are unused here)."""
    import attrs
    from pooltool.objects.cue.datatypes import CueSpecs

    return attrs.evolve(CueSpecs.default(), M=phys["cue_M"])


def pull_in_rim_offsets(a: np.ndarray, b: np.ndarray):
    """(a, b, pulled): offsets on the rim of the unit disk moved OFFSET_HAIR inside it, so that
    pooltool's sqrt(1 - a^2 - b^2) stays real (see the module docstring)."""
    norm = np.hypot(a, b)
    pulled = (norm > 1 - OFFSET_HAIR) & (norm <= 1 + 1e-9)
    scale = np.where(pulled, (1 - OFFSET_HAIR) / np.where(pulled, norm, 1.0), 1.0)
    return a * scale, b * scale, pulled


BALL_IDS = ("0", "1", "2", "3")


def build_system(pt, table, params, cue_specs, xy4, V0, phi, a, b, states=None):
    """A System with balls '0'..'3' at xy4 (table frame, identical to pooltool's) and the
    cue aimed at ball '0'. `states` optionally maps ball index -> (rvw (3,3), s) to start a
    ball moving (used by the self-check); otherwise every ball is at rest."""
    from pooltool.objects.ball.datatypes import Ball, BallState

    balls = {}
    for k, bid in enumerate(BALL_IDS):
        if xy4[k] is None:
            continue
        ball = Ball(id=bid, params=params)
        ball.state.rvw[0] = [float(xy4[k][0]), float(xy4[k][1]), params.R]
        if states and k in states:
            rvw, s = states[k]
            rvw = np.array(rvw, dtype=float)
            rvw[0] = ball.state.rvw[0]
            ball.state = BallState(rvw, s, 0.0)
        balls[bid] = ball
    cue = pt.Cue(V0=float(V0), phi=float(phi), theta=0.0, a=float(a), b=float(b),
                 cue_ball_id="0", specs=cue_specs)
    return pt.System(cue=cue, table=table, balls=balls)


def summarize_events(pt, events):
    """Counts and ball-0 contact bookkeeping from a simulated system's event list."""
    from pooltool.events import EventType

    n_bb = n_cush = cue_cush = 0
    seq = []
    for ev in events:
        et = ev.event_type
        if et == EventType.BALL_BALL:
            n_bb += 1
            ids = ev.ids
            if "0" in ids:
                other = ids[1] if ids[0] == "0" else ids[0]
                seq.append(int(other))
        elif et in (EventType.BALL_LINEAR_CUSHION, EventType.BALL_CIRCULAR_CUSHION):
            n_cush += 1
            if ev.ids[0] == "0":
                cue_cush += 1
    hits = np.array([k in seq for k in (1, 2, 3)])
    first = seq[0] if seq else -1
    return dict(n_events=len(events) - 2, n_ball_ball=n_bb, n_cushion=n_cush,
                cue_cushions=cue_cush, first_contact=first, cue_hits=hits, seq=seq)


WARMUP_SHOTS = 64


def _numba_signature_count() -> int:
    """Total compiled signatures over all numba dispatchers in loaded pooltool modules."""
    from numba.core.registry import CPUDispatcher

    seen, total = set(), 0
    for name, mod in list(sys.modules.items()):
        if not name.startswith("pooltool") or mod is None:
            continue
        for obj in list(vars(mod).values()):
            if isinstance(obj, CPUDispatcher) and id(obj) not in seen:
                seen.add(id(obj))
                total += len(obj.signatures)
    return total


class _Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise _Timeout("shot exceeded --timeout")


def run_shots(inp: dict, max_events: int = 0, timeout: float = 30.0, quiet: bool = False,
              repeat: int = 1, phys: dict = BILLIARD):
    import signal

    pt = _import_pooltool()
    engine = make_engine(pt)
    params = make_ball_params(pt, phys)
    table = make_table(pt, phys)
    cue_specs = make_cue_specs(pt, phys)
    W, L = phys["table_w"], phys["table_l"]

    pos = np.asarray(inp["positions"], dtype=float)
    V0 = np.asarray(inp["V0"], dtype=float)
    phi = np.asarray(inp["phi_deg"], dtype=float)
    a, b, pulled = pull_in_rim_offsets(np.asarray(inp["a"], dtype=float),
                                       np.asarray(inp["b"], dtype=float))
    n = pos.shape[0]
    assert pos.shape == (n, 4, 2), pos.shape
    for arr in (V0, phi, a, b):
        assert arr.shape == (n,), arr.shape

    # warn about layouts pooltool would treat oddly (overlap -> "collide now")
    R = params.R
    bad = 0
    for i in range(n):
        p = pos[i]
        oob = np.any(p[:, 0] < R) or np.any(p[:, 0] > W - R) or \
            np.any(p[:, 1] < R) or np.any(p[:, 1] > L - R)
        d = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1))
        ovl = np.any(d[np.triu_indices(4, 1)] < 2 * R)
        bad += bool(oob or ovl)
    if bad and not quiet:
        print(f"warning: {bad} layouts overlap or cross a cushion nose line", file=sys.stderr)

    # warm-up (not timed): numba compiles (or loads from its on-disk cache) one machine-code
    # version per argument-type signature on first use, and some signatures only show up on
    # rare paths (e.g. the cushion make_kiss fallback). A hand shot plus a batch of random
    # shots reaches them; any signature first seen in the timed loop is reported below.
    t0 = time.perf_counter()
    warm = [build_system(pt, table, params, cue_specs,
                         [(0.3, 0.5), (0.4, 1.0), (1.0, 2.0), (0.9, 0.6)], 3.0, 63.0, 0.2, 0.1)]
    wr = make_random_shots(WARMUP_SHOTS, seed=987654321, phys=phys)
    warm += [build_system(pt, table, params, cue_specs, wr["positions"][i], wr["V0"][i],
                          wr["phi_deg"][i], wr["a"][i], wr["b"][i]) for i in range(WARMUP_SHOTS)]
    for system in warm:
        try:
            pt.simulate(system, engine=engine, inplace=True)
        except Exception:  # noqa: BLE001
            pass
    warm_s = time.perf_counter() - t0
    n_sig0 = _numba_signature_count()

    out = dict(
        final_positions=np.full((n, 4, 2), np.nan),
        n_events=np.zeros(n, np.int64),
        n_ball_ball=np.zeros(n, np.int64),
        n_cushion=np.zeros(n, np.int64),
        cue_cushions=np.zeros(n, np.int64),
        seconds=np.full(n, np.nan),
        sim_time=np.full(n, np.nan),
        ok=np.zeros(n, bool),
        first_contact=np.full(n, -1, np.int64),
        cue_hits=np.zeros((n, 3), bool),
        cue_ball_seq=np.full((n, SEQ_LEN), -1, np.int64),
        offset_pulled_in=pulled,
        error=np.array([""] * n, dtype=object),
        physics=np.array(json.dumps(phys, sort_keys=True)),
    )
    use_alarm = timeout and timeout > 0 and hasattr(signal, "setitimer")
    if use_alarm:
        old = signal.signal(signal.SIGALRM, _alarm)
    for i in range(n):
        try:
            dt = np.inf
            for _ in range(max(1, repeat)):  # deterministic: keep the fastest wall time
                system = build_system(pt, table, params, cue_specs, pos[i], V0[i], phi[i],
                                      a[i], b[i])
                if use_alarm:
                    signal.setitimer(signal.ITIMER_REAL, timeout)
                t0 = time.perf_counter()
                pt.simulate(system, engine=engine, inplace=True, max_events=max_events)
                dt = min(dt, time.perf_counter() - t0)
                if use_alarm:
                    signal.setitimer(signal.ITIMER_REAL, 0)
        except Exception as exc:  # noqa: BLE001 - record and go on
            if use_alarm:
                signal.setitimer(signal.ITIMER_REAL, 0)
            out["error"][i] = f"{type(exc).__name__}: {exc}"
            continue
        out["seconds"][i] = dt
        fin = np.array([system.balls[bid].state.rvw for bid in BALL_IDS])
        if not np.all(np.isfinite(fin)):
            # pooltool has no miscue model: a^2 + b^2 > 1 gives a NaN state, not an error
            out["error"][i] = "non-finite final state (miscue: a^2 + b^2 > 1?)"
            continue
        out["ok"][i] = True
        out["sim_time"][i] = system.t
        for k, bid in enumerate(BALL_IDS):
            out["final_positions"][i, k] = system.balls[bid].state.rvw[0, :2]
        s = summarize_events(pt, system.events)
        for key in ("n_events", "n_ball_ball", "n_cushion", "cue_cushions", "first_contact"):
            out[key][i] = s[key]
        out["cue_hits"][i] = s["cue_hits"]
        seq = s["seq"][:SEQ_LEN]
        out["cue_ball_seq"][i, : len(seq)] = seq
    if use_alarm:
        signal.signal(signal.SIGALRM, old)
    out["error"] = out["error"].astype(str)
    new_sigs = _numba_signature_count() - n_sig0
    if new_sigs and not quiet:
        print(f"warning: {new_sigs} numba signature(s) were compiled/loaded inside the timed "
              "loop; the affected shots' `seconds` include that one-off cost", file=sys.stderr)
    return out, warm_s


# --- self-check -----------------------------------------------------------------------
def selfcheck(verbose: bool = True, phys: dict = BILLIARD) -> bool:
    """Hand-computed sanity shots against the formulas of docs/physics.md, on phys's table, balls and
    cue. Returns True if all pass."""
    from pooltool.events import EventType

    pt = _import_pooltool()
    engine = make_engine(pt)
    params = make_ball_params(pt, phys)
    table = make_table(pt, phys)
    cue_specs = make_cue_specs(pt, phys)
    m, R, M = params.m, params.R, cue_specs.M
    W, L, H = phys["table_w"], phys["table_l"], phys["cushion_height"]
    results = []

    def check(name, got, want, tol):
        got = np.asarray(got, float)
        want = np.asarray(want, float)
        ok = bool(np.all(np.abs(got - want) <= tol))
        results.append(ok)
        if verbose:
            fmt = lambda x: [float(f"{v:.7g}") + 0.0 for v in np.ravel(x)]  # noqa: E731
            print(f"  [{'ok' if ok else 'FAIL'}] {name}: got {fmt(got)} want {fmt(want)} "
                  f"(tol {tol:g})")

    def first(events, et, ids=None):
        for ev in events:
            if ev.event_type == et and (ids is None or set(ids) <= set(ev.ids)):
                return ev
        raise AssertionError(f"no {et} event with ids {ids}")

    def agent(ev, bid):
        return next(ag for ag in ev.agents if ag.id == bid)

    print("pooltool", pt.__version__)
    # 0. configuration
    print("configuration:")
    check("ball params m, R, u_s, u_r, u_sp, e_c, f_c, e_b, u_b, g",
          [params.m, params.R, params.u_s, params.u_r, params.u_sp, params.e_c, params.f_c,
           params.e_b, params.u_b, params.g],
          [phys["m"], phys["R"], phys["u_s"], phys["u_r"], phys["u_sp_proportionality"] * phys["R"],
           phys["e_c"], phys["f_c"], phys["e_b"], 1e-12, phys["g"]], 1e-15)
    check("cue M", M, phys["cue_M"], 0)
    segs = table.cushion_segments.linear
    geo = {k: (tuple(map(float, s.p1)), tuple(map(float, s.p2))) for k, s in segs.items()}
    want_geo = {"3": ((0, 0, H), (0, L, H)), "12": ((W, L, H), (W, 0, H)),
                "9": ((0, L, H), (W, L, H)), "18": ((0, 0, H), (W, 0, H))}
    ok_geo = (set(geo) == set(want_geo) and all(np.allclose(geo[k], want_geo[k], atol=1e-12)
                                                  for k in geo)
              and not table.cushion_segments.circular and not table.pockets
              and table.table_type == pt.TableType.BILLIARD
              and abs(table.w - W) < 1e-12 and abs(table.l - L) < 1e-12)
    results.append(ok_geo)
    print(f"  [{'ok' if ok_geo else 'FAIL'}] table: BILLIARD w={table.w} l={table.l} "
          f"segments {geo} circular={len(table.cushion_segments.circular)} "
          f"pockets={len(table.pockets)}")
    rs = engine.resolver
    print(f"  resolver: ball_ball={type(rs.ball_ball).__name__}"
          f"({type(rs.ball_ball.friction).__name__}), cushion={type(rs.ball_linear_cushion).__name__}, "
          f"stick={type(rs.stick_ball).__name__}(english_throttle={rs.stick_ball.english_throttle}, "
          f"squirt_throttle={rs.stick_ball.squirt_throttle})")

    # 1. centre hit: v = 2 V0 / (1 + m/M) along phi (1.4595 V0 on BILLIARD), no spin; the
    #    last stroke is on the rim of the tip-offset disk, pulled in as run_shots does
    print("cue strike:")
    rim_a, rim_b, _ = pull_in_rim_offsets(np.array([0.6]), np.array([0.8]))
    for V0, phi, a, b in [(2.0, 90.0, 0.0, 0.0), (3.0, 30.0, 0.3, -0.4), (1.5, 200.0, -0.5, 0.2),
                          (2.5, 300.0, float(rim_a[0]), float(rim_b[0]))]:
        sys_ = build_system(pt, table, params, cue_specs, [(W / 2, 0.5), None, None, None],
                            V0, phi, a, b)
        pt.simulate(sys_, engine=engine, inplace=True)
        ev = first(sys_.events, EventType.STICK_BALL)
        rvw = agent(ev, "0").final.state.rvw
        v = 2 * V0 / (1 + m / M + 2.5 * (a * a + b * b))
        ph = np.radians(phi)
        w = 5 * v / (2 * R) * np.array([-b * np.sin(ph), b * np.cos(ph), -a])
        check(f"V0={V0} phi={phi} a={a} b={b}: v (no squirt)", rvw[1],
              [v * np.cos(ph), v * np.sin(ph), 0], 1e-12)
        check("   omega", rvw[2], w, 1e-9)
        if a == 0 and b == 0:
            check("   |v|/V0 = 2/(1 + m/M)", np.hypot(*rvw[1, :2]) / V0, 2 / (1 + m / M), 1e-12)

    # 2. Han 2005 sanity: roll straight into the x = w rail at speed V. Expected values from
    #    the corrected closed form (docs/physics.md section 5), whichever branch phys selects (on
    #    BILLIARD the slide branch: -0.8288 V, +0.3207 V/R, rolls away at -0.5004 V)
    th = np.arcsin(H / R - 1)
    e_c, mu = params.e_c, params.f_c
    sx = np.sin(th) + 1.0  # per unit V: v_x sin(th) + R w_y with w_y = V/R; s_y = 0
    PzE = (1 + e_c) * m * np.cos(th)
    stick = 2 * m / 7 * sx <= mu * PzE
    PxE = 2 * m / 7 * sx if stick else mu * PzE
    PX = -PxE * np.sin(th) - PzE * np.cos(th)
    PZ = PxE * np.cos(th) - PzE * np.sin(th)
    vx_han = 1 + PX / m
    wy_han = 1 + 5 / (2 * m) * (PX * np.sin(th) - PZ * np.cos(th))  # times V/R
    v_roll = vx_han - 2 / 7 * (vx_han - wy_han)  # v - (2/7) u at the end of the slide
    print(f"ball-cushion (Han 2005, corrected; {'stick' if stick else 'slide'} branch):")
    for V in (1.0, 2.5):
        rvw0 = [[0, 0, 0], [V, 0, 0], [0, V / R, 0]]
        sys_ = build_system(pt, table, params, cue_specs, [(W / 2, L / 2), None, None, None],
                            0.0, 0.0, 0.0, 0.0, states={0: (rvw0, 3)})
        pt.simulate(sys_, engine=engine, inplace=True)
        ev = first(sys_.events, EventType.BALL_LINEAR_CUSHION)
        check(f"V={V}: cushion id", int(ev.ids[1]), 12, 0)
        vi = agent(ev, "0").initial.state.rvw
        vf = agent(ev, "0").final.state.rvw
        Vi = vi[1, 0]  # rolling decelerated slightly before the rail
        check(f"   v_x'/V ({vx_han:.4f})", vf[1, 0] / Vi, vx_han, 1e-12)
        check(f"   omega_y' R/V ({wy_han:.4f})", vf[2, 1] * R / Vi, wy_han, 1e-12)
        check("   v_y', omega_x', omega_z'", [vf[1, 1], vf[2, 0], vf[2, 2]], [0, 0, 0], 1e-12)
        tr = [e for e in sys_.events if e.event_type == EventType.SLIDING_ROLLING
              and e.time > ev.time][0]
        vr = agent(tr, "0").final.state.rvw[1, 0]
        check(f"   rolls away at v/V ({v_roll:.4f})", vr / Vi, v_roll, 1e-12)

    # 3. ball-ball: sliding ball 0 hits resting ball 1; normal exchange with e = e_b,
    #    tangential velocities and spins unchanged (u_b = 1e-12)
    print("ball-ball (equal-mass restitution exchange, no friction):")
    e_b = params.e_b
    for cut_deg in (0.0, 35.0):
        c = np.radians(cut_deg)
        p1 = np.array([W / 2, 1.0])
        p2 = p1 + (2 * R + 2e-3) * np.array([np.cos(c), np.sin(c)])
        rvw0 = [[0, 0, 0], [1.2, 0, 0], [0, 10.0, 3.0]]  # sliding, with spin
        sys_ = build_system(pt, table, params, cue_specs, [tuple(p1), tuple(p2), None, None],
                            0.0, 0.0, 0.0, 0.0, states={0: (rvw0, 2)})
        pt.simulate(sys_, engine=engine, inplace=True)
        ev = first(sys_.events, EventType.BALL_BALL, ("0", "1"))
        b1i, b1f = agent(ev, "0").initial.state.rvw, agent(ev, "0").final.state.rvw
        b2f = agent(ev, "1").final.state.rvw
        r1 = agent(ev, "0").final.state.rvw[0]
        r2 = agent(ev, "1").final.state.rvw[0]
        n_ = (r2 - r1)[:2] / np.hypot(*(r2 - r1)[:2])
        vn = b1i[1, :2] @ n_
        vt = b1i[1, :2] - vn * n_
        check(f"cut {cut_deg} deg: separation after make_kiss = 2R + 1e-6",
              np.hypot(*(r2 - r1)[:2]), 2 * R + 1e-6, 1e-9)
        check("   v1' = vt + (1 - e_b)/2 vn n", b1f[1, :2], vt + (1 - e_b) / 2 * vn * n_, 1e-9)
        check("   v2' = (1 + e_b)/2 vn n", b2f[1, :2], (1 + e_b) / 2 * vn * n_, 1e-9)
        check("   spins unchanged", np.r_[b1f[2], b2f[2]], np.r_[b1i[2], 0, 0, 0], 1e-9)

    npass = sum(results)
    print(f"selfcheck: {npass} passed, {len(results) - npass} failed")
    return npass == len(results)


def main():
    args = ARGS
    phys = load_physics(args.physics)
    if args.make_random is not None:
        d = make_random_shots(args.make_random, args.seed, args.vmin, args.vmax,
                              args.max_english, phys)
        np.savez(args.inp, **d)
        print(f"wrote {args.make_random} random shots (seed {args.seed}) to {args.inp}")
        return 0
    if args.selfcheck:
        ok = selfcheck(phys=phys)
        if args.inp is None:
            return 0 if ok else 1
        if not ok:
            return 1
    with np.load(args.inp) as f:
        inp = {k: f[k] for k in ("positions", "V0", "phi_deg", "a", "b")}
    out, warm_s = run_shots(inp, args.max_events, args.timeout, args.quiet, args.repeat, phys)
    np.savez(args.out, **out)
    n = len(out["ok"])
    okm = out["ok"]
    sec = out["seconds"][okm]
    mean_us = sec.mean() * 1e6 if sec.size else float("nan")
    med_us = np.median(sec) * 1e6 if sec.size else float("nan")
    ev = out["n_events"][okm].mean() if okm.any() else float("nan")
    print(f"N={n} mean={mean_us:.0f} us/shot median={med_us:.0f} us "
          f"failures={int((~okm).sum())} mean_events={ev:.1f} "
          f"rim_offsets_pulled_in={int(out['offset_pulled_in'].sum())} "
          f"threads={args.threads} repeat={args.repeat} warmup={warm_s:.1f}s -> {args.out}")
    if not args.quiet:
        for i in np.flatnonzero(~okm)[:10]:
            print(f"  shot {i} failed: {out['error'][i]}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    finally:
        import shutil

        shutil.rmtree(_TMP_HOME, ignore_errors=True)
