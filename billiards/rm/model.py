"""The reward model: an MLP estimate of ``V_rm(s, a) = P(score = 1 | s, a)`` for one shot.

* :func:`rm_inputs` is THE single definition of the model's 13 input features; training,
  inference and the env transform all call it.
* :class:`RewardModel` maps features to one logit; :meth:`RewardModel.prob` is the numpy
  in, numpy out probability.
* :func:`save_model` / :func:`load_model` store the weights, the layer sizes and a metadata
  dict in one ``torch.save`` file (written atomically).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch
from torch import nn

from billiards.files import save_tagged
from billiards.physics import DEFAULT_PARAMS, PhysicsParams
from billiards import compat
from billiards.physics.config import physics_record, recorded_physics

N_FEATURES = 13  # 8 normalised coordinates + cos(theta), sin(theta), 2p - 1, a, b
DEFAULT_HIDDEN = (128, 128)
FILE_FORMAT = "billiards.rm/1"  # tag stored in every saved model file


class RewardModelError(ValueError):
    """A reward-model file that is missing, empty, corrupt or incompatible."""


# ----------------------------------------------------------------------------- features


def rm_inputs(positions, actions, params: PhysicsParams = DEFAULT_PARAMS) -> np.ndarray:
    """The reward model's input features, float32 ``(..., 13)``.

    positions (..., 4, 2) ball centres in metres (white, yellow, red1, red2), actions (..., 4)
    raw ``(theta, p, a, b)``; the leading axes broadcast against each other. Features, in order:

    * ``[0:8]``  ``2 x / w - 1`` and ``2 y / l - 1`` for each ball (x, y interleaved, ball
      order), i.e. the table mapped onto [-1, 1]^2 (w, l = ``params.table_width/length``);
    * ``[8:10]`` ``cos(theta), sin(theta)`` (so theta's wrap-around is seamless);
    * ``[10]``   ``2 p - 1`` (power mapped from [0, 1] to [-1, 1]);
    * ``[11:13]`` the tip offsets ``a, b`` as given (already in [-1, 1]).
    """
    positions = np.asarray(positions, dtype=np.float64)
    actions = np.asarray(actions, dtype=np.float64)
    if positions.ndim < 2 or positions.shape[-2:] != (4, 2):
        raise ValueError(f"positions must have shape (..., 4, 2); got {positions.shape}")
    if actions.ndim < 1 or actions.shape[-1] != 4:
        raise ValueError(f"actions must have shape (..., 4) = (theta, p, a, b); got {actions.shape}")
    lead = np.broadcast_shapes(positions.shape[:-2], actions.shape[:-1])
    size = np.array([params.table_width, params.table_length])
    coords = (2.0 * positions / size - 1.0).reshape(positions.shape[:-2] + (8,))
    theta, p, a, b = np.moveaxis(actions, -1, 0)
    shot = np.stack([np.cos(theta), np.sin(theta), 2.0 * p - 1.0, a, b], axis=-1)
    out = np.empty(lead + (N_FEATURES,), dtype=np.float32)
    out[..., :8] = coords
    out[..., 8:] = shot
    return out


# ----------------------------------------------------------------------------- model


class RewardModel(nn.Module):
    """MLP ``13 -> hidden... -> 1`` with ReLU activations; outputs the score logit."""

    def __init__(self, hidden: Sequence[int] = DEFAULT_HIDDEN):
        super().__init__()
        self.hidden = tuple(int(h) for h in hidden)
        if any(h < 1 for h in self.hidden):
            raise ValueError(f"hidden layer sizes must be >= 1, got {list(hidden)}")
        layers: list[nn.Module] = []
        width = N_FEATURES
        for h in self.hidden:
            layers += [nn.Linear(width, h), nn.ReLU()]
            width = h
        layers.append(nn.Linear(width, 1))
        self.net = nn.Sequential(*layers)
        self.meta: dict[str, Any] = {}  # filled by load_model
        self.params = DEFAULT_PARAMS  # the table of its training data (load_model sets it from meta)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Features (..., 13) -> logits (...,)."""
        return self.net(x).squeeze(-1)

    @torch.no_grad()
    def prob(self, positions, actions, batch_size: int = 65_536) -> np.ndarray:
        """P(score | s, a) as float64 of the broadcast leading shape of positions (..., 4, 2)
        and actions (..., 4); evaluated in batches of ``batch_size`` rows."""
        x = rm_inputs(positions, actions, self.params)
        flat = x.reshape(-1, N_FEATURES)
        out = np.empty(flat.shape[0], dtype=np.float64)
        for start in range(0, flat.shape[0], batch_size):
            logits = self(torch.from_numpy(flat[start:start + batch_size]))
            out[start:start + batch_size] = torch.sigmoid(logits).double().numpy()
        return out.reshape(x.shape[:-1])


# ----------------------------------------------------------------------------- files


def _plain(value: Any) -> Any:
    """JSON-compatible plain Python types (numpy scalars and arrays converted)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot store {type(value).__name__} in reward-model metadata")


def save_model(path, model: RewardModel, meta: dict | None = None) -> Path:
    """Write the model (weights, layer sizes, ``meta``) to ``path`` atomically
    (:func:`billiards.files.atomic_open`). ``meta`` must be JSON-serialisable (numpy
    scalars/arrays are converted). Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": FILE_FORMAT,
        "n_features": N_FEATURES,
        "hidden": list(model.hidden),
        "state_dict": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        # the table its inputs are scaled to (metadata given by the caller may restate it)
        "meta": json.loads(json.dumps({**physics_record(model.params), **(meta or {})}, default=_plain)),
    }
    return save_tagged(path, payload)


MAX_WIDTH = 4096  # units of a hidden layer a reward-model file may declare
MAX_LAYERS = 8


def check_reward_model(payload: dict, path) -> RewardModel:
    """The one place a reward-model file's content is checked, after its seal: its keys and
    their types, the input features this code computes, the hidden sizes 1 to
    :data:`MAX_LAYERS` widths in [1, :data:`MAX_WIDTH`], the weights real and finite with the
    names and shapes of the network those sizes build (compared before anything is loaded), the
    metadata plain data (and its table, if it names one, valid). :class:`RewardModelError`
    naming the file and what is wrong; returns the model with the weights loaded."""
    from billiards.files import key_problem, plain_data_problem, shape_problem, tensor_problem

    def bad(why: str) -> RewardModelError:
        return RewardModelError(f"reward model file {path} is not a usable reward model: {why}")

    if why := key_problem(payload, {"n_features": int, "hidden": list, "state_dict": dict}):
        raise bad(why)
    if payload["n_features"] != N_FEATURES:
        raise bad(f"it expects {payload['n_features']} input features, this code computes {N_FEATURES}")
    hidden = payload["hidden"]
    if not (0 < len(hidden) <= MAX_LAYERS
            and all(isinstance(h, int) and not isinstance(h, bool) and 1 <= h <= MAX_WIDTH for h in hidden)):
        raise bad(f"hidden={hidden!r}: not 1 to {MAX_LAYERS} layer widths in [1, {MAX_WIDTH}]")
    meta = payload.get("meta") or {}
    if why := (plain_data_problem(meta, "meta") or key_problem({"meta": meta}, {"meta": dict})
               or tensor_problem(payload["state_dict"], "state_dict")):
        raise bad(why)
    model = RewardModel(hidden)
    if why := shape_problem({k: v.shape for k, v in model.state_dict().items()}, payload["state_dict"], "state_dict"):
        raise bad(why)
    model.load_state_dict(payload["state_dict"], strict=True)
    try:
        model.params = recorded_physics(compat.upgrade_artefact_meta(meta)["physics_params"])
    except (ValueError, TypeError, AttributeError) as err:
        raise bad(f"its metadata's table is not valid ({err})") from None
    model.meta = dict(meta)
    return model


def load_model(path) -> RewardModel:
    """Load a model written by :func:`save_model`, in eval mode, with its metadata in
    ``model.meta``. Raises :class:`RewardModelError` naming the path if the file is missing,
    empty, not a reward-model file, or its content is not a usable model
    (:func:`check_reward_model`)."""
    from billiards.files import load_tagged

    path = Path(path)
    payload = load_tagged(path, FILE_FORMAT, RewardModelError, "reward model")
    return check_reward_model(payload, path).eval()
