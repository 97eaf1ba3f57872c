"""docs/benchmark.md's examples run as written: each ```python block as a script (in this process,
conftest.app_here, with what the process holds put back afterwards), in an empty working
directory (the SB3 one where Stable-Baselines3 is installed)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BLOCKS = re.findall(r"```python\n(.*?)```", (REPO / "docs" / "benchmark.md").read_text(), flags=re.S)


def test_the_docs_have_an_example_per_agent_kind():
    text = "\n".join(BLOCKS)
    for needle in ("def act(obs)", "TensorDictModule", "stable_baselines3", "results/policies/base/seed0.pt"):
        assert needle in text, needle


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_docs_example_runs_as_written(index, tmp_path, tmp_path_factory):
    from conftest import app_here

    code = BLOCKS[index]
    if "stable_baselines3" in code and importlib.util.find_spec("stable_baselines3") is None:
        pytest.skip("Stable-Baselines3 is not installed (the sb3 extra)")
    script = tmp_path_factory.mktemp("example") / "example.py"  # beside, not in, the working directory
    script.write_text(code)
    proc = app_here(script, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    if "out=" in code:  # the example that writes a run dir: its scorecard is there
        assert (tmp_path / "outputs" / "evaluate" / "sac_base" / "scorecard.md").is_file()


def test_the_docs_say_what_evaluate_writes_from_python_and_that_a_submission_needs_a_name():
    """What ``billiards.bench.evaluate`` writes (nothing without ``out=``: tests/bench/test_submission.py
    checks it), and ``name=`` in the submission section, its command included."""
    text = " ".join((REPO / "docs" / "benchmark.md").read_text().split())
    assert "`billiards.bench.evaluate(agent, track)` in Python returns the scorecard (a dict) and writes files only into a " \
           "directory given as `out=`" in text
    assert "writes these files only where it is given `out=<dir>` (without it, nothing is written)" in text
    submitting = text.split("**Submitting an agent.**", 1)[1].split("## ", 1)[0]
    assert "with `name=`, which is required for a submission" in submitting
    assert "python evaluate.py track=p1-exact-v1 agent=my_agent.py:act name=my-agent out=" in submitting
