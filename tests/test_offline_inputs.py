"""The offline datasets' input checks (billiards.offline, issue #57): every numeric option has a
documented bound and a sentence beyond it; every input is checked before anything is written
(a refused agent leaves nothing, and the corrected command then works); each block is checked
against the episodes its manifest says it holds; a damaged dataset.json, a damaged block, a
missing folder, an ``--out`` that is a file or cannot be written: each one sentence
(``Error: ...``), naming the file, never its contents, and no traceback.

Most cases run on a small synthetic dataset (one block of zeros in the blocks' layout), written
here without playing."""

from __future__ import annotations

import errno
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from billiards import offline
from billiards.files import ROOT

MARK = 4242.5  # every float of the synthetic block: a sentence must never show it


def manifest_of(dataset: str = "t", agent: str = "nearest", blocks: int = 1) -> dict:
    """The manifest ``generate(dataset, "none", blocks * 1000, out, agent_spec=agent)`` writes."""
    return {"dataset_id": offline.dataset_id(dataset, "none"), "dataset": dataset, "noise": "none", "agent": agent,
            "physics": "korean_medium", "shots_per_inning": offline.SHOTS, "block": offline.BLOCK, "blocks": blocks,
            "seed": offline.DATASET_SEED, "budget": 400, "commit": "test"}


def block_arrays(manifest: dict) -> dict[str, np.ndarray]:
    """A block in the layout ``manifest`` asks for: finite floats, shots inside the action space."""
    arrays = {k: np.zeros(shape, dtype) for k, (shape, dtype) in offline.block_layout(manifest).items()}
    arrays["observations"][:] = MARK
    arrays["actions"][..., 1] = 0.5
    arrays["truncations"][:, -1] = True
    return arrays


def write_dataset(out: Path, manifest: dict | None = None, arrays: dict | None = None) -> Path:
    manifest = manifest or manifest_of()
    (out / "blocks").mkdir(parents=True)
    (out / "dataset.json").write_text(json.dumps(manifest))
    np.savez(out / "blocks" / "block00000.npz", **(block_arrays(manifest) if arrays is None else arrays))
    return out


@pytest.fixture
def dataset(tmp_path) -> Path:
    return write_dataset(tmp_path / "ds")


def snapshot(path: Path) -> dict:
    """Every file under ``path`` (or ``path`` itself) with its bytes."""
    if path.is_file():
        return {path: path.read_bytes()}
    return {p: p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()} if path.exists() else {}


def refused(call, *args, match: str, **kwargs) -> str:
    """The sentence ``call`` refuses with: a DatasetError (a SystemExit), ``Error: ...``, one line."""
    with pytest.raises(offline.DatasetError) as err:
        call(*args, **kwargs)
    text = str(err.value)
    assert isinstance(err.value, SystemExit) and text.startswith("Error: ") and "\n" not in text, text
    assert re.search(match, text), text
    return text


def test_the_synthetic_dataset_passes(dataset):
    """The cases below change one thing each in this dataset, which passes every check."""
    eps = list(offline.episodes(dataset))
    assert len(eps) == offline.BLOCK and eps[0]["observations"].shape == (offline.SHOTS + 1, 28)
    assert len(offline.checksum(dataset)) == 64


# ----------------------------------------------------------------------------- bounds


@pytest.mark.parametrize("option", list(offline.LIMITS))
def test_every_numeric_option_has_a_bound_and_a_sentence_beyond_it(option):
    lo, hi, why = offline.LIMITS[option]
    assert offline.option_problem(lo, option) is None and offline.option_problem(hi, option) is None
    assert offline.option_problem(hi + 1, option) == f"{option} must be at most {hi:,} ({why}), got {hi + 1}"
    assert offline.option_problem(lo - 1, option) == f"{option} must be at least {lo:,}, got {lo - 1}"
    for bad in (True, 2.0, "3", None):
        assert offline.option_problem(bad, option).startswith(f"{option} must be a whole number")


def test_the_bounds_are_documented():
    text = (ROOT / "docs" / "datasets.md").read_text()
    for option, (lo, hi, _) in offline.LIMITS.items():
        assert re.search(rf"`{option}`[^\n]*{hi:,}", text), f"docs/datasets.md names no bound of {option} ({hi:,})"


def test_shots_beyond_the_bound_never_start_and_write_nothing(tmp_path):
    out = tmp_path / "x"
    refused(offline.generate, "random", "none", 10_000_000_000_000, out, match=r"--shots must be at most 2,000,000 \(")
    refused(offline.generate, "random", "none", 0, out, match="--shots must be at least 1, got 0")
    refused(offline.generate, "random", "none", 1.5e3, out, match="--shots must be a whole number")
    refused(offline.generate, "random", ["none"], 1000, out, match="--noise and --dataset must be names, got list and str")
    refused(offline.main, ["generate", "--dataset", "random", "--shots", "10000000000000", "--out", str(out)],
            match="--shots must be at most")
    assert not out.exists()


def test_iql_options_beyond_their_bounds_are_refused_before_anything_is_read(tmp_path):
    for updates, seed, match in ((10**13, 0, "--updates must be at most 10,000,000"), (0, 0, "--updates must be at least 1"),
                                 (10, -1, "--seed must be at least 0"), (10, 2**31, "--seed must be at most 2,147,483,647")):
        refused(offline.train_iql, tmp_path / "nothing", updates, tmp_path / "iql", seed=seed, match=match)
    assert not (tmp_path / "iql").exists()


# ----------------------------------------------------------------------------- choices and the agent, before writing


@pytest.mark.parametrize("kwargs,match", [
    ({"agent_spec": "nosuch"}, "--agent: agent 'nosuch' names nothing"),
    ({"agent_spec": "no_file.py:act"}, "--agent: agent 'no_file.py:act': no file no_file.py"),
    ({"agent_spec": "results/policies/none.pt"}, "no such file"),
    pytest.param({"agent_spec": "search:nosuch"}, "the search must be default or one of", marks=pytest.mark.slow),  # composes
    ({"agent_spec": "   "}, "--agent must name an agent"),
    ({"agent_spec": "random", "noise": "loud"}, "--noise must be one of none, fastfiz, fastfiz_x5, variable"),
    ({"agent_spec": "random", "dataset": "../x"}, "--dataset must be a name of letters"),
    ({"agent_spec": "random", "dataset": "a/b"}, "--dataset must be a name of letters"),
    ({"dataset": "superb"}, "--dataset must be one of expert, medium, random"),
    ({"noise": "loud"}, "--noise must be one of none, fastfiz"),
])
def test_a_refused_choice_or_agent_leaves_nothing_behind(tmp_path, kwargs, match):
    new, empty = tmp_path / "new", tmp_path / "empty"
    empty.mkdir()
    args = {"dataset": "t", "noise": "none", **kwargs}
    for out in (new, empty):
        refused(offline.generate, args["dataset"], args["noise"], 1000, out, agent_spec=args.get("agent_spec"),
                progress=False, match=match)
    assert not new.exists() and not any(empty.iterdir())


@pytest.mark.slow  # plays a block of random shots (about 2 s)
def test_the_corrected_command_works_after_a_refused_agent_or_one_that_failed(tmp_path):
    out = tmp_path / "ds"
    refused(offline.generate, "t", "none", 1000, out, agent_spec="nosuch", progress=False, match="names nothing")
    assert not out.exists()
    # an agent that builds and then answers wrongly: its manifest stays, no block; the corrected command replaces it
    bad = tmp_path / "bad.py"
    bad.write_text("import numpy as np\n\ndef act(obs):\n    return np.full((len(obs), 4), np.nan)\n")
    refused(offline.generate, "t", "none", 1000, out, agent_spec=f"{bad}:act", progress=False,
            match=r"the agent .* failed in block 1: .*; the 0 finished blocks are kept")
    assert (out / "dataset.json").is_file() and not list((out / "blocks").iterdir())
    offline.generate("t", "none", 1000, out, agent_spec="random", progress=False)
    assert json.loads((out / "dataset.json").read_text())["agent"] == "random"
    assert len(list(offline.episodes(out))) == offline.BLOCK
    # once a block is played, the folder is that dataset's
    refused(offline.generate, "t", "none", 1000, out, agent_spec="nearest", progress=False,
            match="holds another dataset \\(agent 'random' there, 'nearest' here\\); give another --out")


# ----------------------------------------------------------------------------- blocks against their episodes


def _mutations():
    n, T = offline.BLOCK, offline.SHOTS

    def change(key, value):
        def f(a):
            a[key] = value
        return f

    def drop(key):
        return lambda a: a.pop(key)

    def poke(key, index, value):
        def f(a):
            a[key][index] = value
        return f

    return {
        "5 observations for 10 actions": (change("observations", np.full((n, 5, 28), MARK, np.float32)),
                                          r"observations is float32 of shape \(100, 5, 28\), where 100 innings of 10 shots "
                                          r"need float32 of shape \(100, 11, 28\)"),
        "9 actions": (change("actions", np.zeros((n, T - 1, 4))), r"actions is float64 of shape \(100, 9, 4\)"),
        "11 rewards": (change("rewards", np.zeros((n, T + 1))), r"rewards is float64 of shape \(100, 11\)"),
        "fewer innings": (change("terminations", np.zeros((n - 1, T), bool)), r"terminations is bool of shape \(99, 10\)"),
        "flags as floats": (change("truncations", np.zeros((n, T))), "truncations is float64 of shape .* need bool"),
        "a 29-float observation": (change("observations", np.full((n, T + 1, 29), MARK, np.float32)),
                                   r"observations is float32 of shape \(100, 11, 29\)"),
        "observations as float64": (change("observations", np.full((n, T + 1, 28), MARK)), "observations is float64"),
        "positions of 3 balls": (change("info/positions", np.zeros((n, T + 1, 3, 2))), r"info/positions is float64 of shape"),
        "no truncations": (drop("truncations"), "lacks truncations"),
        "no info": (lambda a: [a.pop(k) for k in list(a) if k.startswith("info/")], "lacks info/score, info/foul"),
        "an extra array": (change("secret", np.zeros(3)), r"holds 1 array\(s\) a block does not \(secret\)"),
        "object observations": (change("observations", np.full((n, T + 1, 28), None, object)), "observations is object"),
        "NaN observation": (poke("observations", (3, 4, 5), np.nan), "observations holds NaN or an infinity"),
        "infinite reward": (poke("rewards", (7, 2), np.inf), "rewards holds NaN or an infinity"),
        "NaN position": (poke("info/positions", (0, 0, 0, 0), np.nan), "info/positions holds NaN or an infinity"),
        "power 2": (poke("actions", (1, 1, 1), 2.0), "actions hold shots outside the datasets' action space"),
        "angle 7": (poke("actions", (1, 1, 0), 7.0), "actions hold shots outside"),
    }


MUTATIONS = _mutations()


@pytest.mark.parametrize("case", list(MUTATIONS))
def test_a_block_that_disagrees_with_its_episodes_is_refused_naming_the_file(tmp_path, case):
    mutate, match = MUTATIONS[case]
    arrays = block_arrays(manifest_of())
    mutate(arrays)
    out = write_dataset(tmp_path / "ds", arrays=arrays)
    block = str(out / "blocks" / "block00000.npz")
    for call in (lambda: list(offline.episodes(out)), lambda: offline.checksum(out), lambda: offline.read_block(out, 0, manifest_of())):
        text = refused(call, match=match)
        assert text.startswith(f"Error: {block}: ") and text.endswith("remove it and run generate again to play it again")
        assert str(MARK) not in text and "4242" not in text and "[" not in text  # what is wrong, never what the file holds


def test_a_refused_block_builds_nothing(tmp_path):
    """The adversarial trial's case: a block of 5 observations for 10 actions no longer builds a
    Minari dataset; the sound block does."""
    arrays = block_arrays(manifest_of())
    arrays["observations"] = arrays["observations"][:, :5]
    out = write_dataset(tmp_path / "ds", arrays=arrays)
    refused(offline.build, out, match=r"block00000.npz: observations is float32 of shape \(100, 5, 28\)")
    assert not (out / "minari").exists()
    good = write_dataset(tmp_path / "good")
    ds = offline.build(good)
    assert ds.total_episodes == offline.BLOCK and ds.total_steps == offline.BLOCK * offline.SHOTS


def _truncate(path: Path):
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _flip(path: Path):  # one byte inside the observations' data: the zip's CRC no longer matches
    data = bytearray(path.read_bytes())
    data[2000] ^= 0xFF
    path.write_bytes(bytes(data))


DAMAGE = {
    "truncated": (_truncate, "BadZipFile"),
    "empty": (lambda p: p.write_bytes(b""), "BadZipFile"),
    "not a zip": (lambda p: p.write_bytes(b"SECRET " * 100), "BadZipFile"),
    "a flipped byte": (_flip, "BadZipFile"),
    "a folder": (lambda p: (p.unlink(), p.mkdir()), "missing"),
}


@pytest.mark.parametrize("case", list(DAMAGE))
def test_a_truncated_or_damaged_block_file_is_refused_naming_the_file(dataset, case):
    damage, kind = DAMAGE[case]
    path = dataset / "blocks" / "block00000.npz"
    damage(path)
    want = (rf"{re.escape(str(path))}: not a readable block \(truncated or damaged: {kind}\); remove it and run generate "
            "again to play it again") if kind != "missing" else rf"{re.escape(str(path))}: missing; run generate again"
    for call in (lambda: list(offline.episodes(dataset)), lambda: offline.checksum(dataset)):
        text = refused(call, match=want)
        assert "SECRET" not in text
    # resuming the same command checks the finished blocks before playing beside them
    refused(offline.generate, "t", "none", 1000, dataset, agent_spec="nearest", progress=False, match="block00000.npz: ")


def test_a_compressed_block_of_the_right_layout_reads(dataset):
    np.savez_compressed(dataset / "blocks" / "block00000.npz", **block_arrays(manifest_of()))
    assert len(list(offline.episodes(dataset))) == offline.BLOCK


def test_a_missing_block_is_named_before_building(dataset):
    manifest = {**manifest_of(), "blocks": 2}
    (dataset / "dataset.json").write_text(json.dumps(manifest))
    refused(offline.build, dataset, match="1 of 2 blocks not played yet; run generate again")
    refused(lambda: list(offline.episodes(dataset)), match="block00001.npz: missing; run generate again to play it")


# ----------------------------------------------------------------------------- dataset.json


def _json(value):
    return lambda p: p.write_text(json.dumps(value))


def _keys(**changes):
    m = manifest_of()
    m.update(changes)
    return _json({k: v for k, v in m.items() if v is not ...})


MANIFESTS = {
    "not JSON": (lambda p: p.write_text('{"dataset": "SECRET", oops'), r"damaged: not JSON \(line 1, column 23\)"),
    "not UTF-8": (lambda p: p.write_bytes(b"\xff\xfe SECRET \x00"), "damaged: not JSON text"),
    "empty": (lambda p: p.write_text(""), r"damaged: not JSON \(line 1, column 1\)"),
    "nested past the stack": (lambda p: p.write_text("[" * 100_000 + "]" * 100_000), "damaged: not JSON text"),
    "too large": (lambda p: p.write_text(" " * (2 << 20) + "{}"), "damaged: larger than 1,048,576 bytes"),
    "a list": (_json(["SECRET"]), "damaged: not a JSON object but a list"),
    "a number": (_json(7), "damaged: not a JSON object but a number"),
    "null": (_json(None), "damaged: not a JSON object but null"),
    "missing keys": (_json({"dataset": "SECRET"}), "damaged: lacks dataset_id, noise, agent, physics, shots_per_inning"),
    "blocks as a string": (_keys(blocks="1"), "damaged: blocks must be a whole number, got a string"),
    "blocks as a boolean": (_keys(blocks=True), "damaged: blocks must be a whole number, got a boolean"),
    "blocks as a float": (_keys(blocks=1.0), "damaged: blocks must be a whole number, got a number"),
    "no blocks": (_keys(blocks=0), r"damaged: blocks must lie in 1\.\.2,000, got 0"),
    "a billion blocks": (_keys(blocks=10**9), r"damaged: blocks must lie in 1\.\.2,000"),
    "agent as a list": (_keys(agent=["SECRET"]), "damaged: agent must be a string, got a list"),
    "an unknown noise": (_keys(noise="loud", dataset_id="billiards/loud/t-v0"), "damaged: noise must be one of"),
    "an unknown table": (_keys(physics="SECRET"), "damaged: physics must be one of"),
    "a path as its name": (_keys(dataset="../../x"), "damaged: dataset is no dataset name"),
    "another id": (_keys(dataset_id="billiards/none/other-v0"), "damaged: dataset_id is not billiards/none/t-v0"),
    "5 shots an inning": (_keys(shots_per_inning=5), "damaged: shots_per_inning is 5; this code plays and reads shots_per_inning 10"),
    "another seed": (_keys(seed=0), "damaged: seed is 0"),
    "a commit number": (_keys(commit=7), "damaged: commit must be a string, got a number"),
    "a folder": (lambda p: (p.unlink(), p.mkdir()), "not a file"),
}


@pytest.mark.parametrize("case", list(MANIFESTS))
def test_a_damaged_dataset_json_is_refused_with_a_sentence(dataset, tmp_path, case):
    damage, match = MANIFESTS[case]
    path = dataset / "dataset.json"
    damage(path)
    before = snapshot(dataset)
    calls = {"read": lambda: offline.read_manifest(dataset), "episodes": lambda: list(offline.episodes(dataset)),
             "checksum": lambda: offline.checksum(dataset), "build": lambda: offline.build(dataset),
             "generate": lambda: offline.generate("t", "none", 1000, dataset, agent_spec="nearest", progress=False),
             "iql": lambda: offline.train_iql(dataset, 10, tmp_path / "iql", progress=False),
             "transitions": lambda: offline.transitions(dataset)}
    for name, call in calls.items():
        text = refused(call, match=re.escape(str(path)) + ": " + match)
        assert "SECRET" not in text, (name, text)
    assert snapshot(dataset) == before and not (tmp_path / "iql").exists()


# ----------------------------------------------------------------------------- folders


def test_a_missing_folder_a_file_or_a_folder_of_no_dataset_is_refused(tmp_path):
    missing, file, other = tmp_path / "missing", tmp_path / "file", tmp_path / "other"
    file.write_text("x")
    other.mkdir()
    (other / "notes.txt").write_text("x")
    for out, match in ((missing, "no such folder"), (file, "a file, not a dataset folder"),
                       (other, "holds no dataset.json, so no dataset of python -m billiards.offline generate")):
        for call in (offline.read_manifest, offline.build, offline.checksum, offline.transitions,
                     lambda d: list(offline.episodes(d)), lambda d: offline.train_iql(d, 10, tmp_path / "iql")):
            refused(call, out, match=f"Error: {re.escape(str(out))}: {match}")
    assert not missing.exists() and not (tmp_path / "iql").exists()


def test_an_out_that_is_a_file_or_cannot_be_written_is_refused_before_writing(tmp_path, dataset, monkeypatch):
    file = tmp_path / "file.txt"
    file.write_text("keep me")
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    blocks_file = tmp_path / "blocks_file"
    blocks_file.mkdir()
    (blocks_file / "blocks").write_text("x")
    (blocks_file / "dataset.json").write_text(json.dumps(manifest_of(agent="random")))
    (dataset / "minari").write_text("keep me")  # in place of build's default root
    gen = lambda out: offline.generate("t", "none", 1000, out, agent_spec="random", progress=False)  # noqa: E731
    before = snapshot(tmp_path)
    refused(gen, file, match=f"--out {re.escape(str(file))}: a file, not a directory")
    refused(gen, file / "sub", match=f"--out {re.escape(str(file / 'sub'))}: cannot be created: .*file.txt is a file")
    refused(gen, other, match="holds 1 file\\(s\\) and no dataset.json, so no dataset; choose a new or empty folder")
    refused(offline.main, ["generate", "--agent", "random", "--dataset", "t", "--out", str(file)], match="a file, not a directory")
    refused(offline.build, dataset, root=file, match=f"--root {re.escape(str(file))}: a file, not a directory")
    refused(offline.build, dataset, match=f"--root {re.escape(str(dataset / 'minari'))}: a file, not a directory")
    refused(offline.train_iql, dataset, 10, file, match=f"--out {re.escape(str(file))}: a file, not a directory")
    refused(offline.train_iql, dataset, 10, other, match="not empty .*; choose a new or empty folder")
    refused(gen, blocks_file, match="its blocks is a file, not a folder")
    assert snapshot(tmp_path) == before
    # a folder this user cannot write (a read-only file system): looked at, refused, nothing created
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if str(p).startswith(str(tmp_path / "ro")) else real(p, mode, **kw))
    (tmp_path / "ro").mkdir()
    refused(gen, tmp_path / "ro", match="this user cannot read and write that directory")
    refused(gen, tmp_path / "ro" / "new", match="cannot be created: this user cannot write")
    assert not any((tmp_path / "ro").iterdir())


def test_a_write_that_fails_gives_a_sentence(tmp_path, monkeypatch):
    """A checked folder whose file system then refuses the write (full, remounted read-only)."""
    def fail(path, data):
        raise OSError(errno.EROFS, "Read-only file system", str(path))

    monkeypatch.setattr(offline, "atomic_write_bytes", fail)
    refused(offline.generate, "t", "none", 1000, tmp_path / "ds", agent_spec="random", progress=False,
            match=r"dataset.json: cannot be written \(Read-only file system\); the finished blocks are kept")


# ----------------------------------------------------------------------------- the command line


@pytest.mark.slow
def test_the_command_line_says_one_sentence_and_no_traceback(tmp_path, dataset):
    """``python -m billiards.offline ...``, in this process (conftest.app_here)."""
    from conftest import app_here

    (tmp_path / "file").write_text("x")
    _truncate(dataset / "blocks" / "block00000.npz")
    damaged = write_dataset(tmp_path / "damaged")
    (damaged / "dataset.json").write_text("{oops")
    cases = [
        (["generate", "--shots", "10000000000000", "--out", str(tmp_path / "x")], "--shots must be at most 2,000,000"),
        (["generate", "--agent", "nosuch", "--dataset", "t", "--out", str(tmp_path / "x")], "--agent: agent 'nosuch' names nothing"),
        (["generate", "--out", str(tmp_path / "file")], "a file, not a directory"),
        (["build", str(tmp_path / "missing")], "no such folder"),
        (["build", str(damaged)], "dataset.json: damaged: not JSON"),
        (["build", str(dataset)], "block00000.npz: not a readable block"),
        (["iql", str(dataset), "--updates", "-3", "--out", str(tmp_path / "iql")], "--updates must be at least 1"),
    ]
    for argv, match in cases:
        run = app_here("billiards.offline", *argv, cwd=tmp_path)
        assert run.returncode == 1 and "Traceback" not in run.stderr, (argv, run.stderr)
        assert run.stderr.startswith("Error: ") and match in run.stderr and run.stderr.count("\n") == 1, (argv, run.stderr)
    assert not (tmp_path / "x").exists() and not (tmp_path / "iql").exists()
