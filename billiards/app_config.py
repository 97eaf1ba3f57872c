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
import re
from pathlib import Path
from typing import Any, Optional

from hydra.core.config_store import ConfigStore
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from billiards.physics.config import PhysicsConfig
from billiards.physics.noise import NoiseConfig

SCHEMA_GROUP = "schema"  # where option schemas live (outside the option groups)


# ``resume=auto``: continue the job's own run directory if an earlier attempt left one there
# (a finished run does nothing), else start fresh in it: what a re-launched multirun job wants
# (each stage of the reproduction, a job a cluster preempted and requeued)
RESUME_AUTO = "auto"


def _or(value: Any, default: str) -> str:
    """``${billiards.or:${resume},outputs/...}``: the value unless it is null, empty or ``auto``."""
    return str(value) if value and value != RESUME_AUTO else default


def _output_subdir(resume: Optional[str]) -> str:
    """hydra.output_subdir: a resume keeps the original ``.hydra`` and records its own beside it."""
    return ".hydra_resume" if resume and resume != RESUME_AUTO else ".hydra"


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


def _list_help_groups(loader, groups: tuple[str, ...]) -> str:
    def options(group: str) -> list[str]:
        own = list(loader.get_group_options(group))
        subs = [f"{sub}/{o}" for sub in sorted(loader.list_groups(group)) for o in options(f"{group}/{sub}")]
        return own + subs

    lines = []
    for token in groups:
        group, _, app = token.partition("@")
        found = options(group)
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
    runs: SystemExit naming every failing job (``errors`` are the exceptions that mean an
    invalid config), or naming the job that does not compose (Hydra would only warn and go on)."""
    try:
        jobs = job_configs(config)
    except Exception as err:
        raise SystemExit(f"Error: {err}") from None
    errs = []
    for job in jobs:
        try:
            validate(job)
        except errors as err:
            errs.append(f"job {list(job.hydra.overrides.task)}: {err}")
    if errs:
        raise SystemExit("Error: " + "\n".join(errs))


BASIC_SWEEPER = "hydra._internal.core_plugins.basic_sweeper.BasicSweeper"


class ValidatingCallback(Callback):
    """A Hydra callback (``hydra.callbacks.validate`` in an app's config) that validates before
    Hydra creates the run directory -- for a basic-sweeper multirun, every job's config first --
    so a bad command line fails at once, writes nothing, and exits with the message (Hydra would
    only warn). Subclasses set ``validate`` (a function raising ValueError)."""

    validate = None

    def on_run_start(self, config, **kwargs) -> None:
        try:
            type(self).validate(config)
        except ValueError as err:
            raise SystemExit(f"Error: {err}") from None

    def on_multirun_start(self, config, **kwargs) -> None:
        if config.hydra.sweeper._target_ != BASIC_SWEEPER:
            self.on_run_start(config)
            return
        validate_jobs(config, type(self).validate, errors=(ValueError,))

# ----------------------------------------------------------------------------- numbers in range

INT_BOUND = 2**31 - 1  # the largest count any kernel, array or generator here is sized by


def numeric_bound_errors(cfg, skip: tuple[str, ...] = ("physics", "noise", "hydra")) -> list[str]:
    """Every integer of the composed config within +-(2^31 - 1) and every float finite (the
    physics and noise nodes have their own, tighter bounds; ``skip``): a count of 10^19 or a
    NaN step is refused while validating, not inside a kernel."""
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
CONF_DIR = Path(__file__).resolve().parent.parent / "conf"


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

    def groups(parent: str):
        for name in loader.list_groups(parent):
            yield f"{parent}/{name}"
            yield from groups(f"{parent}/{name}")

    for group in groups("hydra"):
        for option in loader.get_group_options(group):
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


def install_composition_guard() -> None:
    """Check every config Hydra composes in this process before Hydra builds anything from it
    (idempotent); :func:`guard_command_line` calls it."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    ConfigLoaderImpl.load_configuration = _guarded(ConfigLoaderImpl.load_configuration)


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


__all__ = ["BASIC_SWEEPER", "RESUME_AUTO", "SCHEMA_GROUP", "ValidatingCallback", "composition_errors", "fixed_job_config",
           "guard_command_line", "install_composition_guard", "job_configs", "numeric_bound_errors", "override_errors",
           "register_app", "register_resolvers", "validate_jobs"]
