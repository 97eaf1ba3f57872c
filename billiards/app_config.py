"""The one config dialect of the two Hydra apps: ``train.py`` (schema in
:mod:`billiards.rl.config`) and ``search.py`` (:mod:`billiards.search.config`).

* **Schemas** are dataclasses; a closed set of words is an ``enum`` or one typed schema per
  group option. A group whose options take different keys (``algo``, ``search``, ``protocol``,
  ``proposer``) is ``Any = MISSING`` in the root schema and each option's YAML (or stored
  node) brings its own schema, so a key of another option (``algo=ppo algo.utd=2``,
  ``search=h2 search.c_puct=5``) fails while Hydra composes.
* **Registration** happens when the app's config module is imported (the entry point imports
  it before ``@hydra.main``; tests and tools that compose import it too), through
  :func:`register_app`: the root schema under the app's name, every option schema at
  ``schema/<group>[/<option>]`` -- outside the option groups, so ``group=`` lists only real
  options, and an option pulls its schema in with ``/schema/<group>/<option>@_here_`` in its
  defaults list --, the physics and noise schemas both apps share and the resolvers their YAML uses.
  The two apps' schemas have distinct names (``TrainConfig``, ``SearchAppConfig``) and live
  side by side in one ConfigStore.
* **Validation**: each app's ``validate(cfg)`` checks what a type cannot express; its Hydra
  callback runs it before Hydra writes any directory, for every job of a multirun
  (:func:`job_configs`), and exits with the message, no traceback.
* **Configs are data**: :func:`guard_command_line` refuses a command line that names code or a
  file (:func:`override_errors`), and checks every config Hydra composes before Hydra builds
  anything from it (:func:`composition_errors`); docs/reliability.md.

Imports Hydra and OmegaConf, not torch and not the simulator's kernels: loading it is fast.
"""

from __future__ import annotations

import functools
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

from hydra.core.config_store import ConfigStore
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from billiards import files
from billiards.files import CONF_DIR
from billiards.physics.config import PhysicsConfig
from billiards.physics.noise import NoiseConfig

SCHEMA_GROUP = "schema"  # where option schemas live (outside the option groups)


@dataclass
class AppConfig:
    """What every app's root schema holds (``train.py``'s :class:`~billiards.rl.config.TrainConfig`,
    ``search.py``'s :class:`~billiards.search.config.SearchAppConfig`, ``match.py``'s
    :class:`~billiards.league.config.MatchAppConfig`): the table (``physics=``), the execution
    noise (``noise=``), the seed, the progress bar and ``resume=`` (a run directory of the app to
    continue; ``auto``: the job's own directory if it holds one). Each app adds its own keys."""

    physics: PhysicsConfig = field(default_factory=PhysicsConfig)  # the table: physics=korean_medium|international
    noise: NoiseConfig = field(default_factory=NoiseConfig)  # execution noise: noise=none|fastfiz|fastfiz_x5|variable
    seed: int = 0
    progress: bool = True  # progress with totals and ETA on stderr
    resume: Optional[str] = None  # a run dir of this app to continue; auto: this job's own dir if it holds a run

    # the keys that say how a run runs, not what it finds: a resume takes them from its own
    # command line, and a run's identity leaves them out. Each app adds its own (a plain class
    # attribute, not a field)
    RUNTIME = ("threads", "progress")


# ``resume=auto``: continue the job's own run directory if an earlier attempt left one there
# (a finished run does nothing), else start fresh in it: what a re-launched multirun job wants
# (each stage of the reproduction, a job a cluster preempted and requeued)
RESUME_AUTO = "auto"


def _or(value: Any, default: str) -> str:
    """``${billiards.or:${resume},outputs/...}``: the value unless it is null, empty or ``auto``."""
    return str(value) if value and value != RESUME_AUTO else default


def _output_subdir(resume: Optional[str]) -> str:
    """hydra.output_subdir: a resume keeps the original ``.hydra`` and records its own beside it;
    so does ``resume=auto`` where an earlier attempt of the job left its ``.hydra`` (Hydra
    resolves this in the job, once its output dir is known)."""
    if resume and resume != RESUME_AUTO:
        return ".hydra_resume"
    if resume == RESUME_AUTO:
        from hydra.core.hydra_config import HydraConfig

        own = OmegaConf.select(HydraConfig.get(), "runtime.output_dir", default=None,
                               throw_on_missing=False) if HydraConfig.initialized() else None
        if own and os.path.isdir(os.path.join(str(own), ".hydra")):
            return ".hydra_resume"
    return ".hydra"


def _job_tag() -> str:
    """``[job N] `` inside a multirun job (prefixes its log lines), empty otherwise."""
    from hydra.core.hydra_config import HydraConfig

    if not HydraConfig.initialized():
        return ""
    num = OmegaConf.select(HydraConfig.get(), "job.num", default=None, throw_on_missing=False)
    return "" if num is None else f"[job {num}] "


ROOTS: dict[str, type] = {}  # root schema name -> its dataclass (register_app fills it; --help reads it)


def _help_groups(*groups: str) -> str:
    """``--help``: each of the app's option groups with its options, one line per group; a
    group's subgroups' options as ``sub/option`` (``variant=table4/aim``); ``experiment@<app>``:
    the experiment presets of that app only (the paper tables' ``paper.app``, train by default)."""
    from hydra.core.global_hydra import GlobalHydra

    loader = GlobalHydra.instance().config_loader()
    # Hydra resolves this while it composes (each composition of a run: the mode's, the run's, the
    # composition guard's baseline): list the options once per config loader
    cache = loader.__dict__.setdefault("_billiards_help_groups", {})
    if groups not in cache:
        cache[groups] = _list_help_groups(loader, groups)
    return cache[groups]


def _group_options(loader, group: str):
    """Every option of ``group`` and of its subgroups, depth first (a group's own options, then
    its subgroups in order), as ``(its group, its name)``. From the loader's own repository (its
    search path: the project allows no other): the loader's ``get_group_options`` deep-copies
    that repository, ConfigStore's schemas included, at every call."""
    from hydra.core.object_type import ObjectType

    repo = loader.repository
    for option in repo.get_group_options(group, ObjectType.CONFIG):
        yield group, option
    for sub in sorted(repo.get_group_options(group, ObjectType.GROUP)):
        yield from _group_options(loader, f"{group}/{sub}")


def _list_help_groups(loader, groups: tuple[str, ...]) -> str:
    lines = []
    for token in groups:
        group, _, app = token.partition("@")
        found = [f"{where}/{option}"[len(group) + 1:] for where, option in _group_options(loader, group)]
        if app:
            from billiards.tables import paper_tables

            tables = paper_tables()
            found = [o for o in found if (tables[o].app if o in tables else "train") == app]
        lines.append(f"{group}: {', '.join(found)}")
    return "\n".join(lines)


def _help_choices(root_name: str) -> str:
    """``--help``: every key of the app's schema that takes one of a fixed set of words (an
    enum), with the words, e.g. ``env.paradigm: canonical_reset, ...``."""
    import dataclasses
    import enum
    import typing

    lines: list[str] = []

    def walk(schema: type, prefix: str) -> None:
        hints = typing.get_type_hints(schema)
        for f in dataclasses.fields(schema):
            kind = hints.get(f.name)
            for candidate in (kind, *typing.get_args(kind)):
                if isinstance(candidate, type) and issubclass(candidate, enum.Enum):
                    lines.append(f"{prefix}{f.name}: {', '.join(str(e.value) for e in candidate)}")
                elif isinstance(candidate, type) and dataclasses.is_dataclass(candidate):
                    walk(candidate, f"{prefix}{f.name}.")

    walk(ROOTS[root_name], "")
    return "\n".join(lines) or "(none)"


RESOLVERS = {"billiards.or": _or, "billiards.output_subdir": _output_subdir, "billiards.job_tag": _job_tag,
             "billiards.help_groups": _help_groups, "billiards.help_choices": _help_choices}


def register_resolvers() -> None:
    for name, fn in RESOLVERS.items():
        OmegaConf.register_new_resolver(name, fn, replace=True)


def register_app(root_name: str, root: type, groups: dict[str, type | dict[str, type]]) -> ConfigStore:
    """Store an app's schema in Hydra's ConfigStore (idempotent): ``root`` as ``root_name`` (the
    first entry of the app's defaults list); for each group, one schema for all its options at
    ``schema/<group>`` or one per option at ``schema/<group>/<option>``; ``schema/physics`` and
    ``schema/noise`` (both apps' table and execution noise); and the resolvers. Returns the
    ConfigStore (for option nodes the app stores itself)."""
    cs = ConfigStore.instance()
    cs.store(name=root_name, node=root)
    ROOTS[root_name] = root
    for group, schemas in groups.items():
        if isinstance(schemas, dict):
            for option, node in schemas.items():
                cs.store(group=f"{SCHEMA_GROUP}/{group}", name=option, node=node)
        else:
            cs.store(group=SCHEMA_GROUP, name=group, node=schemas)
    cs.store(group=SCHEMA_GROUP, name="physics", node=PhysicsConfig)  # conf/physics/*.yaml, both apps
    cs.store(group=SCHEMA_GROUP, name="noise", node=NoiseConfig)  # conf/noise/*.yaml, both apps
    register_resolvers()
    return cs


def fixed_job_config(config: DictConfig) -> tuple[DictConfig, set[str]]:
    """For a sweeper that composes its own jobs (Optuna ...): the job config with every
    override that is not a sweep applied, and the keys the sweeper will set (its
    ``hydra.sweeper.params`` and the command line's sweep overrides)."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    loader = GlobalHydra.instance().config_loader()
    parser = OverridesParser.create(config_loader=loader)
    swept = {str(k) for k in (config.hydra.sweeper.get("params") or {})}
    fixed = []
    for override in parser.parse_overrides(list(config.hydra.overrides.task)):
        if override.is_sweep_override():
            swept.add(override.key_or_group)
        else:
            fixed.append(override.input_line)
    return loader.load_sweep_config(config, fixed), swept


def job_configs(config: DictConfig) -> list[DictConfig]:
    """Every job config a multirun of ``config`` would launch (what Hydra's basic sweeper
    composes, including ``hydra.sweeper.params`` of experiment presets)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    loader = GlobalHydra.instance().config_loader()
    arguments = [f"{k}={v}" for k, v in (config.hydra.sweeper.get("params") or {}).items()]
    arguments += list(config.hydra.overrides.task)
    overrides = OverridesParser.create(config_loader=loader).parse_overrides(arguments)
    batches = BasicSweeper.split_arguments(overrides, None)
    return [loader.load_sweep_config(config, list(job)) for batch in batches for job in batch]


def validate_jobs(config: DictConfig, validate, errors: tuple[type[BaseException], ...] = (Exception,)) -> None:
    """Compose every job of a basic-sweeper multirun and ``validate`` each, before any job
    runs: SystemExit with each problem once, naming the jobs that have it (``every job of the
    multirun (9)`` when all do; ``errors`` are the exceptions that mean an invalid config), or
    naming the job that does not compose (Hydra would only warn and go on)."""
    try:
        jobs = job_configs(config)
    except Exception as err:
        raise SystemExit(f"Error: {err}") from None
    failing: dict[str, list[list[str]]] = {}  # message -> the jobs it is the problem of, in order
    for job in jobs:
        try:
            validate(job)
        except errors as err:
            failing.setdefault(str(err), []).append(list(job.hydra.overrides.task))
    if failing:
        said = []
        for message, which in failing.items():
            if len(which) == 1:
                said.append(f"job {which[0]}: {message}")
            elif len(which) == len(jobs):
                said.append(f"every job of the multirun ({len(jobs)}): {message}")
            else:
                said.append(f"{len(which)} of {len(jobs)} jobs ({', '.join(map(str, which))}): {message}")
        raise SystemExit("Error: " + "\n".join(said))


BASIC_SWEEPER = "hydra._internal.core_plugins.basic_sweeper.BasicSweeper"


class ValidatingCallback(Callback):
    """A Hydra callback (``hydra.callbacks.validate`` in an app's config) that validates before
    Hydra creates the run directory -- for a basic-sweeper multirun, every job's config first --
    so a bad command line fails at once, writes nothing, and exits with the message (Hydra would
    only warn); then claims the run's directories (:func:`claim_run_directory`,
    :func:`claim_sweep_directories`: "Whose directory" in docs/reliability.md). Subclasses set
    ``validate`` (a function raising ValueError)."""

    validate = None

    def _validate(self, config) -> None:
        try:
            type(self).validate(config)
        except (ValueError, OSError) as err:
            raise SystemExit(f"Error: {err}") from None

    def on_run_start(self, config, **kwargs) -> None:
        self._validate(config)
        claim_run_directory(config)

    def on_multirun_start(self, config, **kwargs) -> None:
        if config.hydra.sweeper._target_ != BASIC_SWEEPER:
            self._validate(config)
            claim_sweep_directories(config)
            return
        claim_sweep_directories(config, type(self).validate, errors=(ValueError, OSError))


# ----------------------------------------------------------------------------- whose directory

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
    # billiards.bench.run's IDENTITY_FILE, LEDGER_FILE, SCORECARD_JSON, SCORECARD_MD
    RunKind("evaluate", "evaluate.py", "evaluation", ("evaluation.json", "units.jsonl", "scorecard.json", "scorecard.md"),
            _has("scorecard.json"), claims=False),
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
    names = sorted(n for n in os.listdir(d) if n != files.LOCK_FILE)
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

# ----------------------------------------------------------------------------- numbers in range

INT_BOUND = 2**31 - 1  # the largest count any kernel, array or generator here is sized by


def numeric_bound_errors(cfg, skip: tuple[str, ...] = ("physics", "noise", "hydra")) -> list[str]:
    """Every integer of the composed config within +-(2^31 - 1) and every float finite (the
    physics and noise nodes have their own, tighter bounds; ``skip``): a count of 10^19 or a
    NaN step is refused while validating, not inside a kernel. Run it on the resolved config
    (:func:`resolved_config`): an interpolation is skipped here. Each schema's own check adds
    its keys' finite upper bounds (:func:`upper_bound_errors`)."""
    import math

    errors: list[str] = []

    def walk(node, path: str) -> None:
        if isinstance(node, DictConfig):
            items = ((str(k), node._get_node(k)) for k in node.keys())
        elif OmegaConf.is_list(node):
            items = ((str(i), node._get_node(i)) for i in range(len(node)))
        else:
            return
        for key, child in items:
            name = f"{path}.{key}" if path else key
            if not path and key in skip:
                continue
            if OmegaConf.is_config(child):
                walk(child, name)
                continue
            try:
                value = child._value() if hasattr(child, "_value") else child
            except Exception:  # an unresolvable interpolation: the schema's check reports it
                continue
            if isinstance(value, bool) or value is None or isinstance(value, str):
                continue
            if isinstance(value, int) and not -INT_BOUND <= value <= INT_BOUND:
                errors.append(f"{name}={value}: integers here must lie within +-{INT_BOUND:,}")
            elif isinstance(value, float) and not math.isfinite(value):
                errors.append(f"{name}={value}: must be a finite number")

    walk(cfg, "")
    return errors


def _bound_text(x: float) -> str:
    return f"{int(x):,}" if float(x).is_integer() and abs(x) >= 1000 else f"{x:g}"


def upper_bound_errors(node, prefix: str, bounds: dict) -> list[str]:
    """Each key of ``bounds`` (key -> ``(upper bound, why)``, a schema's ``UPPER``) at most its
    bound in ``node`` (a config node or an option object), every entry of a list value too:
    ``"algo.lr must be at most 1 (...), got 5.0"``. Null, NaN and non-numbers are left to the
    schema's other checks (:func:`numeric_bound_errors` refuses NaN); infinity fails here too."""
    errors = []
    for key, (hi, why) in bounds.items():
        value = getattr(node, key, None) if not hasattr(node, "get") else node.get(key)
        values = list(value) if OmegaConf.is_list(value) or isinstance(value, (list, tuple)) else [value]
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or v != v:
                continue
            if v > hi:
                errors.append(f"{prefix}{key} must be at most {_bound_text(hi)} ({why}), got {v!r}")
                break
    return errors


# ----------------------------------------------------------------------------- the resolved config

# The resolvers a config value may use: the project's own (RESOLVERS: billiards.*) and Hydra's
# ``now`` (a date) and ``hydra`` (the job's own settings). Any other -- oc.env reads this machine's
# environment, oc.decode and oc.create build values from text, oc.select and the others reach
# past the schema -- would hand the validator one value and the run another, or no value at all.
ALLOWED_RESOLVERS = ("now", "hydra")
RESOLVER_CALL = re.compile(r"\$\{\s*([A-Za-z_][\w.\-]*)\s*:")


def _allowed_resolver(name: str) -> bool:
    return name in ALLOWED_RESOLVERS or name.startswith("billiards.")


def resolver_errors(cfg, skip: tuple[str, ...] = ("hydra",)) -> list[str]:
    """One sentence for each value of ``cfg`` (less the ``skip`` nodes: the hydra node is the
    composition guard's) that interpolates through a resolver other than the project's
    ``billiards.*`` and Hydra's ``now`` and ``hydra``, naming its key."""
    errors: list[str] = []

    def walk(node, path: str) -> None:
        if node._is_none() or node._is_missing() or node._is_interpolation():
            return
        keys = list(node.keys()) if isinstance(node, DictConfig) else range(len(node))
        for key in keys:
            name = f"{path}.{key}" if path else str(key)
            if not path and key in skip:
                continue
            child = node._get_node(key)
            if child._is_interpolation():
                text = str(child._value())
                bad = sorted({r for r in RESOLVER_CALL.findall(text) if not _allowed_resolver(r)})
                if bad:
                    errors.append(f"{name}={text}: interpolates through {', '.join(bad)}; a value may refer to other keys "
                                  f"(${{key}}) and use the project's billiards.* resolvers and Hydra's now and hydra, "
                                  f"nothing else (oc.env would read this machine's environment, oc.decode and oc.create "
                                  f"build values no check sees): give the value itself")
            elif OmegaConf.is_config(child):
                walk(child, name)

    walk(cfg, "")
    return errors


def resolved_config(cfg, skip: tuple[str, ...] = ("hydra",)) -> tuple[Optional[DictConfig], list[str]]:
    """``(copy, errors)``: a copy of the composed ``cfg`` (its schema types kept) with every
    interpolation resolved and the ``skip`` nodes left out -- what the run will read, so that
    the app's checks see the values, not ``${...}`` -- or ``(None, errors)``: an interpolation
    through a resolver the project does not allow (:func:`resolver_errors`), or one that does
    not resolve (a missing key, a value its key's type refuses), each naming its key."""
    import copy

    errors = resolver_errors(cfg, skip)
    if errors:
        return None, errors
    out = copy.deepcopy(cfg)
    OmegaConf.set_readonly(out, False)
    struct = OmegaConf.is_struct(out)
    OmegaConf.set_struct(out, False)
    for key in skip:
        out.pop(key, None)
    OmegaConf.set_struct(out, struct)
    try:
        OmegaConf.resolve(out)
    except Exception as err:  # OmegaConf's errors, or one a resolver raised
        key = getattr(err, "full_key", None) or "a value"
        first = str(err).splitlines()[0] if str(err) else type(err).__name__
        return None, [f"{key}: its interpolation does not resolve to a valid value ({first})"]
    return out, []


# ----------------------------------------------------------------------------- configs are data

# Hydra calls whatever a ``_target_`` names (its callbacks are built before any app code runs),
# logging's dictConfig imports and calls a handler's ``class`` (or ``()``) and opens its
# ``filename``, an option of a config group is a file path, and --experimental-rerun unpickles
# a file. So a command line, a campaign spec or a preset may choose the project's configs and
# Hydra's installed plugins by name, and set data; it may never name a callable, a file outside
# conf/ or a config directory. Two checks hold this, one mechanism for every app:
#
# * :func:`override_errors`, on the command-line words before Hydra sees them
#   (:func:`guard_command_line`, which the entry points call before ``@hydra.main``);
# * :func:`composition_errors`, on every config Hydra composes (the run's, ``--help``'s, each
#   multirun job's) before Hydra builds anything from it: :func:`guard_command_line` installs
#   it in Hydra's config loader (:func:`install_composition_guard`).
ALLOWED_FLAGS = {"-m", "--multirun", "--cfg", "-c", "--package", "-p", "--help", "-h", "--hydra-help", "--info", "-i",
                 "--resolve", "--version"}
FLAGS_WITH_VALUE = ("--cfg", "-c", "--package", "-p", "--info", "-i")
CODE_KEYS = ("_target_", "_partial_", "_args_", "_recursive_", "_convert_")
# set in conf/ only: each would run or load code before the config is validated (hydra.launcher.setup:
# the shell lines submitit runs on a cluster node)
FORBIDDEN_KEYS = ("hydra.callbacks", "hydra.searchpath", "hydra.job.env_set", "hydra.job.env_copy", "hydra.launcher.setup")
LOGGING_NODES = ("hydra.hydra_logging", "hydra.job_logging")
# the keys of logging's dictConfig that import and call code, open a file or look up an object by name
LOGGING_CODE_KEYS = ("class", "()", ".", "filename", "stream", "queue", "listener")
LOGGING_REFERENCES = ("ext://", "cfg://")  # dictConfig resolves (imports) these in any value
NODE_RESOLVERS = ("oc.decode", "oc.create")  # resolvers that make config nodes out of text
# where Hydra builds objects from the composed config: a value there that the project's own
# configuration does not have is resolved and checked
CODE_NODES = ("hydra.callbacks", "hydra.launcher", "hydra.sweeper") + LOGGING_NODES
# as the project's own configuration composes them, whatever the overrides
LOCKED_NODES = ("hydra.callbacks", "hydra.searchpath", "hydra.job.env_set", "hydra.job.env_copy")
SWEEP_PARAMS = "hydra.sweeper.params"
# an option of a config group: a name, or sub/name for a group's sub-groups (variant=table4/aim)
OPTION_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*(/[A-Za-z0-9_][A-Za-z0-9_.-]*)*")
FILE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


def _is_hydra_group(group: str) -> bool:
    return group == "hydra" or group.startswith("hydra/")


def _under(path: str, roots) -> Optional[str]:
    return next((r for r in roots if path == r or path.startswith(r + ".")), None)


class _ConfOptions:
    """The config groups and their options as the project's conf/ and Hydra's ConfigStore hold
    them: what a command line may choose before Hydra has a config loader."""

    def __init__(self, conf_dir=CONF_DIR):
        self.conf_dir = Path(conf_dir)

    @staticmethod
    def _stored(group: str) -> Optional[dict]:
        node = ConfigStore.instance().repo
        for part in group.split("/"):
            node = node.get(part) if isinstance(node, dict) else None
        return node if isinstance(node, dict) else None

    def is_group(self, key: str) -> bool:
        return "/" in key or (self.conf_dir / key).is_dir() or self._stored(key) is not None

    def options(self, group: str) -> list[str]:
        folder = self.conf_dir / group
        found = {p.relative_to(folder).with_suffix("").as_posix() for p in folder.rglob("*.yaml")} if folder.is_dir() else set()
        found |= {name[:-5] for name in self._stored(group) or {} if name.endswith(".yaml")}
        return sorted(found)

    def has(self, group: str, option: str) -> bool:
        *sub, name = option.split("/")
        return (self.conf_dir / group / f"{option}.yaml").is_file() or f"{name}.yaml" in (self._stored("/".join([group, *sub])) or {})


class _LoaderOptions:
    """The same, from the config loader Hydra composes with (its search path: conf/, the
    ConfigStore, the installed plugins)."""

    def __init__(self, loader):
        self.repository = loader.repository

    def is_group(self, key: str) -> bool:
        return "/" in key or self.repository.group_exists(key)

    def options(self, group: str) -> list[str]:
        return sorted(self.repository.get_group_options(group))

    def has(self, group: str, option: str) -> bool:
        return self.repository.config_exists(f"{group}/{option}")


def _dict_keys(value) -> set[str]:
    """Every key of every dict in a parsed override value (dicts and lists at any depth, sweeps)."""
    from hydra.core.override_parser.types import ChoiceSweep

    if isinstance(value, ChoiceSweep):
        value = value.list
    if isinstance(value, dict):
        return {str(k) for k in value} | {k for v in value.values() for k in _dict_keys(v)}
    if isinstance(value, list):
        return {k for v in value for k in _dict_keys(v)}
    return set()


def _option_errors(say: str, group: str, value, options) -> list[str]:
    """A config group's value: option names only (each of a sweep or a list), and (outside
    ``hydra/``, whose options include the installed plugins') options that exist."""
    from hydra.core.override_parser.types import ChoiceSweep, Glob

    if value is None or isinstance(value, Glob):  # null removes the group; glob(...) picks among its options
        return []
    names = value.list if isinstance(value, ChoiceSweep) else value if isinstance(value, list) else [value]
    names = [n for item in names for n in (item if isinstance(item, list) else [item])]
    errors = []
    for name in names:
        name = str(name) if isinstance(name, (str, int)) and not isinstance(name, bool) else name
        if not isinstance(name, str) or not OPTION_NAME.fullmatch(name) or ".." in name:
            known = ", ".join(options.options(group)) or "see --help"
            errors.append(f"{say}: {group} takes the name of one of its options ({known}), not {name!r}")
        elif not _is_hydra_group(group) and not options.has(group, name):
            errors.append(f"{say}: Could not find '{group}/{name}' (the options of {group}: "
                          f"{', '.join(options.options(group))})")
    return errors


def _override_word_errors(arg: str, what: str, options, parser) -> list[str]:
    head, has_value, text = arg.partition("=")
    key = head.lstrip("+~").strip()
    group, _, package = key.partition("@")
    path = key.replace("/", ".").replace("@", ".")
    parts = path.split(".")
    say = f"{what} {arg!r}"
    if code := next((p for p in parts if p in CODE_KEYS), None):
        return [f"{say}: configs are data here; a {code} would make Hydra call code (choose an option by name, "
                f"e.g. hydra/launcher=joblib)"]
    if _under(path, FORBIDDEN_KEYS) or _under(package, FORBIDDEN_KEYS):  # group@package: where the option lands
        return [f"{say}: {key} may not be set from outside the project's conf/ (it would run or load code before the "
                f"config is validated)"]
    logging = _under(path, LOGGING_NODES)
    if logging and (bad := next((p for p in parts[2:] if p in LOGGING_CODE_KEYS), None)):
        return [f"{say}: a '{bad}' under {logging} may be set in the project's conf/ only (logging would import, call "
                f"or open what it names)"]
    if not has_value:
        return []
    errors = []
    try:
        override = parser.parse_override(arg)
        value = override.value()
    except Exception:  # Hydra refuses a malformed override itself while composing, before it builds anything
        override, value = None, text
    if word := next((w for w in CODE_KEYS + NODE_RESOLVERS if w in text), None):
        errors.append(f"{say}: configs are data here; a value may not hold {word} (Hydra would call code, or build "
                      f"config from text that no check sees)")
    elif bad := sorted(_dict_keys(value) & ({"()", "class"} | (set(LOGGING_CODE_KEYS) if logging else set()))):
        errors.append(f"{say}: configs are data here; a dict in a value may not hold the key {bad[0]!r} (logging "
                      f"imports and calls what it names)")
    if logging and ("${" in text or any(r in text for r in LOGGING_REFERENCES)):
        errors.append(f"{say}: a value under {logging} may not hold an interpolation or an ext:// or cfg:// reference "
                      f"(it could bring in a handler that opens a file, or an object by name)")
    if path == "hydra.job.name" and not FILE_NAME.fullmatch(str(value)):
        errors.append(f"{say}: hydra.job.name names the job's log file in its run directory: a plain name "
                      f"(letters, digits, _ . -), not a path")
    if path == "hydra.output_subdir" and value is not None and (
            not isinstance(value, str) or value.startswith(("/", "~", "\\")) or "\\" in value or "${" in value
            or ".." in value.split("/")):
        errors.append(f"{say}: hydra.output_subdir is a folder inside the run directory: a relative path without '..'")
    if key and options.is_group(group):
        errors += _option_errors(say, group, value, options)
    if path.startswith(SWEEP_PARAMS + "."):  # a job override the sweeper will compose with
        errors += override_errors([f"{key[len(SWEEP_PARAMS) + 1:]}={text}"], what=f"{say}: the sweep's", options=options)
    elif path == SWEEP_PARAMS and isinstance(value, dict):
        errors += override_errors([f"{k}={v}" for k, v in value.items()], what=f"{say}: the sweep's", options=options)
    return errors


def override_errors(args, what: str = "override", options=None) -> list[str]:
    """Why each of ``args`` (command-line words after the script) may not be given, one sentence
    each; empty when every word is plain data:

    * a key or a value that names a ``_target_`` (or another instantiation key; a dict in a value
      with a ``()`` or ``class`` key, logging's factories; a value built by ``oc.decode`` or
      ``oc.create``), a Hydra callback, a search path, the job's environment;
    * under ``hydra.hydra_logging`` / ``hydra.job_logging``: a ``class``, ``()``, ``filename``,
      ``stream`` (...) key, an interpolation or an ``ext://`` reference;
    * a config group's value that is not the name of one of its options (``experiment=../x``
      would load any YAML file): names only, each existing under conf/ (or the ConfigStore;
      ``hydra/<group>``: the name rule alone, its options are the installed plugins'), for
      each value of a sweep or list too, and in ``hydra.sweeper.params``;
    * ``hydra.job.name`` or ``hydra.output_subdir`` as a path out of the run directory;
    * a flag that adds a config directory or reruns a pickled config.

    ``options`` answers which keys are groups and which options exist (default: conf/ and the
    ConfigStore)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    options = options or _ConfOptions()
    parser = OverridesParser.create()
    errors = []
    args = [str(a) for a in args]
    for i, arg in enumerate(args):
        if arg.startswith("-"):
            flag = arg.split("=", 1)[0]
            if flag not in ALLOWED_FLAGS:
                errors.append(f"{what} {arg!r}: the flag {flag} is not accepted here (configs come from the project's conf/; "
                              f"allowed: {', '.join(sorted(ALLOWED_FLAGS))})")
            continue
        if i > 0 and args[i - 1] in FLAGS_WITH_VALUE and "=" not in arg:
            continue  # the value of a flag (job, hydra, all, a package, an --info topic), never an override
        errors += _override_word_errors(arg, what, options, parser)
    return errors


# ----------------------------------------------------------------------------- the composed config


def _hashable(value):
    return value if isinstance(value, (str, int, float, bool, type(None))) else str(value)


def _raw(cfg, path: str):
    """The node at ``path`` as plain containers, interpolations unresolved (None if absent)."""
    node = cfg
    for part in path.split("."):
        if not isinstance(node, DictConfig) or node._is_none() or node._is_interpolation() or node._is_missing():
            return None
        node = node._get_node(part, throw_on_missing_key=False)
        if node is None:
            return None
    return OmegaConf.to_container(node, resolve=False) if OmegaConf.is_config(node) else node._value()


def _scan(config, prefix: tuple[str, ...] = (), known: frozenset = frozenset(), resolve: bool = True):
    """What Hydra or logging would build from ``config`` (its path in the composed config:
    ``prefix``): ``(pairs, interpolations, unresolved)``. ``pairs``: (path, value) of every
    instantiation key at any depth (``_target_`` ...) and, under the logging nodes, of every
    ``class``, ``()``, ``filename``, ``stream`` ... key and ``ext://`` reference;
    ``interpolations``: (path, text) of each interpolation under :data:`CODE_NODES`. An
    interpolation there that is not in ``known`` is resolved and what it yields is scanned too
    (a dict copied in by reference holds keys of its own); ``unresolved``: the paths of those
    that cannot be resolved now."""
    pairs: set = set()
    interpolations: set = set()
    unresolved: list[str] = []

    def visit(parent, key, path: tuple[str, ...]) -> None:
        node = parent._get_node(key)
        dotted, name = ".".join(path), path[-1]
        logging = _under(dotted, LOGGING_NODES)
        code = name in CODE_KEYS or (logging and name in LOGGING_CODE_KEYS)
        if node._is_interpolation():
            text = node._value()
            if code:
                pairs.add((dotted, text))
                return
            if not _under(dotted, CODE_NODES):
                return
            interpolations.add((dotted, text))
            if not resolve or (dotted, text) in known:
                return
            try:
                value = parent[key]
            except Exception:
                unresolved.append(dotted)
                return
            if OmegaConf.is_config(value):
                walk(value, path)
            elif logging and isinstance(value, str) and value.startswith(LOGGING_REFERENCES):
                pairs.add((dotted, value))
            return
        if OmegaConf.is_config(node):
            walk(node, path)
            return
        value = node._value()
        if code or (logging and isinstance(value, str) and value.startswith(LOGGING_REFERENCES)):
            pairs.add((dotted, _hashable(value)))

    def walk(container, path: tuple[str, ...]) -> None:
        if container._is_none() or container._is_missing() or container._is_interpolation():
            return
        keys = list(container.keys()) if isinstance(container, DictConfig) else range(len(container))
        for key in keys:
            visit(container, key, (*path, str(key)))

    walk(config, prefix)
    return pairs, interpolations, unresolved


def _hydra_option_pairs(loader) -> tuple[set, set]:
    """:func:`_scan` of every option of every ``hydra/...`` group the loader knows (Hydra's own,
    the installed plugins', the project's conf/hydra/), each at its package: what choosing an
    option there by name may bring in (``hydra/launcher=joblib`` its launcher's ``_target_``)."""
    cached = loader.__dict__.get("_billiards_hydra_options")
    if cached is not None:
        return cached
    pairs: set = set()
    interpolations: set = set()
    for group, option in _group_options(loader, "hydra"):
        if group == "hydra":  # hydra/config, Hydra's own node: not an option of a hydra/... group
            continue
        try:
            loaded = loader.repository.load_config(f"{group}/{option}")
        except Exception:  # an option that does not load cannot be chosen either
            continue
        if loaded is None or not OmegaConf.is_config(loaded.config):
            continue
        package = ((loaded.header or {}).get("package") or "_group_").replace("_group_", group.replace("/", "."))
        prefix = () if package == "_global_" else tuple(package.split("."))
        found, interps, _ = _scan(loaded.config, prefix, resolve=False)
        pairs |= found
        interpolations |= interps
    loader.__dict__["_billiards_hydra_options"] = (pairs, interpolations)
    return pairs, interpolations


def composition_errors(cfg, baseline, loader=None) -> list[str]:
    """Why Hydra may not build from the composed ``cfg`` (hydra node included), one sentence
    each; ``baseline``: the same app's config composed without any override. Compared with it:

    * every instantiation key (``_target_`` ...) at any depth, and every ``class``, ``()``,
      ``filename``, ``stream`` ... of the logging configs, must be the baseline's at that path, or
      what an option of a ``hydra/...`` group brings there (``hydra/launcher=joblib``); anything
      new -- from a config file an override pulled in, or from a value -- is refused;
    * ``hydra.callbacks``, ``hydra.searchpath`` and the job's environment must be the baseline's;
    * the overrides the config was composed with, and the sweep's ``hydra.sweeper.params``, obey
      :func:`override_errors`.

    ``loader``: Hydra's config loader (for the ``hydra/...`` options and which options exist)."""
    options = _LoaderOptions(loader) if loader is not None else _ConfOptions()
    errors = []
    for path in LOCKED_NODES:
        got, own = _raw(cfg, path), _raw(baseline, path)
        if got != own:
            errors.append(f"{path}: set to {got!r}, but the project's configuration has {own!r}; it may be set in the "
                          f"project's conf/ only (Hydra would run or load code from it before the config is validated)")
    allowed, known, _ = _scan(baseline)
    known = frozenset(known)
    pairs, _, unresolved = _scan(cfg, known=known)
    if (pairs - allowed or unresolved) and loader is not None:
        option_pairs, option_interpolations = _hydra_option_pairs(loader)
        allowed, known = allowed | option_pairs, known | option_interpolations
        pairs, _, unresolved = _scan(cfg, known=known)
    for path, value in sorted(pairs - allowed, key=str):
        who = "logging" if _under(path, LOGGING_NODES) else "Hydra"
        errors.append(f"{path}={value!r}: neither the project's configuration nor an option of Hydra's groups sets this; "
                      f"{who} would import, call or open what it names before the config is validated (a config file "
                      f"an override chose by path, or the override itself, brought it in)")
    for path in unresolved:
        errors.append(f"{path}: an interpolation that cannot be resolved before Hydra builds from it; give the value itself")
    params = _raw(cfg, SWEEP_PARAMS)
    if isinstance(params, dict):
        errors += override_errors([f"{k}={v}" for k, v in params.items()], what=SWEEP_PARAMS, options=options)
    overrides = [*(_raw(cfg, "hydra.overrides.hydra") or []), *(_raw(cfg, "hydra.overrides.task") or [])]
    errors += override_errors(overrides, options=options)
    return errors


def _guarded(load):
    """Hydra's ``ConfigLoaderImpl.load_configuration`` that checks what it composed
    (:func:`composition_errors`, against the same config composed without overrides) before it
    returns it: Hydra builds the callbacks, the logging, the launcher and the sweeper from what
    it returns, before any app code runs."""
    if getattr(load, "billiards_guarded", False):
        return load

    @functools.wraps(load)
    def load_configuration(self, config_name, overrides, run_mode, *args, **kwargs):
        from hydra.types import RunMode

        cfg = load(self, config_name, overrides, run_mode, *args, **kwargs)
        if not overrides:
            return cfg  # the project's own configuration
        baselines = self.__dict__.setdefault("_billiards_baselines", {})
        if config_name not in baselines:
            baselines[config_name] = load(self, config_name, [], RunMode.MULTIRUN, validate_sweep_overrides=False)
        errors = composition_errors(cfg, baselines[config_name], loader=self)
        if errors:
            raise SystemExit("Error: " + "\n".join(dict.fromkeys(errors)))
        return cfg

    load_configuration.billiards_guarded = True
    return load_configuration


def _plain_listing(get_group_options):
    """Hydra's ``ConfigLoaderImpl.get_group_options`` that answers a plain question (no primary
    config, no overrides) from the loader's own repository. Hydra's copies that repository,
    ConfigStore's schemas included, for every question, in case overrides add a search path;
    without overrides there is none to add (and the project allows none), and ``--help`` asks
    one question per config group: 33 copies, most of the 6 s ``python train.py --help`` took."""
    from hydra.core.object_type import ObjectType

    if getattr(get_group_options, "billiards_listed", False):
        return get_group_options

    @functools.wraps(get_group_options)
    def group_options(self, group_name, results_filter=ObjectType.CONFIG, config_name=None, overrides=None):
        # results_filter as Hydra's: CONFIG by default, None for configs and groups alike
        if config_name is None and not overrides:
            return self.repository.get_group_options(group_name, results_filter)
        return get_group_options(self, group_name, results_filter, config_name, overrides)

    group_options.billiards_listed = True
    return group_options


def install_composition_guard() -> None:
    """Check every config Hydra composes in this process before Hydra builds anything from it,
    and list config groups without copying the config repository (:func:`_plain_listing`); idempotent.
    :func:`guard_command_line` calls it."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    ConfigLoaderImpl.load_configuration = _guarded(ConfigLoaderImpl.load_configuration)
    ConfigLoaderImpl.get_group_options = _plain_listing(ConfigLoaderImpl.get_group_options)


def guard_command_line(argv=None) -> None:
    """Exit with every reason (no traceback, nothing written) if the app's command line names
    code or a file (:func:`override_errors`); then check every config Hydra composes from it
    before Hydra builds anything (:func:`install_composition_guard`). The entry points call it
    before ``@hydra.main``."""
    import sys

    errors = override_errors(sys.argv[1:] if argv is None else argv)
    if errors:
        raise SystemExit("Error: " + "\n".join(errors))
    install_composition_guard()


__all__ = ["AppConfig", "BASIC_SWEEPER", "RESUME_AUTO", "SCHEMA_GROUP", "ValidatingCallback", "composition_errors", "fixed_job_config",
           "guard_command_line", "install_composition_guard", "job_configs", "numeric_bound_errors", "override_errors",
           "register_app", "register_resolvers", "validate_jobs",
           # whose directory
           "RUN_KINDS", "RunDirectoryError", "RunFinished", "RunKind", "claim_run_directory", "claim_sweep_directories",
           "path_problem", "run_directory_problem", "sweep_directory_problem"]
