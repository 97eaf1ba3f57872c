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
                          (torch.tensor([[0.5], [0.0]]), '"shot" must hold integers')):
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


@pytest.mark.parametrize("dt", [-1.0, 0.0, float("nan"), float("inf"), 1e-12, True, "0.1"])
def test_trajectory_needs_a_positive_time_step(dt):
    result = simulate_shot(canonical_rack(), SHOT)
    with pytest.raises(ValueError, match="^dt must be a finite time step"):
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
    from billiards.compat import main
    from billiards.files import ROOT, SEAL_KEY
    from billiards.search.ranker import RankerFileError, ShotRanker

    payload = torch.load(ROOT / SHIPPED["ranker"], map_location="cpu", weights_only=True)
    payload.pop(SEAL_KEY)
    torch.save(payload, tmp_path / "old.pt")
    with pytest.raises(RankerFileError, match="carries no checksum: python -m billiards.compat seal"):
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
    from billiards.files import ROOT
    from conftest import app_here

    data = bytearray((ROOT / SHIPPED[kind]).read_bytes())
    damaged = tmp_path / "damaged.pt"
    damaged.write_bytes(bytes(data[: len(data) // 2]))  # truncated
    proc = app_here(app, *(o.format(f=damaged) for o in overrides), cwd=tmp_path)
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


# ----------------------------------------------------------------------------- contracts at the boundary
# Each boundary (the physics API, the gymnasium env, its vector env, the TorchRL env, the
# PettingZoo env) checks its inputs once, through billiards.physics.checks: a bad one is a
# ValueError/TypeError whose message names the argument ("<name> must be ..., got ..."), and
# the env then plays the next valid call as if the bad one had never been made.

RACK = canonical_rack()
MASKED4 = np.ma.array([0.1, 0.5, 0.0, 0.0], mask=[0, 1, 0, 0])
COMPLEX4 = np.array([0.1 + 1j, 0.5, 0.0, 0.0])
STRING4 = [0.1, "0.5", 0.0, 0.0]
ZERO_D = np.array(0.3)
INF4 = [np.inf, 0.5, 0.0, 0.0]
BOOL4 = np.array([True, False, True, False])


def _refused(call, name: str) -> None:
    with pytest.raises((ValueError, TypeError), match=name):
        call()


def _physics_cases():
    from billiards.physics import PhysicsParams, action_to_cue, check_actions, check_positions, random_rack, random_racks
    from billiards.physics.noise import NoiseModel

    rng = np.random.default_rng(0)
    result = simulate_shot(RACK, SHOT)
    return {
        "shot: masked action": (lambda: simulate_shot(RACK, MASKED4), "^action must be a plain array of real numbers"),
        "shot: complex action": (lambda: simulate_shot(RACK, COMPLEX4), "^action must hold real numbers.*complex"),
        "shot: a list with a string": (lambda: simulate_shot(RACK, STRING4), "^action must hold real numbers"),
        "shot: 0-d action": (lambda: simulate_shot(RACK, ZERO_D), r"^action must have shape \(4,\)"),
        "shot: inf action": (lambda: simulate_shot(RACK, INF4), "^action has a non-finite theta"),
        "shot: boolean action": (lambda: simulate_shot(RACK, BOOL4), "^action must hold real numbers.*booleans"),
        "shot: masked positions": (lambda: simulate_shot(np.ma.masked_array(RACK), SHOT), "^positions must be a plain array"),
        "batch: complex positions": (lambda: simulate_batch(RACK[None] + 0j, SHOT[None]), "^positions must hold real numbers"),
        "batch: 0-d actions": (lambda: simulate_batch(RACK[None], ZERO_D), r"^actions must have shape \(N, 4\)"),
        "check_actions: masked": (lambda: check_actions(np.ma.masked_array([SHOT])), "^action must be a plain array"),
        "check_positions: complex": (lambda: check_positions(RACK + 1j), "^positions must hold real numbers"),
        "action_to_cue: masked": (lambda: action_to_cue(MASKED4), "^action must be a plain array"),
        "random_racks: n=-1": (lambda: random_racks(rng, -1), "^n must be an integer >= 0"),
        "random_racks: n=1.5": (lambda: random_racks(rng, 1.5), "^n must be an integer >= 0"),
        "random_racks: n=True": (lambda: random_racks(rng, True), "^n must be an integer >= 0.*boolean"),
        "random_racks: n=-0.0": (lambda: random_racks(rng, -0.0), "^n must be an integer >= 0"),
        "random_racks: n=inf": (lambda: random_racks(rng, np.inf), "^n must be an integer >= 0"),
        "random_racks: rng=None": (lambda: random_racks(None, 2), "^rng must be a numpy.random.Generator"),
        "random_rack: rng=None": (lambda: random_rack(None), "^rng must be a numpy.random.Generator"),
        "random_rack: rng=0": (lambda: random_rack(0), "^rng must be a numpy.random.Generator"),
        "trajectory: dt=1e-12": (lambda: trajectory(result, dt=1e-12), "^dt must be a finite time step of at least"),
        "trajectory: dt=True": (lambda: trajectory(result, dt=True), "^dt must be"),
        "trajectory: no result": (lambda: trajectory(None), "^result must be a ShotResult"),
        "params: squirt='no'": (lambda: PhysicsParams(squirt="no"), "^PhysicsParams.squirt must be True or False"),
        "params: squirt=nan": (lambda: PhysicsParams(squirt=float("nan")), "^PhysicsParams.squirt must be True or False"),
        "params: squirt=2": (lambda: PhysicsParams(squirt=2), "^PhysicsParams.squirt must be True or False"),
        "params: table_width=10**400": (lambda: PhysicsParams(table_width=10**400), "^PhysicsParams.table_width must be"),
        "params: max_events=True": (lambda: PhysicsParams(max_events=True), "^PhysicsParams.max_events must be an integer"),
        "params: max_events=5000.0": (lambda: PhysicsParams(max_events=5000.0), "^PhysicsParams.max_events must be an integer"),
        "params: e_ball complex": (lambda: PhysicsParams(e_ball=0.9 + 0j), "^PhysicsParams.e_ball must be"),
        "params: ball_ball=3": (lambda: PhysicsParams(ball_ball=3), "^PhysicsParams.ball_ball must be one of"),
        "noise: sigma 1e308": (lambda: NoiseModel(sigma_aim_deg=1e308), "^NoiseModel.sigma_aim_deg must be at most 90"),
        "noise: speed sigma 1e3": (lambda: NoiseModel(sigma_speed=1e3), "^NoiseModel.sigma_speed must be at most"),
        "noise: tip sigma inf": (lambda: NoiseModel(sigma_tip_mm=np.inf), "^NoiseModel.sigma_tip_mm must be a finite"),
        "noise: sigma True": (lambda: NoiseModel(sigma_aim_deg=True), "^NoiseModel.sigma_aim_deg must be"),
        "noise: level_range 1e30": (lambda: NoiseModel(0.1, 0.1, 0.1, level_range=(0, 1e30)), "^NoiseModel.level_range"),
        "noise: sigma x top level": (lambda: NoiseModel(2.0, level_range=(0, 50)), "^NoiseModel.sigma_aim_deg times the top level"),
    }


PHYSICS_CASES = sorted(_physics_cases())


@pytest.mark.parametrize("case", PHYSICS_CASES)
def test_the_physics_api_refuses_bad_input_naming_it(case):
    call, name = _physics_cases()[case]
    before = simulate_shot(RACK, SHOT).positions
    _refused(call, name)
    np.testing.assert_array_equal(simulate_shot(RACK, SHOT).positions, before)  # and plays on, bit for bit


GYM_CASES = {  # (env options, what is called: make / step / reset, the bad input, the argument's name)
    "make: max_shots=True": ({}, "make", dict(max_shots=True), "^max_shots must be an integer.*boolean"),
    "make: max_shots=inf": ({}, "make", dict(max_shots=float("inf")), "^max_shots must be an integer"),
    "make: max_shots=2.0": ({}, "make", dict(max_shots=2.0), "^max_shots must be an integer"),
    "make: max_shots=-0.0": ({}, "make", dict(max_shots=-0.0), "^max_shots must be an integer"),
    "make: max_shots=0": ({}, "make", dict(max_shots=0), "^max_shots must be an integer in"),
    "make: constrain_aim=1": ({}, "make", dict(constrain_aim=1), "^constrain_aim must be True or False"),
    "make: start=3": ({}, "make", dict(start=3), "^start must be one of"),
    "make: render_mode": ({}, "make", dict(render_mode="window"), "^render_mode must be one of"),
    "make: foul_penalty='1'": ({}, "make", dict(foul_penalty="1"), "^foul_penalty must be a finite number"),
    "make: noise sigma 1e308": ({}, "make", dict(noise={"sigma_aim_deg": 1e308}), "^NoiseModel.sigma_aim_deg must be at most"),
    "make: physics squirt='no'": ({}, "make", dict(physics={"squirt": "no"}), "^PhysicsParams.squirt must be True or False"),
    "step: u=5": (dict(constrain_aim=True), "step", [5.0, 0.0, 0.0, 0.0], r'^"action" has the aim constraint: u .* \[-1, 1\]'),
    "step: u=1e30": (dict(constrain_aim=True), "step", [1e30, 0.0, 0.0, 0.0], r'^"action" has the aim constraint'),
    "step: raw u=-1.5": (dict(constrain_aim=True, normalize_actions=False), "step", [-1.5, 0.5, 0.0, 0.0],
                         r'^"action" has the aim constraint'),
    "step: masked": ({}, "step", MASKED4, '^"action" must be a plain array'),
    "step: complex": ({}, "step", COMPLEX4, '^"action" must hold real numbers'),
    "step: a list with a string": ({}, "step", STRING4, '^"action" must hold real numbers'),
    "step: 0-d": ({}, "step", ZERO_D, r'^"action" must have shape \(4,\)'),
    "step: inf": ({}, "step", INF4, '^"action" must hold finite numbers'),
    "step: booleans": ({}, "step", BOOL4, '^"action" must hold real numbers'),
    "reset: complex positions": ({}, "reset", RACK + 0j, r'^options\["positions"\] must hold real numbers'),
    "reset: masked positions": ({}, "reset", np.ma.masked_array(RACK), r'^options\["positions"\] must be a plain array'),
    "reset: 0-d positions": ({}, "reset", np.array(0.5), r'^options\["positions"\] must have shape \(4, 2\)'),
}


def _gym_step(env, seed=0):
    env.reset(seed=seed)
    obs, reward, *_ = env.step(np.array([0.1, 0.2, 0.0, 0.0], dtype=np.float32))
    return obs, reward


@pytest.mark.parametrize("case", sorted(GYM_CASES))
def test_the_gym_env_refuses_bad_input_naming_it_and_plays_on(case):
    options, kind, bad, name = GYM_CASES[case]
    expected = _gym_step(Billiards4BallInningEnv(**options))
    if kind == "make":
        _refused(lambda: Billiards4BallInningEnv(**options, **bad), name)
        env = Billiards4BallInningEnv(**options)
    else:
        env = Billiards4BallInningEnv(**options)
        env.reset(seed=0)
        _refused((lambda: env.step(bad)) if kind == "step" else (lambda: env.reset(options={"positions": bad})), name)
    obs, reward = _gym_step(env)
    np.testing.assert_array_equal(obs, expected[0])
    assert reward == expected[1]


VECTOR_CASES = {
    "make: num_envs=True": ({}, "make", dict(num_envs=True), "^num_envs must be an integer.*boolean"),
    "make: num_envs=1.5": ({}, "make", dict(num_envs=1.5), "^num_envs must be an integer"),
    "make: num_envs=-0.0": ({}, "make", dict(num_envs=-0.0), "^num_envs must be an integer"),
    "make: num_envs=0": ({}, "make", dict(num_envs=0), "^num_envs must be an integer >= 1"),
    "make: num_envs='2'": ({}, "make", dict(num_envs="2"), "^num_envs must be an integer"),
    "make: max_shots=True": ({}, "make", dict(num_envs=2, max_shots=True), "^max_shots must be an integer"),
    "step: u=5 in row 1": (dict(constrain_aim=True), "step", [[0.0, 0.0, 0.0, 0.0], [5.0, 0.0, 0.0, 0.0]],
                           r'^"action" has the aim constraint.*got 5.0 in row 1'),
    "step: masked": ({}, "step", np.ma.array([MASKED4.data] * 2, mask=[MASKED4.mask] * 2), '^"action" must be a plain array'),
    "step: complex": ({}, "step", np.stack([COMPLEX4] * 2), '^"action" must hold real numbers'),
    "step: a list with a string": ({}, "step", [STRING4, STRING4], '^"action" must hold real numbers'),
    "step: 0-d": ({}, "step", ZERO_D, r'^"action" must have shape \(2, 4\)'),
    "reset: complex positions": ({}, "reset", RACK + 0j, r'^options\["positions"\] must hold real numbers'),
}


def _vector_step(env):
    env.reset(seed=0)
    obs, reward, *_ = env.step(np.array([[0.1, 0.2, 0.0, 0.0]] * 2, dtype=np.float32))
    return obs, reward


@pytest.mark.parametrize("case", sorted(VECTOR_CASES))
def test_the_vector_env_refuses_bad_input_naming_it_and_plays_on(case):
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    options, kind, bad, name = VECTOR_CASES[case]
    expected = _vector_step(Billiards4BallVectorEnv(2, **options))
    if kind == "make":
        _refused(lambda: Billiards4BallVectorEnv(**bad), name)
        env = Billiards4BallVectorEnv(np.int64(2), **options)  # a NumPy integer is an integer
    else:
        env = Billiards4BallVectorEnv(2, **options)
        env.reset(seed=0)
        _refused((lambda: env.step(bad)) if kind == "step" else (lambda: env.reset(options={"positions": bad})), name)
    obs, reward = _vector_step(env)
    np.testing.assert_array_equal(obs, expected[0])
    np.testing.assert_array_equal(reward, expected[1])


def _meta(td):
    td = td.clone().clear_device_()
    td["action"] = torch.zeros(2, 4, device="meta")
    return td


TORCHRL_CASES = {  # (make_env options, make / step, the bad input: make_env kwargs or a change to the reset td, name)
    "make: batch_size=1.5": ({}, "make", dict(batch_size=1.5), "^batch_size must be an integer"),
    "make: batch_size=True": ({}, "make", dict(batch_size=True), "^batch_size must be an integer.*boolean"),
    "make: batch_size=-0.0": ({}, "make", dict(batch_size=-0.0), "^batch_size must be an integer"),
    "make: batch_size=0": ({}, "make", dict(batch_size=0), "^batch_size must be an integer B >= 1"),
    "make: batch_size=[2, 2]": ({}, "make", dict(batch_size=[2, 2]), "^batch_size must be an integer"),
    "make: max_shots=True": ({}, "make", dict(max_shots=True), "^max_shots must be an integer"),
    "make: max_shots=inf": ({}, "make", dict(max_shots=float("inf")), "^max_shots must be an integer"),
    "make: noise sigma 1e308": ({}, "make", dict(noise={"sigma_speed": 1e308}), "^NoiseModel.sigma_speed must be at most"),
    "make: params squirt=2": ({}, "make", dict(params={"squirt": 2}), "^PhysicsParams.squirt must be True or False"),
    "make: gentle='0.2'": ({}, "make", dict(gentle="0.2"), "^gentle must be a finite number"),
    "step: meta action": ({}, "step", _meta, '^"action" must hold values, got a tensor on the meta device'),
    "step: complex action": ({}, "step", lambda td: td.set("action", torch.tensor([[0.1 + 1j, 0.5, 0, 0]] * 2)),
                             '^"action" must hold real numbers'),
    "step: boolean action": ({}, "step", lambda td: td.set("action", torch.ones(2, 4, dtype=torch.bool)),
                             '^"action" must hold real numbers'),
    "step: u=5 (AimConstraint)": (dict(constrain_aim=True), "step", lambda td: td.set("action", torch.tensor([[5.0, 0.5, 0, 0]] * 2)),
                                  r'^"action" has the aim constraint.*\[-1, 1\]'),
    "step: u=1e30 normalised": (dict(constrain_aim=True, normalize_actions=True), "step",
                                lambda td: td.set("action", torch.tensor([[1e30, 0.0, 0, 0]] * 2)), r'^"action" has the aim constraint'),
    "step: noise_level 1e30": (dict(noise="variable"), "step", lambda td: td.set("noise_level", torch.full((2, 1), 1e30)),
                               r'^"noise_level" must lie in \[0, 5\]'),
    "step: noise_level -1": (dict(noise="variable"), "step", lambda td: td.set("noise_level", torch.full((2, 1), -1.0)),
                             r'^"noise_level" must lie in \[0, 5\]'),
    "step: fractional shot": ({}, "step", lambda td: td.set("shot", torch.full((2, 1), 0.5)), '^"shot" must hold integers'),
    "step: complex positions": ({}, "step", lambda td: td.set("positions", td["positions"].to(torch.complex128)),
                                '^"positions" must hold real numbers'),
}


def _torchrl_step(env, bad=None):
    td = env.reset()
    td["action"] = torch.tensor([[0.1, 0.5, 0.0, 0.0]] * 2)  # inside every action space here
    return env.step(bad(td.clone()) if bad else td)["next"]


@pytest.mark.parametrize("case", sorted(TORCHRL_CASES))
def test_the_torchrl_env_refuses_bad_input_naming_it_and_plays_on(case):
    options, kind, bad, name = TORCHRL_CASES[case]
    expected = _torchrl_step(make_env(2, seed=0, **options))
    if kind == "make":
        kwargs = {"batch_size": 2, **options, **bad}
        _refused(lambda: make_env(kwargs.pop("batch_size"), seed=0, **kwargs), name)
        env = make_env(np.int64(2), seed=0, **options)  # a NumPy integer is a size
    else:
        env = make_env(2, seed=0, **options)
        td = env.reset()
        td["action"] = torch.tensor([[0.1, 0.5, 0.0, 0.0]] * 2)
        _refused(lambda: env.step(bad(td.clone())), name)
        env.set_seed(0)  # the refused step drew nothing: the next inning replays as a fresh env's
    got = _torchrl_step(env)
    for key in ("positions", "reward", "observation"):
        torch.testing.assert_close(got[key], expected[key], rtol=0, atol=0)


SAGU_CASES = {  # (env options, make / call, the bad input, name)
    "make: target=True": ({}, "make", dict(target=True), "^target must be an integer.*boolean"),
    "make: target=1.5": ({}, "make", dict(target=1.5), "^target must be an integer"),
    "make: max_innings=0": ({}, "make", dict(max_innings=0), "^max_innings must be an integer"),
    "make: start=3": ({}, "make", dict(start=3), "^start must be one of"),
    "make: first='red'": ({}, "make", dict(first="red"), "^first must be one of"),
    "make: noise sigma 1e308": ({}, "make", dict(noise={"sigma_aim_deg": 1e308}), "^NoiseModel.sigma_aim_deg must be at most"),
    "make: constrain_aim='yes'": ({}, "make", dict(constrain_aim="yes"), "^constrain_aim must be True or False"),
    "make: physics squirt=nan": ({}, "make", dict(physics={"squirt": float("nan")}), "^PhysicsParams.squirt"),
    "observe('black')": ({}, "call", lambda env: env.observe("black"), r"^agent must be one of \('white', 'yellow'\), got 'black'"),
    "action_space(None)": ({}, "call", lambda env: env.action_space(None), "^agent must be one of"),
    "observation_space(0)": ({}, "call", lambda env: env.observation_space(0), "^agent must be one of"),
    "reset first='red'": ({}, "call", lambda env: env.reset(seed=0, options={"first": "red"}), r'^options\["first"\] must be one of'),
    "step: u=5": (dict(constrain_aim=True), "call", lambda env: env.step(np.array([5.0, 0.0, 0, 0])), r'^"action" has the aim constraint'),
    "step: masked": ({}, "call", lambda env: env.step(MASKED4), '^"action" must be a plain array'),
    "step: complex": ({}, "call", lambda env: env.step(COMPLEX4), '^"action" must hold real numbers'),
    "step: a list with a string": ({}, "call", lambda env: env.step(STRING4), '^"action" must hold real numbers'),
    "step: 0-d": ({}, "call", lambda env: env.step(ZERO_D), r'^"action" must have shape \(4,\)'),
}


def _sagu_play(env):
    env.reset(seed=0)
    env.step(np.array([0.1, 0.2, 0.0, 0.0], dtype=np.float32))
    return env.agent_selection, env.observe("white"), dict(env.rewards)


@pytest.mark.parametrize("case", sorted(SAGU_CASES))
def test_the_pettingzoo_env_refuses_bad_input_naming_it_and_plays_on(case):
    pytest.importorskip("pettingzoo")
    from billiards.envs import sagu_v0

    options, kind, bad, name = SAGU_CASES[case]
    expected = _sagu_play(sagu_v0.env(**options))
    if kind == "make":
        _refused(lambda: sagu_v0.env(**options, **bad), name)
        env = sagu_v0.env(**options)
    else:
        env = sagu_v0.env(**options)
        env.reset(seed=0)
        _refused(lambda: bad(env), name)
    agent, obs, rewards = _sagu_play(env)
    assert agent == expected[0] and rewards == expected[2]
    np.testing.assert_array_equal(obs, expected[1])
