"""Korean 4-ball (sagu) carom rules, in one place.

The white (ball 0) is the player's cue ball, the yellow (ball 1) the opponent's, balls 2 and 3
the reds. For one shot of the white:

* **score** (1 point): the white contacts both reds and never the yellow;
* **foul**: the white contacts the yellow at any time (whatever else it hits);
* **miss**: neither of the above.

Exactly one of the three holds. The simulator reports which balls the white touched
(``hits``), its first contact, and its closest approach to each red; reward shaping reads
those facts through :func:`unhit_red_gap`.
"""

from __future__ import annotations

import numpy as np


def carom_outcome(hit_yellow, hit_red1, hit_red2):
    """(score, foul, miss) from what the white touched.

    Inputs are NumPy booleans (``np.bool_`` scalars or bool arrays, broadcast together); so
    are the outputs.
    """
    foul = hit_yellow
    score = hit_red1 & hit_red2 & ~hit_yellow
    miss = ~(score | foul)
    return score, foul, miss


def unhit_red_gap(hits, closest):
    """The white's closest surface gap (m) to a red it did not touch.

    hits (..., 3) = (yellow, red1, red2) booleans, closest (..., 2) gaps to red1, red2.
    If the white touched exactly one red, the gap to the other; if it touched none, the
    smaller of the two gaps; if it touched both, 0.
    """
    hits = np.asarray(hits, dtype=bool)
    closest = np.asarray(closest, dtype=np.float64)
    r1, r2 = hits[..., 1], hits[..., 2]
    gap = np.where(r1 & ~r2, closest[..., 1], np.where(r2 & ~r1, closest[..., 0], closest.min(axis=-1)))
    return np.where(r1 & r2, 0.0, gap)
