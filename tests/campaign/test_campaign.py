"""The paper's tables as data (billiards.tables), the reproduction's stages on Hydra's launchers
(billiards.campaign) and the reproduction report read from run directories
(billiards.report.reproduction)."""

from __future__ import annotations

import importlib.util
import io
import json
import re
import subprocess
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
import yaml

from billiards.campaign import StageError, paper_stages
from billiards.campaign.__main__ import main
from billiards.report.reproduction import STARTS, Sources, write_report
from billiards.tables import TableError, _parse, paper_tables

REPO = Path(__file__).resolve().parents[2]


def cli(*argv: str) -> tuple[int, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        rc = main(list(argv))
    return rc, out.getvalue() + err.getvalue()


# ----------------------------------------------------------------------------- the tables as data


def test_paper_tables_list_every_row_at_its_budget():
    t = paper_tables()
    assert {n: (x.app, x.seeds, x.steps) for n, x in t.items() if n.startswith("table")} == {
        "table1": ("train", [0, 1, 2, 3, 4], 400_000), "table2": ("train", [0, 1, 2], 400_000),
        "table3": ("train", [0, 1, 2], 1_000_000), "table4": ("train", [0, 1, 2], 1_000_000),
        "table5": ("train", [0, 1, 2], 1_000_000), "table6": ("search", [0], None)}
    assert t["table1"].trained() == ["sac", "td3", "ppo"] and list(t["table1"].rows) == ["td3", "sac", "ppo"]
    shared = {r.key: r.same_as for x in t.values() for r in x.rows.values() if r.same_as}
    assert shared == {"table2/random_continue": "table1/sac", "table3/plain": "table4/plain", "table3/aim": "table4/aim",
                      "table5/aim_features": "table4/aim_features"}
    # a shared row shows its source's figures, updated by its own (Table 3 adds rand. eval)
    plain = t["table3"].rows["plain"].figures
    assert plain == {**t["table4"].rows["plain"].figures, "rand_eval": plain["rand_eval"]} and "rand_eval" in t["table3"].columns
    assert t["table2"].rows["random_continue"].figures["mean"] != t["table1"].rows["sac"].figures["mean"]
    assert t["table6"].sweep == {"proposer": ("base", "gentle", "near_miss", "both", "geometric"), "search": ("h2", "puct"),
                                 "protocol": ("p1", "p3_paper")}
    assert {r.name: r.trained_from for r in t["table6"].rows.values()} == {
        "base": "table5/foul_penalty", "gentle": "table5/gentle", "near_miss": "table5/near_miss", "both": "table5/both",
        "geometric": None}
    assert t["extra"].rows["sac_paper"].compared_with == "table1/sac"


def _figures_as_written(table) -> set[str]:
    out = set()
    for row in table.rows.values():
        if row.same_as or row.compared_with:
            continue
        for key, v in row.figures.items():
            if isinstance(v, list):
                out |= {f"{v[0]:g}", str(v[1])}
            elif key in ("mean", "std", "rand_eval"):
                out.add(f"{v:.3f}")
            elif table.app == "search":
                out.add(f"{v:.2f}")
    return out


@pytest.mark.slow
def test_each_paper_figure_is_written_once_in_its_tables_preset():
    """The paper's figures (means, stds, Table 6's cells) live in conf/experiment/<table>.yaml and
    in no other tracked file outside docs/, results/, tests/ and the README (a value two tables
    share by coincidence sits in both presets, nowhere else)."""
    tracked = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=REPO,
                             capture_output=True, text=True, check=True).stdout.split()
    texts = {p: (REPO / p).read_text(errors="replace") for p in tracked
             if not p.startswith(("docs/", "results/", "tests/")) and p != "README.md"
             and p.endswith((".py", ".yaml", ".yml", ".toml", ".md", ".cfg", ".txt", ".json")) and (REPO / p).is_file()}
    owners: dict[str, set[str]] = {}
    for name, table in paper_tables().items():
        for figure in _figures_as_written(table):
            owners.setdefault(figure, set()).add(f"conf/experiment/{name}.yaml")
    assert {"6.460", "0.418", "2052"} <= set(owners)
    for figure, presets in owners.items():
        found = {p for p, text in texts.items() if re.search(rf"(?<![\d.]){re.escape(figure)}(?!\d)", text)}
        assert found == presets, (figure, found)


@pytest.mark.parametrize("data, message", [
    ({"paper": {"rows": {"a": {"mean": 1.0, "median": 2.0}}}}, "unknown: median"),
    ({"paper": {"columns": ["mean", "speed"], "rows": {}}}, "are not figures"),
    ({"paper": {"rows": {"a": {}}}, "hydra": {"sweeper": {"params": {"variant": "table4/plain"}}}}, "not one of this table's own rows"),
    ({"paper": {"rows": {"a": {}}}}, "neither trained by the sweep nor same_as"),
    ({"paper": {"rows": {"a": {}}}, "hydra": {"sweeper": {"params": {"variant": "tt/a"}}}}, "has no conf/variant/tt/a.yaml"),
    ({"paper": {"app": "fit", "rows": {}}}, "paper.app must be train or search"),
    ({"paper": {"rows": {}}, "hydra": {"sweeper": {"params": {"seed": "0,,1"}}}}, "does not parse"),
])
def test_a_table_definition_that_does_not_hold_together_is_refused_naming_it(data, message):
    with pytest.raises(TableError, match=re.escape(message)):
        _parse("tt", data, "conf/experiment/tt.yaml")


def _compose(overrides_lists, config: str = "config"):
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    import billiards.rl.config  # noqa: F401  (schemas and resolvers)
    import billiards.search.config  # noqa: F401

    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        return [compose(config, overrides=list(o)) for o in overrides_lists]


@pytest.mark.slow
def test_every_trained_row_composes_validates_and_records_its_table_and_row():
    """Each table's sweep composes through the real Hydra config (``experiment=<t> variant=<t>/<row>``)
    and passes the trainer's validation, with the budget, physics and settings its row means."""
    from billiards.rl.validation import validate

    rows = [(name, row) for name, t in paper_tables().items() if t.app == "train" and name != "cpu_hour" for row in t.trained()]
    configs = _compose([[f"experiment={name}", f"variant={name}/{row}", "seed=1"] for name, row in rows])
    for (name, row), cfg in zip(rows, configs):
        validate(cfg)
        assert (cfg.table, cfg.row, cfg.seed, cfg.physics.preset) == (name, row, 1, "korean_medium")
        assert cfg.budget.total_steps == paper_tables()[name].steps
        env, shaping = cfg.env, cfg.shaping
        if name in ("table1", "table2", "extra"):
            assert [str(getattr(s, "value", s)) for s in cfg.eval.starts] == ["random", "canonical"]
            assert not env.constrain_aim and shaping.name == "none"
        expected = {
            "table1": lambda: (cfg.algo.name, env.paradigm.value) == (row, "random_continue"),
            "table2": lambda: (cfg.algo.name, env.paradigm.value) == ("sac", row),
            "table3": lambda: (shaping.rm > 0, cfg.curriculum.name, env.constrain_aim) == {
                "staged": (False, "staged", False), "rm": (True, "none", False), "rm_aim": (True, "none", True)}[row],
            "table4": lambda: (env.constrain_aim, env.extra_features) == {
                "plain": (False, False), "aim": (True, False), "aim_features": (True, True)}[row],
            "table5": lambda: env.constrain_aim and env.extra_features and shaping.name == row and shaping.foul_penalty == 1.0,
            "extra": lambda: (cfg.algo.name, cfg.algo.utd, cfg.algo.lr, cfg.algo.gamma) == ("sac", 1.0, 3e-4, 0.99),
        }[name]
        assert expected(), (name, row)
    # Table 6 is search.py's: its cells compose there, playing the shipped ensembles
    from billiards.search.config import validate as validate_search

    (cfg,) = _compose([["experiment=table6", "proposer=base", "search=puct", "protocol=p3_paper"]], "search")
    validate_search(cfg)
    assert (cfg.table, cfg.search.budget, cfg.protocol.seeds, cfg.protocol.cap) == ("table6", 400, 20, 10_000)
    assert all((REPO / p).is_file() for p in cfg.proposer.checkpoints)


# ----------------------------------------------------------------------------- stages


def test_stages_run_in_order_and_say_their_commands(tmp_path):
    assert [s.table for s in paper_stages(tmp_path)] == ["table1", "table2", "table4", "table3", "table5", "table6"]
    assert [s.table for s in paper_stages(tmp_path, ["table5", "extra"])] == ["table5", "extra"]
    with pytest.raises(StageError, match="no such stage"):
        paper_stages(tmp_path, ["table7"])
    rc, out = cli("commands", "--only", "table4,table6", "--launcher", "submitit_local", "--budget", "smoke",
                  "--root", str(tmp_path), "hydra.launcher.timeout_min=30")
    assert rc == 0
    train, search = [line.split() for line in out.splitlines()]
    assert train[:4] == ["python", "train.py", "-m", "experiment=table4"] and f"hydra.sweep.dir={tmp_path}/table4" in train
    assert {"resume=auto", "hydra/launcher=submitit_local", "budget=smoke", "hydra.launcher.timeout_min=30"} <= set(train)
    assert search[:4] == ["python", "search.py", "-m", "experiment=table6"] and "budget=smoke" not in search


@pytest.mark.parametrize("args, message", [
    (["+hydra.callbacks.x._target_=torch.load"], "configs are data here"),
    (["hydra.sweep.dir=elsewhere"], "the stage sets the sweep's directory"),
    (["experiment=table1"], "the stage sets the sweep's directory and experiment"),
])
def test_a_stage_override_that_names_code_or_the_sweep_is_refused(tmp_path, args, message):
    rc, out = cli("run", "--only", "table4", "--root", str(tmp_path / "state"), *args)
    assert rc == 2 and message in out and not (tmp_path / "state").exists()


def _stage(tmp_path: Path, launcher: str, *extra: str) -> tuple[int, str]:
    return cli("run", "--only", "table4", "--budget", "smoke", "--launcher", launcher, "--root", str(tmp_path),
               "variant=table4/aim", "seed=0", "budget.total_steps=512", "budget.init_random_steps=256",
               "budget.eval_every=0", "budget.checkpoint_every=256", "budget.final_eval_innings=4", *extra)


@pytest.mark.slow
def test_a_stage_runs_on_submitit_local_resumes_and_is_reported(tmp_path):
    """A table's stage is one multirun under hydra/launcher=submitit_local; run again, a finished
    run does nothing (no new start record); status and report read the run directories."""
    rc, out = _stage(tmp_path, "submitit_local")
    assert rc == 0, out
    run = tmp_path / "table4" / "aim" / "seed0"
    assert json.loads((run / "summary.json").read_text())["frames"] == 512
    starts = [json.loads(line) for line in (run / STARTS).read_text().splitlines()]
    assert [s["mode"] for s in starts] == ["fresh"] and starts[0]["command"][:2] == ["python", "train.py"]
    assert "variant=table4/aim" in starts[0]["command"]
    first = (run / "eval.json").read_bytes()
    assert _stage(tmp_path, "submitit_local")[0] == 0
    assert len((run / STARTS).read_text().splitlines()) == 1 and (run / "eval.json").read_bytes() == first
    rc, out = cli("status", "--root", str(tmp_path), "--only", "table4")
    table4 = next(line for line in out.splitlines() if line.startswith("| table4"))
    assert [c.strip() for c in table4.strip("|").split("|")][1:4] == ["1/9", "0", "8"]
    rc, out = cli("report", "paper", "--root", str(tmp_path), "--out", str(tmp_path / "report"))
    assert rc == 0, out
    data = json.loads((tmp_path / "report" / "reproduction.json").read_text())
    aim = next(r for r in data["rows"] if (r["table"], r["variant"]) == (4, "aim"))
    assert aim["seeds"] == [0] and aim["ours"]["mean"] == json.loads(first)["mean"] and not aim["complete"]
    assert (tmp_path / "report" / "training" / "paper" / "table4" / "aim" / "seed0" / "eval.json").is_file()


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("hydra_plugins.hydra_ray_launcher") is None, reason="the ray extra is not installed")
def test_a_stage_runs_on_a_local_ray_cluster(tmp_path):
    """The same stage under hydra/launcher=ray_tasks (a local Ray instance) gives the same run."""
    rc, out = _stage(tmp_path / "ray", "ray_tasks", "hydra.launcher.ray.init.num_cpus=1")
    assert rc == 0, out
    rc, out = _stage(tmp_path / "basic", "basic")
    assert rc == 0, out
    evals = [(tmp_path / k / "table4" / "aim" / "seed0" / "eval.json").read_bytes() for k in ("ray", "basic")]
    assert evals[0] == evals[1]


# ----------------------------------------------------------------------------- the report


def _fake_run(run_dir: Path, table: str, row: str, seed: int, mean: float, best: int, canonical: float, frames: int) -> None:
    """A finished training run's small files, as train.py writes them (the numbers made up)."""
    run_dir.mkdir(parents=True)
    config = {"seed": seed, "table": table, "row": row, "algo": {"name": "sac"}, "env": {"paradigm": "random_continue"},
              "physics": {"preset": "korean_medium"}, "budget": {"total_steps": frames}}
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config))
    ev = {"mean": mean, "best": best, "foul_innings_pct": 50.0 + seed, "foul_per_shot_pct": 10.0 + seed,
          "success_per_shot_pct": 4.0 + seed, "start": "random"}
    (run_dir / "eval.json").write_text(json.dumps(ev))
    (run_dir / "eval_canonical.json").write_text(json.dumps({**ev, "mean": canonical, "start": "canonical"}))
    (run_dir / "summary.json").write_text(json.dumps({"frames": frames, "cpu_seconds": 1800.0 * (seed + 1),
                                                       "physics": "korean_medium"}))
    (run_dir / "checkpoint.pt").write_bytes(b"weights")
    (run_dir / STARTS).write_text(json.dumps({"commit": f"c{seed}", "mode": "fresh"}) + "\n")


def test_report_writes_reproduction_rows_from_the_run_directories(tmp_path):
    """Table 1's row aggregates the finished seeds (mean, population std, max, CPU-hours, the
    commits of their start records), Table 2's shared row reads the same runs, Table 6 rows come
    from results.json; the small files are copied, the checkpoints are not; unfinished rows say so."""
    root, out = tmp_path / "state", tmp_path / "results"
    for seed, mean, best, canonical in ((0, 0.5, 3, 1.0), (1, 0.3, 4, 0.0)):
        _fake_run(root / "table1" / "sac" / f"seed{seed}", "table1", "sac", seed, mean, best, canonical, 400)
    _fake_run(root / "extra" / "sac_paper" / "seed0", "extra", "sac_paper", 0, 0.25, 2, 0.0, 400)
    search_dir = root / "table6" / "geometric" / "h2_p3"
    search_dir.mkdir(parents=True)
    (search_dir / "results.json").write_text(json.dumps({
        "protocol": "p3", "search": "h2", "proposer": "geometric", "mean": 228.9, "max": 496.0, "seconds": 36.0,
        "shots": 2289, "physics": "korean_medium", "sims_per_decision": 400, "values": [100.0] * 9 + [1389.0],
        "commit": "s1", "extra": {"cap": 10000, "seeds": list(range(10)), "reached_cap": 0}}))

    rc, text = cli("report", "paper", "--root", str(root), "--out", str(out))
    assert rc == 0, text
    data = json.loads((out / "reproduction.json").read_text())
    rows = {(r["table"], r.get("variant") or f"{r['proposer']}/{r['method']}_{r['protocol']}"): r for r in data["rows"]}
    sac = rows[(1, "sac")]
    assert sac["seeds"] == [0, 1] and sac["seeds_planned"] == [0, 1, 2, 3, 4] and not sac["complete"]
    assert sac["ours"]["mean"] == pytest.approx(0.4) and sac["ours"]["std"] == pytest.approx(0.1)
    assert sac["ours"]["max"] == 4 and sac["ours"]["foul_inn"] == pytest.approx(50.5)
    assert sac["paper"]["mean"] == paper_tables()["table1"].rows["sac"].figures["mean"]
    assert (sac["steps"], sac["physics"], sac["commits"]) == (400_000, "korean_medium", ["c0", "c1"])
    assert sac["cpu_hours"] == pytest.approx(1.5)
    shared = rows[(2, "random_continue")]
    assert shared["seeds"] == [0, 1] and shared["seeds_planned"] == [0, 1, 2] and shared["shared_with"] == ["table1/sac"]
    assert shared["ours"]["canonical"] == pytest.approx(0.5) and shared["ours"]["mean"] == pytest.approx(0.4)
    h2 = rows[(6, "geometric/h2_p3")]
    assert h2["complete"] and (h2["mean"], h2["max"], h2["cap"], h2["seeds"]) == (228.9, 496.0, 10000, list(range(10)))
    assert h2["proposer_steps"] == 0 and h2["paper"] is None and h2["cpu_hours"] == pytest.approx(0.01)
    assert rows[(6, "base/h2_p3")]["proposer_steps"] == 1_000_000 and rows[(6, "base/h2_p3")]["paper"]["mean"] > 1000
    lo, hi = h2["ci95"]  # percentile bootstrap of the mean: one long chain among ten short ones
    assert 100.0 <= lo < 228.9 < hi <= 1389.0 * 0.5
    assert not rows[(6, "geometric/puct_p1")]["complete"]
    assert data["cpu_hours_by_table"]["table1"] == pytest.approx(1.5) and data["cpu_hours_by_table"]["table2"] == 0.0
    copied = out / "training" / "paper" / "table1" / "sac" / "seed1"
    assert (copied / "eval_canonical.json").is_file() and (copied / STARTS).is_file()
    assert not (copied / "checkpoint.pt").exists()
    assert (out / "search" / "paper" / "table6" / "geometric" / "h2_p3" / "results.json").is_file()
    # the extra run sits beside the tables, compared with the paper's SAC row and ours
    (extra,) = data["extra"]
    assert (extra["variant"], extra["paper_row"], extra["complete"], extra["table"]) == ("sac_paper", "sac", True, 1)
    assert extra["ours"]["mean"] == pytest.approx(0.25) and extra["paper"] == sac["paper"]

    # the copied run directories alone give the same report
    again = tmp_path / "again"
    write_report(Sources("paper", out / "training" / "paper", out / "search" / "paper"), again)
    assert json.loads((again / "reproduction.json").read_text()) == data
    assert (again / "reproduction.md").read_text() == (out / "reproduction.md").read_text()

    rc, text = cli("report", "paper", "--root", str(tmp_path / "nowhere"), "--out", str(out))
    assert rc == 2 and "no stage has run there" in text


@pytest.mark.slow
def test_each_training_row_carries_its_iqm_with_a_stratified_bootstrap_interval(tmp_path):
    """A row whose seeds all recorded their evaluation's per-inning points gets ``aggregate``: the
    IQM over every (seed, inning) with its 95 % stratified bootstrap interval (which holds the
    IQM), the mean and the per-seed means; a table's comparison gets P(X > Y) with its interval;
    both are the same bytes when written again. Rows without the points show none (a dash)."""
    import random

    root = tmp_path / "state"
    rng = random.Random(0)
    for row, centre in (("aim", 2), ("aim_features", 6)):
        for seed in (0, 1):
            d = root / "table4" / row / f"seed{seed}"
            points = [max(0, centre + rng.randint(-2, 3)) for _ in range(20)]
            _fake_run(d, "table4", row, seed, sum(points) / len(points), max(points), 0.0, 400)
            ev = json.loads((d / "eval.json").read_text())
            (d / "eval.json").write_text(json.dumps({**ev, "points": points}))
    _fake_run(root / "table4" / "plain" / "seed0", "table4", "plain", 0, 0.5, 3, 0.0, 400)  # no points recorded

    first, second = tmp_path / "first", tmp_path / "second"
    data = json.loads(write_report(Sources("paper", root, root), first)[0].read_text())
    write_report(Sources("paper", root, root), second)
    for name in ("reproduction.json", "reproduction.md"):
        assert (first / name).read_bytes() == (second / name).read_bytes(), name
    rows = {(r["table"], r.get("variant")): r for r in data["rows"]}
    for key in ((4, "aim"), (4, "aim_features"), (5, "aim_features")):
        agg, ours = rows[key]["aggregate"], rows[key]["ours"]
        assert agg["seeds"] == 2 and len(agg["per_seed"]) == 2
        assert agg["mean"] == pytest.approx(ours["mean"], abs=1e-4)
        lo, hi = agg["ci95"]
        assert lo <= agg["iqm"] <= hi and lo < hi
    assert rows[(5, "aim_features")]["aggregate"] == rows[(4, "aim_features")]["aggregate"]  # the same runs
    assert rows[(4, "plain")]["aggregate"] is None and rows[(4, "plain")]["ours"]["mean"] == pytest.approx(0.5)
    assert rows[(1, "sac")]["aggregate"] is None
    (better,) = [p for p in data["improvement"] if p["table"] == 4]
    assert (better["x"], better["y"], better["seeds"]) == ("aim_features", "aim", [2, 2])
    assert better["ci95"][0] <= better["p"] <= better["ci95"][1] and better["p"] > 0.9
    md = re.sub(" +", " ", (first / "reproduction.md").read_text())
    agg = rows[(4, "aim_features")]["aggregate"]
    assert "| mean ± std | IQM [95 % CI] |" in md
    assert f"{agg['iqm']:.3f} [{agg['ci95'][0]:.3f}, {agg['ci95'][1]:.3f}]" in md
    assert f"| `aim_features` > `aim` | {better['p']:.3f} [" in md
    assert "Deep RL at the Edge of the Statistical Precipice" in md


def test_rand_eval_is_the_points_before_the_first_miss_of_the_random_start_evaluation(tmp_path):
    """Table 3's "rand. eval" column: the mean over seeds of each run's mean points before the
    first miss from random racks; missing unless every run recorded it."""
    from billiards.report import aggregate, read_run

    root = tmp_path / "state"
    for seed, streaks in ((0, [0, 1, 0, 0]), (1, [2, 0, 0, 0])):
        d = root / "table3" / "staged" / f"seed{seed}"
        _fake_run(d, "table3", "staged", seed, 0.5, 3, 0.0, 400)
        ev = json.loads((d / "eval.json").read_text())
        (d / "eval.json").write_text(json.dumps({**ev, "first_miss_points": streaks}))
    runs = [read_run(root / "table3" / "staged" / f"seed{s}") for s in (0, 1)]
    assert aggregate(runs)["rand_eval"] == pytest.approx(0.375)
    without = tmp_path / "seed2"
    _fake_run(without, "table3", "staged", 2, 0.5, 3, 0.0, 400)
    assert aggregate([*runs, read_run(without)])["rand_eval"] is None
    data = json.loads(write_report(Sources("paper", root, root), tmp_path / "out")[0].read_text())
    row = next(r for r in data["rows"] if (r["table"], r["variant"]) == (3, "staged"))
    assert row["ours"]["rand_eval"] == pytest.approx(0.375) and row["paper"]["rand_eval"] > 0


@pytest.mark.slow
def test_report_draws_each_tables_learning_curves_from_its_finished_runs(tmp_path):
    """Per table with a finished run: the mean over its finished seeds of their periodic
    evaluations (only steps all of them reached) in img/reproduction_<table>.png, linked under the
    table; an unfinished run's evaluations are left out; a finished extra run gets its own figure."""
    from billiards.report import mean_curve, read_curve

    root, out = tmp_path / "state", tmp_path / "results"
    for key, seed, evals in (("table1/sac", 0, [0.1, 0.3, 0.5]), ("table1/sac", 1, [0.3, 0.5]),
                             ("table1/sac", 2, [0.9, 0.9, 0.9]), ("extra/sac_paper", 0, [0.1, 0.2])):
        d = root / key / f"seed{seed}"
        _fake_run(d, *key.split("/"), seed, evals[-1], 3, 0.0, 400)
        (d / "eval_history.jsonl").write_text("".join(
            json.dumps({"step": 100 * (i + 1), "cpu_time": 60.0 * i, "wall_time": 60.0 * i, "eval_mean": m,
                        "eval_best": 2, "start": "random"}) + "\n" for i, m in enumerate(evals)))
    (root / "table1" / "sac" / "seed2" / "eval.json").unlink()  # seed 2 unfinished

    steps, mean, std = mean_curve([read_curve(root / "table1" / "sac" / f"seed{s}") for s in (0, 1)])
    assert steps.tolist() == [100, 200] and mean == pytest.approx([0.2, 0.4]) and std == pytest.approx([0.1, 0.1])
    rc, text = cli("report", "paper", "--root", str(root), "--out", str(out))
    assert rc == 0, text
    data = json.loads((out / "reproduction.json").read_text())
    assert data["figures"] == {"table1": "img/reproduction_table1.png", "table2": "img/reproduction_table2.png",
                               "extra_table1": "img/reproduction_extra_table1.png"}
    for figure in data["figures"].values():
        assert (out / figure).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    md = (out / "reproduction.md").read_text()
    assert md.index("](img/reproduction_extra_table1.png)") > md.index("## Extra: the authors' SAC settings")
