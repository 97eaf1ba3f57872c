"""The campaign runner (billiards.campaign): the paper's declarative run list, spec checks,
and one tiny campaign run for real -- drained after its first checkpoint, resumed to the end,
skipped once finished, flagged stale when its definition changes -- with status and --dry-run
read off the same state. The training processes are real ``train.py`` runs of a few hundred
steps; the whole file takes about a minute on one core."""

from __future__ import annotations

import io
import json
import os
import threading
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
import yaml

from billiards.campaign import Campaign, Entry, SpecError, load_spec, paper_campaign
from billiards.campaign.__main__ import main
from billiards.campaign.ledger import LEDGER, STARTS
from billiards.campaign.runner import Runner, parse_deadline
from billiards.campaign.status import entry_states, summarize

REPO = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------------------- the paper's list


def test_paper_campaign_lists_every_table_at_its_budget():
    c = paper_campaign()
    by_table = {}
    for e in c.select(None):
        by_table.setdefault(e.table, []).append(e)
    assert {t: len(v) for t, v in by_table.items()} == {
        "table1": 15, "table2": 12, "table4": 9, "table3": 15, "table5": 15, "table6": 20}
    runs = [e for e in c.select(None) if e.kind == "train" and not e.same_as]
    assert len(runs) == 15 + 9 + 9 + 9 + 12
    for e in runs:
        assert "physics=korean_medium" in e.args and f"seed={e.seed}" in e.args and "budget=paper" in e.args
        assert e.steps == (400_000 if e.table in ("table1", "table2") else 1_000_000)
        assert f"paper_steps={e.steps}" in e.args and f"table={e.table}" in e.args
    ppo = [e for e in runs if e.variant == "ppo"]
    assert len(ppo) == 5 and all("algo=ppo_paper" in e.args for e in ppo)
    assert all("algo=sac" in e.args for e in runs if e.table != "table1")
    shared = {e.key: e.same_as for e in c.entries if e.same_as}
    assert shared["table2/random_continue/seed2"] == "table1/sac/seed2"
    assert shared["table3/aim/seed0"] == "table4/aim/seed0" and shared["table5/aim_features/seed1"] == "table4/aim_features/seed1"
    searches = [e for e in c.entries if e.kind == "search"]
    assert len(searches) == 5 * 2 * 2 and all("search.budget=400" in e.args for e in searches)
    base = c.by_key()["table6/base/puct_p3"]
    # Table 6 searches the shipped ensembles (committed files), 20 chains per P3 cell
    assert base.needs() == [] and "proposer=base" in base.args and "protocol.cap=10000" in base.args
    assert "protocol.seeds=20" in base.args and not any("checkpoints" in a for a in base.args)
    # the optional run of the authors' SAC runs only when asked for
    assert "extra/sac_paper/seed0" not in {e.key for e in c.select(None)}
    assert [e.key for e in c.select(["extra"])] == ["extra/sac_paper/seed0"]
    assert all(e.optional for e in c.entries if e.table == "extra")
    # --only table2 brings the Table 1 SAC runs its random_continue row shares
    assert {e.key for e in c.select(["table2"])} >= {"table1/sac/seed0", "table1/sac/seed2"}


def _compose_all(overrides_lists):
    """The training configs of several command lines, composed in one Hydra context."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    import billiards.rl.config  # noqa: F401  (schema and resolvers)

    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        return [compose("config", overrides=list(o)) for o in overrides_lists]


@pytest.mark.slow
def test_paper_training_runs_compose_and_validate():
    """Every training run's overrides compose through the real Hydra config and pass the
    trainer's validation, with the table, seed, budget, table physics and variant intended."""
    from billiards.rl.config import validate

    c = paper_campaign()
    runs = [e for e in c.entries if e.kind == "train" and not e.same_as]
    # the seeds of a variant differ in nothing but the seed, so composing seed 0 checks them all
    for e in runs:
        seed0 = c.by_key()[f"{e.table}/{e.variant}/seed0"]
        assert [a for a in e.args if not a.startswith("seed=")] == [a for a in seed0.args if not a.startswith("seed=")]
    firsts = [e for e in runs if e.seed == 0]
    shared_check = [c.by_key()["table4/aim/seed1"].args,
                    ["table=table3", "paper_steps=1000000", "budget=paper", "physics=korean_medium", "algo=sac", "variant=aim", "seed=1"]]
    *configs, t4, t3 = _compose_all([e.args for e in firsts] + shared_check)
    for e, cfg in zip(firsts, configs):
        validate(cfg)
        assert (cfg.table, cfg.seed, cfg.budget.total_steps, cfg.physics.preset) == (e.table, e.seed, e.steps, "korean_medium"), e.key
        env, shaping = cfg.env, cfg.shaping
        if e.table in ("table1", "table2"):
            assert [str(getattr(s, "value", s)) for s in cfg.eval.starts] == ["random", "canonical"]
            assert not env.constrain_aim and shaping.name == "none"
        if e.table == "table1":
            assert cfg.algo.name == e.variant and env.paradigm.value == "random_continue"
        if e.table == "table2":
            assert env.paradigm.value == e.variant and cfg.algo.name == "sac"
        if e.table == "table3":
            assert (shaping.rm > 0, cfg.curriculum.name) == {"staged": (False, "staged"), "rm": (True, "none"),
                                                            "rm_aim": (True, "none")}[e.variant]
            assert env.constrain_aim == (e.variant == "rm_aim")
        if e.table == "table4":
            assert (env.constrain_aim, env.extra_features) == {"plain": (False, False), "aim": (True, False),
                                                               "aim_features": (True, True)}[e.variant]
        if e.table == "table5":
            assert env.constrain_aim and env.extra_features and shaping.name == e.variant and shaping.foul_penalty == 1.0
        if e.table == "extra":  # the authors' SAC on Table 1's task and on Table 5's first two rows
            assert (cfg.algo.name, cfg.algo.utd, cfg.algo.lr, cfg.algo.gamma) == ("sac", 1.0, 3e-4, 0.99)
            t5 = e.variant.startswith("sac_paper_t5_")
            assert (env.constrain_aim, env.extra_features, cfg.budget.total_steps) == (t5, t5, 1_000_000 if t5 else 400_000)
            assert shaping.foul_penalty == (1.0 if e.variant.endswith("foul_penalty") else 0.0)
    # a shared row is the same training config as its source (Table 3's own preset, variant=aim),
    # only the table label differs
    t3.table = t4.table
    assert t3 == t4


# ----------------------------------------------------------------------------- spec checks


@pytest.mark.parametrize("entries, message", [
    ([Entry("t", "a", seed=0, steps=1), Entry("t", "a", seed=0, steps=1)], "listed twice"),
    ([Entry("t", "a", seed=0, steps=1, after=("t/b",))], "refers to 't/b'"),
    ([Entry("t", "a", kind="train", steps=0)], "budget in steps"),
    ([Entry("t", "a", kind="fit", steps=1)], "kind must be one of"),
    ([Entry("t", "../a", steps=1)], "plain path names"),
    ([Entry("t", "a", steps=1, after=("t/b",)), Entry("t", "b", steps=1, after=("t/a",))], "cycle"),
    ([Entry("t", "a", steps=1), Entry("t", "b", same_as="t/a"), Entry("t", "c", same_as="t/b")], "itself shared"),
])
def test_bad_campaigns_are_refused_naming_the_entry(entries, message):
    with pytest.raises(SpecError, match=message):
        Campaign("bad", entries)


def test_spec_files_are_checked(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nruns:\n  - {table: t, variant: a, steps: 5, sede: 1}\n")
    with pytest.raises(SpecError, match="unknown: sede"):
        load_spec(bad)
    bad.write_text("!!python/object/apply:os.system ['echo hacked']\n")
    with pytest.raises(SpecError, match="cannot be read"):
        load_spec(bad)
    with pytest.raises(SpecError, match="does not exist"):
        load_spec(tmp_path / "missing.yaml")
    with pytest.raises(SpecError, match="no such table"):
        paper_campaign().select(["table7"])


def test_deadline_parsing():
    now = time.mktime((2026, 1, 1, 20, 0, 0, 0, 0, -1))
    assert parse_deadline(1.5, None, now) == now + 5400
    assert parse_deadline(None, "21:30", now) == now + 5400
    assert parse_deadline(None, "19:00", now) == now + 23 * 3600  # tomorrow
    assert parse_deadline(None, None, now) is None
    for hours, until, msg in ((0.0, None, "--hours"), (None, "25:00", "HH:MM"), (None, "9", "HH:MM"), (1.0, "10:00", "not both")):
        with pytest.raises(SpecError, match=msg):
            parse_deadline(hours, until, now)


# ----------------------------------------------------------------------------- a tiny campaign, for real

TINY_ARGS = ["table=t1", "budget=smoke", "budget.total_steps=1024", "budget.checkpoint_every=256", "budget.eval_every=0",
             "budget.init_random_steps=128", "budget.log_every=128", "budget.final_eval_innings=4", "env.num_envs=16",
             "algo=sac", "algo.hidden_sizes=[32,32]", "algo.batch_size=32", "seed=0"]


def _tiny_spec(path: Path, args=TINY_ARGS) -> Path:
    path.write_text(yaml.safe_dump({"name": "tiny", "runs": [
        {"table": "t1", "variant": "a", "seed": 0, "steps": 1024, "cost": "sac", "args": list(args)},
        {"table": "t2", "variant": "shared", "seed": 0, "same_as": "t1/a/seed0"},
        {"table": "t3", "variant": "b", "seed": 0, "steps": 1024, "cost": "sac", "args": list(args)},
    ]}))
    return path


def cli(*argv: str) -> tuple[int, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        rc = main(list(argv))
    return rc, out.getvalue() + err.getvalue()


def _ledger(root: Path) -> dict:
    return json.loads((root / LEDGER).read_text())


def test_a_drained_run_is_stopped_after_its_next_checkpoint_not_its_last(tmp_path):
    """Draining waits for a checkpoint written after the drain began: one the run wrote earlier
    (its work since then would be lost) does not count, and neither does none at all."""
    from billiards.campaign.runner import Slot

    entry = Entry("t1", "a", "train", 0, ("seed=0",), 1024, "sac")
    ckpt = tmp_path / "checkpoint.pt"
    slot = Slot(entry, tmp_path, pid=os.getpid())
    assert not slot.checkpointed()  # the drain has not begun
    slot.drain_began()
    assert not slot.checkpointed()  # no checkpoint yet
    ckpt.write_bytes(b"first")
    assert slot.checkpointed()  # the first checkpoint came after the drain began

    old = Slot(entry, tmp_path, pid=os.getpid())  # a run that checkpointed before the drain
    os.utime(ckpt, ns=(1_000_000_000, 1_000_000_000))
    old.drain_began()
    assert not old.checkpointed()
    os.utime(ckpt, ns=(2_000_000_000, 2_000_000_000))  # its next checkpoint
    assert old.checkpointed()
    ckpt.unlink()
    assert not old.checkpointed()


def test_a_run_with_long_checkpoint_intervals_drains_one_interval_before_the_deadline(tmp_path):
    """A run whose checkpoints are further apart than the grace (the authors' SAC: ~13 min)
    drains on its own when its next checkpoint is its last before the deadline: its interval
    comes from its eval history until two checkpoints written while watched measure it; it is
    stopped right after that checkpoint (nothing lost) and not started again, while a run with
    short intervals keeps running."""
    import subprocess

    from billiards.campaign.runner import HARD_STOP, LEAD_MARGIN, Slot, checkpoint_interval_estimate

    spec = _tiny_spec(tmp_path / "tiny.yaml")
    root = tmp_path / "state"
    slow_dir, fast_dir = root / "t1" / "a" / "seed0", root / "t3" / "b" / "seed0"
    for d, per_step in ((slow_dir, 0.016), (fast_dir, 0.002)):  # wall seconds per step
        d.mkdir(parents=True)
        (d / "config.yaml").write_text(yaml.safe_dump({"budget": {"checkpoint_every": 50_000}}))
        (d / "eval_history.jsonl").write_text("".join(json.dumps(
            {"step": k * 50_000, "wall_time": 10.0 + k * 50_000 * per_step, "final": False}) + "\n" for k in (1, 2, 3)))
    assert checkpoint_interval_estimate(slow_dir) == pytest.approx(800.0)
    assert checkpoint_interval_estimate(tmp_path) is None  # no history: the grace alone

    campaign = load_spec(spec)
    runner = Runner(campaign, root, deadline=time.time() + 600.0, grace=120.0, out=io.StringIO())
    procs = [subprocess.Popen(["sleep", "60"], start_new_session=True) for _ in range(2)]
    try:
        slow, fast = (Slot(campaign.by_key()[k], d, p.pid, p) for k, d, p in
                      (("t1/a/seed0", slow_dir, procs[0]), ("t3/b/seed0", fast_dir, procs[1])))
        assert (slow.checkpoint_interval(), fast.checkpoint_interval()) == (pytest.approx(800.0), pytest.approx(100.0))
        runner.slots += [slow, fast]
        assert runner.lead_reached(slow) and not runner.lead_reached(fast) and not runner.draining()
        runner.step()
        assert slow.drain_seen and not slow.draining and not fast.drain_seen  # waiting for the slow run's checkpoint
        (slow_dir / "checkpoint.pt").write_bytes(b"its last before the deadline")
        runner.step()
        assert slow.draining and slow.term_at is not None and fast.term_at is None
        assert "t1/a/seed0" in runner.wound_down and "t1/a/seed0" not in {e.key for e in runner.runnable()}
        log = runner.out.getvalue()
        assert "drain  t1/a/seed0: checkpoints every 13.3 min, its next is its last before the deadline" in log
    finally:
        for p in procs:
            p.kill()
            p.wait()

    # two checkpoints written while watched measure the interval, replacing the estimate
    watched = Slot(campaign.by_key()["t1/a/seed0"], slow_dir, os.getpid())
    for second in (1_000, 1_030):
        os.utime(slow_dir / "checkpoint.pt", ns=(second * 10**9, second * 10**9))
        watched.watch()
    assert watched.checkpoint_interval() == pytest.approx(30.0)
    late = Runner(campaign, root, deadline=time.time() + HARD_STOP + LEAD_MARGIN * 30.0 + 60.0)
    assert not late.lead_reached(watched)


@pytest.mark.slow
def test_tiny_campaign_drains_resumes_skips_and_counts(tmp_path):
    spec, root = _tiny_spec(tmp_path / "tiny.yaml"), tmp_path / "state"
    common = ("--spec", str(spec), "--root", str(root), "--only", "t1,t2")
    run_dir = root / "t1" / "a" / "seed0"

    # --dry-run: the command that would run; nothing written
    rc, out = cli("run", *common, "--dry-run")
    assert rc == 0 and f"fresh         t1/a/seed0: train.py {' '.join(TINY_ARGS)}" in out
    assert f"hydra.run.dir={run_dir}" in out and "left (shared) t2/shared/seed0 = t1/a/seed0" in out
    assert "t3/b" not in out and not root.exists()

    # first invocation, drained (`stop`) while the run trains: stopped right after its first checkpoint
    log = io.StringIO()
    first = Runner(load_spec(spec), root, only=["t1", "t2"], poll=0.1, out=log)
    result = {}
    runner = threading.Thread(target=lambda: result.update(left=first.run()))
    runner.start()
    deadline = time.time() + 120
    while time.time() < deadline and not ((root / LEDGER).is_file() and _ledger(root)["runs"].get("t1/a/seed0", {}).get("pid")):
        time.sleep(0.1)
    rc2, out2 = cli("run", *common)  # a second runner on the same root is refused
    assert rc2 == 2 and "another runner" in out2
    assert f"a runner is active (pid {os.getpid()})" in cli("status", *common)[1]
    assert cli("stop", *common)[0] == 0
    runner.join(timeout=240)
    assert not runner.is_alive() and result["left"] == 2, log.getvalue()
    rec = _ledger(root)["runs"]["t1/a/seed0"]
    assert [s["outcome"] for s in rec["starts"]] == ["stopped"] and rec["starts"][0]["mode"] == "fresh"
    assert rec["starts"][0]["cpu_seconds"] > 0 and rec["pid"] is None and len(rec["commits"]) == 1
    assert (run_dir / "checkpoint.pt").is_file() and not (run_dir / "eval.json").exists()
    assert log.getvalue().count("drain  t1/a/seed0") == 1 and "end   t1/a/seed0: stopped" in log.getvalue()

    states = {s.entry.key: s for s in entry_states(load_spec(spec), root)}
    assert states["t1/a/seed0"].state == "resumable" and 0 < states["t1/a/seed0"].frames < 1024
    tables = summarize(list(states.values()))
    assert (tables["t1"]["done"], tables["t1"]["left"], tables["t2"]["left"], tables["t3"]["left"]) == (0, 1, 1, 1)
    rc, out = cli("run", *common, "--dry-run")
    assert f"resume        t1/a/seed0: train.py resume={run_dir} threads=1" in out

    # second invocation: resumes from the checkpoint and finishes
    rc, out = cli("run", *common, "--poll", "0.1")
    assert rc == 0, out
    rec = _ledger(root)["runs"]["t1/a/seed0"]
    assert [(s["mode"], s["outcome"]) for s in rec["starts"]] == [("fresh", "stopped"), ("resume", "finished")]
    assert rec["starts"][1]["frames"] > 0
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["frames"] == 1024 and (run_dir / "eval.json").is_file()
    lines = [json.loads(x) for x in (run_dir / STARTS).read_text().splitlines()]
    assert [x.get("mode") or x["outcome"] for x in lines] == ["fresh", "stopped", "resume", "finished"]
    assert lines[0]["commit"] == rec["commits"][0] and "resume=" in " ".join(lines[2]["command"])
    assert "start  t1/a/seed0 (resume at" in out
    train_log = (run_dir / "train.log").read_text()
    assert "t1/a/seed0, fresh at commit" in train_log and "t1/a/seed0, resume at commit" in train_log
    assert "final eval (random start)" in train_log  # the trainer's own log lines land there too

    # status: t1 done, its shared row in t2 done, t3 (not selected) left; CPU from the summary
    rc, out = cli("status", "--spec", str(spec), "--root", str(root))
    assert rc == 0 and "no runner active" in out
    assert "| t1 | 1 | 1 (0) | 0 | 0 (0, 0, 0) |" in out and "| t2 | 1 | 1 (1) | 0 | 0 (0, 0, 0) |" in out
    assert "| t3 | 1 | 0 (0) | 0 | 1 (0, 0, 0) |" in out
    assert f"{summary['cpu_seconds'] / 3600:.2f}" in out.split("| t1 |")[1].split("\n")[0]

    # third invocation: everything selected is done, nothing starts
    t0 = time.time()
    rc, out = cli("run", *common)
    assert rc == 0 and "start " not in out and "2 of 2 entries done" in out and time.time() - t0 < 10
    assert len(_ledger(root)["runs"]["t1/a/seed0"]["starts"]) == 2

    # --check-config: the run's config.yaml is what its arguments compose to now; an edited one is not
    rc, out = cli("status", *common, "--check-config")
    assert rc == 0 and "the 1 started training runs match" in out
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())
    (run_dir / "config.yaml").write_text(yaml.safe_dump({**saved, "algo": {**saved["algo"], "lr": 0.5}}))
    rc, out = cli("status", *common, "--check-config")
    assert rc == 4 and "t1/a/seed0: algo.lr = 0.5 in the run, 0.001 now" in out
    # a run started before an option existed (no `noise` node) has not drifted: a resume gives the
    # option its default; a key missing under a group its arguments set (algo=sac) has
    (run_dir / "config.yaml").write_text(yaml.safe_dump({k: v for k, v in saved.items() if k != "noise"}))
    assert "noise" in saved and cli("status", *common, "--check-config")[0] == 0
    (run_dir / "config.yaml").write_text(yaml.safe_dump({**saved, "algo": {k: v for k, v in saved["algo"].items() if k != "lr"}}))
    rc, out = cli("status", *common, "--check-config")
    assert rc == 4 and "t1/a/seed0: algo.lr = None in the run, 0.001 now" in out

    # the definition changes: the finished run is stale, not re-run without --restart-stale
    _tiny_spec(spec, [a if a != "algo.batch_size=32" else "algo.batch_size=16" for a in TINY_ARGS])
    rc, out = cli("status", "--spec", str(spec), "--root", str(root))
    assert "| t1 | 1 | 0 (0) | 0 | 1 (0, 0, 1) |" in out
    rc, out = cli("run", *common, "--dry-run")
    assert "stale         t1/a/seed0" in out
    rc, out = cli("run", *common)
    assert rc == 3 and "start " not in out and len(_ledger(root)["runs"]["t1/a/seed0"]["starts"]) == 2

    # --restart-stale: the old dir is moved aside, the run starts over under the new definition
    rc, out = cli("run", *common, "--restart-stale", "--poll", "0.1")
    assert rc == 0 and "start  t1/a/seed0 (fresh)" in out, out
    moved = list(run_dir.parent.glob("seed0.stale-*"))
    assert len(moved) == 1 and json.loads((moved[0] / "summary.json").read_text())["frames"] == 1024
    assert yaml.safe_load((run_dir / "config.yaml").read_text())["algo"]["batch_size"] == 16
    rec = _ledger(root)["runs"]["t1/a/seed0"]
    assert rec["args"][-2] == "algo.batch_size=16" and len(rec["archived"]) == 1
    assert [s["outcome"] for s in rec["starts"]] == ["stopped", "finished", "finished"]


@pytest.mark.slow
def test_search_runs_compose_with_the_shipped_policies(tmp_path):
    """Table 6's search.py overrides compose through conf/search.yaml and validate; a policy
    proposer plays the three committed policy files of its shipped ensemble."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from billiards.campaign.ledger import fill
    from billiards.search.config import validate
    c = paper_campaign()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        searches = [x for x in c.entries if x.kind == "search"]
        for e in searches:  # the policy proposers' entries differ only in the proposer's name
            assert [a.replace(e.variant.split("/")[0], "P") for a in e.args] == \
                [a.replace("base", "P") for a in c.by_key()[f"table6/base/{e.variant.split('/')[1]}"].args] or \
                e.variant.startswith("geometric")
        for e in (x for x in searches if x.variant.split("/")[0] in ("base", "geometric")):
            cfg = compose("search", overrides=[fill(a, tmp_path) for a in e.args])
            proposer, rest = e.variant.split("/")
            assert (cfg.proposer.name, f"{cfg.search.kind}_{cfg.protocol.name}", cfg.search.budget) == (proposer, rest, 400)
            assert cfg.physics.preset == "korean_medium"
            validate(cfg)
            if proposer != "geometric":
                assert list(cfg.proposer.checkpoints) == [f"results/policies/{proposer}/seed{s}.pt" for s in range(3)]
                assert all((REPO / p).is_file() for p in cfg.proposer.checkpoints)


@pytest.mark.parametrize("args,message", [
    (["budget=smoke", "+hydra.callbacks.x._target_=torch.load", "+hydra.callbacks.x.f=evil.pt"], "configs are data here"),
    (["budget=smoke", "hydra.run.dir=elsewhere"], "Hydra's own settings (hydra.*) are the runner's"),
    (["--experimental-rerun"], "is not accepted here"),
])
def test_a_spec_file_is_data_and_may_not_name_code(tmp_path, args, message):
    """A campaign spec's arguments pass the apps' own check before anything runs or is written."""
    spec = tmp_path / "evil.yaml"
    spec.write_text(yaml.safe_dump({"name": "evil", "runs": [{"table": "t", "variant": "x", "seed": 0, "args": args}]}))
    rc, out = cli("run", "--spec", str(spec), "--root", str(tmp_path / "state"))
    assert rc == 2 and message in out and not (tmp_path / "state").exists()


@pytest.mark.slow
def test_a_failing_run_is_retried_then_left_alone(tmp_path):
    """A run whose command fails (here an unknown config key) is tried MAX_FAILURES times,
    each failure recorded with its exit status; then runs leave it alone until --retry-failed."""
    from billiards.campaign.runner import MAX_FAILURES

    spec = tmp_path / "bad.yaml"
    spec.write_text(yaml.safe_dump({"name": "bad", "runs": [
        {"table": "t", "variant": "x", "seed": 0, "steps": 10, "args": ["budget=smoke", "algo.lrr=1"]}]}))
    root = tmp_path / "state"
    rc, out = cli("run", "--spec", str(spec), "--root", str(root), "--poll", "0.1")
    assert rc == 3 and f"see {root / 't' / 'x' / 'seed0' / 'train.log'}" in out
    rec = _ledger(root)["runs"]["t/x/seed0"]
    assert rec["failures"] == MAX_FAILURES and all(s["outcome"] == "failed (exit 1)" for s in rec["starts"])
    assert "algo.lrr" in (root / "t" / "x" / "seed0" / "train.log").read_text()
    rc, out = cli("status", "--spec", str(spec), "--root", str(root))
    assert "| t | 1 | 0 (0) | 0 | 1 (0, 1, 0) |" in out
    rc, out = cli("run", "--spec", str(spec), "--root", str(root))
    assert rc == 3 and "start " not in out


@pytest.mark.slow
def test_a_run_left_by_a_killed_runner_is_adopted_not_started_twice(tmp_path):
    """The ledger names a live process running the entry (its runner was killed, it was not):
    status counts it as running; a new runner waits for it instead of starting a duplicate."""
    import subprocess
    import sys

    spec = _tiny_spec(tmp_path / "tiny.yaml")
    root = tmp_path / "state"
    run_dir = (root / "t1" / "a" / "seed0").resolve()
    run_dir.mkdir(parents=True)
    # a process standing in for the orphaned training run: its command line names the run dir
    orphan = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)", f"hydra.run.dir={run_dir}"],
                              start_new_session=True)
    from billiards.campaign.ledger import pid_alive

    ready = time.time() + 10  # a loaded machine may take a moment to show the new command line
    while not pid_alive(orphan.pid, run_dir) and time.time() < ready:
        time.sleep(0.05)
    try:
        (root / LEDGER).write_text(json.dumps({"campaign": "tiny", "runs": {"t1/a/seed0": {
            "args": TINY_ARGS, "starts": [{"commit": "abc1234", "started": "x", "mode": "fresh", "frames": 0}],
            "commits": ["abc1234"], "pid": orphan.pid, "failures": 0}}}))
        rc, out = cli("status", "--spec", str(spec), "--root", str(root), "--only", "t1")
        assert "| t1 | 1 | 0 (0) | 1 | 0 (0, 0, 0) |" in out
        log = io.StringIO()
        runner = Runner(load_spec(spec), root, only=["t1"], poll=0.1, out=log)
        thread = threading.Thread(target=runner.run)
        thread.start()
        until = time.time() + 20
        while "adopt  t1/a/seed0" not in log.getvalue() and time.time() < until:
            time.sleep(0.05)
        (root / "STOP").touch()  # drain: nothing may start once the orphan ends (set after the runner cleared it)
        time.sleep(0.5)
        assert thread.is_alive() and "adopt  t1/a/seed0" in log.getvalue() and "start " not in log.getvalue()
        orphan.kill()
        orphan.wait()
        thread.join(timeout=30)
        assert not thread.is_alive()
    finally:
        orphan.kill()
    rec = _ledger(root)["runs"]["t1/a/seed0"]
    assert rec["pid"] is None and rec["starts"][-1]["outcome"] == "ended (adopted, exit status unknown)"
    assert len(rec["starts"]) == 1 and "start " not in log.getvalue()


def test_a_stopped_search_is_not_done_and_p3_resumes(tmp_path):
    """A search stopped by the runner leaves a results.json marked partial: not done; a P3
    continues with `search.py resume=<dir>`, a P1 starts over."""
    c, root = paper_campaign(), tmp_path / "state"
    p3, p1 = (root / "table6" / "geometric" / f"h2_{p}" for p in ("p3", "p1"))
    for run_dir, proto in ((p3, "p3"), (p1, "p1")):
        run_dir.mkdir(parents=True)
        (run_dir / "config.yaml").write_text(yaml.safe_dump({"protocol": {"name": proto}}))
        (run_dir / "results.json").write_text(json.dumps({"shots": 120, "seconds": 6.0, "extra": {"partial": True}}))
    rc, out = cli("run", "--root", str(root), "--only", "table6", "--dry-run")
    assert f"resume        table6/geometric/h2_p3: search.py resume={p3.resolve()} threads=1" in out
    assert "fresh         table6/geometric/h2_p1: search.py proposer=geometric" in out
    states = {s.entry.key: s.state for s in entry_states(c, root, c.select(["table6"]))}
    assert states["table6/geometric/h2_p3"] == "resumable" and states["table6/geometric/h2_p1"] == "new"
    (p3 / "results.json").write_text(json.dumps({"shots": 900, "seconds": 30.0, "extra": {}}))
    states = {s.entry.key: s for s in entry_states(c, root, c.select(["table6"]))}
    assert states["table6/geometric/h2_p3"].state == "done" and states["table6/geometric/h2_p3"].frames == 900


def _fake_run(run_dir: Path, table: str, seed: int, mean: float, best: int, canonical: float, frames: int,
              **config_extra) -> None:
    """A finished training run's small files, as train.py writes them (the numbers made up)."""
    run_dir.mkdir(parents=True)
    config = {"seed": seed, "table": table, "algo": {"name": "sac"}, "env": {"paradigm": "random_continue"},
              "physics": {"preset": "korean_medium"}, "budget": {"total_steps": frames}, **config_extra}
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config))
    ev = {"mean": mean, "best": best, "foul_innings_pct": 50.0 + seed, "foul_per_shot_pct": 10.0 + seed,
          "success_per_shot_pct": 4.0 + seed, "start": "random"}
    (run_dir / "eval.json").write_text(json.dumps(ev))
    (run_dir / "eval_canonical.json").write_text(json.dumps({**ev, "mean": canonical, "start": "canonical"}))
    (run_dir / "summary.json").write_text(json.dumps({"frames": frames, "cpu_seconds": 1800.0 * (seed + 1),
                                                       "physics": "korean_medium"}))
    (run_dir / "checkpoint.pt").write_bytes(b"weights")
    (run_dir / STARTS).write_text(json.dumps({"commit": f"c{seed}", "mode": "fresh"}) + "\n")


def test_report_writes_reproduction_rows_from_finished_runs(tmp_path):
    """`report`: Table 1's row aggregates the finished seeds (mean, population std, max, CPU-hours),
    Table 2's shared row reads the same runs, Table 6 rows come from results.json; the small
    files are copied, the checkpoints are not; unfinished rows say so."""
    spec = tmp_path / "mini.yaml"
    spec.write_text(yaml.safe_dump({"name": "mini", "runs": [
        *({"table": "table1", "variant": "sac", "seed": s, "steps": 400, "cost": "sac", "args": ["algo=sac"]} for s in range(3)),
        *({"table": "table2", "variant": "random_continue", "seed": s, "same_as": f"table1/sac/seed{s}"} for s in range(2)),
        {"table": "table6", "variant": "geometric/h2_p3", "kind": "search", "steps": 10, "cost": "h2", "args": ["search=h2"]},
        {"table": "table6", "variant": "geometric/puct_p1", "kind": "search", "steps": 10, "cost": "puct", "args": ["search=puct"]},
        {"table": "extra", "variant": "sac_paper", "seed": 0, "steps": 400, "cost": "sac_paper", "args": ["algo=sac_paper"]},
    ]}))
    root, out = tmp_path / "state", tmp_path / "results"
    for seed, mean, best, canonical in ((0, 0.5, 3, 1.0), (1, 0.3, 4, 0.0)):
        _fake_run(root / "table1" / "sac" / f"seed{seed}", "table1", seed, mean, best, canonical, 400)
    _fake_run(root / "extra" / "sac_paper" / "seed0", "extra", 0, 0.25, 2, 0.0, 400)
    search_dir = root / "table6" / "geometric" / "h2_p3"
    search_dir.mkdir(parents=True)
    (search_dir / "results.json").write_text(json.dumps({
        "protocol": "p3", "search": "h2", "proposer": "geometric", "mean": 228.9, "max": 496.0, "seconds": 36.0,
        "shots": 2289, "physics": "korean_medium", "sims_per_decision": 400, "values": [100.0] * 9 + [1389.0],
        "extra": {"cap": 10000, "seeds": list(range(10)), "reached_cap": 0}}))

    rc, text = cli("report", "--spec", str(spec), "--root", str(root), "--out", str(out))
    assert rc == 0, text
    data = json.loads((out / "reproduction.json").read_text())
    rows = {(r["table"], r.get("variant") or f"{r['proposer']}/{r['method']}_{r['protocol']}"): r for r in data["rows"]}
    sac = rows[(1, "sac")]
    assert sac["seeds"] == [0, 1] and sac["seeds_planned"] == [0, 1, 2] and not sac["complete"]
    assert sac["ours"]["mean"] == pytest.approx(0.4) and sac["ours"]["std"] == pytest.approx(0.1)
    assert sac["ours"]["max"] == 4 and sac["ours"]["foul_inn"] == pytest.approx(50.5)
    assert sac["paper"]["mean"] == 0.418 and sac["steps"] == 400 and sac["physics"] == "korean_medium"
    assert sac["cpu_hours"] == pytest.approx(1.5) and sac["commits"] == []  # no ledger starts: commits come from the runner
    shared = rows[(2, "random_continue")]
    assert shared["complete"] and shared["shared_with"] == ["table1/sac"]
    assert shared["ours"]["canonical"] == pytest.approx(0.5) and shared["ours"]["mean"] == pytest.approx(0.4)
    h2 = rows[(6, "geometric/h2_p3")]
    assert h2["complete"] and (h2["mean"], h2["max"], h2["cap"], h2["seeds"]) == (228.9, 496.0, 10000, list(range(10)))
    assert h2["proposer_steps"] == 0 and h2["paper"] is None and h2["cpu_hours"] == pytest.approx(0.01)
    lo, hi = h2["ci95"]  # percentile bootstrap of the mean: one long chain among ten short ones
    assert 100.0 <= lo < 228.9 < hi <= 1389.0 * 0.5
    assert not rows[(6, "geometric/puct_p1")]["complete"]
    copied = out / "training" / "mini" / "table1" / "sac" / "seed1"
    assert (copied / "eval_canonical.json").is_file() and (copied / STARTS).is_file()
    assert not (copied / "checkpoint.pt").exists()
    assert (out / "search" / "mini" / "table6" / "geometric" / "h2_p3" / "results.json").is_file()
    md = (out / "reproduction.md").read_text()
    assert "| sac | 2/3 | 400 | 0.400 ± 0.100 \\| 0.418 ± 0.038 |" in md
    assert f"| geometric | h2 | p3 | 228.9 (496) [{lo:.0f}, {hi:.0f}], 10 chains |" in md

    # the extra run sits beside the tables, compared with the paper's SAC row and ours
    assert all(r["table"] != "extra" for r in data["rows"])
    (extra,) = data["extra"]
    assert (extra["variant"], extra["paper_row"], extra["complete"], extra["seeds"]) == ("sac_paper", "sac", True, [0])
    assert extra["ours"]["mean"] == pytest.approx(0.25) and extra["paper"]["mean"] == 0.418

    # the copied run directories alone (no campaign state) give the same report
    from billiards.campaign.reproduction import write_report
    from billiards.campaign.spec import load_spec

    again = tmp_path / "again"
    write_report(load_spec(spec), None, again, results=out)
    regenerated = json.loads((again / "reproduction.json").read_text())
    # there the commits come from the runs' own start records (the fakes' c0, c1; the ledger had none)
    assert regenerated["rows"][0]["commits"] == ["c0", "c1"]
    strip = lambda d: [{k: v for k, v in r.items() if k != "commits"} for r in d["rows"] + d["extra"]]
    assert strip(regenerated) == strip(data) and regenerated["cpu_hours_by_table"] == data["cpu_hours_by_table"]
    assert "| sac_paper | 1/1 | 400 | 0.250 ± 0.000 | 2 | 50.0 | 0.50 |" in md
    assert "| Table 1 `sac` (project CPU settings) | 2/3 | 400 | 0.400 ± 0.100 | 4 | 50.5 |" in md

    rc, text = cli("report", "--spec", str(spec), "--root", str(tmp_path / "nowhere"), "--out", str(out))
    assert rc == 2 and "has not started" in text


def test_rand_eval_is_the_points_before_the_first_miss_of_the_random_start_evaluation(tmp_path):
    """Table 3's "rand. eval" column: the mean over seeds of each run's mean points before the
    first miss from random racks (eval.json when its start is random, else eval_random.json);
    missing ("–") unless every run recorded it."""
    from billiards.report import PAPER, aggregate, read_run

    runs = []
    for seed, streaks in ((0, [0, 1, 0, 0]), (1, [2, 0, 0, 0])):
        d = tmp_path / f"seed{seed}"
        _fake_run(d, "table3", seed, 0.5, 3, 0.0, 400)
        ev = json.loads((d / "eval.json").read_text())
        (d / "eval.json").write_text(json.dumps({**ev, "first_miss_points": streaks}))
        runs.append(read_run(d))
    assert aggregate(runs)["rand_eval"] == pytest.approx(0.375)
    legacy = tmp_path / "seed2"
    _fake_run(legacy, "table3", 2, 0.5, 3, 0.0, 400)
    assert aggregate([*runs, read_run(legacy)])["rand_eval"] is None
    assert "rand_eval" in PAPER["table3"]["columns"] and PAPER["table3"]["rows"]["plain"]["rand_eval"] == 0.053


def test_report_writes_table3_rand_eval_beside_the_papers(tmp_path):
    spec = tmp_path / "mini.yaml"
    spec.write_text(yaml.safe_dump({"name": "mini", "runs": [
        {"table": "table3", "variant": "plain", "seed": s, "steps": 400, "cost": "sac", "args": ["algo=sac"]} for s in range(2)]}))
    root, out = tmp_path / "state", tmp_path / "results"
    for seed, streaks in ((0, [0, 1, 0, 0]), (1, [2, 0, 0, 0])):
        d = root / "table3" / "plain" / f"seed{seed}"
        _fake_run(d, "table3", seed, 0.5, 3, 0.0, 400)
        ev = json.loads((d / "eval.json").read_text())
        (d / "eval.json").write_text(json.dumps({**ev, "first_miss_points": streaks}))
    rc, text = cli("report", "--spec", str(spec), "--root", str(root), "--out", str(out))
    assert rc == 0, text
    row = next(r for r in json.loads((out / "reproduction.json").read_text())["rows"] if r["table"] == 3)
    assert row["ours"]["rand_eval"] == pytest.approx(0.375) and row["paper"]["rand_eval"] == 0.053
    assert "0.375 \\| 0.053" in (out / "reproduction.md").read_text()


def test_report_draws_each_tables_learning_curves_from_its_finished_runs(tmp_path):
    """`report` draws, per table with a finished run, the mean over its finished seeds of their
    periodic evaluations (only steps all of them reached) to img/reproduction_<table>.png and
    links it under the table; an unfinished run's evaluations are left out."""
    from billiards.report import mean_curve, read_curve

    spec = tmp_path / "mini.yaml"
    spec.write_text(yaml.safe_dump({"name": "mini", "runs": [
        *({"table": "table1", "variant": "sac", "seed": s, "steps": 400, "cost": "sac", "args": ["algo=sac"]} for s in range(3)),
        *({"table": "extra", "variant": v, "seed": 0, "steps": 400, "cost": "sac_paper", "args": ["algo=sac_paper"]}
          for v in ("sac_paper", "sac_paper_t5_foul_penalty"))]}))
    root, out = tmp_path / "state", tmp_path / "results"
    for name, seed, evals in (("table1/sac", 0, [0.1, 0.3, 0.5]), ("table1/sac", 1, [0.3, 0.5]), ("table1/sac", 2, [0.9, 0.9, 0.9]),
                              ("extra/sac_paper", 0, [0.1, 0.2]), ("extra/sac_paper_t5_foul_penalty", 0, [1.0, 2.0])):
        d = root / name / f"seed{seed}"
        _fake_run(d, name.split("/")[0], seed, evals[-1], 3, 0.0, 400)
        (d / "eval_history.jsonl").write_text("".join(
            json.dumps({"step": 100 * (i + 1), "cpu_time": 60.0 * i, "wall_time": 60.0 * i, "eval_mean": m,
                        "eval_best": 2, "start": "random"}) + "\n" for i, m in enumerate(evals)))
    (root / "table1" / "sac" / "seed2" / "eval.json").unlink()  # seed 2 unfinished
    (root / "extra" / "sac_paper_t5_foul_penalty" / "seed0" / "eval.json").unlink()  # unfinished: no Table 5 extra figure

    steps, mean, std = mean_curve([read_curve(root / "table1" / "sac" / f"seed{s}") for s in (0, 1)])
    assert steps.tolist() == [100, 200] and mean == pytest.approx([0.2, 0.4]) and std == pytest.approx([0.1, 0.1])

    rc, text = cli("report", "--spec", str(spec), "--root", str(root), "--out", str(out))
    assert rc == 0, text
    figure = out / "img" / "reproduction_table1.png"
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # a finished extra run is drawn beside the variant it is compared with, in a figure of its own
    assert json.loads((out / "reproduction.json").read_text())["figures"] == {
        "table1": "img/reproduction_table1.png", "extra_table1": "img/reproduction_extra_table1.png"}
    assert (out / "img" / "reproduction_extra_table1.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    md = (out / "reproduction.md").read_text()
    assert "](img/reproduction_table1.png)" in md
    assert md.index("](img/reproduction_extra_table1.png)") > md.index("## Extra: the authors' SAC settings (`algo=sac_paper`) on Table 1")


@pytest.mark.parametrize("ledger", ['["not", "a", "ledger"]', '{"campaign": "mini", "runs": []}',
                                    '{"campaign": "mini", "runs": {"t/x/seed0": {"starts": 3}}}',
                                    '{"campaign": "mini", "runs": {"t/x/seed0": "done"}}'])
def test_a_ledger_of_the_wrong_shape_is_refused_clearly(tmp_path, ledger):
    """A campaign.json of the wrong shape, or one whose content no longer matches its checksum,
    is refused with the file named, no traceback."""
    spec = tmp_path / "mini.yaml"
    spec.write_text(yaml.safe_dump({"name": "mini", "runs": [{"table": "t", "variant": "x", "seed": 0, "steps": 10,
                                                          "args": ["budget=smoke"]}]}))
    root = tmp_path / "state"
    root.mkdir()
    (root / LEDGER).write_text(ledger)
    for extra in (["status"], ["run", "--dry-run"]):
        rc, out = cli(extra[0], "--spec", str(spec), "--root", str(root), *extra[1:])
        assert rc == 2 and "is not a campaign ledger" in out and "Traceback" not in out, out


def test_a_ledger_edited_after_it_was_sealed_is_refused(tmp_path):
    from billiards.campaign.ledger import Ledger
    from billiards.campaign.spec import SpecError

    Ledger(tmp_path, "mini").save()
    data = json.loads((tmp_path / LEDGER).read_text())
    assert len(data["sha256"]) == 64
    Ledger(tmp_path, "mini")  # intact: loads
    data["runs"]["t/x/seed0"] = {"args": None, "starts": [], "commits": [], "pid": None, "failures": 0}
    (tmp_path / LEDGER).write_text(json.dumps(data))
    with pytest.raises(SpecError, match="is damaged: its contents do not match its sha256 checksum"):
        Ledger(tmp_path, "mini")
