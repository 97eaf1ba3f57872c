"""The search app's configuration (``conf/search.yaml``): typed schemas, registered in Hydra's
ConfigStore when this module is imported (the idiom both apps share, :mod:`billiards.app_config`).

Every group option has its own closed schema, so a knob of another option fails while Hydra
composes: ``search=h2 search.c_puct=5`` is rejected (``Key 'c_puct' not in 'H2Config'``),
``search=puct search.c_puct=5`` works; likewise ``protocol=p3 protocol.n_innings=5`` and
``proposer=geometric proposer.checkpoints=[...]``. The schemas of the options live at
``schema/<group>/<option>``, outside the option groups:

* ``search``: ``h2`` (:class:`~billiards.search.settings.H2Config`) | ``puct``
  (:class:`~billiards.search.settings.PUCTConfig`) | ``robust``
  (:class:`~billiards.search.settings.RobustConfig`, needs execution noise): each the search
  method's own settings (:mod:`billiards.search.settings`), ``conf/search/*.yaml``; the default
  is ``for_noise_${noise}``: h2 without noise, robust under ``noise=fastfiz|fastfiz_x5|variable``
  (an explicit ``search=`` wins);
* ``protocol``: ``p1`` (:class:`P1Config`) | ``p3`` (:class:`P3Config`), ``conf/protocol/*.yaml``;
* ``noise``: the execution noise (:class:`~billiards.physics.noise.NoiseConfig`, ``conf/noise/*.yaml``,
  shared with train.py);
* ``proposer``: ``geometric`` or ``forgiving`` (:class:`GeometricProposerConfig`), ``ranked``
  (:class:`RankedProposerConfig`: geometric draws ranked by a learned shot ranker) or a policy ensemble
  (:class:`PolicyProposerConfig`). The shipped ensembles are one config parametrised by name,
  :func:`shipped_proposer`: ``proposer=<name>`` for every name of :data:`SHIPPED_PROPOSERS`
  plays ``results/policies/<name>/seed{0,1,2}.pt``. Policies of your own:
  ``proposer=policy proposer.checkpoints=[a.pt,b.pt]`` (and ``proposer.name=...`` for the
  results), or a YAML in ``conf/proposer/`` whose defaults list starts with
  ``/schema/proposer/policy@_here_``.

:func:`validate` checks what a type cannot express (budget split, sizes, files) before anything
runs; :class:`ValidateSearchConfig` runs it before Hydra writes a directory, for every job of a
multirun. The option schemas also build what they describe (:meth:`H2Config.actor`,
:meth:`GeometricProposerConfig.build` ...): a closed table from kind to schema, not a
``_target_`` read from a file, so loading a saved config (``resume=``, a picture of a search
run) never runs code named in it. :func:`saved_config` reads one, including the form written
before the per-option schemas (one union node per group).
"""

from __future__ import annotations

import dataclasses
import functools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, List, Optional

from omegaconf import MISSING, DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from billiards import compat
from billiards.tables import paper_tables
from billiards.app_config import (AppConfig, RESUME_AUTO, ValidatingCallback, numeric_bound_errors, register_app, resolved_config,
                                  upper_bound_errors)
from billiards.device import device_error, threads_error
from billiards.files import CONFIG_FILE, read_run_text, repo_path
from billiards.physics.config import physics_errors
from billiards.physics.noise import noise_errors, noise_from_config
from billiards.protocol import Protocol

from .settings import MAX_SEARCH, H2Config, PUCTConfig, RobustConfig

# ----------------------------------------------------------------------------- search
#
# The search options are the search methods' own settings (billiards/search/settings.py): one
# dataclass per method, with its checks (errors(), check()) and bounds (UPPER, listed in
# docs/reliability.md), registered below by kind.


# ----------------------------------------------------------------------------- protocols


class _ProtocolOption:
    UPPER: ClassVar[dict] = {}

    def errors(self) -> list[str]:
        """Every count of the protocol must be >= 1, and at most its bound."""
        return [f"protocol.{f.name} must be >= 1, got {getattr(self, f.name)}"
                for f in dataclasses.fields(self) if f.name != "name" and getattr(self, f.name) < 1] \
            + upper_bound_errors(self, "protocol.", self.UPPER)


@dataclass
class P1Config(_ProtocolOption):
    """P1: ``n_innings`` random-start innings of ``shots`` shots (continue-on-miss)."""

    name: str = Protocol.P1.value
    n_innings: int = 100
    shots: int = 100

    UPPER: ClassVar[dict] = {"n_innings": (10**5, "innings"), "shots": (10**6, "shots of an inning")}


@dataclass
class P3Config(_ProtocolOption):
    """P3: ``seeds`` canonical-start chains (seeds ``seed`` ... ``seed + seeds - 1``), each
    until the first miss or foul, capped at ``cap`` shots."""

    name: str = Protocol.P3.value
    seeds: int = 10
    cap: int = 10000

    UPPER: ClassVar[dict] = {"seeds": (10**5, "chains"), "cap": (10**6, "shots of a chain")}


# ----------------------------------------------------------------------------- proposers


@dataclass
class GeometricProposerConfig:
    """No training: shots inside the aim-constraint cone of the nearest red."""

    kind: str = "geometric"
    name: str = "geometric"
    power_low: float = 0.15
    power_high: float = 0.9
    # narrower draws for forgiving shots under noise (defaults: the full ranges)
    u_low: float = 0.0  # |u| >= u_low (u: where in the aim cone; 0 full hit, 1 graze)
    u_high: float = 1.0
    spin_low: float = -1.0  # vertical tip offset b in [spin_low, spin_high] (-1 draw, 1 follow)
    spin_high: float = 1.0
    far_share: float = 0.0  # this share of the candidates aims into the farther red's cone (0: the nearer red only)

    def errors(self) -> list[str]:
        errs = []
        if not 0.0 <= self.power_low <= self.power_high <= 1.0:
            errs.append(f"proposer.power_low and proposer.power_high must satisfy 0 <= low <= high <= 1, "
                        f"got {self.power_low}, {self.power_high}")
        if not 0.0 <= self.u_low <= self.u_high <= 1.0:
            errs.append(f"proposer.u_low and proposer.u_high must satisfy 0 <= low <= high <= 1, got {self.u_low}, {self.u_high}")
        if not -1.0 <= self.spin_low <= self.spin_high <= 1.0:
            errs.append(f"proposer.spin_low and proposer.spin_high must satisfy -1 <= low <= high <= 1, "
                        f"got {self.spin_low}, {self.spin_high}")
        if not 0.0 <= self.far_share <= 1.0:
            errs.append(f"proposer.far_share must lie in [0, 1], got {self.far_share}")
        return errs

    def build(self, params, device=None):
        """The proposer (NumPy, on the CPU whatever ``device`` says)."""
        from .proposers import GeometricProposer

        return GeometricProposer(power_low=self.power_low, power_high=self.power_high, R=params.ball_radius,
                                 u_low=self.u_low, u_high=self.u_high, spin_low=self.spin_low, spin_high=self.spin_high,
                                 far_share=self.far_share)


# ``proposer=forgiving``: no training needed, the geometric proposer with its draws narrowed toward
# shots that forgive execution noise (results/noise/README.md): a cut (0.3 <= |u| <= 0.9) rather
# than a full hit or a graze, power 0.5..1.0, the vertical tip offset b >= -0.2 (no strong draw).
# Candidate 0 is the geometric baseline shot, as for proposer=geometric. Use it under noise:
# ``python search.py noise=fastfiz proposer=forgiving``.
FORGIVING = dict(name="forgiving", power_low=0.5, power_high=1.0, u_low=0.3, u_high=0.9, spin_low=-0.2, spin_high=1.0)


RANKER_COMMAND = "python -m billiards.search.ranker --out {out} --noise {noise}"


@dataclass
class RankedProposerConfig:
    """Geometric draws ranked by a learned shot ranker (:mod:`billiards.search.ranker`): per
    decision and state, ``pool`` draws (at least as many as the search asks for), the best by
    the ranker first. Nothing is simulated to rank them. ``ranker`` is the ranker file (a
    relative path: from the working directory if it exists there, else from the repository
    root); the shipped one, ``results/rankers/fastfiz/ranker.pt``, was trained for
    ``noise=fastfiz`` on ``korean_medium`` (``command`` says how)."""

    kind: str = "ranked"
    name: str = "ranked"
    ranker: str = "results/rankers/fastfiz/ranker.pt"
    pool: int = 2000
    command: Optional[str] = RANKER_COMMAND.format(out="results/rankers/fastfiz/ranker.pt", noise="fastfiz")

    def path(self) -> str:
        return str(repo_path(self.ranker))

    UPPER: ClassVar[dict] = {"pool": (MAX_SEARCH, "candidates ranked per decision")}

    def errors(self) -> list[str]:
        """The pool, and the ranker file loaded and checked now, before any directory is written."""
        errs = [f"proposer.pool must be >= 1, got {self.pool}"] if self.pool < 1 else []
        errs += upper_bound_errors(self, "proposer.", self.UPPER)
        if not Path(self.path()).is_file():
            how = f" (trained with: {self.command})" if self.command else ""
            return errs + [f"proposer {self.name!r}: no ranker file at {self.ranker}{how}"]
        from .ranker import RankerFileError, ShotRanker

        try:
            ShotRanker.load(self.path())
        except RankerFileError as err:
            errs.append(f"proposer {self.name!r}: {err}")
        return errs

    def build(self, params, device=None):
        """The proposer (NumPy, on the CPU whatever ``device`` says); a ranker trained on
        another table warns (PhysicsMismatchWarning)."""
        from billiards.physics.config import warn_physics_mismatch

        from .ranker import RankedProposer, ShotRanker

        ranker = ShotRanker.load(self.path())
        warn_physics_mismatch(f"proposer {self.name!r} (ranker {self.ranker})", ranker.params, params)
        return RankedProposer(ranker, pool=self.pool, name=self.name, params=params)


@dataclass
class PolicyProposerConfig:
    """An ensemble of trained policies: ``checkpoints`` are exported policy files, training run
    dirs or their checkpoint.pt (a relative path: from the working directory if it exists
    there, else from the repository root); ``command`` says how they were made."""

    kind: str = "policy"
    name: str = MISSING
    checkpoints: List[str] = MISSING
    command: Optional[str] = None  # how the checkpoints were trained (documentation)

    def paths(self) -> list[str]:
        return [str(repo_path(c)) for c in self.checkpoints]

    def errors(self) -> list[str]:
        """Checkpoints listed, there, and each loaded and checked now."""
        if not self.checkpoints:
            return [f"proposer {self.name!r} is a policy ensemble but lists no checkpoints"]
        missing = [c for c, p in zip(self.checkpoints, self.paths()) if not Path(p).exists()]
        if missing:
            how = f" (trained with: {self.command})" if self.command else ""
            return [f"proposer {self.name!r}: no checkpoint at {', '.join(missing)}{how}"]
        return _policy_file_errors(self)

    def build(self, params, device=None):
        """The ensemble, its networks on ``device`` (a :class:`torch.device`; default the CPU)."""
        from .proposers import load_policy_proposer

        return load_policy_proposer(self.paths(), name=self.name, params=params, device=device)


@dataclass
class MixedProposerConfig:
    """A policy and a shot ranker sharing the candidates
    (:class:`~billiards.search.proposers.MixedProposer`): of each draw of k, the first
    ``ceil(share * k)`` from ``policy`` (its own shot first), the rest from ``ranked`` -- the
    proposer expert iteration labels with under noise (``algo.policy_share``,
    docs/expert_iteration.md). ``proposer=mixed proposer.policy.checkpoints=[a.pt]``."""

    kind: str = "mixed"
    name: str = "mixed"
    policy: PolicyProposerConfig = dataclasses.field(default_factory=lambda: PolicyProposerConfig(name="policy", checkpoints=[]))
    ranked: RankedProposerConfig = dataclasses.field(default_factory=RankedProposerConfig)
    share: float = 0.5

    def errors(self) -> list[str]:
        errs = [] if 0.0 <= self.share <= 1.0 else [f"proposer.share must lie in [0, 1], got {self.share}"]
        return errs + self.policy.errors() + self.ranked.errors()

    def build(self, params, device=None):
        """The mixture: the policy's networks on ``device``, the ranker on the CPU."""
        from .proposers import MixedProposer

        return MixedProposer(self.policy.build(params, device=device), self.ranked.build(params), self.share, name=self.name)


# The ensembles the repository ships (results/policies/<name>/seed{0,1,2}.pt, ~0.3 MB each): the
# three seeds of a Table 5 variant of the reproduction (issue #21), by the shaping each was trained
# with (the paper's constants, conf/shaping/<shaping>.yaml): SAC with the project's CPU settings
# (algo=sac), aim constraint + carom features, 1M steps per seed on the paper's table
# (korean_medium), exported from the campaign's runs (its table6/export/<name>, the proposers of
# the reproduced Table 6). The ensembles shipped before (international, 100k steps) are in git
# history up to commit c7b3987.
# proposer=<name>: the ensembles of Table 6 (conf/experiment/table6.yaml), each the three seeds of
# the Table 5 row it was exported from (base: the foul-penalty base), committed under
# results/policies/<name>/ so that Table 6 regenerates from the repository alone
SHIPPED_PROPOSERS = {name: row.trained_from.partition("/")[2] for name, row in paper_tables()["table6"].rows.items()
                     if row.trained_from}
SHIPPED_SEEDS = (0, 1, 2)
# the Table 5 runs of those seeds (a stage of the reproduction), then the export
TRAIN_COMMAND = ("python train.py -m experiment=table5 variant=table5/{shaping} seed=0,1,2 && "
                 "python -m billiards.rl.policy export <the three run dirs> --out {out}")


def _policy_file_errors(proposer) -> list[str]:
    """Each of a policy proposer's files loaded and checked now, before any directory is written
    (:func:`billiards.rl.policy.policy_file_error`: exported policy files by their seal and
    content, run dirs and checkpoint files by the checkpoint's checksum and content)."""
    from billiards.rl.policy import policy_file_error

    return [f"proposer {proposer.name!r}: {given}: {err}" for given, p in zip(proposer.checkpoints, proposer.paths())
            if (err := policy_file_error(p))]


def shipped_proposer(name: str) -> PolicyProposerConfig:
    """``proposer=<name>``: the shipped ensemble ``results/policies/<name>/``."""
    out = f"results/policies/{name}"
    return PolicyProposerConfig(name=name, checkpoints=[f"{out}/seed{s}.pt" for s in SHIPPED_SEEDS],
                                command=TRAIN_COMMAND.format(shaping=SHIPPED_PROPOSERS[name], out=out))


# ----------------------------------------------------------------------------- the app


@dataclass
class SearchAppConfig(AppConfig):
    """search.py's root schema: the shared keys (:class:`~billiards.app_config.AppConfig`; a
    resumed P3 continues from its next chain, a finished run does nothing) and the search's own."""

    proposer: Any = MISSING  # GeometricProposerConfig | PolicyProposerConfig, chosen by proposer=
    search: Any = MISSING  # H2Config | PUCTConfig | RobustConfig, chosen by search=
    protocol: Any = MISSING  # P1Config | P3Config, chosen by protocol=
    threads: Optional[int] = None  # threads for the simulator's batches (numba) and the proposer networks (torch); default: all cores
    picture: bool = True
    table: Optional[str] = None  # the paper table an experiment preset reproduces (experiment=table6)
    paper: Any = None  # that table's paper figures (billiards/tables.py reads them)
    # where a policy proposer's networks run: auto | cpu | cuda | cuda:N (billiards/device.py); the
    # simulator, the search and the geometric proposers stay on the CPU
    device: str = "auto"

    RUNTIME = (*AppConfig.RUNTIME, "picture", "device")


# group -> (the key naming the option inside its node, {option: schema})
OPTIONS: dict[str, tuple[str, dict[str, type]]] = {
    "search": ("kind", {"h2": H2Config, "puct": PUCTConfig, "robust": RobustConfig}),
    "protocol": ("name", {Protocol.P1.value: P1Config, Protocol.P3.value: P3Config}),
    "proposer": ("kind", {"geometric": GeometricProposerConfig, "policy": PolicyProposerConfig,
                          "ranked": RankedProposerConfig, "mixed": MixedProposerConfig}),
}

# `search_schema` (the root), schema/{search,protocol,proposer}/<option>, schema/physics, the
# resolvers; the proposer options themselves are stored nodes (conf/search/ and conf/protocol/
# hold the other groups' options as YAML)
# proposer=exit: the policy of expert iteration (docs/expert_iteration.md), trained by the search
# itself (results/exit/README.md)
EXIT_PROPOSER = PolicyProposerConfig(
    name="exit", checkpoints=["results/policies/exit/seed0.pt"],
    command="python train.py algo=exit env=aim_features budget=exit seed=0 threads=1 && "
            "python -m billiards.rl.policy export <the run dir> --out results/policies/exit")


# proposer=exit_x5: the expert-iteration policy labelled by the position-aware robust search
# under fastfiz_x5 (docs/expert_iteration.md, results/exit/README.md); proposer=exit_x5_mixed: it
# and the fastfiz_x5 shot ranker sharing the candidates, as that run labelled with them
EXIT_X5_PROPOSER = PolicyProposerConfig(
    name="exit_x5", checkpoints=["results/policies/exit_x5/seed0.pt"],
    command="python train.py algo=exit env=aim_features budget=exit noise=fastfiz_x5 algo.policy_share=0.5 "
            "algo.shots_per_round=10000 budget.total_steps=200000 budget.eval_every=10000 budget.checkpoint_every=10000 "
            "budget.log_every=10000 seed=0 threads=1 && "
            "python -m billiards.rl.policy export <the run dir> --out results/policies/exit_x5")


# ``proposer=ranked_exact``: the geometric draws ranked by the shot ranker trained for exact play
# (whether a shot scores; results/rankers/README.md), from a pool of 500
RANKED_EXACT = RankedProposerConfig(name="ranked_exact", ranker="results/rankers/none/ranker.pt", pool=500,
                                    command=RANKER_COMMAND.format(out="results/rankers/none/ranker.pt", noise="none"))
# ``proposer=ranked_exact_small``: the same from a pool of 1,000 by a ranker of two hidden layers of 64 (a
# 24th of the network's multiply-adds): the chains of the pilot in a quarter of the time
RANKED_EXACT_SMALL = RankedProposerConfig(
    name="ranked_exact_small", ranker="results/rankers/none_small/ranker.pt", pool=1000,
    command=RANKER_COMMAND.format(out="results/rankers/none_small/ranker.pt", noise="none") + " --hidden 64 --layers 2")


def proposer_options() -> dict[str, GeometricProposerConfig | PolicyProposerConfig]:
    """The ``proposer=`` options: ``geometric``, ``forgiving`` (geometric, narrowed for noise:
    :data:`FORGIVING`), ``ranked`` (geometric draws ranked by a learned shot ranker,
    :class:`RankedProposerConfig`), ``ranked_exact`` (ranked by the ranker trained for exact play,
    :data:`RANKED_EXACT`; ``ranked_exact_small``: a smaller one, :data:`RANKED_EXACT_SMALL`), the
    shipped ensembles by name, ``exit`` (the expert-iteration
    policy, :data:`EXIT_PROPOSER`), ``exit_x5`` and ``exit_x5_mixed`` (the one trained under
    fastfiz_x5, alone and sharing the candidates with that noise's shot ranker), ``policy``
    (``proposer=policy proposer.checkpoints=[a.pt,b.pt,...]``: an ensemble of your own) and
    ``mixed`` (a policy and a shot ranker sharing the candidates, :class:`MixedProposerConfig`)."""
    return {"geometric": GeometricProposerConfig(), "forgiving": GeometricProposerConfig(**FORGIVING),
            **{name: shipped_proposer(name) for name in SHIPPED_PROPOSERS}, "exit": EXIT_PROPOSER, "exit_x5": EXIT_X5_PROPOSER,
            "exit_x5_mixed": EXIT_X5_MIXED,
            "policy": PolicyProposerConfig(name="policy", checkpoints=[]), "ranked": RankedProposerConfig(),
            "ranked_exact": RANKED_EXACT, "ranked_exact_small": RANKED_EXACT_SMALL, "mixed": MixedProposerConfig()}


# ``proposer=for_noise_<preset>``: each execution-noise preset's shot proposer, the strongest
# measured with the noise-aware search (results/noise/README.md): the geometric draws without
# noise, the learned shot ranker trained for the preset's noise under it; under variable noise
# (levels 0-5) the fastfiz_x5 one (docs/noise.md: ahead of the fastfiz ranker and of forgiving);
# from a pool of 500 draws, not 2,000: the same per-shot success on the tuning racks at a quarter of
# the ranking's cost (results/noisy_track/README.md). A league player's ``proposer: for_noise`` and
# expert iteration's first round under noise play it.
_RANKED_X5 = RankedProposerConfig(ranker="results/rankers/fastfiz_x5/ranker.pt", pool=500,
                                  command=RANKER_COMMAND.format(out="results/rankers/fastfiz_x5/ranker.pt", noise="fastfiz_x5"))
EXIT_X5_MIXED = MixedProposerConfig(name="exit_x5_mixed", policy=EXIT_X5_PROPOSER, ranked=_RANKED_X5, share=0.5)
NOISE_SHOT_PROPOSERS = {
    "none": GeometricProposerConfig(),
    "fastfiz": RankedProposerConfig(pool=500),
    "fastfiz_x5": _RANKED_X5,
    "variable": _RANKED_X5,
}
# ``proposer=default_for_<preset>``: what ``conf/search.yaml`` picks under each preset
# (``proposer: default_for_${noise}``, beside ``search: for_noise_${noise}``): the shot proposer,
# except under fastfiz_x5 and variable noise, where the fastfiz_x5 expert-iteration policy and
# that shot ranker share the candidates (``exit_x5_mixed``), ahead of the ranker alone on the
# tuning racks (+1.3 and +2.0 points per shot) and on the held-out tracks (results/exit/README.md)
NOISE_DEFAULT_PROPOSERS = {**NOISE_SHOT_PROPOSERS, "fastfiz_x5": EXIT_X5_MIXED, "variable": EXIT_X5_MIXED}

_store = register_app("search_schema", SearchAppConfig, {group: schemas for group, (_, schemas) in OPTIONS.items()})
for _name, _node in proposer_options().items():
    _store.store(group="proposer", name=_name, node=_node)
for _preset, _node in NOISE_SHOT_PROPOSERS.items():
    _store.store(group="proposer", name=f"for_noise_{_preset}", node=_node)
for _preset, _node in NOISE_DEFAULT_PROPOSERS.items():
    _store.store(group="proposer", name=f"default_for_{_preset}", node=_node)


class SearchConfigError(ValueError):
    """An invalid search configuration; the message names the key and what is allowed,
    ``problems`` lists each problem on its own."""

    def __init__(self, message: str, problems: list[str] | None = None):
        super().__init__(message)
        self.problems = list(problems) if problems is not None else [message]


def option_schema(group: str, node) -> type:
    """The schema of a ``search`` / ``protocol`` / ``proposer`` node: its type if Hydra typed
    it, else the one its ``kind`` (``name`` for a protocol) names."""
    key, schemas = OPTIONS[group]
    if isinstance(node, DictConfig) and OmegaConf.get_type(node) in schemas.values():
        return OmegaConf.get_type(node)
    value = node.get(key) if node is not None and hasattr(node, "get") else None
    if value not in schemas:
        raise SearchConfigError(f"{group}.{key} must be one of {', '.join(schemas)}; got {value!r}")
    return schemas[value]


def _extra_keys(node, schema: type, prefix: str) -> list[str]:
    """Keys of ``node`` that ``schema`` does not have (Hydra's ``+key=value`` appends them even
    to a closed node)."""
    own = {f.name for f in dataclasses.fields(schema)}
    return [f"{prefix}{k}" for k in node.keys() if k not in own]


@functools.lru_cache(maxsize=None)
def _structured(schema: type) -> DictConfig:
    """``OmegaConf.structured(schema)``, made once (it is slow): callers merge into it, and
    ``OmegaConf.merge`` copies its first config, so the node is never changed."""
    return OmegaConf.structured(schema)


@functools.lru_cache(maxsize=None)
def _schema_node(options: tuple) -> DictConfig:
    """The app's schema node with the option schemas ``options`` (one per group of
    :data:`OPTIONS`, in order) at their groups, made once per combination (as :func:`_structured`)."""
    schema = OmegaConf.structured(SearchAppConfig)
    for group, option_type in zip(OPTIONS, options):
        schema[group] = _structured(option_type)
    return schema


def option(group: str, node):
    """The node as an instance of its option schema (a typed object with ``settings``,
    ``actor`` or ``build``); a key the option does not take is a :class:`SearchConfigError`."""
    schema = option_schema(group, node)
    extra = _extra_keys(node, schema, f"{group}.")
    if extra:
        own = ", ".join(f.name for f in dataclasses.fields(schema))
        raise SearchConfigError(f"{', '.join(extra)}: not a key of {schema.__name__} "
                                f"({group}={node.get(OPTIONS[group][0])} takes {own})")
    try:
        return OmegaConf.to_object(OmegaConf.merge(_structured(schema), node))
    except OmegaConfBaseException as err:
        raise SearchConfigError(f"{group} ({schema.__name__}): {err}") from None


def typed(cfg) -> DictConfig:
    """A whole search config -- Hydra's, or a plain one -- merged into the schema with every
    option node typed: unknown keys and wrong types fail as while composing, and keys the config
    leaves out take their defaults."""
    cfg = cfg if isinstance(cfg, DictConfig) else OmegaConf.create(cfg)
    schema = _schema_node(tuple(option_schema(group, cfg.get(group)) for group in OPTIONS))
    try:
        return OmegaConf.merge(schema, cfg)  # a copy of the schema node, merged into
    except OmegaConfBaseException as err:
        raise SearchConfigError(str(err)) from None


def search_config(search: str = "h2", protocol: str = Protocol.P3.value, proposer: str = "geometric") -> DictConfig:
    """What ``python search.py search=<search> protocol=<protocol> proposer=<proposer>``
    composes, without Hydra (for scripts and tests)."""
    cfg = OmegaConf.structured(SearchAppConfig)
    cfg.search = OmegaConf.structured(OPTIONS["search"][1][search])
    cfg.protocol = OmegaConf.structured(OPTIONS["protocol"][1][protocol])
    cfg.proposer = OmegaConf.structured(proposer_options()[proposer])
    return cfg


# Keys every node of a group had before each option got its own schema: a config saved then
# (config.yaml of a search run, results.json's "config") has them all, and the option ignored
# those that were not its own (the robust knobs and the geometric u_*/spin_* ranges: the union
# nodes of the runs under execution noise, results/noise/).
def upgrade(saved: dict) -> dict:
    """A saved search config (a plain dict) in today's form (billiards.compat.upgrade_search_config)."""
    return compat.upgrade_search_config(saved, lambda group, node: {f.name for f in dataclasses.fields(option_schema(group, node))})


def saved_config(run_dir: str | Path) -> DictConfig:
    """The typed config a search run saved (``<run_dir>/config.yaml``), in any form a run ever
    wrote; :class:`SearchConfigError` if there is none or it does not fit the schema."""
    path = Path(run_dir) / CONFIG_FILE
    if not os.path.lexists(path):
        raise SearchConfigError(f"resume={run_dir}: no {CONFIG_FILE} there (not a search run directory)")
    try:  # the one reader of run-folder files: no link, no FIFO, bounded size
        text = read_run_text(path, "config")
    except (OSError, ValueError) as err:
        raise SearchConfigError(f"resume={run_dir}: {err}") from None
    saved = OmegaConf.to_container(OmegaConf.create(text), resolve=False) if text.strip() else None
    if not isinstance(saved, dict):
        raise SearchConfigError(f"{path} is not a search config")
    return typed(upgrade(saved))


def compose_search(overrides: list[str]) -> DictConfig:
    """What ``python search.py <overrides>`` composes (Hydra's compose API over ``conf/``),
    typed and validated (:class:`SearchConfigError` naming what is wrong): for a caller that
    plays search.py's searches without its app (a benchmark agent, expert iteration's noisy
    labeller). Inside a running Hydra app its global state is put back afterwards."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from billiards.files import ROOT

    running = GlobalHydra.instance().hydra
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
            cfg = compose("search", overrides=list(overrides))
    except Exception as err:
        raise SearchConfigError(str(err)) from None
    finally:
        GlobalHydra.instance().clear()
        if running is not None:
            GlobalHydra.instance().initialize(running)
    cfg = typed(cfg)
    validate(cfg)
    return cfg


def labelling_search(train_cfg) -> DictConfig:
    """The search expert iteration labels with under a training config's execution noise
    (``python train.py algo=exit noise=<preset>``, :mod:`billiards.exit`): what ``python search.py
    noise=<preset> physics=<preset> search.budget=<algo.search_budget> proposer=for_noise_<preset>``
    composes: the default search over the noise's shot proposer (round 0's; the policy joins it
    from round 1)."""
    preset = train_cfg.noise.preset
    return compose_search([f"noise={preset}", f"physics={train_cfg.physics.preset}",
                           f"search.budget={train_cfg.algo.search_budget}", f"proposer=for_noise_{preset}"])


def labelling_search_errors(train_cfg) -> list[str]:
    """The problems of :func:`labelling_search` for a training config under execution noise
    (none under exact play, where the labeller is h2 over ``algo``'s own knobs)."""
    from billiards.physics.noise import noise_from_config

    if noise_from_config(train_cfg.noise).is_exact:
        return []
    try:
        labelling_search(train_cfg)
    except SearchConfigError as err:
        return [f"algo=exit under noise={train_cfg.noise.preset} labels with search.py's search for it at "
                f"algo.search_budget={train_cfg.algo.search_budget} simulations: {'; '.join(err.problems)}"]
    return []


def _register_labelling_check() -> None:
    """train.py's validation checks expert iteration's labelling search with the rest of the
    config (billiards.rl does not import this module; this module registers the check)."""
    import billiards.rl.config as train_config

    train_config.ALGO_CHECKS["exit"] = labelling_search_errors


_register_labelling_check()


# ----------------------------------------------------------------------------- validation


def errors(cfg) -> list[str]:
    """Every problem of a composed search config that a type cannot express, each naming its key;
    checked on its resolved values (:func:`resolved_config`: an interpolation is checked as what
    it yields, one through a resolver the project does not allow is refused)."""
    errs: list[str] = []
    if isinstance(cfg, DictConfig):
        cfg, errs = resolved_config(cfg)
        if errs:
            return errs
        errs = numeric_bound_errors(cfg)
    extra = [k for k in _extra_keys(cfg, SearchAppConfig, "") if k != "hydra"]  # hydra: the callback's view
    if extra:
        errs.append(f"{', '.join(extra)}: not a key of SearchAppConfig")
    nodes = {}
    for group, (key, schemas) in OPTIONS.items():
        try:
            nodes[group] = option(group, OmegaConf.select(cfg, group) if isinstance(cfg, DictConfig) else cfg.get(group))
        except SearchConfigError as err:
            errs.append(str(err))
            continue
        chosen = next(name for name, schema in schemas.items() if isinstance(nodes[group], schema))
        value = getattr(nodes[group], key)
        if value not in schemas:
            errs.append(f"{group}.{key} must be one of {', '.join(schemas)}, chosen with {group}=<option>; got {value!r}")
        elif value != chosen:
            errs.append(f"{group}.{key}={value!r} contradicts {group}={chosen} "
                        f"(choose the {group} with {group}=<option>; {key} follows it)")
    search = nodes.get("search")
    for node in nodes.values():  # each option's own checks (its schema's errors())
        errs.extend(node.errors())
    if cfg.seed < 0:
        errs.append(f"seed must be >= 0 (a numpy seed), got {cfg.seed}")
    if (device_err := device_error(cfg.get("device", "auto"))) is not None:
        errs.append(device_err)
    if cfg.threads is not None and (err := threads_error(cfg.threads)):
        errs.append(err)
    if cfg.get("resume") and cfg.resume != RESUME_AUTO and not (Path(cfg.resume) / CONFIG_FILE).is_file():
        errs.append(f"resume={cfg.resume!r}: not a search run directory (no {CONFIG_FILE} there)")
    errs.extend(physics_errors(cfg.physics))
    noise = cfg.noise
    noise_errs = noise_errors(noise)
    errs.extend(noise_errs)
    if isinstance(search, RobustConfig) and not noise_errs and noise_from_config(noise).is_exact:
        errs.append("search=robust scores candidates over noisy replays: it needs execution noise "
                    "(noise=fastfiz|fastfiz_x5|variable or noise.aim_deg=...); without noise use search=h2")
    return errs


def validate(cfg) -> None:
    """Raise :class:`SearchConfigError` listing every problem of a search config."""
    errs = errors(cfg)
    if errs:
        raise SearchConfigError("invalid search config:\n  - " + "\n  - ".join(errs), errs)


class ValidateSearchConfig(ValidatingCallback):
    """Hydra callback (``hydra.callbacks`` in conf/search.yaml): :func:`validate` before Hydra
    creates the run directory."""

    validate = staticmethod(validate)


__all__ = ["FORGIVING", "GeometricProposerConfig", "H2Config", "OPTIONS", "P1Config", "P3Config",
           "PUCTConfig", "PolicyProposerConfig", "RankedProposerConfig", "RobustConfig", "SHIPPED_PROPOSERS", "SearchAppConfig",
           "SearchConfigError", "ValidateSearchConfig", "errors", "option", "proposer_options", "saved_config",
           "shipped_proposer", "typed", "upgrade", "validate"]
