"""Whose directory (billiards.app_config, docs/reliability.md): train.py, search.py and match.py
claim their run directories before Hydra writes anything. A fresh directory (missing or empty)
and a resume of the same run are theirs; anything else -- another app's run, a run without
resume=, files of no run -- is someone else's and refused with one sentence, nothing written;
so is a path that is a file, cannot be created or written, or is too long. A resume of a
finished run says so and changes nothing.

The checks run in-process on configs composed by Hydra's compose API (what the validating
callback is handed); one run of each app's entry point (conftest.app_here) shows that Hydra's
own ``.hydra/`` is never written over another run's."""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.types import RunMode
from omegaconf import OmegaConf, open_dict, read_write

import billiards.league.config  # noqa: F401  (each app's schema, as its entry point registers it)
import billiards.rl.config  # noqa: F401
import billiards.search.config  # noqa: F401
from billiards.app_config import claim_run_directory, claim_sweep_directories

REPO = Path(__file__).resolve().parents[2]
CONF = REPO / "conf"
APPS = {"train": "config", "search": "search", "match": "match"}  # entry point -> its config


@contextlib.contextmanager
def hydra_conf():
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        yield GlobalHydra.instance().config_loader()


def composed(app: str, *overrides: str):
    """A single run's config as Hydra hands it to the validating callback (hydra node included)."""
    with hydra_conf():
        return compose(APPS[app], list(overrides), return_hydra_config=True)


def task_config(app: str, *overrides: str):
    with hydra_conf():
        return compose(APPS[app], list(overrides))


def files(root: Path) -> dict:
    """Every file and folder under ``root``: its bytes and mtime (a folder: its listing and mtime)."""
    out = {}
    for p in sorted(root.rglob("*")):
        st = p.lstat()
        out[str(p.relative_to(root))] = (sorted(os.listdir(p)) if p.is_dir() else p.read_bytes(), st.st_mtime_ns)
    return out


def refused(call, *said: str) -> str:
    """``call`` exits with status 1 and one ``Error: ...`` message holding ``said``, no traceback."""
    with pytest.raises(SystemExit) as info:
        call()
    message = info.value.code
    assert isinstance(message, str) and message.startswith("Error: "), message
    assert all(s in message for s in said) and "Traceback" not in message, message
    return message


def hydra_records(run: Path, config_name: str, config) -> None:
    """What Hydra writes into a run directory before the app runs."""
    (run / ".hydra").mkdir(parents=True)
    OmegaConf.save(config, run / ".hydra" / "config.yaml")
    (run / ".hydra" / "hydra.yaml").write_text(f"hydra:\n  job:\n    name: x\n    config_name: {config_name}\n")
    (run / ".hydra" / "overrides.yaml").write_text("[]\n")


def search_run(run: Path, finished: bool = True) -> Path:
    """A P1 search's run directory, finished (results.json) or stopped (results.json marked partial)."""
    cfg = task_config("search", "protocol=p1")
    hydra_records(run, "search", cfg)
    (run / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    (run / "results.json").write_text(json.dumps({"mean": 2.5, "values": [2, 3], "extra": {} if finished else {"partial": True}}))
    return run


def train_run(run: Path, finished: bool = True) -> Path:
    cfg = task_config("train", "budget=smoke")
    hydra_records(run, "config", cfg)
    (run / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    (run / "checkpoint.pt").write_bytes(b"a damaged checkpoint")
    (run / "metrics.csv").write_text("step\n1024\n")
    (run / "train.log").write_text("log\n")
    if finished:
        (run / "eval.json").write_text("{}")
        (run / "summary.json").write_text("{}")
    return run


def league_run(run: Path, finished: bool = True) -> Path:
    cfg = task_config("match", "players=[random,greedy]", "matches=1")
    hydra_records(run, "match", cfg)
    (run / "matches.jsonl").write_text("")
    if finished:
        (run / "league.json").write_text("{}")
    return run


def unrelated(root: Path) -> Path:
    (root / "data").mkdir(parents=True)
    (root / "notes.txt").write_text("mine\n")
    (root / "data" / "x.csv").write_text("1,2\n")
    return root


MAKE = {"train": train_run, "search": search_run, "match": league_run}


def test_the_run_kinds_name_each_apps_own_files():
    from billiards.app_config import RUN_KINDS
    from billiards.files import IDENTITY_FILE, SCORECARD_JSON, SCORECARD_MD, UNITS_FILE

    assert RUN_KINDS["evaluate"].marks == (IDENTITY_FILE, UNITS_FILE, SCORECARD_JSON, SCORECARD_MD)
    marks = [m for kind in RUN_KINDS.values() for m in kind.marks]
    assert len(marks) == len(set(marks))  # no file is two apps' mark


# ----------------------------------------------------------------------------- (a) fresh


@pytest.mark.parametrize("app", APPS)
@pytest.mark.slow
def test_a_fresh_directory_missing_or_empty_is_the_runs(app, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "empty").mkdir()
    claim_run_directory(composed(app))  # the default, timestamped directory
    claim_run_directory(composed(app, "hydra.run.dir=new/deeper"))
    claim_run_directory(composed(app, "hydra.run.dir=empty"))
    claim_run_directory(composed(app, "resume=auto", "hydra.run.dir=empty"))
    assert sorted(os.listdir(tmp_path)) == ["empty"] and not os.listdir(tmp_path / "empty")  # looked only


# ----------------------------------------------------------------------------- (b) the same run


@pytest.mark.parametrize("app", APPS)
@pytest.mark.slow
def test_a_resume_of_the_same_run_is_the_runs(app, tmp_path, monkeypatch):
    """resume=<dir> of a stopped run of this app, resume=auto over the job's own stopped run (or
    one killed before it wrote anything but Hydra's records); a multirun's jobs with resume=auto
    over their own finished runs go on (each says it is finished)."""
    monkeypatch.chdir(tmp_path)
    stopped = MAKE[app](tmp_path / "stopped", finished=False)
    before = files(tmp_path)
    claim_run_directory(composed(app, f"resume={stopped}"))
    claim_run_directory(composed(app, "resume=auto", f"hydra.run.dir={stopped}"))
    killed = tmp_path / "killed"
    hydra_records(killed, APPS[app], OmegaConf.create({}))
    claim_run_directory(composed(app, "resume=auto", f"hydra.run.dir={killed}"))
    MAKE[app](tmp_path / "sweep" / "s0", finished=True)
    (tmp_path / "sweep" / "multirun.yaml").write_text("{}\n")
    before = files(tmp_path)
    with hydra_conf() as loader:
        sweep = loader.load_configuration(APPS[app], ["seed=0,1", "hydra.sweep.dir=sweep", "hydra.sweep.subdir=s${seed}",
                                                      "resume=auto"], RunMode.MULTIRUN)
        claim_sweep_directories(sweep, lambda job: None)
    assert files(tmp_path) == before


def test_resume_auto_keeps_the_first_attempts_hydra_record(tmp_path):
    """A job started again with resume=auto records this attempt in .hydra_resume: the run's
    own .hydra (a league's settings) stays as it started."""
    from hydra.core.hydra_config import HydraConfig

    from billiards.app_config.schema import _output_subdir

    job = composed("match", "resume=auto")
    with read_write(job.hydra), open_dict(job.hydra):
        job.hydra.runtime.output_dir = str(tmp_path)  # what Hydra sets in the job, before it saves its records
    saved = HydraConfig.instance().cfg
    try:
        HydraConfig.instance().set_config(job)
        assert job.hydra.output_subdir == ".hydra"
        assert _output_subdir("auto") == ".hydra"  # the first attempt
        (tmp_path / ".hydra").mkdir()
        assert _output_subdir("auto") == ".hydra_resume" and _output_subdir(str(tmp_path)) == ".hydra_resume"
        assert job.hydra.output_subdir == ".hydra_resume"
        assert _output_subdir(None) == ".hydra"
    finally:
        HydraConfig.instance().cfg = saved


def test_match_resume_auto_continues_the_league_of_its_own_directory(tmp_path):
    from billiards.league import run

    over = ["+agents.r2={kind: random}", "players=[random,r2]", "matches=1", "target=1", "max_innings=4",
            "progress=false", "picture=false", "resume=auto"]
    cfg = task_config("match", *over)
    out = tmp_path / "run"
    (out / ".hydra").mkdir(parents=True)
    OmegaConf.save(cfg, out / ".hydra" / "config.yaml")  # what Hydra saves
    OmegaConf.save(OmegaConf.create(over), out / ".hydra" / "overrides.yaml")
    first = run(cfg.copy(), out)  # nothing there yet: a new league
    lines = (out / "matches.jsonl").read_text().splitlines()
    assert len(lines) == 2
    (out / "matches.jsonl").write_text(lines[0] + "\n")  # the second match lost
    again = run(cfg.copy(), out)  # resume=auto: continues it
    assert again["run"] == first["run"] and (out / "matches.jsonl").read_text().splitlines()[0] == lines[0]
    assert len((out / "matches.jsonl").read_text().splitlines()) == 2


# ----------------------------------------------------------------------------- a finished run


@pytest.mark.slow
def test_a_resume_of_a_finished_run_says_so_and_changes_nothing(tmp_path, monkeypatch, capsys):
    """Exit status 0, the app's line, nothing written (Hydra's .hydra_resume neither); a run
    that cannot be read is refused before anything is written."""
    monkeypatch.chdir(tmp_path)
    done = search_run(tmp_path / "done")
    before = files(tmp_path)
    for overrides in ([f"resume={done}"], ["resume=auto", f"hydra.run.dir={done}"]):
        with pytest.raises(SystemExit) as info:
            claim_run_directory(composed("search", *overrides))
        assert info.value.code == 0 and "done is finished (mean 2.50): nothing to do" in capsys.readouterr().out
    assert files(tmp_path) == before
    # a finished training run whose checkpoint is damaged: its own sentence, nothing written
    damaged = train_run(tmp_path / "damaged")
    before = files(tmp_path)
    refused(lambda: claim_run_directory(composed("train", f"resume={damaged}")), f"resume={damaged}: cannot resume: ",
            "checkpoint.pt")
    # a league whose saved settings are gone
    league = league_run(tmp_path / "league")
    (league / ".hydra" / "config.yaml").write_text("- not a league\n")
    before = files(tmp_path)
    refused(lambda: claim_run_directory(composed("match", f"resume={league}")),
            "config.yaml cannot be read as a league's record")
    assert files(tmp_path) == before


# ----------------------------------------------------------------------------- (c) someone else's


@pytest.mark.parametrize("app", APPS)
@pytest.mark.slow
def test_someone_elses_directory_is_refused_naming_what_holds_it(app, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    own = MAKE[app](tmp_path / "own")
    stopped = MAKE[app](tmp_path / "stopped", finished=False)
    other_app = next(a for a in APPS if a != app)
    other = MAKE[other_app](tmp_path / "other")
    unrelated(tmp_path / "mine")
    (tmp_path / "file").write_text("x")
    what = {"train": "training run", "search": "search", "match": "league"}
    cases = [
        (["hydra.run.dir=own"], f"own holds a finished {what[app]} ("),  # a finished run without resume=
        (["hydra.run.dir=own"], "resume=own continues a stopped one, or choose another hydra.run.dir"),
        (["hydra.run.dir=stopped"], f"stopped holds an unfinished {what[app]} ("),
        (["hydra.run.dir=other"], f"other holds a finished {what[other_app]} of {other_app}.py ("),
        (["hydra.run.dir=mine"], "mine is not empty and holds files of no run of this project (data, notes.txt); "
                                 "choose an empty or new directory"),
        (["resume=auto", "hydra.run.dir=mine"], "mine holds files of no run of this project"),
        (["resume=auto", "hydra.run.dir=other"], f"resume=auto continues only a {what[app]} there"),
        ([f"resume={other}"], f"holds a finished {what[other_app]} of {other_app}.py (", f"not a {what[app]}"),
        (["resume=mine"], "resume=mine: holds files of no run of this project"),
        (["resume=nowhere"], "resume=nowhere: no such run directory"),
        (["resume=file"], "resume=file: a file, not a directory"),
        ([f"resume={stopped}", "hydra.run.dir=mine"], "mine is not empty"),  # Hydra's records would go there
        (["hydra.run.dir=own/inside"], f"lies inside {own}, which holds a finished {what[app]}"),
    ]
    before = files(tmp_path)
    for overrides, *said in cases:
        refused(lambda: claim_run_directory(composed(app, *overrides)), *said)
    assert files(tmp_path) == before
    if app == "search":  # the brief's sentence
        refused(lambda: claim_run_directory(composed(app, "hydra.run.dir=own")),
                "own holds a finished search (results.json); resume=own continues a stopped one, or choose another "
                "hydra.run.dir")


@pytest.mark.slow
def test_a_sweep_refuses_jobs_that_are_not_its_own(tmp_path, monkeypatch):
    """Each job's directory is checked as a run's; two jobs may not share one; the sweep
    directory may not be a run's or hold loose files."""
    monkeypatch.chdir(tmp_path)
    search_run(tmp_path / "sweep" / "s1")
    (tmp_path / "sweep" / "multirun.yaml").write_text("{}\n")
    search_run(tmp_path / "run")
    unrelated(tmp_path / "loose")
    before = files(tmp_path)

    def sweep(*overrides: str):
        with hydra_conf() as loader:
            cfg = loader.load_configuration("search", ["seed=0,1", *overrides], RunMode.MULTIRUN)
            claim_sweep_directories(cfg, lambda job: None)

    refused(lambda: sweep("hydra.sweep.dir=sweep", "hydra.sweep.subdir=s${seed}"), "job ['seed=1']: ",
            "sweep/s1 holds a finished search (results.json); resume=auto continues a stopped one, or choose another "
            "hydra.sweep.dir")
    refused(lambda: sweep("hydra.sweep.dir=new", "hydra.sweep.subdir=same"), "the job's directory new/same is job 0's too")
    refused(lambda: sweep("hydra.sweep.dir=run"), "run holds a finished search (results.json), not a sweep")
    refused(lambda: sweep("hydra.sweep.dir=loose"), "loose holds files that are no sweep's (notes.txt)")
    refused(lambda: sweep("hydra.sweep.dir=loose", "hydra.sweep.subdir=data", "resume=auto"), "loose holds files that are no sweep's")
    unrelated(tmp_path / "mixed" / "s0")
    before = files(tmp_path)
    refused(lambda: sweep("hydra.sweep.dir=mixed", "hydra.sweep.subdir=s${seed}", "resume=auto"),
            "job ['seed=0', 'resume=auto']: mixed/s0 holds files of no run of this project (data, notes.txt); resume=auto continues only "
            "a search there")
    assert files(tmp_path) == before


# ----------------------------------------------------------------------------- paths no run can be written at


@pytest.mark.slow
def test_a_path_that_is_a_file_unwritable_or_too_long_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "file").write_text("x")
    long = "a" * 300
    cases = [
        ("hydra.run.dir=file", "hydra.run.dir=file: a file, not a directory"),
        ("hydra.run.dir=file/run", "hydra.run.dir=file/run: cannot be created: "),
        (f"hydra.run.dir={long}", "is 300 bytes long, and this file system allows 255; choose a shorter name"),
        (f"resume={long}", f"resume={long}: the name aaa"),
    ]
    readonly = None
    if os.geteuid() != 0:
        readonly = tmp_path / "readonly"
        readonly.mkdir()
        readonly.chmod(0o555)
    elif os.path.isdir("/proc/sys") and not os.access("/proc/sys", os.W_OK):
        readonly = Path("/proc/sys")  # root may write anywhere but here
    if readonly is not None:
        cases.append((f"hydra.run.dir={readonly}/run", f"cannot be created: this user cannot write {readonly}"))
    before = files(tmp_path)
    for app in APPS:
        for override, said in cases:
            refused(lambda: claim_run_directory(composed(app, override)), said)
        with hydra_conf() as loader:
            cfg = loader.load_configuration(APPS[app], ["seed=0,1", "hydra.sweep.dir=file"], RunMode.MULTIRUN)
            refused(lambda: claim_sweep_directories(cfg, lambda job: None), "hydra.sweep.dir=file: a file, not a directory")
    assert files(tmp_path) == before


# ----------------------------------------------------------------------------- Hydra's own records


@pytest.mark.slow
@pytest.mark.parametrize("app", APPS)
def test_hydra_never_writes_its_records_over_another_run(app, tmp_path):
    """The trial's case: ``<app>.py hydra.run.dir=<a finished run>`` -- Hydra writes .hydra/
    before any code of the app runs; the directory check runs before that."""
    done = MAKE[app](tmp_path / "done")
    before = files(tmp_path)
    from conftest import app_here

    proc = app_here(f"{app}.py", f"hydra.run.dir={done}", cwd=tmp_path, env={"HYDRA_FULL_ERROR": "0"})
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert f"Error: {done} holds a finished " in proc.stderr and "resume=" in proc.stderr, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr + proc.stdout
    assert files(tmp_path) == before


def test_telling_whose_a_directory_is_never_blocks_on_a_fifo_or_follows_a_link(tmp_path):
    """The directory checks read a run folder's files through the one reader (billiards.files):
    a FIFO in place of results.json or of Hydra's record is refused unread, never waited on, and
    a link to a file elsewhere is not followed."""
    import os
    import threading

    from billiards import app_config

    run = tmp_path / "run"
    (run / ".hydra").mkdir(parents=True)
    os.mkfifo(run / "results.json")
    os.mkfifo(run / ".hydra" / "hydra.yaml")
    elsewhere = tmp_path / "elsewhere.yaml"
    elsewhere.write_text("hydra:\n  job:\n    config_name: search\n")
    os.symlink(elsewhere, run / "config.yaml")
    answers = {}
    worker = threading.Thread(target=lambda: answers.update(
        results=app_config.rundirs._final_results(run), hydra=app_config.rundirs._yaml_head(run / ".hydra" / "hydra.yaml"),
        linked=app_config.rundirs._yaml_head(run / "config.yaml")), daemon=True)
    worker.start()
    worker.join(timeout=300)  # only a guard against a hang (a FIFO read blocks forever)
    assert not worker.is_alive(), "a FIFO in a run folder blocked the directory check"
    assert answers == {"results": False, "hydra": None, "linked": None}
