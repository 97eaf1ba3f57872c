"""billiards.compat is the one place that knows what earlier versions wrote: each older form it
names, built from a file of today by taking away what that form lacked (or adding what it
held), upgrades to today's form; a file of today goes through unchanged; and no other module
of the package mentions an older form."""

from __future__ import annotations

import copy
import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

from billiards import compat
from billiards.compat import SCHEMA_KEY

REPO = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------------------- files of today


def _training_config() -> dict:
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf

    import billiards.rl.config  # noqa: F401  (registers the training app's schemas)

    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base=None):
        cfg = compose("config", ["budget=smoke"])
    return OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)


def _checkpoint() -> dict:
    """The content of a checkpoint of today (every entry :func:`RunState.capture` writes, small)."""
    from billiards.rl.checkpoint import FORMAT_VERSION, REQUIRED, rng_state

    rngs = {"env": np.random.default_rng(1), "env_noise": np.random.default_rng([1, 1])}
    state = {"format_version": FORMAT_VERSION, SCHEMA_KEY: compat.CHECKPOINT.version, "config": _training_config(),
             "agent": {}, "agent_extra": {}, "buffer": None,
             "counters": {"frames": 0, "owed": 0.0, "train_seconds": 0.0, "cpu_seconds": 0.0, "next_log": 256,
                          "next_eval": 512, "next_ckpt": 768},
             "eval_history": [], "rng": rng_state(rngs), "collector": None, "wandb_id": None, "stage_log": []}
    assert set(REQUIRED) <= set(state)
    state["rng"]["torch"] = state["rng"]["torch"].tolist()  # plain values: compared with ==
    return state


def _eval_record() -> dict:
    from billiards.evaluation import summarize

    score = np.array([[1, 1, 0], [0, 1, 1]], dtype=bool)
    return dataclasses.asdict(summarize(score, np.zeros_like(score), seed=3, noise="fastfiz"))


def _artefact_meta() -> dict:
    from billiards.physics.config import physics_record
    from billiards.physics.params import PRESETS

    return {"n": 100, "seed": 0, "chunk": 10, **physics_record(PRESETS["korean_medium"])}


TODAY = {"training config": _training_config, "search config": _training_config, "training checkpoint": _checkpoint,
         "evaluation record": _eval_record, "artefact's metadata": _artefact_meta}


def _set(d: dict, path: str, value) -> None:
    *parents, leaf = path.split(".")
    for key in parents:
        d = d.setdefault(key, {})
    d[leaf] = value


def _discard(d: dict, path: str) -> None:
    *parents, leaf = path.split(".")
    for key in parents:
        d = d.get(key) if isinstance(d, dict) else None
    if isinstance(d, dict):
        d.pop(leaf, None)


def _international(today: dict) -> dict:
    from billiards.physics.params import PRESETS

    out = copy.deepcopy(today)
    if "physics_params" in out:  # an artefact's metadata: the table's label and fields
        out.update(physics="international", physics_params=PRESETS["international"].to_dict())
    else:  # a config's node: the preset, no overrides
        out["physics"] = {**{k: None for k in out["physics"]}, "preset": "international"}
    return out


def _expected(kind: str, step: str, today: dict) -> dict:
    """Today's file as the upgrade of the older form gives it: what the older form lacked, as
    the step fills it in (the values those files were written with)."""
    out = copy.deepcopy(today)
    if step == "physics":
        return _international(today)
    if step == "noise" and kind == "evaluation record":
        out["noise"] = "none"  # exact play
    elif step == "noise":  # exact play: the node of that time, then scale 1 and no level range
        out["noise"] = {"preset": "none", "aim_deg": None, "speed": None, "tip_mm": None, "scale": 1.0, "level_range": None}
    if step == "noise.scale":
        out["noise"].update(scale=1.0, level_range=None)
    if kind == "training checkpoint":
        out["rng"]["env_noise"] = None  # not saved: the generator keeps its seeded state
    if step == "first_miss_points":
        out["first_miss_points"] = []  # not recorded
    return out


@pytest.mark.parametrize("kind", sorted(compat.CHAINS))
@pytest.mark.slow
def test_each_older_form_upgrades_to_todays(kind):
    chain = compat.CHAINS[kind]
    today = TODAY[kind]()
    assert chain.upgrade(copy.deepcopy(today)) == today, "a file of today goes through unchanged"
    assert chain.steps and [s.version for s in chain.steps] == list(range(1, len(chain.steps) + 1))
    oldest = copy.deepcopy(today)
    oldest.pop(SCHEMA_KEY, None)  # the oldest form carries no version
    expected_oldest = today
    for step in chain.steps:
        older = copy.deepcopy(today)
        older.pop(SCHEMA_KEY, None)
        for path in step.added:
            _discard(older, path)
            _discard(oldest, path)
        for path in step.dropped:
            _set(older, path, 0)
            _set(oldest, path, 0)
        assert older != today, f"{kind}, step {step.name}: the older form differs from today's"
        kept = copy.deepcopy(older)
        upgraded = chain.upgrade(older)
        assert upgraded == _expected(kind, step.name, today), f"{kind}, step {step.name} ({step.what})"
        assert older == kept, "the file read is not changed"
        assert chain.upgrade(upgraded) == upgraded
        expected_oldest = _expected(kind, step.name, expected_oldest)
    assert chain.upgrade(oldest) == expected_oldest, f"{kind}: the oldest form, every step at once"


@pytest.mark.slow
def test_a_file_of_a_newer_version_is_refused_and_a_checkpoint_without_one_is_the_oldest():
    state = _checkpoint()
    with pytest.raises(compat.NewerFormError, match="written by a newer version of billiards"):
        compat.upgrade_checkpoint({**state, SCHEMA_KEY: compat.CHECKPOINT.version + 1})
    old = {k: v for k, v in state.items() if k not in (SCHEMA_KEY, "collector", "stage_log")}
    old["rng"] = {k: v for k, v in state["rng"].items() if k != "env_noise"}
    old["config"] = {k: v for k, v in state["config"].items() if k not in ("physics", "noise")}
    up = compat.upgrade_checkpoint(old)
    assert up[SCHEMA_KEY] == compat.CHECKPOINT.version and up["collector"] is None and up["stage_log"] == []
    assert up["rng"]["env_noise"] is None and up["config"]["physics"]["preset"] == "international"
    assert up["config"]["noise"] == state["config"]["noise"]  # exact play, as it was
    assert compat.checkpoint_format_refusal(b"PK\x03\x04rest") and compat.checkpoint_format_refusal(b"billiards") is None


def test_search_configs_drop_the_other_options_keys_of_the_old_union_nodes():
    today = {"search": {"kind": "h2", "budget": 400, "k1": 60}, "protocol": {"name": "p3", "seeds": 3},
             "proposer": {"name": "geometric"}, "seed": 0}
    own = {"search": {"kind", "budget", "k1"}, "protocol": {"name", "seeds"}, "proposer": {"name"}}
    older = copy.deepcopy(today)
    older["search"].update(c_puct=1.5, pw_c=2.0)  # another option's keys in the one union node
    older["proposer"]["power_low"] = 0.1
    up = compat.upgrade_search_config(older, lambda group, node: own[group])
    assert {g: up[g] for g in own} == {g: today[g] for g in own}
    assert up["physics"]["preset"] == "international" and up["noise"]["preset"] == "none" and up["noise"]["scale"] == 1.0


def test_committed_policy_files_are_read_in_todays_form():
    """The shipped policies' noise nodes predate noise.scale and variable noise: read through
    compat they have both, and nothing else changes."""
    from billiards.files import load_tagged
    from billiards.rl.checkpoint import CheckpointError
    from billiards.rl.policy import POLICY_FORMAT

    path = REPO / "results/policies/fastfiz_aim_features/seed0.pt"
    payload = load_tagged(path, POLICY_FORMAT, CheckpointError, "exported policy")
    assert "scale" not in payload["config"]["noise"]
    up = compat.upgrade_policy_file(payload)
    assert up["config"]["noise"] == {**payload["config"]["noise"], "scale": 1.0, "level_range": None}
    assert {k: v for k, v in up["config"].items() if k != "noise"} == {k: v for k, v in payload["config"].items() if k != "noise"}
    assert up["eval"] == payload["eval"] and compat.upgrade_policy_file(up) == up


def test_ledgers_of_every_form_are_read_by_views_and_only_todays_by_a_resume(tmp_path):
    """Form 0: no seal; form 1: a seal without the run's identity; today: sealed with it."""
    from billiards.files import CHAINS, LedgerError, append_record, read_ledger, sealed_record

    rec = lambda seed: {"seed": seed, "length": 2, "decisions": 3, "seconds": 0.5, "last_shots": [[[0.1], [0.2], True]]}  # noqa: E731
    path = tmp_path / "chains.jsonl"
    path.write_text(json.dumps(rec(0)) + "\n" + json.dumps(sealed_record(rec(1))) + "\n")
    append_record(path, rec(2), "abc")
    assert [r["seed"] for r in compat.ledger_records(path, CHAINS)] == [0, 1, 2]
    assert compat.ledger_scan(path.read_bytes(), "x", CHAINS).unchecked == [1, 2]
    with pytest.raises(LedgerError, match="line 1 is not an intact P3 chain record: it carries no seal"):
        read_ledger(path, CHAINS)
    path.write_text(json.dumps(sealed_record(rec(1))) + "\n")
    with pytest.raises(LedgerError, match="line 1 is not an intact P3 chain record: it carries no run identity"):
        read_ledger(path, CHAINS)


# ----------------------------------------------------------------------------- nobody else knows


# What would name an older form of a file, a fallback for one or its history
OLDER_FORM = re.compile(r"\blegacy\b|written before|saved before|\bolder\b|before (it|they) existed|earlier versions?\b",
                        re.IGNORECASE)
NOT_A_FORM = {  # (file, what the line holds): why it is not about an older form
    ("billiards/rl/checkpoint.py", "get_state(legacy=False)"): "numpy's own keyword: the state as a dict",
}
def test_no_module_but_compat_mentions_an_older_form():
    found = []
    for path in sorted((REPO / "billiards").rglob("*.py")):
        name = path.relative_to(REPO).as_posix()
        if name == "billiards/compat.py":
            continue
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if OLDER_FORM.search(line) and not any(f == name and what in line for f, what in NOT_A_FORM):
                found.append(f"{name}:{n}: {line.strip()}")
    assert not found, "only billiards/compat.py reads older forms; move these there:\n" + "\n".join(found)


def test_the_grep_finds_what_it_looks_for():
    for line in ("# absent from configs saved before it existed", "legacy=True", "written by an older version",
                 "checkpoints written before it existed", "keys configs saved by earlier versions have"):
        assert OLDER_FORM.search(line), line
    for line in ("the folders it reads", "holder", "before the first miss"):
        assert not OLDER_FORM.search(line), line
