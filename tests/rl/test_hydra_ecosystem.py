"""The Hydra ecosystem around train.py (issue #18, item 4): the Ray launcher preset, the Optuna
sweeper preset and ``logger=tensorboard``.

The plugins and tensorboard are optional extras (``pip install -e ".[ray,optuna,tensorboard]"``),
so the suite runs without them: what needs no plugin always runs (the Ray preset composes, the
Optuna search space is valid for every algorithm, the tensorboard backend is validated); what
needs one is skipped unless it is installed (the Optuna preset composes and runs a study, Ray
runs a multirun, a run writes TensorBoard event files).
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from billiards.rl.config import ConfigError, LoggerBackend
from billiards.rl.validation import ValidateConfig, validate
from conftest import APP_ENV

REPO = Path(__file__).resolve().parents[2]
TRAIN = str(REPO / "train.py")
ENV = {**APP_ENV, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
       "RAY_USAGE_STATS_ENABLED": "0"}
# A run of a few seconds: 4 collector iterations of 32 innings, a 2-inning final evaluation.
SHORT = ["budget=smoke", "budget.init_random_steps=64", "budget.eval_every=0", "budget.checkpoint_every=0",
         "budget.log_every=64", "budget.final_eval_innings=2", "progress=false"]
TINY = SHORT + ["budget.total_steps=128"]


def has(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def needs(*modules: str):
    missing = [m for m in modules if not has(m)]
    return pytest.mark.skipif(bool(missing), reason=f"optional extra not installed: {', '.join(missing)}")


def compose_cfg(*overrides: str, hydra: bool = False):
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides), return_hydra_config=hydra)


def train(cwd: Path, *overrides: str, timeout: float = 900) -> subprocess.CompletedProcess:
    """``python train.py <overrides>`` in ``cwd`` (conftest.app_here: in this process, a multirun
    in a process of its own)."""
    from conftest import app_here

    return app_here(TRAIN, *overrides, cwd=cwd, env=ENV)


def ok(proc: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-5000:]}"
    return proc


# ----------------------------------------------------------------------------- launchers


@pytest.mark.parametrize("preset,target", [
    ("local_parallel", "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher"),
    ("slurm", "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher"),
    ("ray_tasks", "hydra_plugins.hydra_ray_launcher.ray_launcher.RayLauncher"),  # composes without the plugin
])
@pytest.mark.slow
def test_launcher_presets_compose(preset, target):
    launcher = compose_cfg(f"hydra/launcher={preset}", hydra=True).hydra.launcher
    assert launcher._target_ == target
    if preset == "ray_tasks":
        # one core per job; a local instance by default; joining a cluster must not pass
        # object_store_memory (the plugin's own default), which ray.init rejects there
        assert launcher.ray.remote.num_cpus == 1 and launcher.ray.init.address is None
        assert "object_store_memory" in launcher.ray.init and launcher.ray.init.object_store_memory is None
        joined = compose_cfg("hydra/launcher=ray_tasks", "hydra.launcher.ray.init.address=auto", hydra=True)
        assert joined.hydra.launcher.ray.init.address == "auto"


@needs("ray", "hydra_plugins.hydra_ray_launcher")
def test_ray_multirun_runs_every_job(tmp_path):
    """A local Ray instance runs a two-seed sweep; each job writes its run dir under the
    (relative) sweep dir, as the joblib launcher does."""
    ok(train(tmp_path, "-m", "hydra/launcher=ray_tasks", "hydra.launcher.ray.init.num_cpus=2", "seed=0,1", *TINY,
             "hydra.sweep.dir=sweep", timeout=900))
    runs = sorted((tmp_path / "sweep").glob("*/eval.json"))
    assert [r.parent.name[:2] for r in runs] == ["0_", "1_"]
    assert {json.loads((r.parent / "summary.json").read_text())["seed"] for r in runs} == {0, 1}


# ----------------------------------------------------------------------------- optuna


def search_space() -> dict:
    preset = OmegaConf.load(REPO / "conf/hydra/sweeper/optuna_eval.yaml")
    return OmegaConf.to_container(preset.params)


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["sac", "td3", "ppo"])
def test_optuna_search_space_is_valid_for_every_algorithm(algo):
    """Every bound of every parameter of the preset's search space is a valid override of the
    training config (no plugin needed: Hydra's own parser reads the sweep syntax)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.core.override_parser.types import ChoiceSweep, IntervalSweep

    overrides = OverridesParser.create().parse_overrides([f"{k}={v}" for k, v in search_space().items()])
    assert overrides and all(o.is_sweep_override() for o in overrides)
    corners: list[list[str]] = [[]]
    for o in overrides:
        sweep = o.value()
        if isinstance(sweep, IntervalSweep):
            values = [sweep.start, sweep.end]
            if "log" in sweep.tags:
                assert sweep.start > 0
        else:
            assert isinstance(sweep, ChoiceSweep)
            values = list(sweep.list)
        corners = [c + [f"{o.key_or_group}={v}"] for c in corners for v in values]
    for corner in corners:
        validate(compose_cfg(f"algo={algo}", *corner))


@needs("hydra_plugins.hydra_optuna_sweeper", "optuna")
def test_optuna_preset_composes_and_maximises():
    sweeper = compose_cfg("hydra/sweeper=optuna_eval", hydra=True).hydra.sweeper
    assert sweeper._target_ == "hydra_plugins.hydra_optuna_sweeper.optuna_sweeper.OptunaSweeper"
    assert sweeper.direction == "maximize" and sweeper.max_failure_rate == 1.0
    assert sweeper.sampler._target_ == "optuna.samplers.TPESampler"
    assert OmegaConf.to_container(sweeper.params) == search_space()


@needs("hydra_plugins.hydra_optuna_sweeper", "optuna")
def test_optuna_study_records_a_failed_trial_and_keeps_the_best(tmp_path):
    """Four trials over budget.total_steps in {-1, 128, 192} (the random sampler with seed 2
    draws 192, -1, 128, 128): the invalid trial is recorded as FAIL and the study goes on;
    every completed trial's value is its run's final evaluation, and the reported best is the
    largest of them (the study maximises)."""
    import optuna
    import yaml

    db = f"sqlite:///{tmp_path / 'study.db'}"
    proc = ok(train(tmp_path, "-m", "hydra/sweeper=optuna_eval", "hydra/sweeper/sampler=random",
                    "hydra.sweeper.sampler.seed=2", "hydra.sweeper.n_trials=4", "hydra.sweeper.params=null",
                    "budget.total_steps=choice(-1,128,192)", f"hydra.sweeper.storage={db}", "hydra.sweeper.study_name=t",
                    *SHORT, "hydra.sweep.dir=sweep", timeout=900))
    assert "budget.total_steps must be > 0, got -1" in proc.stdout + proc.stderr
    study = optuna.load_study(study_name="t", storage=db)
    assert study.direction == optuna.study.StudyDirection.MAXIMIZE and len(study.trials) == 4
    steps = [t.params["budget.total_steps"] for t in study.trials]
    assert set(steps) == {-1, 128, 192}
    assert [t.state.name for t in study.trials] == ["FAIL" if n < 0 else "COMPLETE" for n in steps]
    completed = [t for t in study.trials if t.state.name == "COMPLETE"]
    for t in completed:
        (run,) = (tmp_path / "sweep").glob(f"{t.number}_*")
        assert json.loads((run / "eval.json").read_text())["mean"] == pytest.approx(t.value)
        assert json.loads((run / "summary.json").read_text())["frames"] == t.params["budget.total_steps"]
    best = yaml.safe_load((tmp_path / "sweep/optimization_results.yaml").read_text())
    assert best["best_value"] == max(t.value for t in completed)


@needs("hydra_plugins.hydra_optuna_sweeper", "optuna")
def test_optuna_sweep_with_an_invalid_fixed_setting_fails_before_the_study(tmp_path):
    """What the sweeper does not vary is validated before the study starts: every trial would
    fail, so nothing runs and nothing is written."""
    proc = train(tmp_path, "-m", "hydra/sweeper=optuna_eval", "budget=smoke", "budget.total_steps=-1", timeout=900)
    assert proc.returncode != 0
    assert "every trial of the sweep would fail" in proc.stderr and "budget.total_steps must be > 0" in proc.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_fixed_part_check_leaves_swept_keys_to_the_trials():
    """ValidateConfig's check for non-basic sweepers: an error on a key the sweeper varies is
    not raised up front (a trial may pick a valid value); any other error is."""
    def with_params(params: dict):
        cfg = compose("config", ["budget.total_steps=-1"], return_hydra_config=True)
        OmegaConf.set_readonly(cfg, False)
        cfg.hydra.sweeper.params = params  # what a sweeper's preset or the command line sets
        return cfg

    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        ValidateConfig._check_fixed_part(with_params({"budget.total_steps": "choice(-1,5)"}))  # swept: passes
        with pytest.raises(SystemExit, match="every trial of the sweep would fail"):
            ValidateConfig._check_fixed_part(with_params({"algo.lr": "choice(0.1,0.2)"}))


# ----------------------------------------------------------------------------- tensorboard


@pytest.mark.slow
def test_tensorboard_backend_composes_and_is_validated(monkeypatch):
    cfg = compose_cfg("logger=tensorboard", "budget=smoke")
    assert cfg.logger.backend == LoggerBackend.tensorboard and cfg.logger.csv
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "tensorboard" else real(name, *a))
    with pytest.raises(ConfigError, match=r'logger=tensorboard needs the \'tensorboard\' package.*pip install -e "\.\[tensorboard\]"'):
        validate(cfg)
    validate(compose_cfg("logger=csv", "budget=smoke"))  # the other backends need nothing extra


@needs("tensorboard")
@pytest.mark.slow
def test_tensorboard_resume_purges_the_killed_process_events(tmp_path):
    """A resumed run's event files read as one run: the steps the killed process logged after
    the checkpoint are replaced by the resumed process's, as in metrics.csv."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from billiards.rl.metrics import TENSORBOARD_DIR, MetricLogger

    cfg = compose_cfg("logger=tensorboard", "budget=smoke")
    first = MetricLogger(cfg, tmp_path, ("loss_actor",))
    for step in (100, 200, 300, 400):
        first.log({"step": step, "train_reward": step / 1000, "loss_actor": 1.0, "eval_mean": None})
    first.close()  # the checkpoint was at 200; the process was killed after logging 400
    second = MetricLogger(cfg, tmp_path, ("loss_actor",), resume_step=200)
    second.log({"step": 300, "train_reward": -1.0, "loss_actor": 2.0})
    second.close()
    acc = EventAccumulator(str(tmp_path / TENSORBOARD_DIR))
    acc.Reload()
    assert [(e.step, pytest.approx(e.value)) for e in acc.Scalars("train/reward")] == [(100, 0.1), (200, 0.2), (300, -1.0)]
    assert "eval/mean" not in acc.Tags()["scalars"]  # None values are not logged
    rows = (tmp_path / "metrics.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["100", "200", "300"]


@pytest.mark.slow
@needs("tensorboard")
def test_tensorboard_smoke_run_writes_event_files(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from billiards.rl.metrics import TENSORBOARD_DIR

    run = tmp_path / "run"
    ok(train(tmp_path, "logger=tensorboard", *TINY, f"hydra.run.dir={run}"))
    events = list((run / TENSORBOARD_DIR).glob("events.out.tfevents.*"))
    assert len(events) == 1 and events[0].stat().st_size > 0
    acc = EventAccumulator(str(run / TENSORBOARD_DIR))
    acc.Reload()
    scalars = acc.Tags()["scalars"]
    assert {"train/reward", "speed/fps", "eval/mean", "agent/loss_actor"} <= set(scalars)
    final = json.loads((run / "eval.json").read_text())["mean"]
    assert acc.Scalars("eval/mean")[-1].step == 128 and acc.Scalars("eval/mean")[-1].value == pytest.approx(final)
    csv_steps = [int(r.split(",")[0]) for r in (run / "metrics.csv").read_text().splitlines()[1:]]
    assert sorted({e.step for e in acc.Scalars("speed/fps")}) == sorted(set(csv_steps))
    assert "config" in "".join(acc.Tags()["tensors"])  # the resolved config as text
