"""The table value's model: its input (:func:`table_features`) and the network
(:class:`TableValue`), what the searches load and price leaves with. How a value is made (the
training data, the labelling searches, ``python -m billiards.search.value``) is
:mod:`billiards.search.value`'s; the model is apart so that a search loads it without the code
that trains it (which itself plays the robust search)."""

from __future__ import annotations

import numpy as np

from billiards import numerics
from billiards.physics import DEFAULT_PARAMS, PhysicsParams
from billiards.physics.core import RED1, RED2, WHITE, YELLOW

from .ranker import TaggedMLP

FORMAT = "billiards-table-value-1"
N_FEATURES = 20


class ValueFileError(ValueError):
    """A table-value file that is missing, corrupt or not a table value."""


def table_features(positions: np.ndarray, levels, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """The value's input for tables ``positions`` (..., 4, 2) (the shooter's cue ball in slot
    0) at noise ``levels`` (broadcast to ...): (..., :data:`N_FEATURES`) float32.

    The table's two mirror symmetries are folded away (the cue ball is reflected into the
    lower-left quarter) and the reds are ordered nearer / farther from the cue ball. Per ball
    (cue, yellow, near red, far red) its centre as fractions of the table and its distance to
    the nearest rail; the six centre distances; the level and its square.
    """
    pos = np.array(positions, dtype=np.float64)
    W, L = params.table_width, params.table_length
    flip_x = pos[..., WHITE, 0] > W / 2
    flip_y = pos[..., WHITE, 1] > L / 2
    pos[..., 0] = np.where(flip_x[..., None], W - pos[..., 0], pos[..., 0])
    pos[..., 1] = np.where(flip_y[..., None], L - pos[..., 1], pos[..., 1])
    d = lambda a, b: np.hypot(pos[..., a, 0] - pos[..., b, 0], pos[..., a, 1] - pos[..., b, 1])
    swap = d(WHITE, RED2) < d(WHITE, RED1)
    near = np.where(swap[..., None], pos[..., RED2, :], pos[..., RED1, :])
    far = np.where(swap[..., None], pos[..., RED1, :], pos[..., RED2, :])
    balls = (pos[..., WHITE, :], pos[..., YELLOW, :], near, far)
    cols = []
    for p in balls:
        cols += [p[..., 0] / W, p[..., 1] / L,
                 np.minimum.reduce([p[..., 0], W - p[..., 0], p[..., 1], L - p[..., 1]]) / W]
    for i in range(4):
        for j in range(i + 1, 4):
            cols.append(np.hypot(balls[i][..., 0] - balls[j][..., 0], balls[i][..., 1] - balls[j][..., 1]) / L)
    level = np.broadcast_to(np.asarray(levels, dtype=np.float64), pos.shape[:-2])
    cols += [level, level * level]
    out = np.stack(cols, axis=-1).astype(np.float32)
    assert out.shape[-1] == N_FEATURES
    return out


class TableValue(TaggedMLP):
    """The table value: a :class:`~billiards.search.ranker.TaggedMLP` over
    :func:`table_features`; :meth:`predict` is the value (the module docstring says which).
    ``meta`` records the table (``physics_params``), the base noise (``noise``: level 1), the
    training command, its held-out check and its cost."""

    FORMAT = FORMAT
    N_FEATURES = N_FEATURES
    ERROR = ValueFileError
    WHAT = "table value"

    def predict(self, positions: np.ndarray, levels, params: PhysicsParams | None = None) -> np.ndarray:
        """The value (...,) float64 in (0, 1) of tables (..., 4, 2) at noise ``levels``: P(the next
        shot scores), or the normalised discounted run for a value made with a discount."""
        logit = self.logits(table_features(positions, levels, params or self.params)).astype(np.float64)
        return 1.0 / (1.0 + numerics.exp(-logit))


__all__ = ["FORMAT", "N_FEATURES", "TableValue", "ValueFileError", "table_features"]
