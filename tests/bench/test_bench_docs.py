"""docs/benchmark.md's examples run as written: each ```python block, in a fresh interpreter, in
an empty working directory (the SB3 one where Stable-Baselines3 is installed)."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
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
def test_docs_example_runs_as_written(index, tmp_path):
    code = BLOCKS[index]
    if "stable_baselines3" in code and importlib.util.find_spec("stable_baselines3") is None:
        pytest.skip("Stable-Baselines3 is not installed (the sb3 extra)")
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=900,
                          env={**__import__("os").environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == 0, proc.stderr[-3000:]
    if "out=" in code:  # the example that writes a run dir: its scorecard is there
        assert (tmp_path / "outputs" / "evaluate" / "sac_base" / "scorecard.md").is_file()
