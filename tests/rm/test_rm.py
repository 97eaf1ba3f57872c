"""The reward-model package: features, model files, the resumable data set, metrics, training."""

from __future__ import annotations

import json
import math

import numba
import numpy as np
import pytest
import torch

from billiards.files import SEAL_KEY, save_tagged

from billiards.physics import DEFAULT_PARAMS, PRESETS, canonical_rack, simulate_batch
from billiards.rm import (
    N_FEATURES,
    DatasetError,
    RewardModel,
    RewardModelError,
    auc,
    average_ranks,
    calibration_table,
    chunk_rows,
    draw_chunk,
    generate,
    load_dataset,
    load_model,
    log_loss,
    read_meta,
    rm_inputs,
    save_model,
    train_rm,
)
from billiards.rm.__main__ import main

N, SEED, CHUNK = 3000, 7, 512  # 6 chunks, the last one partial (440 rows)
FILES = ("positions.npy", "actions.npy", "score.npy", "foul.npy")


@pytest.fixture(autouse=True)
def _light_threads():
    """Keep torch and numba on one thread (the machine is shared)."""
    torch_threads, numba_threads = torch.get_num_threads(), numba.get_num_threads()
    torch.set_num_threads(1)
    numba.set_num_threads(1)
    yield
    torch.set_num_threads(torch_threads)
    numba.set_num_threads(numba_threads)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """A small finished data set, generated in one uninterrupted call."""
    out = tmp_path_factory.mktemp("rm") / "full"
    meta = generate(out, n=N, seed=SEED, chunk=CHUNK, progress=False, threads=1)
    return out, meta


def file_bytes(directory) -> dict[str, bytes]:
    return {name: (directory / name).read_bytes() for name in FILES}


# ----------------------------------------------------------------------------- features and model


def test_rm_inputs_values_and_shapes():
    P = PRESETS["international"]
    w, l = P.table_width, P.table_length
    rack = canonical_rack(P)  # white (w - 0.2, l/4), yellow (0.2, l/4), reds (w/2, l/4), (w/2, 3l/4)
    x = rm_inputs(rack, np.array([math.pi / 2, 0.25, 0.2, -0.3]), P)
    assert x.shape == (N_FEATURES,) and x.dtype == np.float32
    expected = [
        2 * (w - 0.2) / w - 1, -0.5, 2 * 0.2 / w - 1, -0.5, 0.0, -0.5, 0.0, 0.5,
        0.0, 1.0, -0.5, 0.2, -0.3,
    ]
    np.testing.assert_allclose(x, expected, atol=1e-7)

    corners = np.array([[0.0, 0.0], [w, l], [0.0, l], [w, 0.0]])
    np.testing.assert_allclose(rm_inputs(corners, [0, 0, 0, 0], P)[:8], [-1, -1, 1, 1, -1, 1, 1, -1])
    np.testing.assert_allclose(rm_inputs(corners, [0, 1, 0, 0], P)[8:11], [1, 0, 1])
    # the default table scales by its own size
    K = DEFAULT_PARAMS
    kc = np.array([[0.0, 0.0], [K.table_width, K.table_length], [0.0, K.table_length], [K.table_width, 0.0]])
    np.testing.assert_allclose(rm_inputs(kc, [0, 0, 0, 0])[:8], [-1, -1, 1, 1, -1, 1, 1, -1])

    # leading axes broadcast: one rack against many actions, many racks against one action
    assert rm_inputs(rack, np.zeros((3, 4))).shape == (3, 13)
    assert rm_inputs(np.stack([rack] * 5), [0, 0, 0, 0]).shape == (5, 13)
    assert rm_inputs(np.zeros((2, 3, 4, 2)), np.zeros((2, 3, 4))).shape == (2, 3, 13)
    with pytest.raises(ValueError, match="positions"):
        rm_inputs(np.zeros((4, 3)), [0, 0, 0, 0])
    with pytest.raises(ValueError, match="actions"):
        rm_inputs(rack, [0, 0, 0])


def test_reward_model_prob_matches_forward():
    torch.manual_seed(0)
    model = RewardModel(hidden=(16, 8))
    rng = np.random.default_rng(0)
    positions, actions = rng.random((7, 4, 2)), rng.random((7, 4))
    x = torch.from_numpy(rm_inputs(positions, actions))
    assert model(x).shape == (7,)
    p = model.prob(positions, actions, batch_size=3)
    assert p.dtype == np.float64 and p.shape == (7,)
    np.testing.assert_allclose(p, torch.sigmoid(model(x)).detach().numpy(), rtol=1e-6)
    assert model.prob(positions[0], actions[:2]).shape == (2,)


def test_save_load_round_trip(tmp_path):
    torch.manual_seed(0)
    model = RewardModel(hidden=(8, 4, 4))
    path = save_model(tmp_path / "sub" / "m.pt", model, {"auc": np.float64(0.7), "rows": np.int64(3)})
    assert not list(path.parent.glob("*.tmp"))
    loaded = load_model(path)
    assert loaded.hidden == (8, 4, 4) and not loaded.training
    assert {k: loaded.meta[k] for k in ("auc", "rows")} == {"auc": 0.7, "rows": 3}
    assert loaded.meta["physics"] == "korean_medium" and loaded.params == model.params == DEFAULT_PARAMS
    rack, action = canonical_rack(), np.array([0.3, 0.5, 0.1, -0.2])
    assert loaded.prob(rack, action) == model.prob(rack, action)
    # the table the inputs are scaled to travels with the file
    model.params = PRESETS["international"]
    again = load_model(save_model(tmp_path / "intl.pt", model))
    assert again.params == PRESETS["international"] and again.prob(rack, action) == model.prob(rack, action)
    assert again.prob(rack, action) != loaded.prob(rack, action)


def test_load_model_rejects_bad_files(tmp_path):
    torch.manual_seed(0)
    good = save_model(tmp_path / "good.pt", RewardModel(hidden=(8,)), {})
    cases = {"missing.pt": None, "empty.pt": b"", "garbage.pt": b"not a torch file at all",
             "truncated.pt": good.read_bytes()[:100]}
    for name, content in cases.items():
        if content is not None:
            (tmp_path / name).write_bytes(content)
    torch.save({"something": 1}, tmp_path / "other.pt")
    payload = torch.load(good, weights_only=True)
    save_tagged(tmp_path / "mismatch.pt", {**{k: v for k, v in payload.items() if k != SEAL_KEY}, "hidden": [16]})
    for name in [*cases, "other.pt", "mismatch.pt"]:
        with pytest.raises(RewardModelError, match=name):
            load_model(tmp_path / name)
    assert issubclass(RewardModelError, ValueError)


# ----------------------------------------------------------------------------- data set


def test_generation_is_deterministic_per_seed(dataset, tmp_path):
    full, meta = dataset
    assert meta["finished"] and meta["chunks_done"] == meta["n_chunks"] == 6 and meta["rows_done"] == N
    assert meta["session_rows"] == N and meta["shots_per_s"] > 0 and meta["git_commit"]
    generate(tmp_path / "again", n=N, seed=SEED, chunk=CHUNK, progress=False)
    assert file_bytes(tmp_path / "again") == file_bytes(full)
    generate(tmp_path / "other", n=N, seed=SEED + 1, chunk=CHUNK, progress=False)
    other = file_bytes(tmp_path / "other")
    assert all(other[name] != data for name, data in file_bytes(full).items() if name != "foul.npy")


def test_interrupted_generation_resumes_bit_for_bit(dataset, tmp_path):
    full, _ = dataset
    out = tmp_path / "resumed"
    meta = generate(out, n=N, seed=SEED, chunk=CHUNK, progress=False, max_chunks=2)
    assert meta["chunks_done"] == 2 and not meta["finished"]
    with pytest.raises(DatasetError, match="unfinished"):
        load_dataset(out)
    # a process killed while writing chunk 2 leaves garbage in rows past chunks_done
    start, _ = chunk_rows(2, N, CHUNK)
    for name in FILES:
        arr = np.lib.format.open_memmap(out / name, mode="r+")
        arr[start:] = 1
        arr.flush()
        del arr
    assert generate(out, n=N, seed=SEED, chunk=CHUNK, progress=False, max_chunks=1)["chunks_done"] == 3
    meta = generate(out, n=N, seed=SEED, chunk=CHUNK, progress=False)
    assert meta["finished"] and meta["session_rows"] == N - chunk_rows(3, N, CHUNK)[0]
    assert [s["chunks"] for s in read_meta(out)["sessions"]] == [[0, 2], [2, 3], [3, 6]]
    assert file_bytes(out) == file_bytes(full)

    # killed after meta.json was written but before every array file existed
    early = tmp_path / "early"
    assert generate(early, n=N, seed=SEED, chunk=CHUNK, progress=False, max_chunks=0)["chunks_done"] == 0
    (early / "actions.npy").unlink()
    generate(early, n=N, seed=SEED, chunk=CHUNK, progress=False)
    assert file_bytes(early) == file_bytes(full)


def test_finished_dataset_is_a_noop_and_mismatch_raises(dataset, tmp_path):
    full, _ = dataset
    before = {name: (full / name).stat().st_mtime_ns for name in (*FILES, "meta.json")}
    meta = generate(full, n=N, seed=SEED, chunk=CHUNK, progress=False)
    assert meta["session_rows"] == 0 and meta["finished"]
    assert {name: (full / name).stat().st_mtime_ns for name in before} == before
    for n, seed, chunk in [(N, SEED + 1, CHUNK), (N + 1, SEED, CHUNK), (N, SEED, CHUNK * 2)]:
        with pytest.raises(DatasetError, match="already holds a data set"):
            generate(full, n=n, seed=seed, chunk=chunk, progress=False)
    with pytest.raises(SystemExit, match="^Error: .*already holds a data set"):
        main(["generate", "--out", str(full), "--n", str(N), "--seed", "0", "--no-progress"])
    # arrays without meta.json are never overwritten
    (tmp_path / "score.npy").write_bytes(b"x")
    with pytest.raises(DatasetError, match="no meta.json"):
        generate(tmp_path, n=10, seed=0, chunk=5, progress=False)
    with pytest.raises(DatasetError, match="not found"):
        load_dataset(tmp_path / "nothing")


def test_truncated_array_file_is_regenerated_not_zero_filled(dataset, tmp_path, capsys):
    """A finished data set whose positions.npy lost its tail (e.g. an interrupted copy):
    load_dataset refuses it, and re-running generate goes back to the last chunk every file
    holds and redraws the rest, ending bit-identical to the uninterrupted set."""
    import shutil

    full, _ = dataset
    out = tmp_path / "copy"
    shutil.copytree(full, out)
    path = out / "positions.npy"
    header = len(path.read_bytes()) - N * 4 * 2 * 4
    cut = chunk_rows(3, N, CHUNK)[0] + 100  # 100 rows into chunk 3: chunks 0-2 are intact
    with path.open("r+b") as f:
        f.truncate(header + cut * 4 * 2 * 4)
    with pytest.raises(DatasetError, match=r"positions.npy is truncated: it holds 1,636 of 3,000 rows.*regenerates"):
        load_dataset(out)
    with pytest.warns(UserWarning, match=r"positions.npy \(1,636 rows\) truncated.*regenerating from chunk 3 of 6"):
        main(["generate", "--out", str(out), "--n", str(N), "--seed", str(SEED), "--chunk", str(CHUNK), "--no-progress"])
    assert "3,000 of 3,000 shots (6/6 chunks, finished)" in capsys.readouterr().out
    assert file_bytes(out) == file_bytes(full)  # redrawn, not zeros
    assert read_meta(out)["sessions"][-1]["chunks"] == [3, 6]
    load_dataset(out)

    # a file cut inside its header, or longer than the data set, is refused outright
    (out / "score.npy").write_bytes((full / "score.npy").read_bytes()[:20])
    with pytest.raises(DatasetError, match="cannot open .*score.npy"):
        generate(out, n=N, seed=SEED, chunk=CHUNK, progress=False)
    (out / "score.npy").write_bytes((full / "score.npy").read_bytes() + b"\0" * 7)
    with pytest.raises(DatasetError, match="score.npy is 3,135 bytes, longer than its 3,000 rows"):
        generate(out, n=N, seed=SEED, chunk=CHUNK, progress=False)


def test_stored_rows_match_the_draw_and_the_simulator(dataset):
    full, _ = dataset
    data = load_dataset(full)
    assert not data["score"].flags.writeable
    assert data["positions"].shape == (N, 4, 2) and data["positions"].dtype == np.float32
    assert data["actions"].shape == (N, 4) and data["score"].dtype == np.uint8
    for i in (0, 5):  # first chunk and the partial last one
        start, stop = chunk_rows(i, N, CHUNK)
        positions, actions = draw_chunk(SEED, i, stop - start)  # the float64 draw that was simulated
        np.testing.assert_array_equal(data["positions"][start:stop], positions.astype(np.float32))
        np.testing.assert_array_equal(data["actions"][start:stop], actions.astype(np.float32))
        # re-simulate every score, a few fouls and a few other rows of the chunk
        score, foul = data["score"][start:stop], data["foul"][start:stop]
        rows = np.unique(np.r_[np.flatnonzero(score), np.flatnonzero(foul)[:10], np.arange(0, stop - start, 37)])
        result = simulate_batch(positions[rows], actions[rows])
        np.testing.assert_array_equal(score[rows], result.score)
        np.testing.assert_array_equal(foul[rows], result.foul)
    assert 0 < data["score"].mean() < 0.05 and 0.05 < data["foul"].mean() < 0.3


# ----------------------------------------------------------------------------- metrics


def test_auc_on_hand_computed_examples():
    assert auc([0.1, 0.4, 0.35, 0.8], [0, 0, 1, 1]) == 0.75  # 3 of 4 pairs ordered
    assert auc([0.2, 0.5, 0.5, 0.9], [0, 1, 0, 1]) == 0.875  # (1 + 0.5 + 1 + 1) / 4, one tie
    assert auc([0.5, 0.5, 0.5, 0.5], [0, 1, 0, 1]) == 0.5  # all tied
    assert auc([1, 2, 3], [1, 0, 0]) == 0.0 and auc([1, 2, 3], [0, 0, 1]) == 1.0
    assert math.isnan(auc([0.1, 0.2], [1, 1]))
    np.testing.assert_array_equal(average_ranks([3, 1, 3, 2, 3]), [4, 1, 4, 2, 4])
    # against the brute-force pair count, with many ties
    rng = np.random.default_rng(0)
    s, y = rng.integers(0, 5, 300), rng.random(300) < 0.3
    diff = s[y][:, None] - s[~y][None, :]
    assert auc(s, y) == pytest.approx(((diff > 0) + 0.5 * (diff == 0)).mean(), abs=1e-12)


def test_log_loss_and_calibration_table():
    assert log_loss([0, 1], [0.0, 0.0]) == pytest.approx(math.log(2))
    z, y = np.array([-3.0, 0.5, 2.0]), np.array([0, 1, 1])
    p = 1 / (1 + np.exp(-z))
    assert log_loss(y, z) == pytest.approx(-np.mean(y * np.log(p) + (1 - y) * np.log(1 - p)))
    assert log_loss([1], [800.0]) == 0.0 and math.isfinite(log_loss([0], [800.0]))
    probs = np.linspace(0.01, 0.5, 1000)
    table = calibration_table(probs, np.arange(1000) % 2, bins=10)
    assert [b["count"] for b in table] == [100] * 10
    assert all(b["observed"] == 0.5 for b in table)
    assert table[0]["p_low"] == 0.01 and table[-1]["p_high"] == 0.5
    assert all(a["mean_pred"] < b["mean_pred"] for a, b in zip(table, table[1:]))


# ----------------------------------------------------------------------------- training


@pytest.mark.slow
def test_tiny_training_beats_the_base_rate(tmp_path):
    data = tmp_path / "data"
    generate(data, n=24_000, seed=0, chunk=4096, progress=False, threads=1)
    out = tmp_path / "model" / "rm.pt"
    m = train_rm(data, out, hidden=(64, 64), epochs=2, batch_size=256, lr=3e-3, holdout=0.2, progress=False)
    assert m["train_rows"] == 19_200 and m["heldout_rows"] == 4800 and m["rows"] == 24_000
    assert m["heldout_log_loss"] < m["base_rate_log_loss"]
    assert 0.6 < m["auc"] <= 1.0
    assert len(m["calibration"]) == 10 and sum(b["count"] for b in m["calibration"]) == 4800
    assert json.loads((out.parent / "metrics.json").read_text())["heldout_log_loss"] == m["heldout_log_loss"]
    assert (out.parent / "calibration.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    model = load_model(out)
    assert model.hidden == (64, 64) and model.meta["auc"] == m["auc"] and model.meta["rows"] == 24_000
    p = model.prob(np.asarray(load_dataset(data)["positions"][:5]), np.asarray(load_dataset(data)["actions"][:5]))
    assert p.shape == (5,) and ((0 < p) & (p < 1)).all()
    assert torch.get_num_threads() == 1  # restored


def test_train_cli_errors(tmp_path, dataset):
    with pytest.raises(SystemExit, match="^Error: .*not found"):
        main(["train", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "m.pt"), "--no-progress"])
    full, _ = dataset
    with pytest.raises(SystemExit, match="^Error: .*holdout"):
        main(["train", "--data", str(full), "--out", str(tmp_path / "m.pt"), "--holdout", "1.5", "--no-progress"])
