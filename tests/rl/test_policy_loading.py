"""Loading an exported policy file (billiards.rl.policy.load_policy; issue #57, docs/reliability.md,
"Submissions you can trust"): a file whose config disagrees with its network -- the input width
the config's features give, the action width -- is refused on load with a sentence naming the
file, sealed or not, and the benchmark refuses it as an agent before anything is written."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest

from billiards.files import load_tagged, save_tagged
from billiards.rl.checkpoint import CheckpointError
from billiards.rl.policy import POLICY_FORMAT, load_policy, policy_file_error

ROOT = Path(__file__).resolve().parents[2]
POLICY = ROOT / "results" / "policies" / "base" / "seed0.pt"  # SAC with the carom features: 32 inputs, 8 outputs (mean, std)
FIRST, LAST = "module.0.module.0.0.weight", "module.0.module.0.4"


@pytest.fixture(scope="module")
def payload() -> dict:
    return load_tagged(POLICY, POLICY_FORMAT, CheckpointError, "exported policy")


def _cut_inputs(p: dict, width: int) -> None:
    p["actor"][FIRST] = p["actor"][FIRST][:, :width].clone()


def _cut_actions(p: dict, width: int) -> None:
    p["actor"][f"{LAST}.weight"] = p["actor"][f"{LAST}.weight"][:width].clone()
    p["actor"][f"{LAST}.bias"] = p["actor"][f"{LAST}.bias"][:width].clone()


CHANGES = {  # what disagrees -> (the change, what the refusal says)
    "the features named (32 inputs) for a 28-input network": (lambda p: _cut_inputs(p, 28),
                                                               r"shape \(256, 28\), but the network its config describes has "
                                                               r"\(256, 32\).*extra_features=True"),
    "no features named (28 inputs) for a 32-input network": (lambda p: p["config"]["env"].update(extra_features=False),
                                                             r"shape \(256, 32\), but .* has \(256, 28\).*extra_features=False"),
    "the noise level read (33 inputs) by a 32-input network": (lambda p: p["config"]["noise"].update(preset="variable"),
                                                               r"shape \(256, 32\), but .* has \(256, 33\).*noise=variable"),
    "3 actions (6 outputs) for a 4-action config": (lambda p: _cut_actions(p, 6),
                                                    r"shape \(6, 256\), but .* has \(8, 256\)"),
}


@pytest.mark.parametrize("case", list(CHANGES))
def test_a_policy_whose_config_disagrees_with_its_network_is_refused_on_load(tmp_path, payload, case):
    change, says = CHANGES[case]
    bad = copy.deepcopy(payload)
    change(bad)
    path = save_tagged(tmp_path / "policy.pt", bad)  # sealed again: the seal is intact, the meaning is not
    layer = r"actor\.module\.0\.module\.0\.[04]\.weight"
    with pytest.raises(CheckpointError, match=rf"exported policy file {path} is not a usable policy: {layer}: {says}"):
        load_policy(path)
    assert policy_file_error(path) is not None and str(path) in policy_file_error(path)


@pytest.mark.parametrize("case", list(CHANGES))
def test_the_benchmark_refuses_such_a_policy_as_an_agent_before_writing(tmp_path, payload, case):
    from billiards.bench import AgentError, evaluate

    bad = copy.deepcopy(payload)
    CHANGES[case][0](bad)
    path = save_tagged(tmp_path / "policy.pt", bad)
    with pytest.raises(AgentError, match=rf"{path}: not a policy of this project \(exported policy file .* is not a usable policy"):
        evaluate(str(path), "innings-v1", limit=1, out=tmp_path / "eval", progress=False)
    assert not (tmp_path / "eval").exists()


def test_the_shipped_policy_loads_with_the_widths_its_config_names(payload):
    policy, cfg = load_policy(POLICY)
    assert bool(cfg.env.extra_features) and tuple(payload["actor"][FIRST].shape) == (256, 32)
    assert tuple(payload["actor"][f"{LAST}.weight"].shape) == (8, 256)
