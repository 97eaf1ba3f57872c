"""Composition is data too (billiards.app_config): a config group's value is an option's name,
never a path to a YAML file; no override value carries a ``_target_`` or a logging factory;
and every config Hydra composes -- whatever files the overrides pulled in -- is checked against
the same app's config composed without overrides before Hydra builds its callbacks, logging,
launcher or sweeper. One mechanism for the four apps; docs/reliability.md.

The checks run in this process (a single run of an app too: conftest.app_here); a multirun
(``-m``) runs as a user types it, in a process of its own, since Hydra's launcher starts the
jobs' processes: the three holes refused in a multirun, a multirun over proposers, and a bad
job that stops a multirun before any job runs. (train.py's multiruns: tests/rl/test_train.py.)"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra._internal.config_loader_impl import ConfigLoaderImpl
from hydra.core.global_hydra import GlobalHydra
from hydra.types import RunMode

import billiards.bench.config  # noqa: F401  (each app's schema, as its entry point registers it)
import billiards.league.config  # noqa: F401
import billiards.rl.config  # noqa: F401
import billiards.search.config  # noqa: F401
from billiards import app_config
from billiards.app_config import composition_errors, override_errors

REPO = Path(__file__).resolve().parents[2]
CONF = REPO / "conf"
APPS = {"train": "config", "search": "search", "match": "match", "evaluate": "evaluate"}  # entry point -> config name
# a group each app composes, whose option a hostile YAML may stand in for
GROUP = {"train": "experiment", "search": "experiment", "match": "physics", "evaluate": "hydra/help"}
OPTION = {"experiment": "table4", "physics": "international", "hydra/help": "evaluate"}  # a shipped option of each


def evil_yaml(marker: Path) -> str:
    """A config that makes Hydra build a callback writing ``marker`` (before any validation)."""
    return ("# @package _global_\nhydra:\n  callbacks:\n    x:\n      _target_: billiards.files.atomic_write_text\n"
            f"      path: {marker}\n      text: pwned\n")


def file_handler(node: str, victim: Path) -> list[str]:
    """Overrides that would make logging open (and truncate) ``victim``."""
    return [f"+{node}.handlers.e.class=logging.FileHandler", f"+{node}.handlers.e.filename={victim}",
            f"+{node}.handlers.e.mode=w"]


def run_app(app: str, *args: str, cwd: Path, script_dir: Path = REPO, env: dict | None = None):
    return subprocess.run([sys.executable, str(script_dir / f"{app}.py"), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=900, env={**os.environ, "PYTHONPATH": str(REPO), **(env or {})})


def refused(proc, message: str) -> None:
    assert proc.returncode != 0 and message in proc.stderr, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]


# ----------------------------------------------------------------------------- the command line


@pytest.mark.parametrize("app", APPS)
def test_the_command_line_names_options_and_data_only(app, tmp_path):
    """The three holes of "Hostile input, second pass" and their kin, refused on the words
    before Hydra composes anything (what every app's entry point checks first)."""
    evil = tmp_path / "evil.yaml"
    rel = os.path.relpath(evil.with_suffix(""), CONF / GROUP[app])
    cases = [
        ([f"{GROUP[app]}={rel}"], "takes the name of one of its options"),
        ([f"+{GROUP[app]}={evil.with_suffix('')}"], "takes the name of one of its options"),  # an absolute path
        ([f"{GROUP[app]}={OPTION[GROUP[app]]},{rel}"], "takes the name of one of its options"),  # one value of a sweep
        ([f"{GROUP[app]}=choice({OPTION[GROUP[app]]},{rel})"], "takes the name of one of its options"),
        (["physics=korean_medium/../international"], "takes the name of one of its options"),
        (["physics=bogus"], "Could not find 'physics/bogus'"),
        (["hydra/launcher=../../../x"], "takes the name of one of its options"),
        (["+hydra.sweeper.params.physics=../x"], "takes the name of one of its options"),
        (["hydra.sweeper.params={physics: ../x}"], "takes the name of one of its options"),
        (file_handler("hydra.hydra_logging", tmp_path / "victim")[:1], "a 'class' under hydra.hydra_logging"),
        ([f"+hydra.job_logging.handlers.file.filename={tmp_path / 'victim'}"], "a 'filename' under hydra.job_logging"),
        (["hydra.job_logging.handlers.console.stream=ext://sys.stderr"], "a 'stream' under hydra.job_logging"),
        (["+hydra.hydra_logging.handlers.e={class: logging.FileHandler}"], "a dict in a value may not hold the key 'class'"),
        (["hydra.job_logging.handlers.console=${hydra.job_logging.handlers.file}"], "an interpolation or an ext://"),
        (["hydra.launcher={_target_:tempfile.mkdtemp}"], "a value may not hold _target_"),
        (["+x=[{_partial_: true}]"], "a value may not hold _partial_"),
        (["+x=${oc.decode:abc}"], "a value may not hold oc.decode"),
        (["hydra.job.name=../../elsewhere"], "hydra.job.name names the job's log file"),
        (["hydra.output_subdir=../../conf"], "hydra.output_subdir is a folder inside the run directory"),
        (["hydra.launcher.setup=[touch x]"], "hydra.launcher.setup may not be set from outside the project's conf/"),
    ]
    for overrides, message in cases:
        errors = override_errors(overrides)
        assert len(errors) == 1 and message in errors[0], (overrides, errors)
        with pytest.raises(SystemExit, match="Error: "):
            app_config.guard_command_line(["-m", *overrides])


def test_legitimate_command_lines_pass():
    for words in (["-m", "experiment=table4", "hydra/launcher=joblib"], ["experiment=table4", "variant=table4/aim"],
                  ["physics=international", "noise=fastfiz_x5", "proposer=base", "search=puct", "protocol=p1"],
                  ["-m", "search=puct,h2", "proposer=choice(geometric,base)", "experiment=glob(table*)"],
                  ["hydra/launcher=local_parallel", "hydra.launcher.n_jobs=3", "hydra/job_logging=default"],
                  ["--cfg", "job", "--package", "algo", "resume=outputs/2026-01-01/12-00-00_sac", "experiment=null"],
                  ["~experiment", "+hydra.sweeper.params.seed=0,1", "hydra.run.dir=/tmp/anywhere", "hydra.job.name=mine",
                   "hydra.job_logging.formatters.simple.format='%(message)s'", "hydra.output_subdir=.hydra",
                   "proposer.checkpoints=[results/policies/base/seed0.pt]", "agent=my_agent.py:act", "--help"]):
        assert override_errors(words) == [], words


# ----------------------------------------------------------------------------- the composed config


def loader_for(conf: Path):
    GlobalHydra.instance().clear()
    initialize_config_dir(config_dir=str(conf), version_base="1.3")
    return GlobalHydra.instance().config_loader()


def composed(loader, name: str, *overrides: str):
    return loader.load_configuration(name, list(overrides), RunMode.MULTIRUN, validate_sweep_overrides=False)


@pytest.mark.parametrize("app,name", APPS.items())
@pytest.mark.slow
def test_the_composed_config_holds_only_what_the_project_ships(app, name, tmp_path):
    """What Hydra would build from -- callbacks, logging, launcher, sweeper, at any depth, also
    through an interpolation -- against the override-free composition and Hydra's own options."""
    loader = loader_for(CONF)
    try:
        baseline = composed(loader, name)
        assert composition_errors(baseline, baseline, loader) == []
        legitimate = {"train": [["hydra/launcher=joblib"], ["hydra/launcher=local_parallel", "hydra.launcher.n_jobs=3"],
                                ["hydra/launcher=submitit_local"], ["hydra/launcher=ray_tasks"], ["experiment=table4"],
                                ["physics=international", "hydra/hydra_logging=hydra_debug"]],
                      "search": [["experiment=table6"], ["noise=fastfiz", "proposer=base", "hydra/job_logging=default"]],
                      "match": [["hydra/launcher=slurm", "hydra.job_logging.root.level=DEBUG", "hydra.verbose=true"]],
                      "evaluate": [["hydra/job_logging=default", "hydra/launcher=joblib"]]}
        for overrides in legitimate[app]:
            assert composition_errors(composed(loader, name, *overrides), baseline, loader) == [], overrides
        victim = tmp_path / "victim"
        for overrides, message in [
            (file_handler("hydra.hydra_logging", victim), f"hydra.hydra_logging.handlers.e.filename='{victim}'"),
            ([f"++hydra.job_logging.handlers.file.filename={victim}"], "hydra.job_logging.handlers.file.filename="),
            (["hydra.job_logging.handlers.console=${hydra.hydra_logging.handlers.console}",
              "++hydra.hydra_logging.handlers.console.stream=ext://sys.stderr"], "handlers.console.stream='ext://sys.stderr'"),
            (["hydra.launcher={_target_:tempfile.mkdtemp}"], "hydra.launcher._target_='tempfile.mkdtemp'"),
            (["+hydra.launcher.x={y: {_target_: os.getcwd}}"], "hydra.launcher.x.y._target_='os.getcwd'"),
            (["+hydra.sweeper.x=${hydra.callbacks}"], "hydra.sweeper.x.validate._target_="),  # a copy by reference
            (["+hydra.callbacks.y._target_=billiards.files.atomic_write_text"], "hydra.callbacks: set to"),
            (["+algo._target_=builtins.print"] if app == "train" else ["+seed._target_=builtins.print"], "._target_="),
            *([([f"experiment={'table4' if app == 'train' else 'table6'}", "+hydra.sweeper.params.physics=../x"],
                 "hydra.sweeper.params 'physics=../x'")] if app in ("train", "search") else []),  # a job's override
        ]:
            try:
                cfg = composed(loader, name, *overrides)
            except Exception:  # a key the app's schema refuses while composing: nothing to build from
                assert overrides[0].startswith("+seed"), overrides
                continue
            errors = composition_errors(cfg, baseline, loader)
            assert any(message in e for e in errors), (overrides, errors)
            assert victim not in tmp_path.iterdir()
    finally:
        GlobalHydra.instance().clear()


@pytest.mark.parametrize("app,name", APPS.items())
@pytest.mark.slow
def test_a_hostile_option_file_is_refused_before_hydra_builds_it(app, name, tmp_path, monkeypatch):
    """A YAML file that stands in for a shipped option (the command line names only options;
    what those files hold is checked as composed, by the loader the guard installs)."""
    conf = tmp_path / "conf"
    shutil.copytree(CONF, conf)
    marker = tmp_path / "marker"
    (conf / "physics" / "international.yaml").write_text(evil_yaml(marker))
    monkeypatch.setattr(ConfigLoaderImpl, "load_configuration", app_config.guard._guarded(ConfigLoaderImpl.load_configuration))
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(conf), version_base="1.3"):
            option = "physics=korean_medium" if app != "evaluate" else "threads=1"
            assert compose(name, overrides=[option], return_hydra_config=True).hydra.callbacks.keys() == {"validate"}
            with pytest.raises(SystemExit, match=r"hydra\.callbacks\.x\._target_='billiards\.files\.atomic_write_text'"):
                compose(name, overrides=["+physics=international" if app == "evaluate" else "physics=international"],
                        return_hydra_config=True)
    finally:
        GlobalHydra.instance().clear()
    assert not marker.exists()


# ----------------------------------------------------------------------------- the apps themselves


@pytest.mark.slow
@pytest.mark.parametrize("app", APPS)
def test_each_app_refuses_the_three_holes_and_writes_nothing(app, tmp_path):
    """``<group>=../../evil`` (a YAML whose callback would write a file), a logging FileHandler
    that would truncate a file, a ``_target_`` inside a dict value, with an otherwise bad value:
    the app exits non-zero naming each (train: each alone too); no marker, no truncation, no
    temporary directory, no run directory."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    marker, victim, scratch = elsewhere / "marker", elsewhere / "victim", elsewhere / "tmp"
    (elsewhere / "evil.yaml").write_text(evil_yaml(marker))
    victim.write_text("keep me")
    scratch.mkdir()
    rel = os.path.relpath(elsewhere / "evil", CONF / GROUP[app])
    holes = {"takes the name of one of its options": [f"{GROUP[app]}={rel}"],
             "a 'class' under hydra.hydra_logging may be set in the project's conf/ only":
                 file_handler("hydra.hydra_logging", victim),
             "a value may not hold _target_": ["hydra.launcher={_target_:tempfile.mkdtemp}"]}
    runs = [[word for words in holes.values() for word in words]] + (list(holes.values()) if app == "train" else [])
    for words in runs:
        proc = run_app(app, "-m", "threads=0", *words, cwd=tmp_path, env={"TMPDIR": str(scratch)})
        for message, hole in holes.items():
            if hole[0] in words:
                refused(proc, message)
    assert not marker.exists() and victim.read_text() == "keep me" and list(scratch.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["elsewhere"]  # no outputs/, no run directory


@pytest.mark.slow
@pytest.mark.parametrize("app", APPS)
def test_each_app_checks_what_its_options_compose_to(app, tmp_path, monkeypatch):
    """The app as shipped, but conf/physics/international.yaml replaced by a hostile file: the
    name passes the command-line check, and the composed config is refused before its callback
    is built; the untouched option still runs (--cfg). In this process (conftest.app_here), the
    app's module imported afresh and put back afterwards, CONF_DIR too."""
    import importlib

    import billiards.apps
    import billiards.files
    from conftest import app_here

    module = importlib.import_module(f"billiards.apps.{app}")
    monkeypatch.delitem(sys.modules, module.__name__)  # imported afresh by the script below
    monkeypatch.setattr(billiards.apps, app, module)
    monkeypatch.setattr(billiards.files, "CONF_DIR", billiards.files.CONF_DIR)  # the script sets it
    shutil.copytree(CONF, tmp_path / "conf")
    # the app as shipped, composing this copy of conf/ (billiards.files.CONF_DIR, read when the app is imported)
    (tmp_path / f"{app}.py").write_text(f"import pathlib\nimport billiards.files\n\nbilliards.files.CONF_DIR = "
                                        f"pathlib.Path({str(tmp_path / 'conf')!r})\nfrom billiards.apps.{app} import main\n\nmain()\n")
    marker = tmp_path / "marker"
    (tmp_path / "conf" / "physics" / "international.yaml").write_text(evil_yaml(marker))
    work = tmp_path / "work"
    work.mkdir()
    option = "+physics=international" if app == "evaluate" else "physics=international"
    refused(app_here(tmp_path / f"{app}.py", "threads=0", option, cwd=work),
            "hydra.callbacks.x._target_='billiards.files.atomic_write_text': neither the project's configuration")
    assert not marker.exists() and list(work.iterdir()) == []
    shown = app_here(tmp_path / f"{app}.py", "--cfg", "hydra", "physics=korean_medium" if app != "evaluate" else "threads=1",
                     "hydra/launcher=joblib", cwd=work)
    assert shown.returncode == 0 and "JoblibLauncher" in shown.stdout, shown.stderr[-3000:]


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_a_config_group_is_listed_as_hydra_lists_it_without_copying_the_repository(monkeypatch):
    """The entry points' loader answers a plain ``get_group_options`` (no primary config, no
    overrides: what ``--help`` asks for each group) from its own repository: the same answer as
    Hydra's, for every group and subgroup the apps have, without Hydra's copy per question."""
    import copy

    from hydra.core.object_type import ObjectType

    hydras = ConfigLoaderImpl.get_group_options
    while getattr(hydras, "billiards_listed", False):
        hydras = hydras.__wrapped__
    monkeypatch.setattr(ConfigLoaderImpl, "get_group_options", app_config.guard._plain_listing(hydras))
    assert app_config.guard._plain_listing(ConfigLoaderImpl.get_group_options) is ConfigLoaderImpl.get_group_options  # idempotent
    loader = loader_for(CONF)
    groups, todo = [], [""]
    while todo:
        parent = todo.pop()
        for sub in hydras(loader, parent, ObjectType.GROUP):
            todo.append(f"{parent}/{sub}" if parent else sub)
            groups.append(todo[-1])
    assert {"algo", "proposer", "hydra/launcher", "variant/table4"} <= set(groups)
    copies = []
    deepcopy = copy.deepcopy
    monkeypatch.setattr(copy, "deepcopy", lambda x, *a, **k: copies.append(type(x).__name__) or deepcopy(x, *a, **k))
    for group in groups:
        for kind in (ObjectType.CONFIG, ObjectType.GROUP, None):  # None: configs and groups alike
            assert loader.get_group_options(group, kind) == hydras(loader, group, kind), (group, kind)
        assert loader.get_group_options(group) == hydras(loader, group), group
    listed = len(copies)
    for group in groups:
        loader.get_group_options(group, ObjectType.CONFIG)
    assert len(copies) == listed  # the fast answers copy nothing
    # with overrides or a primary config, Hydra's own answer (its copy: the count above counts)
    assert loader.get_group_options("algo", ObjectType.CONFIG, "config", ["algo=td3"]) == hydras(loader, "algo", ObjectType.CONFIG)
    assert len(copies) > listed
    GlobalHydra.instance().clear()


# ----------------------------------------------------------------------------- multiruns: every job checked first


@pytest.mark.slow
def test_a_search_multirun_over_proposers_runs_and_a_bad_job_stops_it_first(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    search = [sys.executable, str(REPO / "search.py"), "-m"]
    bad = subprocess.run([*search, "search=puct,h2", "search.c_puct=5", f"hydra.sweep.dir={tmp_path / 'bad'}"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert bad.returncode != 0 and "Key 'c_puct' not in 'H2Config'" in bad.stderr, bad.stderr[-2000:]
    assert "Traceback" not in bad.stderr and not (tmp_path / "bad").exists()
    good = subprocess.run([*search, "proposer=geometric,base", "search=puct", "search.budget=4", "search.pool=2",
                           "protocol=p1", "protocol.n_innings=1", "protocol.shots=1",
                           "progress=false", f"hydra.sweep.dir={tmp_path / 'sweep'}"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert good.returncode == 0, good.stderr[-3000:]
    results = {json.loads(p.read_text())["proposer"]: json.loads(p.read_text())
               for p in (tmp_path / "sweep").glob("*/results.json")}
    assert sorted(results) == ["base", "geometric"]
    assert results["base"]["config"]["proposer"]["checkpoints"] == [f"results/policies/base/seed{s}.pt" for s in range(3)]
    assert all(r["search"] == "puct" and r["sims_per_decision"] == 4 for r in results.values())


# search.py's bad overrides that only a multirun shows (the others: tests/search/test_search_runs.py)
SEARCH_MULTIRUN_BAD = [
    (["-m", "search=puct,h2", "search.budget=401"], "job ['search=h2', 'search.budget=401']: invalid search config"),
]


@pytest.mark.slow
@pytest.mark.parametrize("overrides,message", SEARCH_MULTIRUN_BAD, ids=[" ".join(o) for o, _ in SEARCH_MULTIRUN_BAD])
def test_bad_search_overrides_fail_fast_and_write_nothing(tmp_path, overrides, message):
    proc = subprocess.run([sys.executable, str(REPO / "search.py"), *overrides], cwd=tmp_path, capture_output=True, text=True,
                          timeout=900)  # guards against a hang only
    assert proc.returncode != 0 and message in proc.stderr, proc.stderr
    assert not (tmp_path / "pwned").exists()
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == [], f"wrote {list(tmp_path.rglob('*'))}"
