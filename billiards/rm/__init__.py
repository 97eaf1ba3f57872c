"""Learned reward model ``V_rm(s, a) ~ P(score = 1 | s, a)`` from random offline shots.

* :mod:`billiards.rm.data`: generate the resumable, deterministic memmapped data set;
* :mod:`billiards.rm.model`: the input features (:func:`rm_inputs`), the MLP and its files;
* :mod:`billiards.rm.train`: training and held-out evaluation (log loss, AUC, calibration).

Command line: ``python -m billiards.rm generate ...`` and ``python -m billiards.rm train ...``.
"""

from .data import DatasetError, chunk_rows, draw_chunk, generate, load_dataset, n_chunks, read_meta
from .model import N_FEATURES, RewardModel, RewardModelError, load_model, rm_inputs, save_model
from .train import auc, average_ranks, calibration_table, expected_calibration_error, log_loss, train_rm

__all__ = [
    "DatasetError", "chunk_rows", "draw_chunk", "generate", "load_dataset", "n_chunks", "read_meta",
    "N_FEATURES", "RewardModel", "RewardModelError", "load_model", "rm_inputs", "save_model",
    "auc", "average_ranks", "calibration_table", "expected_calibration_error", "log_loss", "train_rm",
]
