"""Numba kernels of the event-based simulator: evolve, detect, resolve, and the event loop.

Pure functions over arrays. A table state is ``st`` (N_BALLS, N_STATE) float64, one row per
ball in the ball order (WHITE, YELLOW, RED1, RED2) with the columns X, Y, VX, VY, WX, WY, WZ
(centre, velocity, angular velocity), plus ``lab`` (N_BALLS,) int64 motion labels. Parameters
arrive as the packed vector of :class:`billiards.physics.params.PhysicsParams` (slots ``P_*``).
Formulas and their sources are in ``docs/physics.md``; section numbers below refer
to it.

Layout (pooltool's split, our code):
* evolve: closed-form slide / roll / spin motion (§2);
* detect: transition times, ball–cushion quadratics, ball–ball quartics (§3), and the next
  event over the per-ball and per-pair caches (:func:`_detect`, :func:`_next_event`);
* resolve: cue strike (§1), ball–ball (§4), Han 2005 cushion (§5), transitions (§2), one
  event by kind (:func:`_resolve`);
* carom: what the white touched, in which order, how close it came (``_carom_*``): facts the
  rules read, kept apart from the physics;
* loop (:func:`run_shot`): detect the next event, evolve every ball to it, resolve it, note
  the carom facts, log it.

Reference counting: only the entry points allocate (:func:`run_shot` its state, caches, outcome
vectors and log). The helpers the loop calls per event (``_evolve_all``, ``_detect``,
``_next_event``, ``_resolve``, ``_carom_*``) are compiled with ``_nrt=False``: they only read
and write the loop's arrays, borrowed for the call, so numba's reference counting (an atomic
increment and decrement per array argument per call, and numba passes the flag on to every
kernel they call) would be pure overhead: with it, this split of the loop ran 35% slower than
the single loop it replaced; without it, a third faster. A helper that allocated an array
would not compile under the flag.

Compile time: numba compiles every kernel on its first call, once per argument types, and
caches it (:mod:`billiards.physics.warmup` says so before it happens). Three habits cut that
first compilation from 30-34 s to 14-15 s on a two-core machine (measured as warmup.py says)
and change no result (the kernels compute the same operations in the same order):

* numba compiles a kernel again for each *constant* it is passed (typed ``Literal[int](-1)``,
  ``Literal[bool](False)``), so a constant argument of a kernel that elsewhere takes runtime
  values is passed as ``np.int64(...)`` (typed like them), and each kernel compiles once
  (``tests/physics/test_first_use.py``); save the event loop and :func:`_halt`, which the batch
  kernels call with the constant ``record=False`` on purpose: that copy has no log code (2-3 %
  faster than with a runtime flag);
* no array is assigned to a slice of another (``a[n] = b``): for that numba compiles a
  shape-mismatch error message, string formatting included, for each pair of dimensions
  (several seconds); the loops copy element by element;
* the per-shot wrappers of the batch kernels (:func:`run_action`, :func:`_store`) are inlined
  (``inline="always"``), not compiled and linked as kernels of their own.

Detection differs from pooltool in one deliberate way: instead of a general quartic solver we
isolate the earliest root inside the *validity horizon* of the two trajectories (the earliest
transition or cushion time of either ball). Any root beyond that horizon would be invalidated
by the horizon event anyway (§6.8), so the chosen event is the same, and the degenerate
quartic of §6.3 (equal accelerations) cannot produce spurious events.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .params import (
    BALL_BALL_ELASTIC, P_BALL_BALL, P_CUE_END_M, P_CUE_M, P_CUE_V_MAX, P_MAX_ENGLISH, P_E_B, P_E_C, P_F_C, P_G, P_H,
    P_L, P_M, P_MAX_EVENTS, P_MAX_TIME, P_MIN_DIST, P_R, P_SQUIRT, P_U_R, P_U_S, P_U_SP, P_W,
)

# Balls, in the order of every array: the white (the player's cue ball), the yellow, the reds.
WHITE, YELLOW, RED1, RED2 = range(4)
N_BALLS = 4
# Columns of a ball's row of the state ``st``: centre, velocity, angular velocity.
X, Y, VX, VY, WX, WY, WZ = range(7)
N_STATE = 7
LABEL = N_STATE  # the event log's state rows carry the motion label after the state columns
# Columns of a ball's trajectory polynomial p(t) = c + b t + a t^2 (§3.1): a and b (c is X, Y).
AX, AY, BX, BY = range(4)
N_POLY = 4
# Motion labels (pooltool's numbering).
STATIONARY, SPINNING, SLIDING, ROLLING = 0, 1, 2, 3
# Event kinds in the log, and the columns of its info rows.
EV_STRIKE, EV_TRANSITION, EV_BALL_BALL, EV_CUSHION, EV_STOP = 0, 1, 2, 3, 4
INFO_KIND, INFO_BALL, INFO_OTHER = range(3)
N_INFO = 3
# Cushions: 0 is x = 0, 1 is x = w, 2 is y = 0, 3 is y = l.
N_CUSHIONS = 4
EPS = 100.0 * np.finfo(np.float64).eps  # pooltool's EPS, 2.2e-14
KISS_SLACK = 9e-7  # m a make_kiss may press a ball into a rail or third ball (< api.POSITION_TOL)
INF = np.inf
NEWTON_ITERATIONS = 100  # the root solvers' iteration cap (they converge in far fewer)
NEWTON_RTOL = 1e-15  # ... and their relative step tolerance
# Pairs of balls, in a fixed order (i < j, so the white is always the first of its pairs).
PAIR_I = np.array([0, 0, 0, 1, 1, 2], dtype=np.int64)
PAIR_J = np.array([1, 2, 3, 2, 3, 3], dtype=np.int64)
N_PAIRS = 6
# Outcome slots of the integer and float result vectors.
O_FIRST, O_HIT1, O_HIT2, O_HIT3, O_NEVENTS, O_TRUNC, O_CUSHIONS, O_SECOND_RED, O_TIMEOUT = range(9)
N_OUT_INT = 9
OF_CLOSE2, OF_CLOSE3, OF_TIME = range(3)
N_OUT_FLOAT = 3
# Validation error codes (see api.py for the messages).
ERR_OK, ERR_NONFINITE, ERR_OFF_TABLE, ERR_OVERLAP = 0, 1, 2, 3
ERR_ACTION_NONFINITE, ERR_POWER, ERR_TIP = 4, 5, 6


# ----------------------------------------------------------------------------- evolve (§2)


@njit(cache=True, error_model="numpy", inline="always")
def _norm(x, y):
    return math.sqrt(x * x + y * y)


@njit(cache=True, error_model="numpy")
def _spin_after(wz, t, alpha):
    """Spin law: w_z decays linearly at alpha, clamped at zero."""
    if abs(wz) < EPS:
        return wz
    return wz - math.copysign(1.0, wz) * alpha * min(t, abs(wz) / alpha)


@njit(cache=True, error_model="numpy")
def _slip_dir(st, i, R):
    """Unit contact-point slip direction; the heading if the slip is exactly zero."""
    ux = st[i, VX] - R * st[i, WY]
    uy = st[i, VY] + R * st[i, WX]
    un = _norm(ux, uy)
    if un > 0.0:
        return ux / un, uy / un, un
    vn = _norm(st[i, VX], st[i, VY])
    if vn > 0.0:
        return st[i, VX] / vn, st[i, VY] / vn, 0.0
    return 0.0, 0.0, 0.0


@njit(cache=True, error_model="numpy")
def evolve_ball(st, lab, i, t, p):
    """Advance ball i by t seconds inside its current motion state, in place."""
    if t == 0.0:
        return
    R, g = p[P_R], p[P_G]
    alpha = 5.0 * p[P_U_SP] * g / (2.0 * R)
    s = lab[i]
    if s == SLIDING:
        ux, uy, _ = _slip_dir(st, i, R)
        mg = p[P_U_S] * g
        st[i, X] += st[i, VX] * t - 0.5 * mg * t * t * ux
        st[i, Y] += st[i, VY] * t - 0.5 * mg * t * t * uy
        st[i, VX] -= mg * t * ux
        st[i, VY] -= mg * t * uy
        k = 5.0 * mg * t / (2.0 * R)
        st[i, WX] -= k * uy
        st[i, WY] += k * ux
        st[i, WZ] = _spin_after(st[i, WZ], t, alpha)
    elif s == ROLLING:
        vn = _norm(st[i, VX], st[i, VY])
        if vn > 0.0:
            hx, hy = st[i, VX] / vn, st[i, VY] / vn
        else:
            hx, hy = 0.0, 0.0
        mg = p[P_U_R] * g
        st[i, X] += st[i, VX] * t - 0.5 * mg * t * t * hx
        st[i, Y] += st[i, VY] * t - 0.5 * mg * t * t * hy
        st[i, VX] -= mg * t * hx
        st[i, VY] -= mg * t * hy
        st[i, WX] = -st[i, VY] / R
        st[i, WY] = st[i, VX] / R
        st[i, WZ] = _spin_after(st[i, WZ], t, alpha)
    elif s == SPINNING:
        st[i, WZ] = _spin_after(st[i, WZ], t, alpha)


@njit(cache=True, error_model="numpy", _nrt=False)
def _evolve_all(st, lab, t, p):
    """Advance every ball by t seconds (the event loop's step between events), in place."""
    for k in range(N_BALLS):
        evolve_ball(st, lab, k, t, p)


@njit(cache=True, error_model="numpy")
def _poly(st, lab, i, p):
    """Trajectory polynomial p(t) = c + b t + a t^2 of ball i (§3.1): returns ax, ay, bx, by."""
    s = lab[i]
    if s == SLIDING:
        ux, uy, _ = _slip_dir(st, i, p[P_R])
        k = -0.5 * p[P_U_S] * p[P_G]
        return k * ux, k * uy, st[i, VX], st[i, VY]
    if s == ROLLING:
        vn = _norm(st[i, VX], st[i, VY])
        if vn > 0.0:
            k = -0.5 * p[P_U_R] * p[P_G] / vn
            return k * st[i, VX], k * st[i, VY], st[i, VX], st[i, VY]
    return 0.0, 0.0, 0.0, 0.0


# ----------------------------------------------------------------------------- detect (§3)


@njit(cache=True, error_model="numpy")
def transition_time(st, lab, i, p):
    """Time until ball i's next motion transition, and the label it goes to (§2)."""
    R, g = p[P_R], p[P_G]
    s = lab[i]
    alpha = 5.0 * p[P_U_SP] * g / (2.0 * R)
    if s == SLIDING:
        _, _, un = _slip_dir(st, i, R)
        return 2.0 * un / (7.0 * p[P_U_S] * g), ROLLING
    if s == ROLLING:
        tau_r = _norm(st[i, VX], st[i, VY]) / (p[P_U_R] * g)
        tau_sp = abs(st[i, WZ]) / alpha
        if tau_sp > tau_r:
            return tau_r, SPINNING
        return tau_r, STATIONARY
    if s == SPINNING:
        return abs(st[i, WZ]) / alpha, STATIONARY
    return INF, STATIONARY


@njit(cache=True, error_model="numpy")
def _quadratic_roots(a, b, c):
    """Real roots of a t^2 + b t + c, ascending, NaN where absent; handles a = 0 and b = 0."""
    if a == 0.0:
        if b == 0.0:
            return np.nan, np.nan
        return -c / b, np.nan
    disc = b * b - 4.0 * a * c
    if disc < 0.0:
        return np.nan, np.nan
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    if q == 0.0:
        return 0.0, 0.0
    r1, r2 = q / a, c / q
    if r1 > r2:
        r1, r2 = r2, r1
    return r1, r2


@njit(cache=True, error_model="numpy")
def _cubic_eval(c3, c2, c1, c0, t):
    return ((c3 * t + c2) * t + c1) * t + c0


@njit(cache=True, error_model="numpy")
def _newton_step(t, ft, dft, lo, hi, below):
    """One safeguarded Newton step towards the root bracketed by [lo, hi], from t where f is
    ft and f' is dft; ``below`` says t lies on lo's side of the root. The bracket shrinks to
    t's side; a step that leaves it (or a flat f') bisects instead. Returns (next t, lo, hi,
    converged): converged when the step is below NEWTON_RTOL of t or lands on the bracket."""
    if below:
        lo = t
    else:
        hi = t
    tn = t - ft / dft if dft != 0.0 else 0.5 * (lo + hi)
    if not (lo < tn < hi):
        tn = 0.5 * (lo + hi)
    return tn, lo, hi, abs(tn - t) <= NEWTON_RTOL * abs(t) or tn == lo or tn == hi


@njit(cache=True, error_model="numpy")
def _cubic_root(c3, c2, c1, c0, lo, hi, flo):
    """Root of a cubic that is monotone on [lo, hi] and changes sign there (flo = value at
    lo), by :func:`_newton_step` from the bracket's midpoint."""
    t = 0.5 * (lo + hi)
    for _ in range(NEWTON_ITERATIONS):
        ft = _cubic_eval(c3, c2, c1, c0, t)
        if ft == 0.0:
            return t
        dft = (3.0 * c3 * t + 2.0 * c2) * t + c1
        tn, lo, hi, done = _newton_step(t, ft, dft, lo, hi, (ft > 0.0) == (flo > 0.0))
        if done:
            return tn
        t = tn
    return t


@njit(cache=True, error_model="numpy")
def _cubic_roots_in(c3, c2, c1, c0, T):
    """Real roots of the cubic inside (0, T), ascending: (count, r0, r1, r2).

    The cubic is split at the roots of its derivative into monotone pieces, and each piece
    with a sign change is solved, so degenerate (lower-degree) cubics need no special case.
    """
    q1, q2 = _quadratic_roots(3.0 * c3, 2.0 * c2, c1)
    if not (q1 == q1 and 0.0 < q1 < T):
        q1 = np.nan
    if not (q2 == q2 and 0.0 < q2 < T and not q2 <= q1):
        q2 = np.nan
    if q1 != q1:
        q1, q2 = q2, np.nan
    n = 0
    r0, r1, r2 = np.nan, np.nan, np.nan
    lo = 0.0
    flo = _cubic_eval(c3, c2, c1, c0, lo)
    for k in range(3):
        hi = q1 if k == 0 else (q2 if k == 1 else T)
        if hi != hi:
            if k < 2:
                continue
        fhi = _cubic_eval(c3, c2, c1, c0, hi)
        if flo != 0.0 and fhi != 0.0 and (flo > 0.0) != (fhi > 0.0):
            r = _cubic_root(c3, c2, c1, c0, lo, hi, flo)
        elif fhi == 0.0 and hi < T:
            r = hi
        else:
            r = np.nan
        if r == r:
            if n == 0:
                r0 = r
            elif n == 1:
                r1 = r
            else:
                r2 = r
            n += 1
        lo, flo = hi, fhi
    return n, r0, r1, r2


@njit(cache=True, error_model="numpy")
def _sep2(dax, day, dbx, dby, dcx, dcy, t):
    """Squared centre distance at t of two balls with relative polynomial dA t^2 + dB t + dC."""
    x = (dax * t + dbx) * t + dcx
    y = (day * t + dby) * t + dcy
    return x * x + y * y


@njit(cache=True, error_model="numpy")
def _relative_poly(st, poly, i, j):
    return (poly[j, AX] - poly[i, AX], poly[j, AY] - poly[i, AY], poly[j, BX] - poly[i, BX],
            poly[j, BY] - poly[i, BY], st[j, X] - st[i, X], st[j, Y] - st[i, Y])


@njit(cache=True, error_model="numpy")
def _span(a, b, c, T):
    """Range [lo, hi] of the parabola c + b t + a t^2 over t in [0, T]."""
    if a == 0.0 and b == 0.0:
        return c, c
    end = (a * T + b) * T + c
    lo, hi = min(c, end), max(c, end)
    if a != 0.0:
        tv = -b / (2.0 * a)
        if 0.0 < tv < T:
            v = (a * tv + b) * tv + c
            lo, hi = min(lo, v), max(hi, v)
    return lo, hi


@njit(cache=True, error_model="numpy")
def _box_gap(st, poly, i, j, T):
    """A lower bound on the centre distance of balls i and j over [0, T]: the gap between
    the axis-aligned boxes their trajectory polynomials sweep."""
    ilx, ihx = _span(poly[i, AX], poly[i, BX], st[i, X], T)
    ily, ihy = _span(poly[i, AY], poly[i, BY], st[i, Y], T)
    jlx, jhx = _span(poly[j, AX], poly[j, BX], st[j, X], T)
    jly, jhy = _span(poly[j, AY], poly[j, BY], st[j, Y], T)
    gx = max(jlx - ihx, ilx - jhx, 0.0)
    gy = max(jly - ihy, ily - jhy, 0.0)
    return _norm(gx, gy)


@njit(cache=True, error_model="numpy")
def _quartic_derivative(dax, day, dbx, dby, dcx, dcy):
    """Coefficients of d/dt |dA t^2 + dB t + dC|^2, a cubic."""
    a4 = dax * dax + day * day
    a3 = 2.0 * (dax * dbx + day * dby)
    a2 = dbx * dbx + dby * dby + 2.0 * (dax * dcx + day * dcy)
    a1 = 2.0 * (dbx * dcx + dby * dcy)
    return 4.0 * a4, 3.0 * a3, 2.0 * a2, a1


@njit(cache=True, error_model="numpy")
def _contact_root(dax, day, dbx, dby, dcx, dcy, r2, lo, hi):
    """The contact time inside a bracket [lo, hi] with f(lo) > 0 >= f(hi), f(t) the squared
    centre distance minus r2 in its direct (non-expanded) form, by :func:`_newton_step`
    from lo."""
    t = lo
    for _ in range(NEWTON_ITERATIONS):
        x = (dax * t + dbx) * t + dcx
        y = (day * t + dby) * t + dcy
        ft = x * x + y * y - r2
        dft = 2.0 * (x * (2.0 * dax * t + dbx) + y * (2.0 * day * t + dby))
        tn, lo, hi, done = _newton_step(t, ft, dft, lo, hi, ft > 0.0)
        if done:
            return tn
        t = tn
    return t


@njit(cache=True, error_model="numpy")
def ball_ball_time(st, poly, lab, i, j, R, T):
    """Earliest time in [0, T] at which balls i and j come into contact (§3.2), or INF.

    f(t) = |dA t^2 + dB t + dC|^2 - (2R)^2 is a quartic. Its derivative's real roots split
    [0, T] into monotone pieces; the first piece on which f falls from > 0 to <= 0 holds the
    contact, found by safeguarded Newton on the direct (non-expanded) form of f. Balls that
    touch or overlap (f <= 0, within the input tolerance or after a make_kiss that had no
    room) collide where they start to approach: now, or at the start of the first piece on
    which f falls from <= 0; separating, they do not.
    """
    if lab[i] <= SPINNING and lab[j] <= SPINNING:
        return INF
    d2 = 2.0 * R
    if _box_gap(st, poly, i, j, T) > d2:
        return INF
    dax, day, dbx, dby, dcx, dcy = _relative_poly(st, poly, i, j)
    r2 = d2 * d2
    f0 = dcx * dcx + dcy * dcy - r2
    c3, c2, c1, c0 = _quartic_derivative(dax, day, dbx, dby, dcx, dcy)
    if f0 <= 0.0 and c0 < 0.0:
        return 0.0  # already touching or overlapping and approaching: contact now (§3.2)
    n, q0, q1, q2 = _cubic_roots_in(c3, c2, c1, c0, T)
    lo, flo = 0.0, f0
    for k in range(n + 1):
        hi = T if k == n else (q0 if k == 0 else (q1 if k == 1 else q2))
        fhi = _sep2(dax, day, dbx, dby, dcx, dcy, hi) - r2
        if flo > 0.0 and fhi <= 0.0:
            return _contact_root(dax, day, dbx, dby, dcx, dcy, r2, lo, hi)
        if flo <= 0.0 and fhi < flo:
            return lo  # touching at lo and turning towards each other there
        lo, flo = hi, fhi
    return INF


@njit(cache=True, error_model="numpy")
def min_separation(st, poly, lab, i, j, T):
    """Smallest centre distance between balls i and j over [0, T] along their polynomials."""
    dax, day, dbx, dby, dcx, dcy = _relative_poly(st, poly, i, j)
    best = _sep2(dax, day, dbx, dby, dcx, dcy, 0.0)
    if lab[i] <= SPINNING and lab[j] <= SPINNING:
        return math.sqrt(best)
    c3, c2, c1, c0 = _quartic_derivative(dax, day, dbx, dby, dcx, dcy)
    n, q0, q1, q2 = _cubic_roots_in(c3, c2, c1, c0, T)
    if n > 0:
        best = min(best, _sep2(dax, day, dbx, dby, dcx, dcy, q0))
    if n > 1:
        best = min(best, _sep2(dax, day, dbx, dby, dcx, dcy, q1))
    if n > 2:
        best = min(best, _sep2(dax, day, dbx, dby, dcx, dcy, q2))
    best = min(best, _sep2(dax, day, dbx, dby, dcx, dcy, T))
    return math.sqrt(best)


@njit(cache=True, error_model="numpy")
def _moving_in(fa, fb, fc, t):
    """Whether a ball whose penetration past a nose line is f(t) = fa t^2 + fb t + fc is
    pressing into the rail at t: f' > 0, or f' = 0 with f'' > 0 (about to)."""
    d = 2.0 * fa * t + fb
    return d > 0.0 or (d == 0.0 and fa > 0.0)


@njit(cache=True, error_model="numpy")
def cushion_time(st, poly, lab, i, p, T):
    """Earliest time in [0, T] at which ball i meets a cushion (§3.3): (time, cushion).

    The ball meets cushion w when its penetration past w's nose line, f(t) (a quadratic), is
    >= 0 while it presses into the rail (:func:`_moving_in`). A ball already touching or
    pressed into a cushion (by up to the make-kiss spacers of an earlier collision, or by the
    input tolerance) and moving into it collides now (time 0), as overlapping balls do; so
    does one that sits on the nose line with no normal velocity but accelerates into it.
    Otherwise the contact is the first root of f at which the ball moves in. From outside the
    line (f(0) < 0) that is pooltool's rule, the first root > EPS, except that a root <= EPS
    (a ball a hair outside the line) counts too instead of letting the ball through the rail.
    A pressed-in ball moving out does not collide as it leaves, but does if it turns back
    before it is out (at the turn) or comes back later (at the root where it re-enters).
    """
    if lab[i] <= SPINNING:
        return INF, -1
    R = p[P_R]
    ax, ay, bx, by = poly[i, AX], poly[i, AY], poly[i, BX], poly[i, BY]
    best, which = INF, -1
    for w in range(N_CUSHIONS):
        if w < 2:
            a, b, c = ax, bx, st[i, X] - (R if w == 0 else p[P_W] - R)
        else:
            a, b, c = ay, by, st[i, Y] - (R if w == 2 else p[P_L] - R)
        inward = -1.0 if w % 2 == 0 else 1.0  # sign of the velocity component into the cushion
        fa, fb, fc = a * inward, b * inward, c * inward
        if fc >= 0.0 and _moving_in(fa, fb, fc, 0.0):
            return 0.0, w
        if abs(a) < EPS:
            if abs(b) < EPS:
                continue
            r1, r2 = -c / b, np.nan
        else:
            r1, r2 = _quadratic_roots(a, b, c)
        for r in (r1, r2):
            if r == r and 0.0 <= r <= T and r < best and ((r > EPS and fc < 0.0) or _moving_in(fa, fb, fc, r)):
                best, which = r, w
        if fc >= 0.0 and fa > 0.0 and fb < 0.0:
            tv = -fb / (2.0 * fa)  # a pressed-in ball moving out turns back at tv
            if tv <= T and tv < best and (fa * tv + fb) * tv + fc >= 0.0:
                best, which = tv, w
    return best, which


# The event caches of the loop: the absolute time of every ball's next transition, every
# pair's next contact and every ball's next cushion, in one vector ``when`` (N_SLOTS,) of
# slots in that order, beside ``what`` (N_SLOTS,): the transition's new label, the cushion.
SLOT_TRANSITION, SLOT_PAIR, SLOT_CUSHION = 0, N_BALLS, N_BALLS + N_PAIRS
N_SLOTS = 2 * N_BALLS + N_PAIRS


@njit(cache=True, error_model="numpy", _nrt=False)
def _detect(st, lab, p, t, poly, dirty, when, what):
    """Refresh the event caches at time t (§3.4): every ball's trajectory polynomial, and the
    slots of the balls whose trajectory changed (``dirty``, cleared here) and of their pairs.
    A pair's contact is sought only up to the first transition or cushion of either ball,
    which would change its trajectory anyway."""
    for k in range(N_BALLS):
        poly[k, AX], poly[k, AY], poly[k, BX], poly[k, BY] = _poly(st, lab, k, p)
    for k in range(N_BALLS):
        if dirty[k]:
            tau, to = transition_time(st, lab, k, p)
            when[SLOT_TRANSITION + k] = t + tau
            what[SLOT_TRANSITION + k] = to
            tc, w = cushion_time(st, poly, lab, k, p, tau)
            when[SLOT_CUSHION + k] = t + tc
            what[SLOT_CUSHION + k] = w
    for q in range(N_PAIRS):
        i, j = PAIR_I[q], PAIR_J[q]
        if dirty[i] or dirty[j]:
            horizon = min(min(when[SLOT_TRANSITION + i], when[SLOT_CUSHION + i]),
                          min(when[SLOT_TRANSITION + j], when[SLOT_CUSHION + j])) - t
            when[SLOT_PAIR + q] = t + ball_ball_time(st, poly, lab, i, j, p[P_R], horizon)
    for k in range(N_BALLS):
        dirty[k] = False


@njit(cache=True, error_model="numpy", _nrt=False)
def _next_event(when, what):
    """The earliest cached event: (kind, ball, other, time), kind -1 if none is left. Exact
    ties go to the first slot: transitions win over collisions (§3.4)."""
    s, t_next = -1, INF
    for q in range(N_SLOTS):
        if when[q] < t_next:
            s, t_next = q, when[q]
    if s < 0:
        return -1, -1, -1, INF
    if s < SLOT_PAIR:
        return EV_TRANSITION, s - SLOT_TRANSITION, what[s], t_next
    if s < SLOT_CUSHION:
        return EV_BALL_BALL, PAIR_I[s - SLOT_PAIR], PAIR_J[s - SLOT_PAIR], t_next
    return EV_CUSHION, s - SLOT_CUSHION, what[s], t_next


# ----------------------------------------------------------------------------- resolve


@njit(cache=True, error_model="numpy")
def strike(st, lab, V0, phi, a, b, p):
    """Level-cue instantaneous-point strike of ball 0 (§1); a, b are fractions of R."""
    R, m = p[P_R], p[P_M]
    v = 2.0 * V0 / (1.0 + m / p[P_CUE_M] + 2.5 * (a * a + b * b))
    heading = phi
    if p[P_SQUIRT] != 0.0:
        heading += -math.atan2(2.5 * a * math.sqrt(1.0 - a * a),
                               1.0 + m / p[P_CUE_END_M] + 2.5 * (1.0 - a * a))
    k = 5.0 * v / (2.0 * R)
    st[WHITE, VX] = v * math.cos(heading)
    st[WHITE, VY] = v * math.sin(heading)
    st[WHITE, WX] = -k * b * math.sin(phi)
    st[WHITE, WY] = k * b * math.cos(phi)
    st[WHITE, WZ] = -k * a
    lab[WHITE] = SLIDING if v > 0.0 else STATIONARY


@njit(cache=True, error_model="numpy")
def _deeper(before, after):
    """Whether a gap to a rail or ball (m; negative: pressed in) that moved from before to
    after went deeper than KISS_SLACK, or deeper at all if it was already past it."""
    return after < -KISS_SLACK and after < before


@njit(cache=True, error_model="numpy")
def _clear(st, k, x, y, p, partner):
    """Whether moving ball k to (x, y) presses it no deeper than KISS_SLACK into any rail or
    other ball but partner (-1: none), nor deeper at all into one it was already past that.

    make_kiss moves balls by a few min_dist, and more when they move slowly; near a rail or a
    third ball (balls resting against each other, a cluster struck at an exact contact) that
    could push one through it, unseen by detection, and the shot would end off the table or
    overlapping. A placement that fails this check is not used. The slack lets a pair wedged
    between touching neighbours still part a little, so that it does not collide again at
    once (a ball pushing another with no normal speed left would do so forever).
    """
    R, W, L = p[P_R], p[P_W], p[P_L]
    if _deeper(st[k, X] - R, x - R) or _deeper(W - R - st[k, X], W - R - x):
        return False
    if _deeper(st[k, Y] - R, y - R) or _deeper(L - R - st[k, Y], L - R - y):
        return False
    for m in range(N_BALLS):
        if m != k and m != partner:
            before = _norm(st[m, X] - st[k, X], st[m, Y] - st[k, Y]) - 2.0 * R
            if _deeper(before, _norm(st[m, X] - x, st[m, Y] - y) - 2.0 * R):
                return False
    return True


@njit(cache=True, error_model="numpy")
def _free_move(st, k, dx, dy, p, partner):
    """The move (dx, dy) of ball k without its components into the rails and balls (but
    partner) that block it (:func:`_clear`): the ball slides along what it presses against.
    (0, 0) if no such move is clear."""
    R, W, L = p[P_R], p[P_W], p[P_L]
    for _ in range(3):
        x, y = st[k, X] + dx, st[k, Y] + dy
        if _clear(st, k, x, y, p, partner):
            return dx, dy
        if _deeper(st[k, X] - R, x - R) or _deeper(W - R - st[k, X], W - R - x):
            dx = 0.0
        if _deeper(st[k, Y] - R, y - R) or _deeper(L - R - st[k, Y], L - R - y):
            dy = 0.0
        for m in range(N_BALLS):
            if m != k and m != partner:
                ux, uy = st[m, X] - st[k, X], st[m, Y] - st[k, Y]
                u = _norm(ux, uy)
                if _deeper(u - 2.0 * R, _norm(st[m, X] - x, st[m, Y] - y) - 2.0 * R):
                    c = (dx * ux + dy * uy) / (u * u)
                    if c > 0.0:
                        dx, dy = dx - c * ux, dy - c * uy
    if _clear(st, k, st[k, X] + dx, st[k, Y] + dy, p, partner):
        return dx, dy
    return 0.0, 0.0


@njit(cache=True, error_model="numpy")
def _place_pair(st, i, j, xi, yi, xj, yj, p):
    """Move balls i and j to the given centres if neither ends up in a rail or a third ball
    (:func:`_clear`); returns whether they moved."""
    if not (_clear(st, i, xi, yi, p, j) and _clear(st, j, xj, yj, p, i)):
        return False
    st[i, X], st[i, Y], st[j, X], st[j, Y] = xi, yi, xj, yj
    return True


@njit(cache=True, error_model="numpy")
def _kiss_balls(st, lab, i, j, p):
    """make_kiss (§4): separate touching balls to 2R + min_dist, along their velocities.

    Where pooltool's placement (along the velocities, else pushed apart symmetrically) would
    push a ball into a rail or a third ball (:func:`_clear`), the push is taken by one ball
    alone (the other being blocked), else a part of the spacer is made, else each ball slides
    along what blocks it (:func:`_free_move`), and if none of that parts them the balls stay
    where they are: they separate after the impulse anyway, and detection treats touching
    balls that turn towards each other as a collision (:func:`ball_ball_time`), so the spacer
    is a convenience, not a need.
    """
    dist = 2.0 * p[P_R] + p[P_MIN_DIST]
    md = p[P_MIN_DIST]
    rx, ry = st[j, X] - st[i, X], st[j, Y] - st[i, Y]
    vx, vy = st[j, VX] - st[i, VX], st[j, VY] - st[i, VY]
    r1, r2 = _quadratic_roots(vx * vx + vy * vy, 2.0 * (rx * vx + ry * vy), rx * rx + ry * ry - dist * dist)
    t = np.nan
    if r1 == r1:
        t = r1
        if r2 == r2 and abs(r2) < abs(r1):
            t = r2
    moving = lab[i] > SPINNING or lab[j] > SPINNING
    if t == t and moving:
        mx = 0.5 * t * (st[i, VX] + st[j, VX])
        my = 0.5 * t * (st[i, VY] + st[j, VY])
        if _norm(mx, my) <= 5.0 * md and _place_pair(
                st, i, j, st[i, X] + t * st[i, VX], st[i, Y] + t * st[i, VY],
                st[j, X] + t * st[j, VX], st[j, Y] + t * st[j, VY], p):
            return
    # fallback: push apart symmetrically along the line of centres
    cx, cy = 0.5 * (st[i, X] + st[j, X]), 0.5 * (st[i, Y] + st[j, Y])
    n = _norm(rx, ry)
    nx, ny = rx / n, ry / n
    if _place_pair(st, i, j, cx - 0.5 * dist * nx, cy - 0.5 * dist * ny, cx + 0.5 * dist * nx, cy + 0.5 * dist * ny, p):
        return
    # blocked: one ball alone, then less than the full spacer
    for scale in (1.0, 0.5, 0.25, 0.125):
        push = scale * (dist - n)
        for share in (0.0, 1.0, 0.5):  # the part of the push ball i takes
            si, sj = share * push, (1.0 - share) * push
            if _place_pair(st, i, j, st[i, X] - si * nx, st[i, Y] - si * ny, st[j, X] + sj * nx, st[j, Y] + sj * ny, p):
                return
    # wedged along the line of centres: each ball slides along what it presses against
    push = dist - n
    dix, diy = _free_move(st, i, -0.5 * push * nx, -0.5 * push * ny, p, j)
    djx, djy = _free_move(st, j, 0.5 * push * nx, 0.5 * push * ny, p, i)
    if (djx - dix) * nx + (djy - diy) * ny > 0.0:
        _place_pair(st, i, j, st[i, X] + dix, st[i, Y] + diy, st[j, X] + djx, st[j, Y] + djy, p)


@njit(cache=True, error_model="numpy")
def resolve_ball_ball(st, lab, i, j, p):
    """Equal-mass restitution exchange along the line of centres (§4b; e = 1 gives §4a)."""
    _kiss_balls(st, lab, i, j, p)
    e = 1.0 if p[P_BALL_BALL] == BALL_BALL_ELASTIC else p[P_E_B]
    nx, ny = st[j, X] - st[i, X], st[j, Y] - st[i, Y]
    n = _norm(nx, ny)
    nx, ny = nx / n, ny / n
    vin = st[i, VX] * nx + st[i, VY] * ny
    vjn = st[j, VX] * nx + st[j, VY] * ny
    vin_new = 0.5 * ((1.0 - e) * vin + (1.0 + e) * vjn)
    vjn_new = 0.5 * ((1.0 + e) * vin + (1.0 - e) * vjn)
    st[i, VX] += (vin_new - vin) * nx
    st[i, VY] += (vin_new - vin) * ny
    st[j, VX] += (vjn_new - vjn) * nx
    st[j, VY] += (vjn_new - vjn) * ny
    lab[i] = SLIDING
    lab[j] = SLIDING


@njit(cache=True, error_model="numpy")
def _cushion_normal(w):
    """Outward (into the cushion) unit normal of cushion w."""
    if w == 0:
        return -1.0, 0.0
    if w == 1:
        return 1.0, 0.0
    if w == 2:
        return 0.0, -1.0
    return 0.0, 1.0


@njit(cache=True, error_model="numpy")
def resolve_cushion(st, lab, i, w, p):
    """Han 2005 ball–cushion impulse, corrected form (§5), with make_kiss to R + min_dist."""
    R, m, md = p[P_R], p[P_M], p[P_MIN_DIST]
    nx, ny = _cushion_normal(w)
    # make_kiss: back along the velocity to distance R + min_dist, else along the normal
    if w == 0:
        d = st[i, X]
    elif w == 1:
        d = p[P_W] - st[i, X]
    elif w == 2:
        d = st[i, Y]
    else:
        d = p[P_L] - st[i, Y]
    # (only where that does not push it into another rail or a ball, see _clear; else part of
    # the spacer, or it stays: detection needs no spacer, see cushion_time)
    need = R + md - d
    vn = _norm(st[i, VX], st[i, VY])
    along = (st[i, VX] * nx + st[i, VY] * ny) / vn if vn > 0.0 else 0.0
    shift = need / along if along > 0.0 else INF
    moved = False
    if abs(shift) <= 5.0 * md:
        x, y = st[i, X] - shift * st[i, VX] / vn, st[i, Y] - shift * st[i, VY] / vn
        moved = _clear(st, i, x, y, p, np.int64(-1))
    for scale in (1.0, 0.5, 0.25, 0.125):  # along the normal; blocked: part of the spacer
        if not moved:
            x, y = st[i, X] - scale * need * nx, st[i, Y] - scale * need * ny
            moved = _clear(st, i, x, y, p, np.int64(-1))
    if not moved:  # wedged: slide along what blocks the push, if that still leaves the rail
        dx, dy = _free_move(st, i, -need * nx, -need * ny, p, np.int64(-1))
        x, y = st[i, X] + dx, st[i, Y] + dy
        moved = dx * nx + dy * ny < 0.0
    if moved:
        st[i, X], st[i, Y] = x, y
    # rail frame: x along the normal oriented with the velocity, y = z cross x
    if st[i, VX] * nx + st[i, VY] * ny < 0.0:
        nx, ny = -nx, -ny
    yx, yy = -ny, nx
    vx = st[i, VX] * nx + st[i, VY] * ny
    vy = st[i, VX] * yx + st[i, VY] * yy
    wx = st[i, WX] * nx + st[i, WY] * ny
    wy = st[i, WX] * yx + st[i, WY] * yy
    wz = st[i, WZ]
    theta = math.asin(p[P_H] / R - 1.0)
    sa, ca = math.sin(theta), math.cos(theta)
    e, mu = p[P_E_C], p[P_F_C]
    sx = vx * sa + R * wy
    sy = -vy - R * wz * ca + R * wx * sa
    s = _norm(sx, sy)
    pze = (1.0 + e) * m * vx * ca
    pzs = 2.0 * m / 7.0 * s
    if pzs <= mu * pze:
        pxe = 2.0 * m / 7.0 * sx
        pye = 2.0 * m / 7.0 * sy
    else:
        pxe = mu * pze * sx / s
        pye = mu * pze * sy / s
    PX = -pxe * sa - pze * ca
    PY = pye
    PZ = pxe * ca - pze * sa
    k = 5.0 / (2.0 * m * R)
    vx += PX / m
    vy += PY / m
    wx -= k * PY * sa
    wy += k * (PX * sa - PZ * ca)
    wz += k * PY * ca
    st[i, VX] = vx * nx + vy * yx
    st[i, VY] = vx * ny + vy * yy
    st[i, WX] = wx * nx + wy * yx
    st[i, WY] = wx * ny + wy * yy
    st[i, WZ] = wz
    lab[i] = SLIDING


@njit(cache=True, error_model="numpy")
def resolve_transition(st, lab, i, new_label):
    """Enter a new motion state (§2): residual velocities are zeroed on entering spin/rest."""
    if new_label == SPINNING or new_label == STATIONARY:
        st[i, VX] = 0.0
        st[i, VY] = 0.0
        st[i, WX] = 0.0
        st[i, WY] = 0.0
        if new_label == STATIONARY:
            st[i, WZ] = 0.0
    lab[i] = new_label


@njit(cache=True, error_model="numpy", _nrt=False)
def _resolve(st, lab, kind, who, other, p, dirty):
    """Resolve one event of the loop in place, and mark the balls whose trajectory changed."""
    if kind == EV_TRANSITION:
        resolve_transition(st, lab, who, other)
    elif kind == EV_BALL_BALL:
        resolve_ball_ball(st, lab, who, other, p)
        dirty[other] = True
    else:
        resolve_cushion(st, lab, who, other, p)
    dirty[who] = True


# ----------------------------------------------------------------------------- carom facts
# What the rules and the shaping read about the white's shot, gathered along the event loop in
# the outcome vectors: the balls it touched (O_HIT*), the first (O_FIRST), the red it touched
# second (O_SECOND_RED), its cushions (O_CUSHIONS), and its closest approach to each red
# (OF_CLOSE*: a centre distance during the shot, the surface gap at its end).


@njit(cache=True, error_model="numpy", _nrt=False)
def _carom_begin(st, out_int, out_float):
    """No contact yet; the white's closest approach to each red so far is where they stand."""
    out_int[O_FIRST] = -1
    out_int[O_SECOND_RED] = -1
    for r in range(2):
        out_float[OF_CLOSE2 + r] = _norm(st[RED1 + r, X] - st[WHITE, X], st[RED1 + r, Y] - st[WHITE, Y])


@njit(cache=True, error_model="numpy", _nrt=False)
def _carom_approach(st, poly, lab, out_int, out_float, dt):
    """Before every ball moves on by dt along ``poly``: the white's closest approach to each red
    it has not touched (the exact minimum, where the swept boxes can beat the best so far)."""
    for r in range(2):
        if out_int[O_HIT2 + r] == 0 and (lab[WHITE] > SPINNING or lab[RED1 + r] > SPINNING):
            if _box_gap(st, poly, np.int64(WHITE), RED1 + r, dt) < out_float[OF_CLOSE2 + r]:
                out_float[OF_CLOSE2 + r] = min(out_float[OF_CLOSE2 + r], min_separation(st, poly, lab, np.int64(WHITE), RED1 + r, dt))


@njit(cache=True, error_model="numpy", _nrt=False)
def _carom_event(kind, who, other, out_int, out_float, R):
    """After a resolved event: a contact of the white (which ball, whether the first, whether
    the second red) or a cushion of the white."""
    if who != WHITE:
        return
    if kind == EV_BALL_BALL:  # the white is always ``who`` of its pairs (PAIR_I < PAIR_J)
        hit = O_HIT1 + other - YELLOW
        if other >= RED1 and out_int[hit] == 0 and out_int[O_HIT1 + (RED1 + RED2 - other) - YELLOW] != 0:
            out_int[O_SECOND_RED] = other  # the white's first contact with the second red
        out_int[hit] = 1
        if out_int[O_FIRST] < 0:
            out_int[O_FIRST] = other
        if other >= RED1:
            out_float[OF_CLOSE2 + other - RED1] = 2.0 * R
    elif kind == EV_CUSHION:
        out_int[O_CUSHIONS] += 1


@njit(cache=True, error_model="numpy", _nrt=False)
def _carom_end(out_float, R):
    """The closest approaches as surface gaps (0 for a red the white touched)."""
    for r in range(2):
        out_float[OF_CLOSE2 + r] = max(out_float[OF_CLOSE2 + r] - 2.0 * R, 0.0)


# ----------------------------------------------------------------------------- event log
# A log is (times (E,), info (E, N_INFO) rows INFO_KIND, INFO_BALL, INFO_OTHER, states (E,
# N_BALLS, N_STATE + 1): every ball's state and LABEL after the event), grown by doubling.


@njit(cache=True, error_model="numpy")
def _new_log(cap):
    return np.empty(cap), np.empty((cap, N_INFO), dtype=np.int64), np.empty((cap, N_BALLS, N_STATE + 1))


@njit(cache=True, error_model="numpy")
def _grow(log, n):
    """The log with twice its room and its n entries (copied element by element)."""
    times, info, states = log
    out_times, out_info, out_states = _new_log(2 * times.shape[0])
    for e in range(n):
        out_times[e] = times[e]
        for c in range(N_INFO):
            out_info[e, c] = info[e, c]
        for k in range(N_BALLS):
            for c in range(N_STATE + 1):
                out_states[e, k, c] = states[e, k, c]
    return out_times, out_info, out_states


@njit(cache=True, error_model="numpy")
def _record(log, n, t, kind, who, other, st, lab):
    """Append one event and every ball's state after it to the log (n entries so far), growing
    it if full; returns the log and its new length."""
    if n >= log[0].shape[0]:
        log = _grow(log, n)
    times, info, states = log
    times[n] = t
    info[n, INFO_KIND], info[n, INFO_BALL], info[n, INFO_OTHER] = kind, who, other
    for k in range(N_BALLS):
        for c in range(N_STATE):
            states[n, k, c] = st[k, c]
        states[n, k, LABEL] = lab[k]
    return log, n + 1


# ----------------------------------------------------------------------------- event loop


@njit(cache=True, error_model="numpy")
def _halt(st, lab, out_int, flag, record, log, n, t):
    """Stop the shot: every ball rests where it is, ``out_int[flag]`` says why (the shot-time
    limit or the event cap), and the log records the stop. Returns the log and its length."""
    for k in range(N_BALLS):
        resolve_transition(st, lab, k, np.int64(STATIONARY))
    out_int[flag] = 1
    if record:
        return _record(log, n, t, np.int64(EV_STOP), np.int64(-1), np.int64(-1), st, lab)
    return log, n


@njit(cache=True, error_model="numpy")
def run_shot(positions, V0, phi, a, b, p, record):
    """Simulate one shot from rest to rest.

    positions: (4, 2) ball centres; V0 cue speed (m/s); phi aim (rad); a, b contact offsets
    (fractions of R). Returns ``(st, out_int, out_float, ev_time, ev_info, ev_state)``: the
    final state, the outcome vectors (slots ``O_*`` and ``OF_*``) and, if ``record``, the
    event log (time; kind, ball, other; all balls' state and labels after the event).

    The loop: detect the next event from the caches (refreshed for the balls the last event
    changed), evolve every ball to it, resolve it, note the carom facts, log it; until no
    event is left, or the shot-time limit or the event cap stops the shot.
    """
    st = np.zeros((N_BALLS, N_STATE))
    lab = np.zeros(N_BALLS, dtype=np.int64)
    for k in range(N_BALLS):
        st[k, X] = positions[k, 0]
        st[k, Y] = positions[k, 1]
    out_int = np.zeros(N_OUT_INT, dtype=np.int64)
    out_float = np.zeros(N_OUT_FLOAT)
    _carom_begin(st, out_int, out_float)
    log = _new_log(64 if record else 1)
    n_rec = np.int64(0)

    strike(st, lab, V0, phi, a, b, p)
    if record:
        log, n_rec = _record(log, n_rec, 0.0, np.int64(EV_STRIKE), np.int64(WHITE), np.int64(-1), st, lab)

    t = 0.0
    n_ev = 0
    max_events = int(p[P_MAX_EVENTS])
    when = np.full(N_SLOTS, INF)
    what = np.full(N_SLOTS, -1, dtype=np.int64)
    dirty = np.ones(N_BALLS, dtype=np.bool_)
    poly = np.empty((N_BALLS, N_POLY))
    while True:
        _detect(st, lab, p, t, poly, dirty, when, what)
        kind, who, other, t_next = _next_event(when, what)
        if kind < 0:
            break
        # the shot-time limit (docs/physics.md §10): evolve to it, then every ball rests
        timeout = t_next > p[P_MAX_TIME]
        if timeout:
            t_next = p[P_MAX_TIME]
        dt = t_next - t
        _carom_approach(st, poly, lab, out_int, out_float, dt)
        _evolve_all(st, lab, dt, p)
        t = t_next
        if timeout:
            log, n_rec = _halt(st, lab, out_int, np.int64(O_TIMEOUT), record, log, n_rec, t)
            break
        _resolve(st, lab, kind, who, other, p, dirty)
        _carom_event(kind, who, other, out_int, out_float, p[P_R])
        n_ev += 1
        if record:
            log, n_rec = _record(log, n_rec, t, kind, who, other, st, lab)
        if n_ev >= max_events:  # safety net
            log, n_rec = _halt(st, lab, out_int, np.int64(O_TRUNC), record, log, n_rec, t)
            break
    out_int[O_NEVENTS] = n_ev
    _carom_end(out_float, p[P_R])
    out_float[OF_TIME] = t
    times, info, states = log
    return st, out_int, out_float, times[:n_rec], info[:n_rec], states[:n_rec]


@njit(cache=True, error_model="numpy", inline="always")
def _store(n, positions, actions, p, out_pos, out_int, out_float):
    # record: the constant False, so the batch kernels' event loop is compiled without the log
    st, oi, of, _, _, _ = run_action(positions[n], actions[n], p, False)
    for k in range(N_BALLS):
        out_pos[n, k, 0] = st[k, X]
        out_pos[n, k, 1] = st[k, Y]
    for k in range(N_OUT_INT):
        out_int[n, k] = oi[k]
    for k in range(N_OUT_FLOAT):
        out_float[n, k] = of[k]


@njit(cache=True, error_model="numpy", parallel=True)
def run_batch(positions, actions, p, out_pos, out_int, out_float):
    """N validated shots in parallel over all numba threads; actions rows (theta, p, a, b)."""
    for n in prange(positions.shape[0]):
        _store(n, positions, actions, p, out_pos, out_int, out_float)


@njit(cache=True, error_model="numpy")
def run_batch_serial(positions, actions, p, out_pos, out_int, out_float):
    """run_batch on the calling thread: small batches skip the thread pool's start-up cost."""
    for n in range(positions.shape[0]):
        _store(n, positions, actions, p, out_pos, out_int, out_float)


@njit(cache=True, error_model="numpy")
def check_positions(positions, p, tol):
    """Validate (N, 4, 2) ball centres: (code, shot, ball, other ball); code ERR_OK if fine."""
    R, W, L = p[P_R], p[P_W], p[P_L]
    for n in range(positions.shape[0]):
        for k in range(N_BALLS):
            x, y = positions[n, k, 0], positions[n, k, 1]
            if not (math.isfinite(x) and math.isfinite(y)):
                return ERR_NONFINITE, n, k, -1
            if x < R - tol or x > W - R + tol or y < R - tol or y > L - R + tol:
                return ERR_OFF_TABLE, n, k, -1
        for k in range(N_BALLS):
            for j in range(k + 1, N_BALLS):
                d = _norm(positions[n, j, 0] - positions[n, k, 0], positions[n, j, 1] - positions[n, k, 1])
                if d < 2.0 * R - tol:
                    return ERR_OVERLAP, n, k, j
    return ERR_OK, -1, -1, -1


@njit(cache=True, error_model="numpy")
def check_actions(actions):
    """Validate (N, 4) actions (theta, p, a, b): (code, row, column); code ERR_OK if fine."""
    for n in range(actions.shape[0]):
        for k in range(4):
            if not math.isfinite(actions[n, k]):
                return ERR_ACTION_NONFINITE, n, k
        if not 0.0 <= actions[n, 1] <= 1.0:
            return ERR_POWER, n, 1
        for k in (2, 3):
            if not -1.0 <= actions[n, k] <= 1.0:
                return ERR_TIP, n, k
    return ERR_OK, -1, -1


@njit(cache=True, error_model="numpy")
def action_to_cue(theta, power, a, b, p):
    """The action convention (see api.py): (theta, p, a, b) -> (V0 m/s, phi rad, a, b in R)."""
    phi = theta % (2.0 * math.pi)
    scale = p[P_MAX_ENGLISH] / max(_norm(a, b), 1.0)
    return power * p[P_CUE_V_MAX], phi, a * scale, b * scale


@njit(cache=True, error_model="numpy")
def actions_to_cue(actions, p):
    out = np.empty_like(actions)
    for n in range(actions.shape[0]):
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = action_to_cue(
            actions[n, 0], actions[n, 1], actions[n, 2], actions[n, 3], p)
    return out


@njit(cache=True, error_model="numpy", inline="always")
def run_action(positions, action, p, record):
    """run_shot for one validated (theta, p, a, b) action."""
    V0, phi, a, b = action_to_cue(action[0], action[1], action[2], action[3], p)
    return run_shot(positions, V0, phi, a, b, p, record)


@njit(cache=True, error_model="numpy")
def checked_shot(positions, action, p, tol):
    """Validate one (4, 2) rack and (4,) action, then simulate it with the event log.

    One compiled call for the whole single-shot path. Returns (ok, run_action's result); on
    invalid input ok is False and a shot without a cue speed stands in (the caller builds the
    message). ``ok`` is also the log flag: a runtime value, so this compiles one event loop.
    """
    ok = check_positions(positions.reshape(1, N_BALLS, 2), p, tol)[0] == ERR_OK
    ok = ok and check_actions(action.reshape(1, 4))[0] == ERR_OK
    V0, phi, a, b = action_to_cue(action[0], action[1], action[2], action[3], p) if ok else (0.0, 0.0, 0.0, 0.0)
    return ok, run_shot(positions, V0, phi, a, b, p, ok)
