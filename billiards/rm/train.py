"""Fit the reward model on an offline data set (:mod:`billiards.rm.data`) and evaluate it.

The last ``holdout`` fraction of the rows is held out. Training streams chunk-sized blocks of
rows from the memmaps (blocks in a fresh random order every epoch, rows shuffled within a
block; the rows are i.i.d. shots, so this is as good as a global shuffle), with
binary cross-entropy on the logit and Adam.

Evaluation on the held-out rows: log loss, the log loss of the constant predictor at the
training set's positive rate (base rate), AUC (:func:`auc`, Mann–Whitney with tie-averaged
ranks), the positive rate and a 10-bin calibration table (:func:`calibration_table`).
Outputs next to the model file: ``metrics.json`` and ``calibration.png``.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Sequence

import numpy as np
import torch
from torch.nn import functional as F
from tqdm import tqdm

from billiards.files import atomic_write_text, display_path
from billiards.provenance import git_commit

from billiards.physics.config import physics_record, recorded_physics

from .data import load_dataset, read_meta
from .model import DEFAULT_HIDDEN, RewardModel, rm_inputs, save_model

METRICS_FILE = "metrics.json"
PLOT_FILE = "calibration.png"
EVAL_BATCH = 65_536


# ----------------------------------------------------------------------------- metrics


def log_loss(labels, logits) -> float:
    """Mean binary cross-entropy (nats) of labels in {0, 1} under sigmoid(logits), computed
    stably as ``log(1 + e^z) - y z``."""
    y = np.asarray(labels, dtype=np.float64)
    z = np.asarray(logits, dtype=np.float64)
    return float(np.mean(np.logaddexp(0.0, z) - y * z))


def average_ranks(x) -> np.ndarray:
    """1-based ranks of x, float64, tied values sharing the mean of their ranks."""
    x = np.asarray(x).ravel()
    order = np.argsort(x, kind="mergesort")
    sorted_x = x[order]
    starts = np.flatnonzero(np.r_[True, sorted_x[1:] != sorted_x[:-1]])
    stops = np.r_[starts[1:], x.size]
    ranks = np.empty(x.size, dtype=np.float64)
    ranks[order] = np.repeat((starts + 1 + stops) / 2.0, stops - starts)
    return ranks


def auc(scores, labels) -> float:
    """Area under the ROC curve: P(score of a random positive > that of a random negative),
    ties counting 1/2 (the Mann–Whitney U statistic over n_pos * n_neg). NaN if there are no
    positives or no negatives."""
    scores = np.asarray(scores, dtype=np.float64).ravel()
    labels = np.asarray(labels).ravel().astype(bool)
    if scores.shape != labels.shape:
        raise ValueError(f"scores and labels must have the same length, got {scores.size} and {labels.size}")
    if np.isnan(scores).any():
        raise ValueError("scores contain NaN")
    n_pos = int(labels.sum())
    n_neg = labels.size - n_pos
    if n_pos == 0 or n_neg == 0:
        return math.nan
    rank_sum = average_ranks(scores)[labels].sum()
    return float((rank_sum - n_pos * (n_pos + 1) / 2.0) / (n_pos * n_neg))


def calibration_table(probs, labels, bins: int = 10) -> list[dict]:
    """Equal-count bins of the predicted probability (sorted, split into ``bins`` parts; the
    positive rate of random shots is low, so equal-width bins would leave most of them empty).

    One dict per bin: ``p_low``, ``p_high`` (range of predictions), ``mean_pred``,
    ``observed`` (frequency of label 1) and ``count``.
    """
    probs = np.asarray(probs, dtype=np.float64).ravel()
    labels = np.asarray(labels, dtype=np.float64).ravel()
    order = np.argsort(probs, kind="mergesort")
    table = []
    for part in np.array_split(order, bins):
        if part.size == 0:
            continue
        p, y = probs[part], labels[part]
        table.append({
            "p_low": float(p.min()),
            "p_high": float(p.max()),
            "mean_pred": float(p.mean()),
            "observed": float(y.mean()),
            "count": int(part.size),
        })
    return table


def expected_calibration_error(table: list[dict]) -> float:
    """Count-weighted mean |mean_pred - observed| over the bins of a calibration table."""
    total = sum(b["count"] for b in table)
    return float(sum(b["count"] * abs(b["mean_pred"] - b["observed"]) for b in table) / total)


def plot_calibration(table: list[dict], path, title: str = "") -> Path:
    """Reliability diagram (log–log, observed vs mean predicted per bin, with binomial
    standard errors; bins without a positive sit on the bottom edge) written to a PNG
    (Agg, no pyplot state)."""
    from matplotlib.figure import Figure

    path = Path(path)
    pred = np.array([b["mean_pred"] for b in table])
    obs = np.array([b["observed"] for b in table])
    count = np.array([b["count"] for b in table])
    err = np.sqrt(np.clip(obs * (1 - obs), 0, None) / np.maximum(count, 1))
    fig = Figure(figsize=(5.5, 5), dpi=120)
    ax = fig.add_subplot()
    floor = max(1e-5, 0.5 * min(pred.min(), obs[obs > 0].min() if (obs > 0).any() else pred.min()))
    top = min(1.0, 2.0 * max(pred.max(), obs.max()))
    ax.plot([floor, top], [floor, top], color="0.6", lw=1, ls="--", label="perfect calibration")
    ax.errorbar(pred, np.maximum(obs, floor), yerr=err, fmt="o-", ms=4, capsize=2, label="held-out bins (equal count)")
    zero = obs == 0
    if zero.any():  # no positive in the bin: drawn on the bottom edge
        ax.plot(pred[zero], np.full(zero.sum(), floor), "v", color="C3", ms=7, label="bin without a score")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(floor, top)
    ax.set_ylim(floor, top)
    ax.set_xlabel("mean predicted P(score)")
    ax.set_ylabel("observed score frequency")
    ax.set_title(title or "reward model calibration", fontsize=8)
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


# ----------------------------------------------------------------------------- training


def _none_if_nan(x: float) -> float | None:
    return None if math.isnan(x) else x


def _block(data: dict, start: int, stop: int, params) -> tuple[np.ndarray, np.ndarray]:
    """Features (rows, 13) float32 and labels (rows,) float32 of rows [start, stop) of a data
    set on the table ``params``."""
    x = rm_inputs(data["positions"][start:stop], data["actions"][start:stop], params)
    y = np.asarray(data["score"][start:stop], dtype=np.float32)
    return x, y


@torch.no_grad()
def _logits(model: RewardModel, x: np.ndarray) -> np.ndarray:
    out = np.empty(x.shape[0], dtype=np.float64)
    for s in range(0, x.shape[0], EVAL_BATCH):
        out[s:s + EVAL_BATCH] = model(torch.from_numpy(x[s:s + EVAL_BATCH])).double().numpy()
    return out


def train_rm(
    data_dir,
    out_path,
    hidden: Sequence[int] = DEFAULT_HIDDEN,
    epochs: int = 2,
    batch_size: int = 4096,
    lr: float = 1e-3,
    holdout: float = 0.02,
    seed: int = 0,
    max_rows: int | None = None,
    threads: int = 1,
    progress: bool = True,
) -> dict:
    """Train a :class:`RewardModel` on the first rows of data_dir and save it to out_path.

    Uses the first ``max_rows`` rows (all by default), of which the last ``holdout`` fraction
    is held out. Writes the model (:func:`save_model`, meta = the metrics), ``metrics.json``
    and ``calibration.png`` in out_path's directory; returns the metrics dict.
    ``threads``: torch intra-op threads during training (restored afterwards).
    """
    if epochs < 1 or batch_size < 1 or not lr > 0 or threads < 1:
        raise ValueError(f"need epochs >= 1, batch_size >= 1, lr > 0, threads >= 1; got {epochs}, {batch_size}, {lr}, {threads}")
    if not 0.0 < holdout < 1.0:
        raise ValueError(f"holdout must lie in (0, 1), got {holdout!r}")
    data_dir, out_path = Path(data_dir), Path(out_path)
    data = load_dataset(data_dir)
    meta = read_meta(data_dir)
    block = int(meta["chunk"])
    physics = recorded_physics(meta["physics_params"])
    rows = data["score"].shape[0] if max_rows is None else min(int(max_rows), data["score"].shape[0])
    n_hold = int(round(rows * holdout))
    n_train = rows - n_hold
    if n_hold < 1 or n_train < 1:
        raise ValueError(f"{rows} rows with holdout {holdout} leave {n_train} training and {n_hold} held-out rows; need >= 1 of each")

    previous_threads = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            model = RewardModel(hidden)
        model.params = physics
        rng = np.random.default_rng(seed)
        optimizer = torch.optim.Adam(model.parameters(), lr=lr)
        x_hold, y_hold = _block(data, n_train, rows, physics)
        base_rate = float(np.asarray(data["score"][:n_train], dtype=np.float64).mean())
        starts = np.arange(0, n_train, block)

        history = []
        t0 = time.perf_counter()
        bar = tqdm(total=epochs * n_train, unit="shot", unit_scale=True, dynamic_ncols=True, disable=not progress, desc="train")
        for epoch in range(epochs):
            model.train()
            loss_sum, seen = 0.0, 0
            for start in rng.permutation(starts):
                x, y = _block(data, int(start), min(n_train, int(start) + block), physics)
                perm = rng.permutation(x.shape[0])
                x, y = torch.from_numpy(x[perm]), torch.from_numpy(y[perm])
                for s in range(0, x.shape[0], batch_size):
                    xb, yb = x[s:s + batch_size], y[s:s + batch_size]
                    loss = F.binary_cross_entropy_with_logits(model(xb), yb)
                    optimizer.zero_grad(set_to_none=True)
                    loss.backward()
                    optimizer.step()
                    loss_sum += float(loss.detach()) * xb.shape[0]
                    seen += xb.shape[0]
                bar.update(x.shape[0])
                bar.set_postfix(epoch=epoch + 1, loss=f"{loss_sum / seen:.5f}", refresh=False)
            model.eval()
            history.append({
                "epoch": epoch + 1,
                "train_log_loss": loss_sum / seen,
                "heldout_log_loss": log_loss(y_hold, _logits(model, x_hold)),
                "seconds": time.perf_counter() - t0,
            })
        bar.close()
        train_seconds = time.perf_counter() - t0
        logits = _logits(model, x_hold)
    finally:
        torch.set_num_threads(previous_threads)

    probs = 1.0 / (1.0 + np.exp(-logits))
    table = calibration_table(probs, y_hold)
    base_logit = math.log(base_rate / (1.0 - base_rate)) if 0.0 < base_rate < 1.0 else math.copysign(50.0, base_rate - 0.5)
    metrics = {
        "heldout_log_loss": log_loss(y_hold, logits),
        "base_rate_log_loss": log_loss(y_hold, np.full_like(logits, base_logit)),
        "auc": _none_if_nan(auc(probs, y_hold)),  # None if the held-out set has one class only
        "heldout_positive_rate": float(y_hold.mean()),
        "train_positive_rate": base_rate,
        "heldout_mean_pred": float(probs.mean()),
        "ece": expected_calibration_error(table),
        "calibration": table,
        "history": history,
        "rows": rows,
        "train_rows": n_train,
        "heldout_rows": n_hold,
        "data_dir": display_path(data_dir),
        **physics_record(physics),
        "hidden": list(model.hidden),
        "epochs": epochs,
        "batch_size": batch_size,
        "lr": lr,
        "holdout": holdout,
        "seed": seed,
        "threads": threads,
        "train_seconds": train_seconds,
        "train_rows_per_s": epochs * n_train / train_seconds,
        "git_commit": git_commit(),
    }
    metrics["log_loss_improvement"] = 1.0 - metrics["heldout_log_loss"] / metrics["base_rate_log_loss"]
    save_model(out_path, model, metrics)
    atomic_write_text(out_path.parent / METRICS_FILE, json.dumps(metrics, indent=2) + "\n")
    plot_calibration(
        table, out_path.parent / PLOT_FILE,
        title=f"{out_path.name}: held-out log loss {metrics['heldout_log_loss']:.4f} "
              f"(base rate {metrics['base_rate_log_loss']:.4f}), AUC {metrics['auc']:.3f}",
    )
    return metrics
