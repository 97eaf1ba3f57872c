"""Configs are data, on the command line: :func:`override_errors` says why a command-line word
(an override, a flag) may not be given -- it names code, a file or a config directory -- and
the rules it shares with the composition guard (:mod:`billiards.app_config.guard`): the
instantiation keys, the keys set in conf/ only, logging's code keys, option and file names."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Optional

from hydra.core.config_store import ConfigStore

from billiards.files import CONF_DIR

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
