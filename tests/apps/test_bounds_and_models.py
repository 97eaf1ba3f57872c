"""Hostile input, second pass (docs/reliability.md): numbers are checked with finite bounds on
the resolved config, and model files are checked for what they mean, not only for their seal.

* Mechanism 4, "Numbers with bounds after resolution": each bad value, given literally, through
  ``${oc.decode:...}`` and through an interpolation of another key, is refused by the app's
  validator with a sentence naming the key (in this process, through Hydra's compose API as the
  apps compose); a resolver other than the project's and Hydra's own is refused by name; one
  app run checks that nothing is written.
* Mechanism 5, "Model files checked for meaning": for each file kind (exported policy, training
  checkpoint, shot ranker, table value, reward model) a file corrupted and then sealed again
  (``save_tagged`` / ``save_checkpoint``) is refused on load with a sentence naming the file, and
  an app that names it refuses it while validating, before its run directory exists.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import ConfigCompositionException

import billiards.league.config as match_config
import billiards.rl.config as train_config
import billiards.rl.validation as train_validation
import billiards.search.config as search_config
from billiards.files import ROOT, SEAL_KEY, save_tagged

CONF = str(ROOT / "conf")
VALIDATE = {"config": train_validation.validate, "search": search_config.validate, "match": match_config.validate}


@pytest.fixture(scope="module", autouse=True)
def hydra_conf():
    """One Hydra context for the module: its config loader keeps what it has listed (the
    options --help shows), and a composition takes a fraction of a second."""
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        yield


def composed(app: str, *overrides: str):
    return compose(app, overrides=list(overrides))


def refusal(app: str, *overrides: str) -> str:
    """The validator's message for ``app`` composed with ``overrides`` (a value Hydra refuses while
    composing counts: its message names the key too)."""
    try:
        cfg = composed(app, *overrides)
    except ConfigCompositionException as err:
        return f"{err} {err.__cause__}"
    with pytest.raises(ValueError) as err:
        VALIDATE[app](cfg)
    return str(err.value)


# ----------------------------------------------------------------------------- mechanism 4

# (app, key, bad value, what the refusal says, (a key whose own valid value is bad here, that value)),
# and the app's extra overrides
BAD_NUMBERS = [
    ("config", "env.num_envs", "99999999999", "env.num_envs must be at most 65,536", ("budget.total_steps", "100000"), ()),
    ("config", "algo.lr", "1e308", "algo.lr must be at most 1 ", ("budget.cpu_minutes", "5"), ()),
    ("config", "algo.lr", "nan", "algo.lr", None, ()),
    ("config", "algo.utd", "1e308", "algo.utd must be at most 64", ("budget.cpu_minutes", "100"), ()),
    ("config", "algo.utd", "2147483647", "algo.utd must be at most 64", None, ()),
    ("config", "algo.alpha_init", "1e308", "algo.alpha_init must be at most 1,000", ("budget.cpu_minutes", "5000"), ()),
    ("config", "shaping.foul_penalty", "1e308", "shaping.foul_penalty must be at most 100", ("budget.cpu_minutes", "500"), ()),
    ("config", "budget.total_steps", "2000000000", "budget.total_steps must be at most 1,000,000,000",
     ("paper_steps", "2000000000"), ()),
    ("config", "algo.buffer_size", "100000000", "algo.buffer_size must be at most 10,000,000", None, ()),
    ("config", "algo.hidden_sizes", "[1000000]", "algo.hidden_sizes must be at most 4,096", None, ()),
    ("config", "noise.aim_deg", "1e308", "noise.aim_deg", ("budget.cpu_minutes", "5"), ("noise=fastfiz",)),
    ("config", "noise.speed", "1e308", "noise.speed", ("budget.cpu_minutes", "5"), ("noise=fastfiz",)),
    ("config", "noise.tip_mm", "1e308", "noise.tip_mm", ("budget.cpu_minutes", "50"), ("noise=fastfiz",)),
    ("config", "noise.scale", "1e308", "noise.scale must be at most 20", ("budget.cpu_minutes", "50"), ("noise=fastfiz",)),
    ("search", "search.budget", "200000", "search.budget must be at most 100,000", ("protocol.cap", "200000"), ()),
    ("search", "proposer.pool", "1000000", "proposer.pool must be at most 100,000", ("protocol.cap", "200000"),
     ("proposer=ranked",)),
    ("search", "search.c_puct", "1e308", "search.c_puct must be at most 100", ("protocol.cap", "200000"), ("search=puct",)),
    ("match", "agents.safety_t.threshold", "1e308", "agents.safety_t.threshold must be null or lie in [0, 1]",
     ("foul_penalty", "2"), ()),
    ("match", "foul_penalty", "1e308", "foul_penalty must be at most 100", None, ()),
    ("match", "target", "99999999999", "target must be at most 10,000", None, ()),
]


def _cases():
    for app, key, value, says, source, extra in BAD_NUMBERS:
        yield pytest.param(app, [*extra, f"{key}={value}"], key, says, id=f"{app}:{key}={value}")
        yield pytest.param(app, [*extra, f"{key}=${{oc.decode:'{value}'}}"], key, "oc.decode", id=f"{app}:{key}=oc.decode")
        if source is not None:
            yield pytest.param(app, [*extra, f"{key}=${{{source[0]}}}", f"{source[0]}={source[1]}"], key, says,
                               id=f"{app}:{key}=${{{source[0]}}}")
    for resolver in ("oc.env:HOME", "oc.create:'[1]'", "oc.select:algo.lr"):
        yield pytest.param("config", [f"algo.lr=${{{resolver}}}"], "algo.lr", resolver.split(":")[0], id=resolver)


@pytest.mark.parametrize("app, overrides, key, says", list(_cases()))
@pytest.mark.slow
def test_a_number_out_of_bounds_is_refused_literally_through_a_resolver_and_through_an_interpolation(app, overrides, key, says):
    message = refusal(app, *overrides)
    assert key in message and says in message, message


@pytest.mark.slow
def test_the_bounds_are_listed_in_the_docs_and_the_shipped_configurations_keep_within_them():
    """Every schema's UPPER bound is a row of docs/reliability.md's table (the key and the bound);
    the shipped presets and experiments pass; the config's noise cap is match.py's."""
    from billiards.envs.sagu import MAX_NOISE_LEVEL, noise_cap_error
    from billiards.league.players import PLAYERS
    from billiards.physics.noise import PRACTICAL_LEVEL, NoiseModel, practical_noise_error

    docs = (ROOT / "docs" / "reliability.md").read_text()
    table = docs[docs.index("## Numbers with bounds after resolution"):]
    schemas = {"algo.": [*train_config.ALGO_SCHEMAS.values()], "env.": [train_config.EnvConfig],
               "shaping.": [train_config.ShapingConfig], "budget.": [train_config.BudgetConfig],
               "eval.": [train_config.EvalConfig], "": [train_config.TrainConfig, match_config.MatchAppConfig],
               "search.": [*search_config.OPTIONS["search"][1].values()],
               "protocol.": [search_config.P1Config, search_config.P3Config], "proposer.": [search_config.RankedProposerConfig],
               "agents.<name>.": [p for p in PLAYERS.values() if hasattr(p, "UPPER")]}
    for prefix, classes in schemas.items():
        for schema in classes:
            for key, (hi, _) in schema.UPPER.items():
                bound = f"{int(hi):,}" if float(hi).is_integer() and hi >= 1000 else f"{hi:g}"
                row = next((line for line in table.splitlines() if f"`{prefix}{key}`" in line), None)
                assert row is not None and bound in row, (prefix, key, bound, row)
    assert PRACTICAL_LEVEL == MAX_NOISE_LEVEL
    for top in (1.0, 9.9, 10.0, 10.5):  # the config's cap and match.py's agree on the aim
        model = NoiseModel(sigma_aim_deg=0.125 * top)
        assert (practical_noise_error(model) is None) == (noise_cap_error(model) is None)
    for app, overrides in [("config", ["experiment=table5", "variant=table5/both"]), ("config", ["algo=ppo_paper"]),
                           ("config", ["algo=td3_paper", "noise=fastfiz_x5", "noise.scale=2"]),
                           ("search", ["noise=fastfiz", "noise.scale=5", "protocol=p3_paper"]), ("match", [])]:
        VALIDATE[app](composed(app, *overrides))


@pytest.mark.slow
def test_an_app_refuses_a_bound_before_writing_anything(tmp_path):
    from conftest import app_here

    proc = app_here("train.py", "algo.utd=2147483647", f"hydra.run.dir={tmp_path}/run", cwd=tmp_path)
    assert proc.returncode == 1 and "algo.utd must be at most 64" in proc.stderr, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr and list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- mechanism 5


def _tagged(name: str) -> dict:
    payload = torch.load(ROOT / name, map_location="cpu", weights_only=True)
    payload.pop(SEAL_KEY)
    return payload


def _complex(t: torch.Tensor) -> torch.Tensor:
    return t.to(torch.complex64)


def _policy(change):
    p = _tagged("results/policies/base/seed0.pt")
    change(p)
    return p


def _first(d: dict) -> str:
    return next(iter(d))


POLICY_CASES = {
    "a config of 28 inputs for a 32-input actor": (lambda p: p["config"]["env"].update(extra_features=False), "shape (256, 32)"),
    "complex weights": (lambda p: p["actor"].update({_first(p["actor"]): _complex(p["actor"][_first(p["actor"])])}),
                        "complex64, not of real floating-point numbers"),
    "an interpolation in its config": (lambda p: p["config"]["shaping"].update(rm_model="${oc.env:HOME}"), "an interpolation"),
    "negative hidden sizes": (lambda p: p["config"]["algo"].update(hidden_sizes=[-5]), "hidden_sizes=[-5]"),
    "no actor": (lambda p: p.pop("actor"), "'actor' is missing"),
    "no config": (lambda p: p.pop("config"), "'config' is missing"),
    "another algorithm": (lambda p: p["config"]["algo"].update(name="dqn"), "algo.name='dqn'"),
}


def _mlp_cases(what: str) -> dict:
    meta = lambda p, **kw: json.dumps({**json.loads(p["meta"]), **kw})  # noqa: E731
    return {
        "a zero scale": (lambda p: p["std"].__setitem__(3, 0.0), "a feature's scale must be > 0"),
        "complex weights": (lambda p: p["weights"].__setitem__(0, _complex(p["weights"][0])), "not of real floating-point"),
        "no metadata": (lambda p: p.pop("meta"), "'meta' is missing"),
        "metadata without a table": (lambda p: p.update(meta=json.dumps({"noise": {}})), "'physics_params' is missing"),
        "a table that is not one": (lambda p: p.update(meta=meta(p, physics_params={"table_width": -1.0})), "not valid"),
        "layers that do not chain": (lambda p: p["weights"].__setitem__(1, p["weights"][1][:5]), "do not chain"),
    }


RM_CASES = {
    "negative hidden sizes": (lambda p: p.update(hidden=[-5]), "hidden=[-5]"),
    "hidden sizes its weights do not have": (lambda p: p.update(hidden=[16, 16]), "shape (128, 13)"),
    "complex weights": (lambda p: p["state_dict"].update({"net.0.weight": _complex(p["state_dict"]["net.0.weight"])}),
                        "not of real floating-point"),
    "an interpolation in its metadata": (lambda p: p["meta"].update(data_dir="${oc.env:HOME}"), "an interpolation"),
    "no weights": (lambda p: p.pop("state_dict"), "'state_dict' is missing"),
}


def _model_cases():
    for name, (change, says) in POLICY_CASES.items():
        yield pytest.param("policy", change, says, id=f"policy: {name}")
    for kind in ("ranker", "value"):
        for name, (change, says) in _mlp_cases(kind).items():
            yield pytest.param(kind, change, says, id=f"{kind}: {name}")
    for name, (change, says) in RM_CASES.items():
        yield pytest.param("rm", change, says, id=f"reward model: {name}")


SHIPPED = {"policy": "results/policies/base/seed0.pt", "ranker": "results/rankers/fastfiz/ranker.pt",
           "value": "results/values/value.pt", "rm": "results/rm/model.pt"}


def _loader(kind: str):
    from billiards.rl.checkpoint import CheckpointError
    from billiards.rl.policy import load_policy
    from billiards.rm.model import RewardModelError, load_model
    from billiards.search.ranker import RankerFileError, ShotRanker
    from billiards.search.value import TableValue, ValueFileError

    return {"policy": (load_policy, CheckpointError), "ranker": (ShotRanker.load, RankerFileError),
            "value": (TableValue.load, ValueFileError), "rm": (load_model, RewardModelError)}[kind]


def _naming(kind: str, path: Path) -> list[tuple[str, list[str]]]:
    """(app, overrides) of each app that names a file of ``kind`` at ``path`` in its config."""
    return {
        "policy": [("search", ["proposer=policy", f"proposer.checkpoints=[{path}]"]),
                   ("match", [f"agents.sac.policy={path}", "players=[sac,random]"])],
        "ranker": [("search", ["noise=fastfiz", "proposer=ranked", f"proposer.ranker={path}"])],
        "value": [("search", ["noise=fastfiz", "search=robust", "search.position=1", f"search.value={path}"]),
                  ("match", [f"agents.greedy_v.overrides.value={path}", "players=[greedy_v,random]"])],
        "rm": [("config", ["shaping=rm", f"shaping.rm_model={path}"])],
    }[kind]


@pytest.mark.parametrize("kind, change, says", list(_model_cases()))
@pytest.mark.slow
def test_a_resealed_model_file_that_means_nothing_is_refused_on_load_and_by_each_app_naming_it(tmp_path, kind, change, says):
    payload = _tagged(SHIPPED[kind])
    change(payload)
    path = save_tagged(tmp_path / "resealed.pt", payload)
    load, error = _loader(kind)
    with pytest.raises(error) as err:
        load(path)
    assert str(path) in str(err.value) and says in str(err.value), str(err.value)
    for app, overrides in _naming(kind, path):
        message = refusal(app, *overrides)
        assert "resealed.pt" in message and says in message, (app, message)


# a training checkpoint as the trainer writes one (a small SAC agent, a replay buffer of 64 frames,
# an evaluation history), and what a resealed one may hold that no run could have written
ROWS = 64


def _checkpoint(run_dir: Path, change=None) -> Path:
    from omegaconf import OmegaConf

    from billiards.rl.checkpoint import agent_from_config, rng_state, save_checkpoint

    config = OmegaConf.to_container(composed("config", "budget=smoke", "algo.hidden_sizes=[8]", "env=aim_features"),
                                    resolve=True, enum_to_str=True)
    agent, _ = agent_from_config(config)
    extra = agent.state_dict_extra()
    first = agent.optimizer.param_groups[0]["params"][0]
    extra["optimizer"]["state"] = {0: {"step": torch.tensor(3.0), "exp_avg": torch.zeros_like(first),
                                       "exp_avg_sq": torch.zeros_like(first)}}
    obs = lambda: torch.zeros(ROWS, 32)  # noqa: E731
    flags = lambda: torch.zeros(ROWS, 1, dtype=torch.bool)  # noqa: E731
    state = {"config": config, "agent": agent.state_dict(), "agent_extra": extra,
             "buffer": {"data": {"observation": obs(), "action_norm": torch.zeros(ROWS, 4),
                                 "next": {"observation": obs(), "reward": torch.zeros(ROWS, 1), "done": flags(),
                                          "terminated": flags()}},
                        "rows": ROWS, "writer": {"_cursor": ROWS, "_write_count": ROWS}},
             "counters": {"frames": ROWS, "owed": 0.0, "train_seconds": 1.0, "cpu_seconds": 1.0, "next_log": 256,
                          "next_eval": 1024, "next_ckpt": 1024},
             "eval_history": [{"step": ROWS, "final": False, "eval_mean": 0.5, "start": "random"}],
             "rng": rng_state(np.random.default_rng(0)), "collector": None, "wandb_id": None, "stage_log": []}
    if change is not None:
        change(state)
    run_dir.mkdir(parents=True, exist_ok=True)
    return save_checkpoint(run_dir, state)


CHECKPOINT_CASES = {
    "an impossible buffer size": (lambda c: c["buffer"].update(rows=10**9), "buffer.rows=1000000000"),
    "a buffer of another row count": (lambda c: c["buffer"]["data"].update(action_norm=torch.zeros(3, 4)), "3 rows"),
    "NaN in the replay buffer": (lambda c: c["buffer"]["data"]["next"]["reward"].__setitem__(5, float("nan")),
                                 "buffer.data.next.reward: holds NaN"),
    "another algorithm": (lambda c: c["config"]["algo"].update(name="td3"), "not the network its config describes"),
    "an unknown algorithm": (lambda c: c["config"]["algo"].update(name="dqn"), "algo.name='dqn'"),
    "a malformed evaluation history": (lambda c: c.update(eval_history=[{"step": "x"}]), "eval_history[0]"),
    "an evaluation history of numbers": (lambda c: c.update(eval_history=[5]), "eval_history[0]"),
    "a wrong-shape optimiser state": (lambda c: c["agent_extra"]["optimizer"]["state"][0].update(exp_avg=torch.zeros(2, 2)),
                                      "agent_extra.optimizer.state.0.exp_avg: shape (2, 2)"),
    "an interpolation in its config": (lambda c: c["config"]["logger"].update(project="${oc.env:HOME}"), "an interpolation"),
    "negative hidden sizes": (lambda c: c["config"]["algo"].update(hidden_sizes=[-5]), "hidden_sizes=[-5]"),
    "complex weights": (lambda c: c["agent"].update({_first(c["agent"]): _complex(c["agent"][_first(c["agent"])])}),
                        "not of real floating-point"),
    "updates owed past a batch": (lambda c: c["counters"].update(owed=1e12), "owed=1000000000000.0"),
}


def test_a_checkpoint_as_the_trainer_writes_it_passes(tmp_path):
    from billiards.rl.checkpoint import load_checkpoint
    from billiards.rl.policy import policy_file_error

    _checkpoint(tmp_path / "run")
    assert load_checkpoint(tmp_path / "run")["counters"]["frames"] == ROWS
    assert policy_file_error(tmp_path / "run") is None
    train_validation.validate(composed("config", f"resume={tmp_path / 'run'}"))


@pytest.mark.parametrize("change, says", list(CHECKPOINT_CASES.values()), ids=list(CHECKPOINT_CASES))
@pytest.mark.slow
def test_a_resealed_checkpoint_that_means_nothing_is_refused_on_load_and_by_each_app_naming_it(tmp_path, change, says):
    from billiards.rl.checkpoint import CheckpointError, load_checkpoint

    path = _checkpoint(tmp_path / "run", change)
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(tmp_path / "run")
    assert str(path) in str(err.value) and says in str(err.value), str(err.value)
    for app, overrides in [("config", [f"resume={tmp_path / 'run'}"]),
                           ("search", ["proposer=policy", f"proposer.checkpoints=[{tmp_path / 'run'}]"])]:
        message = refusal(app, *overrides)
        assert "checkpoint.pt" in message and says in message, (app, message)
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["checkpoint.pt"]


@pytest.mark.slow
@pytest.mark.parametrize("app, kind, overrides", [
    ("train.py", "rm", ["shaping=rm", "shaping.rm_model={f}"]),
    ("search.py", "ranker", ["noise=fastfiz", "proposer=ranked", "proposer.ranker={f}"]),
    ("match.py", "policy", ["agents.sac.policy={f}", "players=[sac,random]"]),
])
def test_an_app_naming_a_file_that_means_nothing_writes_nothing(tmp_path, app, kind, overrides):
    payload = _tagged(SHIPPED[kind])
    key = {"rm": "state_dict", "ranker": "std", "policy": "actor"}[kind]
    if kind == "ranker":
        payload["std"][0] = 0.0
    else:
        payload.pop(key)
    path = save_tagged(tmp_path / "resealed.pt", payload)
    from conftest import app_here

    proc = app_here(app, *(o.format(f=path) for o in overrides), f"hydra.run.dir={tmp_path}/run", cwd=tmp_path)
    assert proc.returncode == 1 and "resealed.pt" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["resealed.pt"]


def test_a_stop_request_is_seen_between_two_gradient_updates_and_the_rest_stay_owed():
    """The trainer's update loop (utd x a batch's frames updates) looks for a stop request before
    each update: a run signalled amid thousands of updates stops after the one in progress, and
    what it did not make is owed to its resumed run (checkpointed in the run state)."""
    from types import SimpleNamespace

    from billiards.rl.checkpoint import RunState
    from billiards.rl.train import StopRequests, gradient_updates

    made = []
    stop = StopRequests()

    def update(batch):
        made.append(batch)
        if len(made) == 3:
            stop.signum = 15  # as the handler records SIGTERM
        return {}

    run = SimpleNamespace(state=RunState(owed=0.5), agent=SimpleNamespace(update=update), rb=SimpleNamespace(sample=lambda: 0),
                          window=SimpleNamespace(metrics=None))
    assert not gradient_updates(run, stop, run.state.take_updates(64 * 32 - 0.5))
    assert len(made) == 3 and math.isclose(run.state.owed, 64 * 32 - 3 + 0.0)
    assert run.state.take_updates(0.0) == 64 * 32 - 3 and run.state.owed == 0.0
