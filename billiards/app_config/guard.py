"""Configs are data, once composed: :func:`composition_errors` checks every config Hydra
composes against the same app's config composed without overrides, before Hydra builds anything
from it; :func:`install_composition_guard` puts that check (and a group listing without copies,
:func:`_plain_listing`) into Hydra's config loader, and :func:`guard_command_line` -- what the
entry points call before ``@hydra.main`` -- checks the command line first
(:func:`~billiards.app_config.overrides.override_errors`)."""

from __future__ import annotations

import functools

from omegaconf import DictConfig, OmegaConf

from .overrides import (CODE_KEYS, CODE_NODES, LOCKED_NODES, LOGGING_CODE_KEYS, LOGGING_NODES, LOGGING_REFERENCES, SWEEP_PARAMS,
                        _ConfOptions, _LoaderOptions, _under, override_errors)
from .schema import _group_options

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
