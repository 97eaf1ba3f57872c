"""Strict env and API contracts: calls that would silently do something else are refused, with
a message naming what was wrong (gymnasium's and TorchRL's conventions)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from billiards.envs import Billiards4BallInningEnv, BilliardsEnv, make_env
from billiards.physics import PRESETS, canonical_rack, simulate_batch, simulate_shot, trajectory

SHOT = np.array([0.3, 0.5, 0.0, 0.0], dtype=np.float32)


def _play_to_the_end(env, action) -> None:
    env.reset(seed=0)
    for _ in range(env.max_shots + 1):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            return
    raise AssertionError("the inning never ended")


def test_gym_stepping_a_finished_inning_raises_until_reset():
    env = Billiards4BallInningEnv(max_shots=3)
    _play_to_the_end(env, SHOT)
    with pytest.raises(gym.error.ResetNeeded, match="call reset"):
        env.step(SHOT)
    env.reset(seed=1)
    env.step(SHOT)  # a new inning steps again
    env = Billiards4BallInningEnv(max_shots=5, on_miss="reset")  # ended by a miss (terminated)
    env.reset(options={"positions": canonical_rack()})
    _, _, terminated, _, _ = env.step(np.array([0.5, -0.9, 0.0, 0.0], dtype=np.float32))  # a weak shot away: a miss
    assert terminated
    with pytest.raises(gym.error.ResetNeeded):
        env.step(SHOT)


def test_gym_unknown_reset_options_raise():
    env = Billiards4BallInningEnv()
    with pytest.raises(ValueError, match=r"reset options may only be \['positions'\]; got 'postions'"):
        env.reset(options={"postions": canonical_rack()})
    env.reset(options={})  # no option: a random rack
    env.reset(options={"positions": None})


@pytest.mark.parametrize("action", [["0.1", "0.5", "0", "0"], np.array([0.1 + 1j, 0.5, 0, 0]), np.array([True, False, True, False]),
                                    np.array([object(), 0.5, 0, 0], dtype=object)])
def test_actions_must_be_real_numbers(action):
    env = Billiards4BallInningEnv(normalize_actions=False)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="real numbers|numeric"):
        env.step(action)
    with pytest.raises(ValueError, match="real numbers|numeric"):
        simulate_shot(canonical_rack(), action)


@pytest.mark.parametrize("flag", ["constrain_aim", "extra_features", "normalize_actions"])
def test_boolean_options_must_be_booleans(flag):
    with pytest.raises(TypeError, match=f"{flag} must be True or False, got 'no'"):
        Billiards4BallInningEnv(**{flag: "no"})
    with pytest.raises(TypeError, match=f"{flag} must be True or False"):
        make_env(2, **{flag: "no"})
    assert getattr(Billiards4BallInningEnv(**{flag: np.bool_(True)}), flag) is True


def test_torchrl_stepping_without_a_reset_or_past_the_inning_raises():
    env = BilliardsEnv(2, max_shots=3, seed=0)
    td = env.reset()
    td["action"] = torch.from_numpy(np.stack([SHOT, SHOT]).astype(np.float64))
    env.step(td.clone())  # a valid step
    for shot, message in ((torch.tensor([[0], [3]]), "must lie in \\[0, max_shots - 1 = 2\\]"),
                          (torch.tensor([[-1], [0]]), "innings \\[0\\] have \\[-1\\]"),
                          (torch.tensor([[0.5], [0.0]]), "must be an integer tensor")):
        bad = td.clone()
        bad["shot"] = shot
        with pytest.raises(ValueError, match=message):
            env.step(bad)
    with pytest.raises(KeyError, match="call env.reset"):
        env.step(td.select("action"))


def test_an_action_that_requires_grad_is_played_by_its_values():
    action = torch.from_numpy(np.stack([SHOT, SHOT])).requires_grad_(True)
    played = []
    for a in (action * 1.0, action.detach().clone()):  # part of a graph, and plain
        env = make_env(2, seed=0)
        played.append(env.step(env.reset().set("action", a))["next", "positions"])
    assert torch.equal(*played)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_a_preset_name_is_accepted_wherever_parameters_are(name):
    params = PRESETS[name]
    rack = canonical_rack(name)
    assert np.array_equal(rack, canonical_rack(params))
    by_name, by_params = simulate_shot(rack, SHOT, params=name), simulate_shot(rack, SHOT, params=params)
    assert np.array_equal(by_name.positions, by_params.positions)
    assert np.array_equal(simulate_batch(rack[None], SHOT[None], name).positions, by_params.positions[None])
    assert BilliardsEnv(1, params=name).params == params
    with pytest.raises(ValueError, match="unknown physics preset 'nowhere'"):
        simulate_shot(rack, SHOT, params="nowhere")


@pytest.mark.parametrize("dt", [-1.0, 0.0, float("nan"), float("inf")])
def test_trajectory_needs_a_positive_time_step(dt):
    result = simulate_shot(canonical_rack(), SHOT)
    with pytest.raises(ValueError, match="finite time step dt > 0"):
        trajectory(result, dt=dt)


# ----------------------------------------------------------------------------- sealed files

SHIPPED = {
    "policy": "results/policies/base/seed0.pt",
    "ranker": "results/rankers/fastfiz/ranker.pt",
    "reward model": "results/rm/model.pt",
    "table value": "results/values/value.pt",
}


def _loader(kind):
    from billiards.rl.checkpoint import CheckpointError
    from billiards.rl.policy import load_policy
    from billiards.rm.model import RewardModelError, load_model
    from billiards.search.ranker import RankerFileError, ShotRanker
    from billiards.search.value import TableValue, ValueFileError

    return {"policy": (load_policy, CheckpointError), "ranker": (ShotRanker.load, RankerFileError),
            "reward model": (load_model, RewardModelError), "table value": (TableValue.load, ValueFileError)}[kind]


def _largest_tensor(payload):
    tensors = []

    def walk(x):
        if torch.is_tensor(x):
            tensors.append(x)
        elif isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, (list, tuple)):
            for v in x:
                walk(v)
    walk(payload)
    return max(tensors, key=lambda t: t.numel())


@pytest.mark.parametrize("kind", sorted(SHIPPED))
def test_every_shipped_model_file_is_sealed_and_a_changed_weight_is_refused(tmp_path, kind):
    """A shipped file loads; the same payload with one weight changed by one ulp (saved without
    a new checksum) is refused as damaged; a flipped bit in the file's bytes is refused (by the
    checksum or as a corrupt file); NaN weights under a valid checksum are refused."""
    from billiards.files import ROOT, SEAL_KEY, save_tagged

    load, error = _loader(kind)
    src = ROOT / SHIPPED[kind]
    load(src)
    payload = torch.load(src, map_location="cpu", weights_only=True)
    assert len(payload[SEAL_KEY]) == 64
    weight = _largest_tensor(payload)
    flat = weight.view(-1)
    flat[7] = torch.nextafter(flat[7], torch.tensor(float("inf"), dtype=flat.dtype))
    torch.save(payload, tmp_path / "ulp.pt")
    with pytest.raises(error, match="damaged: its contents do not match its sha256 checksum"):
        load(tmp_path / "ulp.pt")

    data = bytearray(src.read_bytes())
    original = _largest_tensor(torch.load(src, map_location="cpu", weights_only=True))
    at = bytes(data).find(original.view(-1)[:16].numpy().tobytes())
    assert at > 0
    data[at + 5] ^= 0x10
    (tmp_path / "bit.pt").write_bytes(bytes(data))
    with pytest.raises(error):
        load(tmp_path / "bit.pt")

    flat.fill_(float("nan"))
    payload.pop(SEAL_KEY)
    save_tagged(tmp_path / "nan.pt", payload)
    with pytest.raises(error, match="non-finite values"):
        load(tmp_path / "nan.pt")


def test_a_file_written_before_seals_is_refused_until_sealed(tmp_path):
    from billiards.files import ROOT, SEAL_KEY, main
    from billiards.search.ranker import RankerFileError, ShotRanker

    payload = torch.load(ROOT / SHIPPED["ranker"], map_location="cpu", weights_only=True)
    payload.pop(SEAL_KEY)
    torch.save(payload, tmp_path / "old.pt")
    with pytest.raises(RankerFileError, match="carries no checksum.*python -m billiards.files seal"):
        ShotRanker.load(tmp_path / "old.pt")
    assert main(["seal", str(tmp_path / "old.pt")]) == 0
    assert ShotRanker.load(tmp_path / "old.pt").weights[0].shape == ShotRanker.load(ROOT / SHIPPED["ranker"]).weights[0].shape


@pytest.mark.slow
@pytest.mark.parametrize("app,kind,overrides", [
    ("search.py", "ranker", ["noise=fastfiz", "proposer=ranked", "proposer.ranker={f}"]),
    ("search.py", "policy", ["proposer=policy", "proposer.checkpoints=[{f}]"]),
    ("train.py", "reward model", ["shaping=rm", "shaping.rm_model={f}"]),
])
def test_a_damaged_file_named_by_config_is_refused_before_anything_is_written(tmp_path, app, kind, overrides):
    import subprocess
    import sys

    from billiards.files import ROOT

    data = bytearray((ROOT / SHIPPED[kind]).read_bytes())
    damaged = tmp_path / "damaged.pt"
    damaged.write_bytes(bytes(data[: len(data) // 2]))  # truncated
    proc = subprocess.run([sys.executable, str(ROOT / app), *(o.format(f=damaged) for o in overrides)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode != 0 and "damaged.pt" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["damaged.pt"]


def test_exact_positions_reuses_a_table_only_for_the_same_unchanged_tensors():
    """The per-step reuse of the exact table (billiards.envs.torchrl_env.exact_positions) never
    serves a stale table: an in-place change of "positions" or of its bits, or another tensor,
    gives a fresh one; the shared table is read-only."""
    from billiards.envs.torchrl_env import exact_positions

    env = BilliardsEnv(3, seed=0)
    td = env.reset()
    first = exact_positions(td)
    assert exact_positions(td) is first and not first.flags.writeable
    with pytest.raises(ValueError):
        first[0, 0, 0] = 0.0
    before = first.copy()
    td["positions"][0, 0, 0] += 0.01  # in place: the tensor's version moves on
    td["positions_bits"][0] = td["positions"][0].view(torch.int64)
    moved = exact_positions(td)
    assert moved is not first and moved[0, 0, 0] == before[0, 0, 0] + 0.01
    other = td.clone()  # equal values, other tensors
    again = exact_positions(other)
    assert again is not moved and np.array_equal(again, moved)
