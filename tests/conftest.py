"""Fixtures shared by several test modules."""

from pathlib import Path

import pytest

SHIPPED_BASE = Path(__file__).resolve().parents[1] / "results" / "policies" / "base" / "seed0.pt"


@pytest.fixture
def international_policy(tmp_path) -> Path:
    """The shipped ``base`` seed 0 (trained on korean_medium, the default table), saved again as
    if it had been trained on the international table: a policy from another table."""
    import torch

    state = torch.load(SHIPPED_BASE, map_location="cpu", weights_only=True)
    state["config"]["physics"] = {"preset": "international"}
    path = tmp_path / "made_on_international.pt"
    torch.save(state, path)
    return path
