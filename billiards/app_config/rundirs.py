"""Whose directory: before Hydra writes anything, whether a run's directory (and a multirun's
sweep directory and each job's) is this run's to write -- :class:`RunKind` and
:data:`RUN_KINDS` (what each app's runs leave), :func:`run_directory_problem`,
:func:`sweep_directory_problem`, :func:`claim_run_directory`, :func:`claim_sweep_directories`
-- and :func:`path_problem`, why no run can be written at a path."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

from omegaconf import OmegaConf

from billiards import files

from .jobs import BASIC_SWEEPER, validate_jobs
from .schema import RESUME_AUTO

# Hydra creates a run's directory and writes .hydra/ (and the job's log) there before any code of
# the app runs. So the validating callback, before Hydra writes anything, decides whose each run
# directory is -- a run's hydra.run.dir, each multirun job's <hydra.sweep.dir>/<hydra.sweep.subdir>:
#
# * fresh: missing (and creatable) or empty: the run's;
# * the same run: ``resume=<dir>`` naming a run of this app, or ``resume=auto`` over the job's own
#   directory holding a run of this app (or nothing): the run's; a finished run is left as it is
#   (a single run says it is finished and exits before anything is written);
# * anything else -- another app's run, a run of this app without resume=, files of no run -- is
#   someone else's: refused with one sentence naming the directory and what holds it.
#
# A path that is a file, cannot be created or written, or is too long for the file system is
# refused too (looking at it and its nearest existing parent; nothing is created to find out).
# train.py, search.py and match.py claim their directories so; evaluate.py checks its ``out=``
# itself (billiards.bench) and takes the path checks from here.


@dataclass(frozen=True)
class RunKind:
    """What a run of one app leaves in its directory."""

    config_name: str  # the app's config (conf/<name>.yaml): Hydra's hydra.job.config_name
    app: str  # its entry point
    what: str  # what one of its runs is called
    marks: tuple[str, ...]  # files only its runs write
    done: Callable[[Path], bool]  # whether the run there finished (a look at its files)
    config_keys: tuple[str, ...] = ()  # keys of the config.yaml it writes first (a run that wrote nothing else)
    # "module:function", ``(run_dir, config, finished) -> str | None``: reads what a resume of the
    # run in run_dir reads first, raising ValueError (a sentence) if it cannot; with ``finished``
    # the line the app says when nothing is left to do there, else None (the app's own test)
    resume_state: Optional[str] = None
    claims: bool = True  # False: the app checks its run directory itself


def _has(name: str) -> Callable[[Path], bool]:
    return lambda d: (d / name).is_file()


def _final_results(d: Path) -> bool:
    """A search's results.json that is not marked partial."""
    try:  # the one reader of run-folder files: no link, no FIFO, bounded size and depth
        res = files.read_run_json(d / files.RESULTS_FILE)
    except (OSError, ValueError):
        return False
    extra = res.get("extra") if isinstance(res, dict) else None
    return isinstance(res, dict) and not (isinstance(extra, dict) and extra.get("partial"))


READ_LIMIT = 8 << 20  # bytes of a file read to tell whose run a directory holds
RUN_KINDS: dict[str, RunKind] = {kind.config_name: kind for kind in (
    RunKind("config", "train.py", "training run", (files.CHECKPOINT_FILE, files.METRICS_FILE, files.EVAL_FILE,
                                                   files.EVAL_HISTORY_FILE, files.SUMMARY_FILE),
            _has(files.EVAL_FILE), ("algo", "budget"), "billiards.rl.train:resume_state"),
    RunKind("search", "search.py", "search", (files.CHAINS_FILE, files.RESULTS_FILE, "longest_chain.png"), _final_results,
            ("protocol", "proposer"), "billiards.search.run:resume_state"),
    RunKind("match", "match.py", "league", (files.MATCHES_FILE, files.LEAGUE_FILE, "match.gif"), _has(files.LEAGUE_FILE),
            (), "billiards.league:resume_state"),
    RunKind("evaluate", "evaluate.py", "evaluation", (files.IDENTITY_FILE, files.UNITS_FILE, files.SCORECARD_JSON,
                                                      files.SCORECARD_MD), _has(files.SCORECARD_JSON), claims=False),
)}
HYDRA_RECORDS = (".hydra", ".hydra_resume")  # what Hydra writes into a run directory (and the job's .log)
SWEEP_RECORDS = ("multirun.yaml", "optimization_results.yaml")  # what Hydra's sweepers write into a sweep directory


class RunFinished(Exception):
    """A single run's ``resume=`` finds its run finished: ``line`` says so, nothing is written."""

    def __init__(self, line: str):
        super().__init__(line)
        self.line = line


class RunDirectoryError(ValueError):
    """A run directory that is not this run's to write; the message says whose it is."""


@dataclass(frozen=True)
class _Held:
    """What a non-empty directory holds: a run of ``kind`` (None: no run of this project), the
    names that say so (or what is there), whether the run finished."""

    kind: Optional[RunKind]
    names: tuple[str, ...]
    finished: bool = False

    def describe(self, own: Optional[RunKind] = None) -> str:
        if self.kind is None:
            return f"files of no run of this project ({_listed(self.names)})"
        state = "a finished" if self.finished else "an unfinished"
        of = "" if self.kind is own else f" of {self.kind.app}"
        return f"{state} {self.kind.what}{of} ({_listed(self.names)})"


def _listed(names, most: int = 4) -> str:
    names = list(names)
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")


def _yaml_head(path: Path):
    """The YAML document at ``path`` (its first READ_LIMIT bytes), or None if it cannot be read."""
    import yaml

    try:  # the one reader of run-folder files: no link, no FIFO, bounded size
        with files.open_run_file(path, "config") as f:
            return yaml.safe_load(f.read(READ_LIMIT))
    except Exception:  # unreadable, refused, not YAML, cut short: it says nothing
        return None


def _hydra_kind(d: Path) -> Optional[RunKind]:
    """The app whose run Hydra recorded in ``d`` (``.hydra/hydra.yaml``'s job.config_name)."""
    for sub in HYDRA_RECORDS:
        if not os.path.isfile(d / sub / "hydra.yaml"):
            continue
        data = _yaml_head(d / sub / "hydra.yaml")
        try:
            name = data["hydra"]["job"]["config_name"]
        except (TypeError, KeyError):
            continue
        if isinstance(name, str) and name in RUN_KINDS:
            return RUN_KINDS[name]
    return None


def _held(d: Path) -> Optional[_Held]:
    """Whose run the directory ``d`` holds; None if it is empty. Raises OSError if it cannot be listed.
    The run-folder lock file (:data:`billiards.files.LOCK_FILE`, left by a run killed while it
    wrote) belongs to whatever run the rest is, and says nothing alone."""
    names = files.run_folder_names(d)
    if not names:
        return None
    for kind in RUN_KINDS.values():
        found = tuple(n for n in kind.marks if n in names)
        if found:
            return _Held(kind, found, kind.done(d))
    kind = _hydra_kind(d)
    if kind is None and files.CONFIG_FILE in names:
        data = _yaml_head(d / files.CONFIG_FILE)
        kind = next((k for k in RUN_KINDS.values() if isinstance(data, dict) and any(key in data for key in k.config_keys)),
                    None)
    if kind is not None:
        return _Held(kind, tuple(n for n in names if n in (files.CONFIG_FILE, *HYDRA_RECORDS)))
    return _Held(None, tuple(names))


def _pathconf(path: str, name: str, default: int) -> int:
    try:
        value = os.pathconf(path, name)
    except (OSError, ValueError):
        return default
    return value if value and value > 0 else default


def path_problem(path: str, where: str, must_exist: bool = False) -> Optional[str]:
    """Why no run can be written at ``path`` -- empty, a file, a directory this user cannot
    write, one that cannot be created there (its nearest existing parent is a file or not
    writable), a name or a path too long for the file system -- as a sentence starting with
    ``where``; None if it can. Looks only: nothing is created."""
    if not path.strip():
        return f"{where}: an empty path; name a directory"
    if "\0" in path:
        return f"{where}: a path cannot hold a NUL character"
    absolute = os.path.abspath(os.path.expanduser(path))
    parent = absolute
    while not os.path.lexists(parent) and os.path.dirname(parent) != parent:
        parent = os.path.dirname(parent)
    name_max = _pathconf(parent if os.path.isdir(parent) else os.path.dirname(parent), "PC_NAME_MAX", 255)
    path_max = _pathconf(parent if os.path.isdir(parent) else os.path.dirname(parent), "PC_PATH_MAX", 4096)
    for part in Path(absolute).parts[1:]:
        size = len(os.fsencode(part))
        if size > name_max:
            return (f"{where}: the name {part[:24]}...{part[-8:]} is {size} bytes long, and this file system allows "
                    f"{name_max}; choose a shorter name")
    if len(os.fsencode(absolute)) >= path_max:
        return f"{where}: the path is {len(os.fsencode(absolute))} bytes long, and this system allows {path_max - 1}"
    if os.path.lexists(absolute):
        if not os.path.isdir(absolute):
            what = "a link to nothing" if os.path.islink(absolute) else "a file"
            return f"{where}: {what}, not a directory"
        if not os.access(absolute, os.R_OK | os.W_OK | os.X_OK):
            return f"{where}: this user cannot read and write that directory (its permissions, or a read-only file system)"
        return None
    if must_exist:
        return f"{where}: no such run directory"
    if not os.path.isdir(parent):
        return f"{where}: cannot be created: {parent} is a file, not a directory"
    if not os.access(parent, os.W_OK | os.X_OK):
        return (f"{where}: cannot be created: this user cannot write {parent} (its permissions, or a read-only "
                f"file system)")
    return None


def _inside_a_run(path: str, where: str) -> Optional[str]:
    """A sentence if a directory above ``path`` holds a run Hydra recorded for one of the apps
    (writing there would change that run's directory), else None."""
    for parent in Path(os.path.abspath(path)).parents:
        kind = _hydra_kind(parent) if os.path.isdir(parent / ".hydra") or os.path.isdir(parent / ".hydra_resume") else None
        if kind is not None:
            try:
                held = _held(parent)
            except OSError:
                held = None
            what = held.describe() if held is not None else f"a {kind.what} of {kind.app}"
            return f"{where}: lies inside {parent}, which holds {what}; choose a directory outside it"
    return None


def _resume_state(kind: RunKind, run_dir: str, config, finished: bool) -> Optional[str]:
    """The app's ``resume_state`` hook (see :class:`RunKind`): its finished line or None;
    RunDirectoryError naming ``resume=`` if the run cannot be read."""
    if kind.resume_state is None:
        return None
    import importlib

    module, _, name = kind.resume_state.partition(":")
    try:
        return getattr(importlib.import_module(module), name)(Path(run_dir), config, finished)
    except (ValueError, OSError) as err:
        raise RunDirectoryError(f"resume={run_dir}: {err}") from None


def _same_place(a: str, b: str) -> bool:
    return os.path.realpath(a) == os.path.realpath(b)


def run_directory_problem(config, job_dir: Optional[str] = None, single: bool = True) -> Optional[str]:
    """Whose the directory a run (``config``: its composed config, hydra node included) would
    write is; one sentence if it is not this run's to write, None if it is (see the top of this
    section). ``job_dir``: a multirun job's directory (default: ``hydra.run.dir``). A single run
    (``single``) whose ``resume=`` finds its run finished raises :class:`RunFinished`; a
    multirun job goes on (the app says so itself)."""
    kind = RUN_KINDS.get(str(OmegaConf.select(config, "hydra.job.config_name", default="") or ""))
    claims = kind is not None and kind.claims
    resume = OmegaConf.select(config, "resume", default=None) if claims else None
    resume = None if resume in (None, "") else str(resume)
    auto = resume == RESUME_AUTO
    if resume and not auto and (problem := path_problem(resume, f"resume={resume}", must_exist=True)):
        return problem
    own = job_dir if job_dir is not None else str(config.hydra.run.dir)
    where = f"hydra.run.dir={own}" if job_dir is None else f"the job's directory {own}"
    if problem := path_problem(own, where):
        return problem
    if not claims:
        return None
    another = "another hydra.run.dir" if job_dir is None else "another hydra.sweep.dir"
    if resume and not auto:  # the run resume= names, wherever Hydra writes this invocation's records
        held = _held(Path(resume))
        if held is None:
            return f"resume={resume}: an empty directory, no {kind.what} to continue"
        if held.kind is not kind:
            return f"resume={resume}: holds {held.describe(kind)}, not a {kind.what}; {kind.app} resumes only its own runs"
        if (line := _resume_state(kind, resume, config, single and held.finished)) is not None:
            raise RunFinished(line)
        if _same_place(resume, own):
            return None
    if not os.path.isdir(own) or (held := _held(Path(own))) is None:  # fresh
        return _inside_a_run(own, where)
    if auto:  # the job's own directory: an earlier attempt of this run
        if held.kind is not kind:
            return f"{own} holds {held.describe(kind)}; resume=auto continues only a {kind.what} there: choose {another}"
        if (line := _resume_state(kind, own, config, single and held.finished)) is not None:
            raise RunFinished(line)
        return None
    if held.kind is kind:
        again = f"resume={own}" if job_dir is None else "resume=auto"
        return f"{own} holds {held.describe(kind)}; {again} continues a stopped one, or choose {another}"
    if held.kind is not None:
        return f"{own} holds {held.describe(kind)}; choose {another}"
    return f"{own} is not empty and holds {held.describe(kind)}; choose an empty or new directory"


def claim_run_directory(config) -> None:
    """A single run's directory check (:func:`run_directory_problem`), before Hydra writes
    anything: exits with the sentence (status 1, nothing written), or, for a ``resume=`` of a
    finished run, with the app's line saying so (status 0, nothing written)."""
    try:
        problem = run_directory_problem(config)
    except RunFinished as done:
        print(done.line, flush=True)
        raise SystemExit(0) from None
    except RunDirectoryError as err:
        problem = str(err)
    except Exception as err:  # a directory Hydra could not use either (unresolvable, unreadable)
        problem = f"the run directory: {err}"
    if problem:
        raise SystemExit(f"Error: {problem}")


def sweep_directory_problem(config) -> Optional[str]:
    """Why a multirun may not write its ``hydra.sweep.dir`` (Hydra writes ``multirun.yaml``
    and the jobs' directories there): a path that cannot be written, a run's directory, loose
    files that are no sweep's; None if it may (missing, empty, or an earlier sweep's)."""
    sweep = str(config.hydra.sweep.dir)
    where = f"hydra.sweep.dir={sweep}"
    if problem := path_problem(sweep, where):
        return problem
    kind = RUN_KINDS.get(str(OmegaConf.select(config, "hydra.job.config_name", default="") or ""))
    if kind is None or not kind.claims:
        return None
    if not os.path.isdir(sweep) or (held := _held(Path(sweep))) is None:
        return _inside_a_run(sweep, where)
    if held.kind is not None:
        return (f"{sweep} holds {held.describe(kind)}, not a sweep: a multirun writes multirun.yaml and its jobs' "
                f"directories there; choose another hydra.sweep.dir")
    loose = [n for n in held.names if n not in SWEEP_RECORDS and not os.path.isdir(os.path.join(sweep, n))]
    if loose:
        return (f"{sweep} holds files that are no sweep's ({_listed(loose)}): a multirun writes multirun.yaml and its "
                f"jobs' directories there; choose an empty or new hydra.sweep.dir")
    return _inside_a_run(sweep, where)


def _job_directory_check(validate):
    """``validate`` for the jobs of a basic-sweeper multirun in launch order (as
    :func:`validate_jobs` calls it), each followed by its directory's check
    (:func:`run_directory_problem`): RunDirectoryError naming whose the job's directory is, or
    that another job of the sweep writes there too."""
    import itertools

    from omegaconf import open_dict, read_write

    seen: dict[str, int] = {}
    count = itertools.count()

    def check(job) -> None:
        num = next(count)
        validate(job)
        with read_write(job.hydra), open_dict(job.hydra):
            job.hydra.job.num = job.hydra.job.id = num  # what the launcher sets, which hydra.sweep.subdir may use
        try:
            own = os.path.join(str(job.hydra.sweep.dir), str(job.hydra.sweep.subdir))
        except Exception:  # a subdir only the launcher can resolve: the app checks the directory itself
            return
        key = os.path.realpath(own) if "\0" not in own else own
        if key in seen:
            raise RunDirectoryError(f"the job's directory {own} is job {seen[key]}'s too; hydra.sweep.subdir must tell "
                                    f"the jobs apart")
        seen[key] = num
        if problem := run_directory_problem(job, own, single=False):
            raise RunDirectoryError(problem)

    return check


def claim_sweep_directories(config, validate=None, errors: tuple[type[BaseException], ...] = (Exception,)) -> None:
    """A multirun's directory checks, before Hydra writes anything: for any sweeper, the sweep
    directory (:func:`sweep_directory_problem`); for a basic-sweeper multirun, ``validate`` and
    the directory check of every job (:func:`validate_jobs`, which names each failing job).
    Exits with the sentences, nothing written."""
    try:
        problem = sweep_directory_problem(config)
    except Exception as err:  # a directory Hydra could not use either (unresolvable, unreadable)
        problem = f"hydra.sweep.dir: {err}"
    if problem:
        raise SystemExit(f"Error: {problem}")
    if validate is not None and config.hydra.sweeper._target_ == BASIC_SWEEPER:
        validate_jobs(config, _job_directory_check(validate), errors=(*errors, RunDirectoryError))
