"""train.py through its Hydra entry point: smoke runs of every algorithm, a joblib multirun,
kill + resume, and command lines that must fail fast and write nothing. A run, a resume or a
refusal runs the entry point in this process (``train``); a signal, a kill, a multirun and wandb
get a process of their own.

Every run writes under pytest's tmp_path (hydra.run.dir / hydra.sweep.dir) and runs with
cwd=tmp_path, so "writes nothing" can be checked on the whole directory.
"""

from __future__ import annotations

import csv
import json
import re
import math
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from omegaconf import OmegaConf

from billiards.evaluation import EvalResult
from conftest import APP_ENV

REPO = Path(__file__).resolve().parents[2]
TRAIN = str(REPO / "train.py")
ENV = APP_ENV


def train(tmp_path: Path, *overrides: str, timeout: float = 900) -> subprocess.CompletedProcess:
    """``python train.py <overrides> progress=false`` in ``tmp_path`` (conftest.app_here: in this
    process, a multirun or wandb in a process of its own)."""
    from conftest import app_here

    return app_here(TRAIN, *overrides, "progress=false", cwd=tmp_path, env=ENV)


def report(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    """``python -m billiards.report <args>`` in ``tmp_path``, in this process."""
    from conftest import app_here

    return app_here("billiards.report", *args, cwd=tmp_path, env=ENV)


def ok(proc: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-5000:]}"
    return proc


def metric_rows(run_dir: Path) -> list[dict]:
    with (run_dir / "metrics.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def check_finished(run_dir: Path, frames: int, innings: int = 10) -> EvalResult:
    result = EvalResult.from_json(run_dir / "eval.json")
    assert result.n_innings == innings and result.max_shots == 10 and result.start == "random"
    assert 0.0 <= result.mean <= 10.0 and len(result.points) == innings
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["frames"] == frames
    assert (run_dir / "checkpoint.pt").is_file() and (run_dir / "config.yaml").is_file()
    history = [json.loads(line) for line in (run_dir / "eval_history.jsonl").read_text().splitlines()]
    assert history[-1]["final"] and history[-1]["eval_mean"] == result.mean
    steps = [int(r["step"]) for r in metric_rows(run_dir)]
    assert steps == sorted(steps) and steps[-1] == frames
    return result


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_smoke_run_writes_eval_json(tmp_path, algo):
    run_dir = tmp_path / "run"
    # wandb offline: never a login prompt; device=cpu spelled out (the default, auto, is cpu here too)
    extra = {"ppo": ["logger=wandb"], "td3": ["device=cpu"]}.get(algo, [])
    proc = ok(train(tmp_path, f"algo={algo}", "budget=smoke", f"hydra.run.dir={run_dir}", *extra))
    check_finished(run_dir, frames=2048)
    import torch

    expected_device = "cuda:0" if torch.cuda.is_available() and algo != "td3" else "cpu"
    assert json.loads((run_dir / "summary.json").read_text())["device"] == expected_device
    # the run says where its output goes before it starts and where it went at the end
    assert f"output: {run_dir} ({algo}, 2,048 steps, physics korean_medium)" in proc.stdout
    assert f"done: eval.json, summary.json and checkpoint.pt in {run_dir}" in proc.stdout
    if algo == "ppo":
        assert list((run_dir / "wandb").glob("offline-run-*")), "no offline wandb run"
    assert "budget" in yaml.safe_load((run_dir / "config.yaml").read_text()) and "kill_after_checkpoint" not in proc.stdout
    # the report reads the run (no paper table: grouped by settings)
    proc = report(tmp_path, str(run_dir))
    ok(proc)
    assert [f"{algo}, random_continue, plain, shaping=none", "1"] in [r[:2] for r in table_cells(proc.stdout)]
    assert (run_dir / "report.md").read_text() == proc.stdout
    if algo == "sac":
        check_learning_curves(run_dir, tmp_path)


def check_learning_curves(run_dir: Path, tmp_path: Path) -> None:
    """`report --curves --cpu-budget --plot` on a real run: one row per periodic evaluation,
    and the CPU-budget pick is the last evaluation within the budget."""
    from billiards.report import main as report_main

    history = [json.loads(line) for line in (run_dir / "eval_history.jsonl").read_text().splitlines()]
    assert [h["step"] for h in history] == [1024, 2048]
    # a budget between the two evaluations' CPU times picks the first one
    budget_min = (history[0]["cpu_time"] + history[1]["cpu_time"]) / 2 / 60
    out, png = tmp_path / "curves.md", tmp_path / "curves.png"
    report_main([str(run_dir), "--curves", "--cpu-budget", str(budget_min), "--plot", str(png), "--out", str(out)])
    text = out.read_text()
    rows = table_cells(text)
    for h in history:
        assert [f"{h['step']:,}", "1", f"{h['updates']:,}", f"{h['cpu_time'] / 60:.1f}", f"{h['eval_mean']:.3f} ± 0.000"] in \
            [r[:5] for r in rows]
    pick = next(r for r in rows if r[:2] == ["0", "1,024"])  # the CPU-budget pick: seed 0 at its first evaluation
    assert pick[2] == f"{history[0]['cpu_time'] / 60:.1f}" and pick[4:] == [f"{history[0]['eval_mean']:.3f}", "no"]
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(SystemExit):  # a CPU budget without --curves is a usage error
        report_main([str(run_dir), "--cpu-budget", "5"])


@pytest.mark.slow
def test_joblib_multirun_and_report(tmp_path):
    sweep = tmp_path / "sweep"
    proc = ok(train(
        tmp_path, "-m", "hydra/launcher=local_parallel", "seed=0,1", "env=aim_features", "table=table4", "row=aim_features",
        "budget=smoke", "budget.total_steps=1024", "budget.eval_every=0", "budget.checkpoint_every=0",
        f"hydra.sweep.dir={sweep}",
    ))
    assert proc.stdout.startswith(f"sweep: {sweep}\n")
    # the parallel jobs' log lines say which job they come from (job logs: train.log of each run)
    for n in (0, 1):
        log_lines = next(sweep.glob(f"{n}_*/train.log")).read_text().splitlines()
        assert log_lines and all(line.startswith(f"[job {n}] ") for line in log_lines if line.startswith("["))
    runs = sorted(p.parent for p in sweep.glob("*/eval.json"))
    assert len(runs) == 2
    # run dir names are valid unquoted override values (no "=" or ","), so `resume=<dir>` parses
    assert all("=" not in r.name and "," not in r.name for r in runs), [r.name for r in runs]
    assert runs[0].name.startswith("0_") and "+seed-0+" in runs[0].name, runs[0].name
    for run in runs:
        check_finished(run, frames=1024)
    assert {json.loads((r / "summary.json").read_text())["seed"] for r in runs} == {0, 1}
    proc = ok(report(tmp_path, str(sweep)))
    # Table 4 layout with the paper's figures beside ours
    cells = next(r for r in table_cells(proc.stdout) if r[0] == "+ extra feat.")
    assert cells[1] == "2" and cells[6] == paper_figure("table4", "aim_features"), cells
    assert "No runs yet for: plain SAC, + aim constraint." in proc.stdout
    # --copy-to keeps the small files only, and the report reads the copies the same way
    copies = tmp_path / "copies"
    ok(report(tmp_path, str(sweep), "--copy-to", str(copies), "--out", str(tmp_path / "a.md")))
    assert sorted(p.name for p in copies.iterdir()) == [r.name for r in runs]
    assert not list(copies.rglob("checkpoint.pt")) and len(list(copies.rglob("eval.json"))) == 2
    again = ok(report(tmp_path, str(copies)))
    assert cells in table_cells(again.stdout)


def table_cells(markdown: str) -> list[list[str]]:
    """The body rows of every Markdown table in ``markdown``, as lists of stripped cells."""
    lines = [line.strip() for line in markdown.splitlines() if line.strip().startswith("|")]
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in lines]
    return [r for r in rows if not all(set(c) <= set("-: ") for c in r)]


def paper_figure(table: str, row: str) -> str:
    """The paper's mean ± std of a table row as the report prints it."""
    from billiards.tables import paper_tables

    figures = paper_tables()[table].rows[row].figures
    return f"{figures['mean']:.3f} ± {figures['std']:.3f}"


@pytest.mark.slow
def test_cpu_hour_preset_stops_at_its_cpu_budget(tmp_path):
    """experiment=cpu_hour composes (aim + features SAC, lr 1e-3, gamma 0.9, averaged actor) and
    budget.cpu_minutes ends training long before budget.total_steps, then evaluates."""
    sweep = tmp_path / "sweep"
    ok(train(
        tmp_path, "experiment=cpu_hour", "seed=0", "budget=smoke", "budget.total_steps=1000000",
        "budget.cpu_minutes=0.1", "budget.eval_every=0", "budget.checkpoint_every=0", f"hydra.sweep.dir={sweep}",
    ))
    (run,) = [p.parent for p in sweep.glob("*/eval.json")]
    summary = json.loads((run / "summary.json").read_text())
    assert summary["stopped_by"] == "cpu_minutes"
    assert 512 < summary["frames"] < 1_000_000 and summary["cpu_seconds"] >= 6.0
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert (config["algo"]["lr"], config["algo"]["gamma"], config["algo"]["actor_ema"]) == (1e-3, 0.9, 5e-4)
    final = json.loads((run / "eval_history.jsonl").read_text().splitlines()[-1])
    assert final["final"] and "live_eval_mean" in final  # the averaged actor is evaluated, the live one beside it
    assert config["env"]["constrain_aim"] and config["env"]["extra_features"]
    assert EvalResult.from_json(run / "eval.json").n_innings == 10
    proc = ok(report(tmp_path, str(sweep)))
    assert "One CPU hour per seed" in proc.stdout
    row = next(r for r in table_cells(proc.stdout) if r[0] == "+ extra feat.")
    assert row[1] == "1" and row[6] == paper_figure("table4", "aim_features")


def test_report_never_merges_runs_with_different_settings(tmp_path):
    """Runs of one table row that differ in a setting (here algo.lr, or the budget) get one row
    each, named by the setting and still beside the paper's figure; seeds do not split a row,
    and runs of one configuration stopped at different steps (a CPU budget) share it."""
    from billiards.report.markdown import row_summary, steps_label, table_groups
    from billiards.report.runs import find_curves, find_runs, group_curves
    from billiards.tables import paper_tables

    def fake_run(name: str, seed: int, lr: float, mean: float, steps: int, budget: int = 2_000_000) -> None:
        d = tmp_path / "runs" / name
        d.mkdir(parents=True)
        (d / "summary.json").write_text(json.dumps({"frames": steps}))
        config = {"table": "table4", "row": "aim_features", "seed": seed, "physics": {"preset": "korean_medium"},
                  "budget": {"total_steps": budget, "cpu_minutes": 60.0},
                  "algo": {"name": "sac", "lr": lr, "hidden_sizes": [256, 256]},
                  "env": {"paradigm": "random_continue", "constrain_aim": True, "extra_features": True},
                  "shaping": {"name": "none"}}
        (d / "config.yaml").write_text(yaml.safe_dump(config))
        (d / "eval.json").write_text(json.dumps({"mean": mean, "best": 7, "start": "random", "foul_innings_pct": 50.0,
                                                 "foul_per_shot_pct": 10.0, "success_per_shot_pct": 30.0}))
        point = {"step": steps, "updates": 1, "cpu_time": 60.0, "wall_time": 60.0, "eval_mean": mean, "eval_best": 7}
        (d / "eval_history.jsonl").write_text(json.dumps(point) + "\n")

    fake_run("a0", 0, 3e-4, 2.0, 100_000)
    fake_run("a1", 1, 3e-4, 4.0, 200_000)
    fake_run("a2", 2, 3e-4, 3.0, 1_234_567)  # e.g. stopped by a CPU budget: steps shown as a range
    fake_run("b0", 0, 1e-3, 5.0, 100_000)
    groups = table_groups(find_runs([tmp_path / "runs"])[0])["table4"]
    rows = {v: row_summary("table4", v, runs) for v, runs in groups.items()}
    assert sorted(rows) == ["aim_features (algo.lr=0.0003)", "aim_features (algo.lr=0.001)"]
    slow, fast = rows["aim_features (algo.lr=0.0003)"], rows["aim_features (algo.lr=0.001)"]
    assert slow["label"] == "+ extra feat. (algo.lr=0.0003)" and slow["seeds"] == [0, 1, 2]
    assert slow["frames"] == [100_000, 200_000, 1_234_567] and steps_label(slow["frames"]) == "100k–1.23M"
    assert (slow["mean"], round(slow["std"], 3)) == (3.0, 0.816) and (fast["mean"], fast["n"]) == (5.0, 1)
    assert slow["paper"] == fast["paper"] == paper_tables()["table4"].rows["aim_features"].figures
    curves = group_curves(find_curves([tmp_path / "runs"]))
    assert sorted(curves) == [("table4", "aim_features (algo.lr=0.0003)"), ("table4", "aim_features (algo.lr=0.001)")]


def test_report_rows_are_configurations_and_count_distinct_seeds(tmp_path):
    """One seed at two budgets gives two rows; a second run of the same seed and configuration
    is a repeat, not another seed; runs of different physics never share a row."""
    from billiards.report.markdown import row_summary, table_groups
    from billiards.report.runs import find_runs

    def fake_run(name, seed, steps, mean, physics="korean_medium"):
        d = tmp_path / name
        d.mkdir()
        config = {"seed": seed, "budget": {"name": "x", "total_steps": steps, "eval_every": steps // 2},
                  "algo": {"name": "sac"}, "env": {"paradigm": "random_continue"}, "shaping": {"name": "none"}}
        config["physics"] = {"preset": physics}
        (d / "config.yaml").write_text(yaml.safe_dump(config))
        (d / "summary.json").write_text(json.dumps({"frames": steps}))
        (d / "eval.json").write_text(json.dumps({"mean": mean, "best": 3, "start": "random", "foul_innings_pct": 0.0,
                                                 "foul_per_shot_pct": 0.0, "success_per_shot_pct": 10.0}))

    fake_run("s0_2k", 0, 2_000, 0.1, "korean_medium")
    fake_run("s0_100k", 0, 100_000, 0.4, "korean_medium")
    fake_run("s0_100k_again", 0, 100_000, 0.6, "korean_medium")
    fake_run("s1_100k", 1, 100_000, 0.5, "korean_medium")
    fake_run("s1_100k_old", 1, 100_000, 0.9, "international")
    rows = {v: row_summary(None, v, runs) for v, runs in table_groups(find_runs([tmp_path])[0])[None].items()}
    assert len(rows) == 4, rows
    two_k = next(r for label, r in rows.items() if "budget.total_steps=2000" in label)
    assert (two_k["n"], two_k["frames"], two_k["physics"]) == (1, [2000], ["korean_medium"])
    hundred = {label: r for label, r in rows.items() if "budget.total_steps=100000" in label and "physics.preset=korean" in label}
    first = next(r for label, r in hundred.items() if "repeat" not in label)
    assert first["seeds"] == [0, 1] and (round(first["mean"], 3), round(first["std"], 3)) == (0.45, 0.05)  # each seed once
    again = next(r for label, r in hundred.items() if label.endswith("(repeat 2)"))
    assert (again["seeds"], again["mean"]) == ([0], 0.6)
    old = next(r for label, r in rows.items() if "physics.preset=international" in label)
    assert (old["n"], old["physics"]) == (1, ["international"])


def test_report_skips_broken_run_dirs_with_a_warning_naming_them(tmp_path, capsys):
    """A run dir without config.yaml, with unparsable YAML or JSON, or with a config lacking
    what its row needs is skipped with a warning naming it; the other runs are reported."""
    from billiards.report import main as report_main
    from billiards.report.markdown import table_groups
    from billiards.report.runs import find_curves, find_runs

    config = {"seed": 0, "budget": {"total_steps": 1000}, "algo": {"name": "sac"}, "physics": {"preset": "korean_medium"},
              "env": {"paradigm": "random_continue"}, "shaping": {"name": "none"}}
    result = {"mean": 2.5, "best": 6, "start": "random", "foul_innings_pct": 50.0, "foul_per_shot_pct": 10.0,
              "success_per_shot_pct": 25.0}
    point = {"step": 1000, "updates": 1, "cpu_time": 6.0, "wall_time": 6.0, "eval_mean": 2.5, "eval_best": 6}
    runs = {"good": (yaml.safe_dump(config), json.dumps(result)), "no_config": (None, json.dumps(result)),
            "bad_yaml": ("algo: [sac", json.dumps(result)), "bad_json": (yaml.safe_dump(config), '{"mean": 2.'),
            "no_algo": (yaml.safe_dump({"seed": 1, "budget": {"total_steps": 1000}}), json.dumps(result))}
    for name, (cfg_text, eval_text) in runs.items():
        d = tmp_path / "runs" / name
        d.mkdir(parents=True)
        if cfg_text is not None:
            (d / "config.yaml").write_text(cfg_text)
        (d / "eval.json").write_text(eval_text)
        (d / "eval_history.jsonl").write_text(json.dumps(point) + "\n" + ("{oops\n" if name == "bad_json" else ""))
    out = tmp_path / "report.md"
    report_main([str(tmp_path / "runs"), "--out", str(out)])
    err = capsys.readouterr().err
    text = out.read_text()
    groups = table_groups(find_runs([tmp_path / "runs"])[0])
    assert list(groups) == [None] and list(groups[None]) == ["sac, random_continue, plain, shaping=none"]
    assert [r.path.name for r in groups[None]["sac, random_continue, plain, shaping=none"]] == ["good"]
    reasons = {"no_config": "no config.yaml", "bad_yaml": "config.yaml is not valid YAML",
               "bad_json": "eval.json is not valid JSON", "no_algo": "config.yaml lacks what the report reads (KeyError: 'algo')"}
    for name, reason in reasons.items():
        line = next(line for line in err.splitlines() if f"runs/{name}:" in line)
        assert line.startswith("warning: skipping run directory") and f"runs/{name}: {reason}" in line, line
        assert f"runs/{name}: {reason}" in text  # listed in the report too
    report_main([str(tmp_path / "runs"), "--curves", "--out", str(out)])
    err = capsys.readouterr().err
    assert [c.path.name for c in find_curves([tmp_path / "runs"])] == ["good"]
    assert "runs/bad_json: eval_history.jsonl has a line that is not JSON" in err
    assert all(f"runs/{name}: {reasons[name]}" in err for name in ("no_config", "bad_yaml", "no_algo")), err


def run_files(run_dir: Path) -> dict[str, tuple[bytes, int]]:
    """Content and mtime of every file the run wrote (Hydra's own invocation records aside)."""
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in run_dir.iterdir() if p.is_file() and p.suffix != ".log"}


# train.py, SIGKILLed by itself right after writing its first periodic checkpoint: a test hook
# around the real entry point (the production config has no kill switch).
KILL_AFTER_FIRST_CHECKPOINT = f"""
import os, runpy, signal, sys
sys.path.insert(0, {str(REPO)!r})
import billiards.rl.train as train

save = train.save_checkpoint

def save_then_die(run_dir, state):
    save(run_dir, state)
    sys.stdout.flush()
    sys.stderr.flush()
    os.kill(os.getpid(), signal.SIGKILL)

train.save_checkpoint = save_then_die
sys.argv[0] = {TRAIN!r}
runpy.run_path({TRAIN!r}, run_name="__main__")
"""


def train_killed_after_first_checkpoint(tmp_path: Path, *overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", KILL_AFTER_FIRST_CHECKPOINT, *overrides, "progress=false"],
                          cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=900)


@pytest.mark.slow
def test_killed_run_resumes_and_finishes(tmp_path):
    run_dir = tmp_path / "run"
    proc = train_killed_after_first_checkpoint(tmp_path, "budget=smoke", f"hydra.run.dir={run_dir}")
    assert proc.returncode == -9, proc.stderr[-3000:]  # SIGKILL right after the first checkpoint
    assert (run_dir / "checkpoint.pt").is_file() and not (run_dir / "eval.json").exists()
    assert not list(run_dir.glob("*.tmp"))

    ok(train(tmp_path, f"resume={run_dir}"))
    result = check_finished(run_dir, frames=2048)
    history = [json.loads(line) for line in (run_dir / "eval_history.jsonl").read_text().splitlines()]
    assert [h["step"] for h in history] == [1024, 2048]  # the pre-kill evaluation survives
    assert (run_dir / ".hydra" / "overrides.yaml").read_text().count("budget=smoke") == 1
    assert (run_dir / ".hydra_resume").is_dir()

    # resuming the finished run says so and changes none of its files (no second final evaluation)
    before = run_files(run_dir)
    proc = ok(train(tmp_path, f"resume={run_dir}"))
    assert "is already finished (2048 frames" in proc.stdout + proc.stderr
    assert run_files(run_dir) == before

    # a corrupt checkpoint is reported as such
    (run_dir / "checkpoint.pt").write_bytes(b"not a checkpoint")
    proc = train(tmp_path, f"resume={run_dir}")
    assert proc.returncode != 0 and "corrupt or truncated" in proc.stderr
    assert EvalResult.from_json(run_dir / "eval.json") == result  # untouched


def compose_cfg(*overrides: str):
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base=None):
        return compose("config", list(overrides))


def same(a, b) -> bool:
    """Bit-for-bit equality of nested dicts / lists of tensors and plain values."""
    import torch

    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and a.dtype == b.dtype and a.shape == b.shape and torch.equal(a, b)
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def resumed(cfg, run_dir: Path):
    """The parts of the run in ``run_dir`` as ``resume=<run_dir>`` rebuilds them."""
    from billiards.rl.train import load_run_config, make_run

    return make_run(*load_run_config(OmegaConf.merge(cfg, {"resume": str(run_dir)}), run_dir.parent / "unused"))


@pytest.mark.slow
def test_checkpoint_restores_bit_for_bit_old_configs_resume_and_finished_runs_stay_put(tmp_path, monkeypatch, caplog):
    """In process, on a short SAC run: (1) what a resume restores from a checkpoint -- networks,
    optimizers, replay buffer, counters, every RNG -- is bit-identical to the state saved;
    (2) a checkpoint whose config predates algo.actor_ema and budget.cpu_minutes resumes with
    their defaults, and one as the trainer wrote them before the redesign (its config with the
    retired budget.kill_after_checkpoint, without device) resumes to the very same weights;
    (3) resuming a finished run says so, evaluates nothing and writes nothing."""
    import copy
    import logging
    import shutil

    import billiards.rl.train as train_module
    from billiards.rl.checkpoint import load_checkpoint, rng_state, save_checkpoint
    from billiards.rl.train import env_rngs, make_run, train_off_policy

    saved = []

    def save_and_keep(run_dir, state):  # the first (periodic) checkpoint: copy the run dir a kill would leave
        path = save_checkpoint(run_dir, state)
        if not saved:
            saved.append(copy.deepcopy(state))
            for name in ("killed", "old", "old_format"):
                shutil.copytree(run_dir, tmp_path / name)
        return path

    monkeypatch.setattr(train_module, "save_checkpoint", save_and_keep)
    cfg = compose_cfg("budget=smoke", "budget.total_steps=1024", "budget.init_random_steps=256", "budget.eval_every=512",
                      "budget.checkpoint_every=768", "budget.eval_innings=2", "budget.final_eval_innings=2", "progress=false")
    train_off_policy(make_run(cfg, tmp_path / "run"))
    (state,) = saved
    assert state["counters"]["frames"] == 768 and state["buffer"]["rows"] == 768 and state["agent_extra"]["n_updates"] > 0

    # (1) save -> load -> restore is bit-identical
    killed = tmp_path / "killed"
    run = resumed(cfg, killed)
    assert run.run_dir == killed
    assert same(run.agent.state_dict(), state["agent"])
    assert same(run.agent.state_dict_extra(), state["agent_extra"])
    assert same(run.rb.storage[: len(run.rb)].to_dict(), state["buffer"]["data"])
    assert same(run.rb.writer.state_dict(), state["buffer"]["writer"])
    assert same(rng_state(env_rngs(run.env)), state["rng"])
    assert (run.state.frames, run.state.owed, run.state.next_eval) == tuple(state["counters"][k] for k in ("frames", "owed", "next_eval"))
    assert run.state.eval_history == state["eval_history"] and len(state["eval_history"]) == 1
    train_off_policy(run)
    check_finished(killed, frames=1024, innings=2)

    # (2) a config written before algo.actor_ema and budget.cpu_minutes existed
    old = tmp_path / "old"
    ckpt = load_checkpoint(old)
    del ckpt["config"]["algo"]["actor_ema"], ckpt["config"]["budget"]["cpu_minutes"]
    save_checkpoint(old, ckpt)
    run = resumed(cfg, old)
    assert run.cfg.algo.actor_ema == 0.0 and run.cfg.budget.cpu_minutes == 0.0 and run.agent.actor_avg is None
    train_off_policy(run)
    check_finished(old, frames=1024, innings=2)
    # ... and one as written before the redesign: the same weights at the end as (1)
    old_format = tmp_path / "old_format"
    ckpt = load_checkpoint(old_format)
    del ckpt["config"]["device"]
    ckpt["config"]["budget"]["kill_after_checkpoint"] = 0
    save_checkpoint(old_format, ckpt)
    run = resumed(cfg, old_format)
    assert "kill_after_checkpoint" not in run.cfg.budget and run.cfg.device == cfg.device
    train_off_policy(run)
    check_finished(old_format, frames=1024, innings=2)
    final, final_old = load_checkpoint(killed), load_checkpoint(old_format)
    assert same(final_old["agent"], final["agent"]) and same(final_old["agent_extra"], final["agent_extra"])
    assert same(final_old["buffer"], final["buffer"]) and same(final_old["rng"], final["rng"])

    # (3) the finished run again: nothing evaluated, nothing written
    before = run_files(killed)
    mean = EvalResult.from_json(killed / "eval.json").mean
    monkeypatch.setattr(train_module, "evaluate_policy", lambda *a, **k: pytest.fail("evaluated a finished run"))
    with caplog.at_level(logging.WARNING, logger="billiards.rl.train"):
        assert train_module.train(OmegaConf.merge(cfg, {"resume": str(killed)}), killed) == mean
    assert f"{killed} is already finished (1024 frames, final evaluation in eval.json: {mean:.3f}" in caplog.text
    assert run_files(killed) == before


@pytest.mark.slow
def test_metrics_csv_is_rewritten_atomically_on_resume(tmp_path, monkeypatch):
    """A resume rewrites metrics.csv without the rows logged after the checkpoint or cut short
    by the kill; a failure (here: a full disk) in the middle of that rewrite leaves the old
    file whole, not empty."""
    from billiards.rl.metrics import MetricLogger

    cfg = compose_cfg("budget=smoke", "logger=csv")
    logger = MetricLogger(cfg, tmp_path, ())
    for step in (256, 512, 768):
        logger.log({"step": step, "updates": step // 8})
    logger.close()
    with (tmp_path / "metrics.csv").open("a") as f:
        f.write("10")  # the row a killed process was writing, cut short: never kept
    before = (tmp_path / "metrics.csv").read_bytes()

    def disk_full(self, rows):
        raise OSError(28, "No space left on device")

    with monkeypatch.context() as m:
        m.setattr(csv.DictWriter, "writerows", disk_full)
        with pytest.raises(OSError, match="No space left"):
            MetricLogger(cfg, tmp_path, (), resume_step=512)
    assert (tmp_path / "metrics.csv").read_bytes() == before and not list(tmp_path.glob("*.tmp"))
    logger = MetricLogger(cfg, tmp_path, (), resume_step=512)
    logger.log({"step": 768, "updates": 1})
    logger.close()
    assert [(r["step"], r["updates"]) for r in metric_rows(tmp_path)] == [("256", "32"), ("512", "64"), ("768", "1")]


@pytest.mark.slow
def test_checkpoint_never_runs_code_and_refuses_any_changed_byte(tmp_path):
    """load_checkpoint reads tensors and plain data only: a crafted pickle -- as a bare
    torch.save (the old format), behind a valid header and checksum, or raw -- is refused
    with a clear error and never executed; and every single changed byte of a checkpoint
    (header, digest or payload) or a truncation is refused as corrupt."""
    import hashlib
    import io
    import pickle

    import numpy as np
    import torch

    from billiards.rl.checkpoint import CheckpointError, load_checkpoint, rng_state, save_checkpoint

    marker = tmp_path / "pwned"

    class Payload:
        def __init__(self, path):
            self.path = path

        def __reduce__(self):
            return open, (str(self.path), "w")

    # the payload is live: plain unpickling creates its file
    pickle.loads(pickle.dumps(Payload(tmp_path / "live")))
    assert (tmp_path / "live").exists()

    raw = io.BytesIO()
    torch.save({"config": {}, "agent": Payload(marker)}, raw)
    first = b"billiards-checkpoint 2\n"
    crafted = {
        "old": (raw.getvalue(), "older version of billiards in an unsafe format"),
        "signed": (first + b"sha256 " + hashlib.sha256(first + raw.getvalue()).hexdigest().encode() + b"\n" + raw.getvalue(),
                   "holds objects other than tensors and plain data"),
        "pickle": (pickle.dumps({"agent": Payload(marker)}), "corrupt or truncated"),
    }
    for name, (data, message) in crafted.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "checkpoint.pt").write_bytes(data)
        with pytest.raises(CheckpointError, match=message) as err:
            load_checkpoint(tmp_path / name)
        assert str(tmp_path / name / "checkpoint.pt") in str(err.value)
        assert not marker.exists(), f"loading the {name} file ran its code"

    # a small real checkpoint (a SAC agent of 2-unit layers: content the checks accept) round-trips exactly ...
    from billiards.rl.checkpoint import agent_from_config
    from billiards.rl.train import _plain

    run = tmp_path / "run"
    run.mkdir()
    config = _plain(compose_cfg("budget=smoke", "algo.hidden_sizes=[2]"))
    agent, _ = agent_from_config(config)
    state = {"config": config, "agent": agent.state_dict(), "agent_extra": agent.state_dict_extra(),
             "counters": {"frames": 5, "owed": 0.25, "train_seconds": 0.0, "cpu_seconds": 0.0, "next_log": 256,
                          "next_eval": math.inf, "next_ckpt": math.inf},
             "eval_history": [], "rng": rng_state(np.random.default_rng(9)), "buffer": None, "collector": None,
             "wandb_id": None, "stage_log": []}
    path = save_checkpoint(run, state)
    assert same(load_checkpoint(run), {"format_version": 2, "schema": 1, **state})
    # ... and a changed byte anywhere -- every byte of the header and digest, then every 37th
    # byte and the last ones of the payload -- or a truncation is refused
    good = path.read_bytes()
    assert good.startswith(b"billiards-checkpoint 2\nsha256 ") and len(good) > 5000
    for i in [*range(200), *range(200, len(good), 37), *range(len(good) - 30, len(good))]:
        path.write_bytes(good[:i] + bytes([good[i] ^ 0xFF]) + good[i + 1:])
        with pytest.raises(CheckpointError, match="corrupt or truncated"):
            load_checkpoint(run)
    for size in (0, 50, len(good) // 2, len(good) - 1):
        path.write_bytes(good[:size])
        with pytest.raises(CheckpointError, match="corrupt or truncated"):
            load_checkpoint(run)
    # what cannot be loaded safely is never written
    with pytest.raises(TypeError, match=r"checkpoint\['rng'\]\['numpy'\] is a numpy.ndarray"):
        save_checkpoint(run, {**state, "rng": {"numpy": np.zeros(3)}})
    path.write_bytes(good)
    load_checkpoint(run)


@pytest.mark.slow
def test_resume_takes_a_cpu_limit_only_when_given(caplog):
    """A resume keeps the checkpoint's config: budget.cpu_minutes comes from the command line
    only when given there (so a cpu_hour run resumed without it keeps its 60-minute limit),
    threads always, and other overrides are ignored with a warning."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from billiards.rl.train import resume_config

    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base=None):
        saved = OmegaConf.to_container(compose("config", ["budget=smoke", "budget.cpu_minutes=60"]), resolve=True,
                                       enum_to_str=True)
        given = ["budget.cpu_minutes=5", "algo.lr=0.5", "threads=2", "resume=somewhere"]
        current = compose("config", given)
        plain = compose("config", ["resume=somewhere"])
    cfg = resume_config(saved, current, overrides=given)
    assert cfg.budget.cpu_minutes == 5 and cfg.threads == 2 and cfg.resume == "somewhere"
    assert cfg.algo.lr == saved["algo"]["lr"] != 0.5 and cfg.budget.name == "smoke"
    assert "ignoring overrides ['algo.lr=0.5']" in caplog.text
    kept = resume_config(saved, plain, overrides=["resume=somewhere"])
    assert kept.budget.cpu_minutes == 60 and plain.budget.cpu_minutes == 0


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_averaged_actor_is_what_a_run_evaluates_checkpoints_and_exports(tmp_path, algo):
    """algo.actor_ema > 0: after every actor step the average moves by exactly
    ``rate * (live - average)``; evaluations (periodic and final) play the averaged actor and
    record the live one beside it; the checkpoint, load_policy and the exported policy file
    all give the averaged actor."""
    import torch
    from hydra import compose, initialize_config_dir
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from billiards.rl.checkpoint import load_checkpoint
    from billiards.rl.policy import export_policy, load_policy
    from billiards.rl.train import make_run, train_off_policy

    rate = 0.05
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base=None):
        cfg = compose("config", [f"algo={algo}", "budget=smoke", "env=aim_features", f"algo.actor_ema={rate}",
                                 "logger=csv", "progress=false"])
    run_dir = tmp_path / "run"
    run = make_run(cfg, run_dir)
    agent = run.agent
    train_off_policy(run)
    check_finished(run_dir, frames=2048)
    history = [json.loads(line) for line in (run_dir / "eval_history.jsonl").read_text().splitlines()]
    assert len(history) == 2 and all(0 <= h["live_eval_mean"] <= 10 for h in history)
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["eval_live"]["random"]["eval_mean"] == history[-1]["live_eval_mean"]
    from billiards.report import main as report_main  # the learning curves show both actors

    report_main([str(run_dir), "--curves", "--out", str(tmp_path / "curves.md")])
    last = history[-1]
    assert [f"{last['eval_mean']:.3f} ± 0.000", str(last["eval_best"]), f"{last['live_eval_mean']:.3f} ± 0.000"] in \
        [r[4:7] for r in table_cells((tmp_path / "curves.md").read_text())]

    live, avg = list(agent.actor.parameters()), list(agent.actor_avg.parameters())
    assert all(not p.requires_grad for p in avg)
    assert any(not torch.equal(a, b) for a, b in zip(live, avg))
    # one more actor step (TD3 steps its actor every policy_delay-th update): the exact Polyak move
    avg0 = [p.clone() for p in avg]
    for _ in range(getattr(agent, "policy_delay", 1)):
        agent.update(run.rb.sample())
    for a0, a1, l1 in zip(avg0, avg, live):
        torch.testing.assert_close(a1, a0 + rate * (l1 - a0), rtol=1e-5, atol=1e-7)

    obs = TensorDict({"observation": torch.randn(16, 32)}, batch_size=[16])
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        def act(policy):
            return policy(obs.clone())["action"]

        loaded, _ = load_policy(run_dir)  # the checkpoint written at the end of run()
        agent.load_state_dict(load_checkpoint(run_dir)["agent"])
        expected = act(agent.eval_policy)
        assert not torch.allclose(expected, act(agent.policy))
        torch.testing.assert_close(act(loaded), expected)
        exported, _ = load_policy(export_policy(run_dir, tmp_path / "seed0.pt"))
        torch.testing.assert_close(act(exported), expected)


BAD = [
    (["algo=dqn"], "Could not find 'algo/dqn'"),
    (["budget.total_steps=-5"], "budget.total_steps must be > 0, got -5"),
    (["env.paradigm=sideways"], "Invalid value 'sideways', expected one of [canonical_reset"),
    (["foo=1"], "Key 'foo' not in 'TrainConfig'"),
    (["algo.lrr=0.1"], "Key 'lrr' not in 'SACConfig'"),
    (["algo=ppo", "algo.utd=2"], "Key 'utd' not in 'PPOConfig'"),
    (["env.num_envs=0"], "env.num_envs must be > 0"),
    (["budget.cpu_minutes=-1"], "budget.cpu_minutes must be >= 0, got -1.0"),
    (["algo.actor_ema=1.5"], "algo.actor_ema must lie in [0, 1) (0 = off), got 1.5"),
    (["resume=nowhere"], "resume='nowhere': no such run directory"),
    (["eval.seed=-1"], "eval.seed must be an integer >= 0 (a numpy seed), got -1"),
    (["seed=-1"], "seed must be an integer in [0, 2**32 - 1] (a numpy seed), got -1"),
    (["seed=4294967296"], "seed must be an integer in [0, 2**32 - 1] (a numpy seed), got 4294967296"),
    (["-m", "seed=0,1", "budget.eval_innings=0"], "budget.eval_innings must be > 0"),
    (["experiment=table4", "budget.total_steps=-1"], "budget.total_steps must be > 0, got -1"),
    (["curriculum=staged", "curriculum.switch_at=[0.5]"], "curriculum.switch_at needs one fraction per stage boundary (2)"),
    (["curriculum=staged", "algo=ppo"], "curriculum=staged needs an off-policy algorithm"),
    (["shaping=rm", "shaping.rm_model=nowhere.pt"], "shaping.rm_model='nowhere.pt': no reward model there"),
    (["-m", "experiment=table3", "variant=table3/staged", "curriculum.switch_at=[0.7,0.2]"], "curriculum.switch_at must increase"),
    # a problem every job of a multirun has is said once, not once a job
    (["-m", "experiment=table4", "budget.total_steps=-1"], "every job of the multirun (9): invalid training config"),
    (["physics=bogus"], "Could not find 'physics/bogus'"),
    (["physics.preset=bogus"], "physics.preset='bogus' is not a preset"),
    (["physics.u_roll=-1"], "physics.u_roll: PhysicsParams.u_roll must be a finite positive number, got -1.0"),
    (["physics.cue_speed_max=1e200"], "PhysicsParams.cue_speed_max must be at most 50 (a physical bound), got 1e+200"),
    (["physics.max_events=10000000000000000000"], "physics.max_events"),
    (["threads=100000"], "threads must be an integer in [1, "),
    (["budget.total_steps=10000000000000"], "budget.total_steps=10000000000000: integers here must lie within +-2,147,483,647"),
    # configs are data: nothing on the command line may make Hydra call code (the test's "wrote
    # nothing" also checks that Path.touch never ran: it would create ./pwned)
    (["+hydra.callbacks.evil._target_=pathlib.Path.touch", "+hydra.callbacks.evil.self=pwned"], "configs are data here"),
    (["+hydra.callbacks.evil.x=1"], "hydra.callbacks.evil.x may not be set from outside the project's conf/"),
    (["+algo._target_=builtins.print"], "configs are data here; a _target_ would make Hydra call code"),
    (["hydra.searchpath=[file://elsewhere]"], "hydra.searchpath may not be set"),
    (["--experimental-rerun", "config.pickle"], "the flag --experimental-rerun is not accepted here"),
    (["--config-dir", "elsewhere"], "the flag --config-dir is not accepted here"),
    (["physics.u_rol=0.1"], "Key 'u_rol' not in 'PhysicsConfig'"),
    (["physics=international", "physics.table_width=0.2"], "'spots' opening rack does not fit a 0.2 x 2.84 m table"),
    (["shaping.gentle_kind=soft"], "shaping.gentle_kind must be leave"),
    (["device=gpu"], "device='gpu' is not a device: use auto, cpu, cuda or cuda:N"),
    (["device=cpu:0"], "device='cpu:0' is not a device"),
    (["budget.kill_after_checkpoint=1"], "Key 'kill_after_checkpoint' not in 'BudgetConfig'"),  # tests kill runs from outside
    (["+algo.lrr=0.1"], "algo.lrr: not a key of SACConfig"),  # '+' appends even to a closed node
    (["+foo=1"], "foo: not a key of TrainConfig"),
    (["-m", "seed=0,1", "+env.shots=3"], "env.shots: not a key of EnvConfig"),
]


# what only the entry point shows: its flags, multiruns (every job validated first), a Hydra
# callback that would run code (./pwned), and one refusal of each step -- the guard, Hydra's
# composition, the validator -- exiting with the message, no traceback and nothing written
THROUGH_THE_APP = {"algo=dqn", "foo=1", "budget.total_steps=-5", "resume=nowhere"}


def _through_the_app(overrides) -> bool:
    return overrides[0].startswith(("-", "+hydra", "hydra")) or " ".join(overrides) in THROUGH_THE_APP


@pytest.mark.slow
@pytest.mark.parametrize("overrides,message", [b for b in BAD if _through_the_app(b[0])],
                         ids=[" ".join(o) for o, _ in BAD if _through_the_app(o)])
def test_bad_overrides_fail_fast_and_write_nothing(tmp_path, overrides, message):
    # failing before any training is what "fast" means here (no run dir, no checkpoint); the
    # subprocess limit only guards against a hang: a loaded machine must not fail a correct run
    proc = train(tmp_path, *overrides, timeout=900)
    assert proc.returncode != 0
    assert proc.stderr.count(message) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == [], f"wrote {list(tmp_path.rglob('*'))}"


@pytest.mark.slow
@pytest.mark.parametrize("overrides,message", [b for b in BAD if "-m" not in b[0] and not b[0][0].startswith("--")],
                         ids=[" ".join(o) for o, _ in BAD if "-m" not in o and not o[0].startswith("--")])
def test_each_bad_override_is_refused_with_its_message_before_anything_runs(tmp_path, overrides, message):
    """Each single-run case, through the steps the app takes before Hydra writes anything (the
    guard, the composition, the validating callback) in this process; nothing is written."""
    from conftest import refusal

    said = refusal("train.py", *overrides, "progress=false", cwd=tmp_path)
    assert message in said, said
    assert list(tmp_path.iterdir()) == [], f"wrote {list(tmp_path.rglob('*'))}"


def _has_cuda() -> bool:
    import torch

    return torch.cuda.is_available()


@pytest.mark.slow
@pytest.mark.skipif(_has_cuda(), reason="this machine has a CUDA GPU")
@pytest.mark.parametrize("device", ["cuda", "cuda:3"])
def test_cuda_without_a_gpu_fails_fast_and_writes_nothing(tmp_path, device):
    proc = train(tmp_path, f"device={device}", timeout=900)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert f"device={device}: this machine has no CUDA GPU that torch can use" in proc.stderr, proc.stderr
    assert "use device=cpu, or device=auto" in proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_agents_meet_their_interface_and_average_their_actor_bit_exactly():
    """SAC and TD3 are OffPolicy agents, PPO an OnPolicy one; the averaged actor
    (torch's AveragedModel with an EMA) moves by exactly the float32 rate, even for a rate
    whose decay ``1 - rate`` does not round back to it."""
    import numpy as np
    import torch
    from omegaconf import OmegaConf

    from billiards.rl.learners import OffPolicy, OnPolicy, make_agent
    from billiards.rl.config import ALGO_SCHEMAS

    rate = next(r for r in np.geomspace(1e-7, 1e-4, 20_001) if np.float32(1 - (1 - r)) != np.float32(r))
    spec_low, spec_high = torch.tensor([0.0, 0.0, -1.0, -1.0]), torch.tensor([6.283, 1.0, 1.0, 1.0])
    from torchrl.data import Bounded

    spec = Bounded(spec_low, spec_high, shape=(4,))
    for name in ("sac", "td3", "ppo"):
        algo = OmegaConf.structured(ALGO_SCHEMAS[name])
        if name != "ppo":
            algo.actor_ema = float(rate)
        agent = make_agent(algo, 28, spec, num_envs=3)
        kind, other = (OnPolicy, OffPolicy) if name == "ppo" else (OffPolicy, OnPolicy)
        assert isinstance(agent, kind) and not isinstance(agent, other)
        if name == "ppo":
            assert agent.eval_actor is agent.actor and agent.eval_policy is agent.policy
            continue
        assert agent.eval_actor is agent.actor_avg
        # the warm-up plays uniform actions on [-1, 1]^4, one per inning, on the agent's RNG
        from tensordict import TensorDict

        obs = TensorDict({"observation": torch.randn(3, 28)}, batch_size=[3])
        torch.manual_seed(5)
        warm = agent.explore(obs.clone())["action_norm"]
        torch.manual_seed(5)
        assert torch.equal(warm, torch.rand(3, 4) * 2 - 1)
        with torch.no_grad():  # average 0, live 1: the move is the weight itself, to the last bit
            for p in agent.actor_avg.parameters():
                p.zero_()
            for p in agent.actor.parameters():
                p.fill_(1.0)
        avg = [p.clone() for p in agent.actor_avg.parameters()]
        agent._average_actor()
        weight = float(np.float32(rate))  # what the old hand-written torch._foreach_lerp_ moved by
        for a0, a1, live in zip(avg, agent.actor_avg.parameters(), agent.actor.parameters()):
            assert torch.equal(a1, torch.lerp(a0, live, weight))


def test_a_run_on_a_device_collects_with_the_agents_own_policy(tmp_path):
    """device=cpu in process: the collector plays the agent's exploration policy itself on the
    run's device (a device spelled without its index would make TorchRL play a stale copy),
    stores batches there, and the evaluation wrapper returns the policy's own actions."""
    import torch
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from billiards.rl.train import OnDevice, make_collector, make_run

    cfg = compose_cfg("algo=sac", "budget=smoke", "logger=none", "device=cpu", "progress=false")
    run = make_run(cfg, tmp_path / "run")
    assert run.device == torch.device("cpu")
    collector = make_collector(run, run.agent.explore, cfg.env.num_envs)
    try:
        assert collector.policy is run.agent.explore
        assert (collector.policy_device, collector.storing_device, collector.env_device) == (run.device, run.device, torch.device("cpu"))
        data = next(iter(collector))
    finally:
        collector.shutdown()
    run.rb.extend(data.reshape(-1).select(*run.agent.replay_keys))
    assert run.rb.sample()["observation"].device == run.device
    obs = TensorDict({"observation": data["observation"][:5].clone()}, batch_size=[5])
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        wrapped = OnDevice(run.agent.eval_policy, run.device)(obs.clone())
        direct = run.agent.eval_policy(obs.clone())
    assert wrapped["action"].device == torch.device("cpu") and torch.equal(wrapped["action"], direct["action"])


@pytest.mark.slow
def test_a_checkpoint_with_a_valid_checksum_but_impossible_contents_is_refused(tmp_path):
    """A checksum proves a file is what was written, not that it makes sense: impossible counters,
    a malformed random-generator state and a collector state that does not fit the env are
    refused on resume with the checkpoint's error (no traceback), and the run's files are left as
    they were."""
    import torch

    from billiards.rl.checkpoint import load_checkpoint, save_checkpoint

    run_dir = tmp_path / "run"
    train_killed_after_first_checkpoint(tmp_path, "budget=smoke", f"hydra.run.dir={run_dir}")
    good = load_checkpoint(run_dir)
    metrics = (run_dir / "metrics.csv").read_bytes()
    cases = {
        "negative frames": (lambda c: c["counters"].update(frames=-5), "frames=-5"),
        "enormous frames": (lambda c: c["counters"].update(frames=10**15), "frames=1000000000000000"),
        "NaN next checkpoint": (lambda c: c["counters"].update(next_ckpt=float("nan")), "next_ckpt=nan"),
        "negative CPU time": (lambda c: c["counters"].update(cpu_seconds=-1.0), "cpu_seconds=-1.0"),
        "malformed rng": (lambda c: c["rng"].update(env={"bit_generator": "PCG64", "state": "garbage"}),
                          "random-generator state is malformed"),
        "another env's innings": (lambda c: c["collector"]["carrier"].update(shot=torch.zeros(5, 1, dtype=torch.int64)),
                                  "collector state is malformed"),
        "innings past their end": (lambda c: c["collector"]["carrier"].update(shot=torch.full((32, 1), 99)),
                                   "collector state does not fit this env (shot)"),
        "no table": (lambda c: c["collector"]["carrier"].pop("positions"), "collector state does not fit this env (positions)"),
    }
    from billiards.rl.train import train as train_in_process

    # two cases through the command line (the message, no traceback), the others in this process
    through_the_app = ("negative frames", "another env's innings")
    for name, (change, message) in cases.items():
        ckpt = {k: v for k, v in good.items()}
        ckpt["counters"], ckpt["rng"] = dict(good["counters"]), dict(good["rng"])
        ckpt["collector"] = {**good["collector"], "carrier": dict(good["collector"]["carrier"])}
        change(ckpt)
        save_checkpoint(run_dir, ckpt)
        if name in through_the_app:
            proc = train(tmp_path, f"resume={run_dir}", "progress=false")
            assert proc.returncode != 0 and message in proc.stderr and "Traceback" not in proc.stderr, (name, proc.stderr[-1500:])
        else:
            with pytest.raises(SystemExit, match="Error: .*" + re.escape(message)):
                train_in_process(compose_cfg(f"resume={run_dir}", "progress=false"), run_dir)
        assert (run_dir / "metrics.csv").read_bytes() == metrics, name


@pytest.mark.slow
@pytest.mark.parametrize("signame", ["SIGINT"])  # SIGTERM: test_a_stopped_run_resumes_to_the_uninterrupted_runs_result
def test_a_signal_mid_run_checkpoints_that_step_and_exits_cleanly(tmp_path, signame):
    """Ctrl-C (SIGINT) while training: the run finishes its batch, writes a checkpoint at that
    step, says how to continue and exits with 128 + the signal, no traceback; resume= then
    finishes it. (A scheduler's SIGTERM, and a resume equal to the uninterrupted run: the test
    named beside the parameters.)"""
    import signal

    from billiards.rl.checkpoint import load_checkpoint

    run_dir = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, TRAIN, "budget=smoke", "budget.total_steps=4096", "budget.log_every=256",
                             "budget.checkpoint_every=4096", "progress=false", f"hydra.run.dir={run_dir}"],
                            cwd=tmp_path, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 180
    while time.time() < deadline and not ((run_dir / "metrics.csv").is_file()
                                          and len((run_dir / "metrics.csv").read_text().splitlines()) > 3):
        time.sleep(0.2)
    proc.send_signal(getattr(signal, signame))
    out, err = proc.communicate(timeout=900)
    said = out + err
    assert proc.returncode == 128 + getattr(signal, signame), said[-3000:]
    assert f"resume={run_dir}" in said and "Traceback" not in said, said[-3000:]
    frames = load_checkpoint(run_dir)["counters"]["frames"]
    assert 0 < frames < 4096 and f"stopped by {signame} at {frames} frames: checkpoint written" in said
    assert not (run_dir / "eval.json").exists()
    resumed = ok(train(tmp_path, f"resume={run_dir}", timeout=600))
    assert f"at {frames} frames" in resumed.stdout + resumed.stderr
    assert json.loads((run_dir / "summary.json").read_text())["frames"] >= 4096


# train.py sending itself SIGTERM (os.kill, through the trainer's real handler) as its training
# env begins its AT-th step (argv[1]): a test hook around the real entry point, like
# KILL_AFTER_FIRST_CHECKPOINT; evaluations play in envs of their own and do not count.
SIGTERM_AT_STEP = f"""
import os, runpy, signal, sys
sys.path.insert(0, {str(REPO)!r})
import billiards.rl.train as train

at = int(sys.argv.pop(1))
make_train_env = train.make_train_env

def make_signalling_env(cfg, seed):
    env = make_train_env(cfg, seed)
    step, steps = env.base_env._step, []

    def counted(tensordict):
        steps.append(1)
        if len(steps) == at:
            os.kill(os.getpid(), signal.SIGTERM)
        return step(tensordict)

    env.base_env._step = counted
    return env

train.make_train_env = make_signalling_env
sys.argv[0] = {TRAIN!r}
runpy.run_path({TRAIN!r}, run_name="__main__")
"""


@pytest.mark.slow
@pytest.mark.parametrize("algo, at_step, overrides", [
    ("sac", 20, ()),  # SAC updating (after its 512 warm-up frames); also killed after a periodic checkpoint
    ("td3", 5, ("noise=fastfiz", "env=aim_features")),  # in the warm-up, with execution noise
    ("ppo", 19, ("algo.frames_per_batch=256",)),  # in the middle of the third rollout (8 env steps of 32 innings)
])
def test_a_stopped_run_resumes_to_the_uninterrupted_runs_result(tmp_path, algo, at_step, overrides):
    """SIGTERM in the middle of a run: the run finishes its batch and checkpoints that step,
    collector included (every inning's table and shot, the rack and noise generators); resumed,
    it ends with the same final evaluation, networks, optimizers, replay buffer and generators
    as an uninterrupted run of the same seed, bit for bit. For SAC also a run SIGKILLed right
    after its first periodic checkpoint."""
    import signal

    from billiards.rl.checkpoint import load_checkpoint

    common = [f"algo={algo}", "budget=smoke", "budget.total_steps=1024", "budget.eval_every=512",
              "budget.checkpoint_every=512", *overrides]
    whole = tmp_path / "whole"
    ok(train(tmp_path, *common, f"hydra.run.dir={whole}"))
    batch = 256 if algo == "ppo" else 32  # SAC / TD3: one step of the 32 innings per batch
    stops = {"sigterm": math.ceil(at_step * 32 / batch) * batch}
    if algo == "sac":
        stops["sigkill"] = 512
    for how, frames in stops.items():
        run_dir = tmp_path / how
        if how == "sigterm":
            proc = subprocess.run([sys.executable, "-c", SIGTERM_AT_STEP, str(at_step), *common, f"hydra.run.dir={run_dir}",
                                   "progress=false"], cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=900)
            assert proc.returncode == 128 + signal.SIGTERM, proc.stderr[-3000:]
        else:
            proc = train_killed_after_first_checkpoint(tmp_path, *common, f"hydra.run.dir={run_dir}")
            assert proc.returncode == -signal.SIGKILL, proc.stderr[-3000:]
        stopped = load_checkpoint(run_dir)
        assert stopped["counters"]["frames"] == frames and 0 < frames < 1024
        assert stopped["collector"]["carrier"]["positions"].shape == (32, 4, 2)
        assert not (run_dir / "eval.json").exists()
        ok(train(tmp_path, f"resume={run_dir}"))
        assert (run_dir / "eval.json").read_bytes() == (whole / "eval.json").read_bytes(), how
        a, b = load_checkpoint(whole), load_checkpoint(run_dir)
        for key in ("agent", "agent_extra", "buffer", "rng", "counters"):
            if key == "counters":
                a[key], b[key] = ({k: v for k, v in c[key].items() if not k.endswith("_seconds")} for c in (a, b))
            assert same(a[key], b[key]), (how, key)
        summaries = [json.loads((d / "summary.json").read_text()) for d in (whole, run_dir)]
        assert summaries[0]["eval"] == summaries[1]["eval"] and summaries[0]["updates"] == summaries[1]["updates"]


# train.py sending itself SIGTERM as expert iteration starts its AT-th block (argv[1]): a test hook
# around the real entry point, like SIGTERM_AT_STEP above
SIGTERM_AT_BLOCK = f"""
import os, runpy, signal, sys
sys.path.insert(0, {str(REPO)!r})
import billiards.exit as exit_

at, play, calls = int(sys.argv.pop(1)), exit_.play_block, []

def signalling(*args, **kwargs):
    calls.append(1)
    if len(calls) == at:
        os.kill(os.getpid(), signal.SIGTERM)
    return play(*args, **kwargs)

exit_.play_block = signalling
sys.argv[0] = {TRAIN!r}
runpy.run_path({TRAIN!r}, run_name="__main__")
"""


@pytest.mark.slow
def test_an_exit_run_trains_stops_resumes_bit_for_bit_and_exports_a_policy_that_plays_and_proposes(tmp_path):
    """Three rounds of two blocks: the run writes what every training run writes; SIGTERM in the
    block that ends round 0 stops it before the round's updates (owed, checkpointed); resumed,
    it ends with the uninterrupted run's evaluation, networks, optimiser, labelled shots and
    counters, bit for bit. The exported policy loads as every policy file does, plays alone
    and proposes for the search."""
    import signal

    import numpy as np

    from billiards.rl.checkpoint import load_checkpoint
    from test_exit import TINY

    whole, stopped = tmp_path / "whole", tmp_path / "stopped"
    ok(train(tmp_path, *TINY, f"hydra.run.dir={whole}"))
    check_finished(whole, 600)
    summary = json.loads((whole / "summary.json").read_text())
    assert summary["algo"] == "exit" and summary["updates"] == sum(round(2 * n / 64) for n in (200, 400, 600))
    rows = [r for r in (json.loads(line) for line in (whole / "eval_history.jsonl").read_text().splitlines())]
    assert [r["step"] for r in rows] == [200, 400, 600]

    proc = subprocess.run([sys.executable, "-c", SIGTERM_AT_BLOCK, "2", *TINY, f"hydra.run.dir={stopped}", "progress=false"],
                          cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr[-3000:]
    ckpt = load_checkpoint(stopped)
    assert ckpt["counters"]["frames"] == 200 and ckpt["counters"]["owed"] >= 1  # the round's updates are owed
    assert not (stopped / "eval.json").exists()
    ok(train(tmp_path, f"resume={stopped}"))
    assert (stopped / "eval.json").read_bytes() == (whole / "eval.json").read_bytes()
    untimed = lambda d: [{k: v for k, v in json.loads(line).items() if not k.endswith("_time")}
                         for line in (d / "eval_history.jsonl").read_text().splitlines()]
    assert untimed(stopped) == untimed(whole)  # every evaluation due, at its step, the one at the stop too
    a, b = load_checkpoint(whole), load_checkpoint(stopped)
    for key in ("agent", "agent_extra", "buffer", "counters"):
        if key == "counters":
            a[key], b[key] = ({k: v for k, v in c[key].items() if not k.endswith("_seconds")} for c in (a, b))
        assert same(a[key], b[key]), key

    out = tmp_path / "policies"
    from conftest import app_here

    ok(app_here("billiards.rl.policy", "export", str(whole), "--out", str(out), cwd=tmp_path, env=ENV))
    from billiards.bench.adapters import resolve_agent
    from billiards.bench.tracks import get_track
    from billiards.rl.policy import policy_file_error
    from billiards.search.proposers import load_policy_proposer

    path = out / "seed0.pt"
    assert policy_file_error(path) is None
    import torch

    payload = torch.load(path, weights_only=True)
    weight = next(k for k in payload["actor"] if k.endswith("weight"))
    payload["actor"][weight][0, 0] += 1.0
    torch.save(payload, tmp_path / "bad.pt")  # one weight changed, the seal kept
    assert "do not match its sha256" in policy_file_error(tmp_path / "bad.pt")  # checked on load like every model file
    track = get_track("innings-v1")
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    obs, info = Billiards4BallVectorEnv(4, start="random").reset(seed=5)
    agent = resolve_agent(str(path), track)
    shots = agent.act(obs, info["positions"], None)
    assert shots.shape == (4, 4) and np.isfinite(shots).all()
    proposer = load_policy_proposer([path])
    candidates = proposer.propose(info["positions"], 8, np.random.default_rng(0))
    assert candidates.shape == (4, 8, 4) and np.allclose(candidates[:, 0], shots)  # candidate 0: the policy's own shot


def test_a_new_run_into_a_dir_holding_another_run_is_refused_before_anything_is_written(tmp_path):
    """A fresh run (no resume=) whose dir already holds a run's checkpoint, metrics or evaluation
    -- even a run still going -- would truncate its files: refused, naming resume=; an empty
    dir, or resume=auto over a dir without a checkpoint, starts as before."""
    from billiards.rl.config import ConfigError
    from billiards.rl.train import load_run_config

    cfg = compose_cfg("budget=smoke")
    for held in ("metrics.csv", "checkpoint.pt", "eval.json"):
        run_dir = tmp_path / held.split(".")[0]
        run_dir.mkdir()
        (run_dir / held).write_text("step\n1\n")
        with pytest.raises(ConfigError, match=f"already holds a training run \\({held}\\).*resume="):
            load_run_config(cfg.copy(), run_dir)
        assert (run_dir / held).read_text() == "step\n1\n" and sorted(p.name for p in run_dir.iterdir()) == [held]
    (tmp_path / "empty").mkdir()
    assert load_run_config(cfg.copy(), tmp_path / "empty")[2] is None
    # resume=auto (the campaign's jobs) over a job killed before its first checkpoint starts it again
    assert load_run_config(OmegaConf.merge(cfg, {"resume": "auto"}), tmp_path / "metrics")[2] is None
