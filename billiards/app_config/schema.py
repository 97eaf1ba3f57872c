"""The shared root schema and how an app registers its schemas: :class:`AppConfig` (the keys every
app's root schema holds), :func:`register_app` (the ConfigStore entries) and the resolvers the
apps' YAML uses (:data:`RESOLVERS`: ``resume=``'s defaults, the job's tag, the ``--help`` text).

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
  The apps' schemas have distinct names (``TrainConfig``, ``SearchAppConfig`` ...) and live
  side by side in one ConfigStore.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import OmegaConf

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
