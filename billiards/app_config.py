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

Imports Hydra and OmegaConf, not torch and not the simulator's kernels: loading it is fast.
"""

from __future__ import annotations

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

# Hydra calls whatever a ``_target_`` names (its callbacks are built before any app code runs) and
# unpickles --experimental-rerun's file; a command line, a campaign spec or a preset may select
# the project's configs and Hydra's installed plugins by name, but never name a callable or add
# a config directory. The flags that only print or select are allowed.
ALLOWED_FLAGS = {"-m", "--multirun", "--cfg", "-c", "--package", "-p", "--help", "-h", "--hydra-help", "--info", "-i",
                 "--resolve", "--version"}
CODE_KEYS = ("_target_", "_partial_", "_args_", "_recursive_", "_convert_")
FORBIDDEN_KEYS = ("hydra.callbacks", "hydra/callbacks", "hydra.searchpath", "hydra.job.env_set", "hydra.job.env_copy")


def override_errors(args, what: str = "override") -> list[str]:
    """Why each of ``args`` (command-line words after the script) may not be given: a ``_target_``
    (or another instantiation key), a Hydra callback, a search path, a flag that adds a config
    directory or reruns a pickled config. Empty when every word is plain data."""
    errors = []
    args = list(args)
    for i, arg in enumerate(args):
        arg = str(arg)
        if arg.startswith("-"):
            flag = arg.split("=", 1)[0]
            if flag not in ALLOWED_FLAGS:
                errors.append(f"{what} {arg!r}: the flag {flag} is not accepted here (configs come from the project's conf/; "
                              f"allowed: {', '.join(sorted(ALLOWED_FLAGS))})")
            continue
        if i > 0 and str(args[i - 1]) in ("--cfg", "-c", "--package", "-p", "--info", "-i"):
            continue  # the value of a flag
        key = arg.split("=", 1)[0].lstrip("+~").strip()
        parts = key.replace("/", ".").replace("@", ".").split(".")
        if any(p in CODE_KEYS for p in parts):
            errors.append(f"{what} {arg!r}: configs are data here; a {next(p for p in parts if p in CODE_KEYS)} "
                          f"would make Hydra call code (choose an option by name, e.g. hydra/launcher=joblib)")
        elif any(key == k or key.startswith(k + ".") or key.startswith(k + "/") for k in FORBIDDEN_KEYS):
            errors.append(f"{what} {arg!r}: {key.split('=')[0]} may not be set from outside the project's conf/ "
                          f"(it would run or load code before the config is validated)")
    return errors


def guard_command_line(argv=None) -> None:
    """Exit with every reason (no traceback, nothing written) if the app's command line names
    code; the entry points call it before Hydra sees the arguments."""
    import sys

    errors = override_errors(sys.argv[1:] if argv is None else argv)
    if errors:
        raise SystemExit("Error: " + "\n".join(errors))


__all__ = ["BASIC_SWEEPER", "RESUME_AUTO", "SCHEMA_GROUP", "ValidatingCallback", "fixed_job_config", "guard_command_line",
           "job_configs", "numeric_bound_errors", "override_errors", "register_app", "register_resolvers", "validate_jobs"]
