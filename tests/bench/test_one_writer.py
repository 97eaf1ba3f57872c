"""One writer per evaluation folder: an evaluation takes the folder's lock (billiards.files.run_lock)
from its claim to its scorecard, so the same command started twice on one out= plays once."""

from __future__ import annotations

import os

import pytest

from billiards import files
from billiards.bench.run import UNITS_FILE, SCORECARD_JSON, EvaluationError, evaluate


def test_a_second_writer_is_refused_naming_the_holder_and_the_folder_then_resumes(tmp_path):
    out = tmp_path / "eval"
    with files.run_lock(out, command="python evaluate.py (the first)", say=None):
        with pytest.raises(EvaluationError, match=rf"pid {os.getpid()}|{os.getpid()}") as err:
            evaluate("nearest", "p1-exact-v1", out=out, limit=1, progress=False)
        assert "the first" in str(err.value)
        assert not (out / UNITS_FILE).exists() and not (out / SCORECARD_JSON).exists()  # nothing played
    card = evaluate("nearest", "p1-exact-v1", out=out, limit=1, progress=False)  # the holder gone: it runs
    assert (out / SCORECARD_JSON).is_file() and not card["partial"]
    assert not (out / files.LOCK_FILE).exists()  # released with the scorecard


def test_the_lock_is_released_when_the_evaluation_fails(tmp_path):
    out = tmp_path / "eval"

    def act(obs):
        raise RuntimeError("the agent's own bug")

    with pytest.raises(EvaluationError, match="the agent's own bug"):
        evaluate(act, "p1-exact-v1", out=out, limit=1, progress=False, name="buggy")
    assert not (out / files.LOCK_FILE).exists()
