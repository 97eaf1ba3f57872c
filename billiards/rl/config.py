"""The training configuration schema: dataclasses registered in Hydra's ConfigStore.

``conf/config.yaml`` starts its defaults list with ``schema`` (the :class:`TrainConfig` below)
and every group option (``conf/algo/sac.yaml`` ...) starts with its own ``/schema/...`` entry,
so Hydra merges every YAML file and every command-line override into these typed, closed
(struct) nodes. Importing this module registers them, the idiom both apps share
(:mod:`billiards.app_config`):

* an unknown key (``algo.lrr=1``, ``foo=1``) or a key of another algorithm
  (``algo=sac algo.clip_epsilon=0.1``) is rejected while composing;
* a wrongly typed value (``budget.total_steps=abc``) or a value outside an enum
  (``env.paradigm=sideways``, ``logger.mode=maybe``) is rejected while composing;
* an unknown group option (``algo=dqn``) is rejected by Hydra with the list of options;
* everything else a type cannot express (negative budgets, ``frames_per_batch`` not a
  multiple of ``num_envs`` ...) is checked by :func:`validate`, which the Hydra callback
  :class:`ValidateConfig` runs *before* Hydra creates a run or sweep directory, for every job
  of a multirun. A bad command line therefore fails in about a second and writes nothing.

This module imports neither torch nor the simulator's kernels, so the checks stay fast.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, List, Optional

from omegaconf import MISSING, DictConfig, OmegaConf

from billiards.device import device_error, threads_error
from billiards.app_config import (AppConfig, RESUME_AUTO, numeric_bound_errors, register_app, resolved_config,
                                  upper_bound_errors)
from billiards.files import CHECKPOINT_FILE, repo_path
from billiards.files import CONFIG_FILE, EVAL_FILE, EVAL_HISTORY_FILE, METRICS_FILE  # noqa: F401  (re-exported: the run dir's files)
from billiards.physics.config import physics_errors
from billiards.physics.noise import noise_errors
from billiards.shaping import ShapingOptions



class Paradigm(str, enum.Enum):
    """The paper's four training paradigms: starting rack x miss handling (Table 2)."""

    canonical_reset = "canonical_reset"
    canonical_continue = "canonical_continue"
    random_reset = "random_reset"
    random_continue = "random_continue"


class Start(str, enum.Enum):
    random = "random"
    canonical = "canonical"


class LoggerBackend(str, enum.Enum):
    wandb = "wandb"
    tensorboard = "tensorboard"  # TorchRL's TensorboardLogger; needs the [tensorboard] extra
    csv = "csv"
    none = "none"


# Backends that need a package outside the core dependencies: (module, pip extra).
LOGGER_EXTRAS = {LoggerBackend.tensorboard: ("tensorboard", "tensorboard")}


class WandbMode(str, enum.Enum):
    offline = "offline"
    online = "online"
    disabled = "disabled"


# ----------------------------------------------------------------------------- bounds
#
# Every number a run is sized by has a finite upper bound, written once in its schema's ``UPPER``
# (key -> (bound, why); :func:`billiards.app_config.upper_bound_errors`) and listed in
# docs/reliability.md ("Numbers with bounds after resolution"): a value past it is refused while
# validating, before a directory exists, instead of overflowing, allocating without end or
# making a run that cannot finish or be stopped.
MAX_WIDTH = 4096  # units of a hidden layer
MAX_LAYERS = 8  # hidden layers of a network
MAX_STEPS = 10**9  # frames of a budget (and every cadence in frames)
MAX_INNINGS = 10_000  # innings of an evaluation, shots of an inning
MAX_PPO_UPDATES = 10_000  # PPO gradient updates per rollout (epochs x minibatches), made before a stop is seen
RATE = (1.0, "a learning rate")
NETWORK = (MAX_WIDTH, "units per hidden layer")


# ----------------------------------------------------------------------------- algorithms


def _positive(path: str, value, strict: bool = True) -> list[str]:
    """``[message]`` unless ``value`` is finite and > 0 (``strict``) or >= 0."""
    ok = (value > 0 if strict else value >= 0) and math.isfinite(value)
    return [] if ok else [f"{path} must be {'> 0' if strict else '>= 0'}, got {value!r}"]


def _need(ok: bool, message: str) -> list[str]:
    return [] if ok else [message]


# Each schema's ``errors(node)`` checks what its types cannot say about its own node (a composed
# DictConfig node, read by attribute); checks across nodes are :func:`config_errors`'.

@dataclass
class AlgoConfig:
    """What every algorithm's node has (each algorithm's schema derives from it, setting its own
    defaults): its name, the networks' hidden layers, the optimiser's learning rate, the discount
    and the env frames of a collector batch; :meth:`errors` checks them and every key's upper
    bound (the schema's ``UPPER``)."""

    name: str = MISSING
    hidden_sizes: List[int] = field(default_factory=lambda: [256, 256])
    lr: float = 3e-4
    gamma: float = 0.99
    frames_per_batch: int = 0  # env frames per collector iteration (all innings together); off-policy: 0 = env.num_envs

    UPPER: ClassVar[dict] = {"lr": RATE, "hidden_sizes": NETWORK}
    KEEPS_REPLAY: ClassVar[bool] = False  # a replay buffer, held in the checkpoints

    @classmethod
    def most_owed(cls, algo, env) -> float:
        """The most gradient updates a run stopped amid its updates may owe (``algo``, ``env``: a
        checkpoint's plain config nodes; what a checkpoint's counters are checked against): none."""
        return 0.0

    @classmethod
    def errors(cls, a) -> list[str]:
        return [*_need(0 < len(a.hidden_sizes) <= MAX_LAYERS and all(h > 0 for h in a.hidden_sizes),
                       f"algo.hidden_sizes must be a non-empty list of at most {MAX_LAYERS} positive widths, "
                       f"got {list(a.hidden_sizes)}"),
                *_positive("algo.lr", a.lr), *_need(0.0 < a.gamma <= 1.0, f"algo.gamma must lie in (0, 1], got {a.gamma!r}"),
                *upper_bound_errors(a, "algo.", cls.UPPER)]


@dataclass
class OffPolicyConfig(AlgoConfig):
    """Shared by SAC and TD3. ``utd`` is the update-to-data ratio: gradient updates per
    collected env frame (one frame = one shot of one of the ``env.num_envs`` innings);
    ``frames_per_batch`` 0 (the default) is one step of every inning."""

    batch_size: int = 256
    utd: float = 0.125
    tau: float = 0.005  # soft target update rate
    buffer_size: int = 1_000_000
    # Polyak rate of an averaged copy of the actor, updated after every actor update and used
    # for evaluation (periodic and final; the live actor is evaluated beside it). 0 = off:
    # evaluate the live actor.
    actor_ema: float = 0.0

    KEEPS_REPLAY: ClassVar[bool] = True
    UPPER: ClassVar[dict] = {
        **AlgoConfig.UPPER,
        "batch_size": (65_536, "replay rows per gradient update"),
        "utd": (64.0, "gradient updates per collected frame"),
        "buffer_size": (10**7, "replay rows, allocated at the first batch"),
        "frames_per_batch": (2**20, "frames per collector batch"),
    }

    @classmethod
    def most_owed(cls, algo, env) -> float:
        """One collector batch's updates: utd x the batch's frames."""
        return float(algo.get("utd", 0.0)) * max(int(algo.get("frames_per_batch") or 0), int(env.get("num_envs") or 1))

    @classmethod
    def errors(cls, a) -> list[str]:
        return [*super().errors(a), *_positive("algo.batch_size", a.batch_size), *_positive("algo.utd", a.utd),
                *_positive("algo.buffer_size", a.buffer_size), *_need(0.0 < a.tau <= 1.0, f"algo.tau must lie in (0, 1], got {a.tau!r}"),
                *_need(0.0 <= a.actor_ema < 1.0, f"algo.actor_ema must lie in [0, 1) (0 = off), got {a.actor_ema!r}"),
                *_positive("algo.frames_per_batch", a.frames_per_batch, strict=False)]


@dataclass
class SACConfig(OffPolicyConfig):
    name: str = "sac"
    lr: float = 1e-3  # learns far more per CPU minute here than 3e-4 (conf/algo/sac.yaml)
    gamma: float = 0.9  # the horizon of a 10-shot inning; 0.99 learns far slower here
    alpha_init: float = 1.0
    target_entropy: Optional[float] = None  # None = "auto" = -dim(action)

    UPPER: ClassVar[dict] = {**OffPolicyConfig.UPPER, "alpha_init": (1e3, "the entropy temperature's start")}

    @classmethod
    def errors(cls, a) -> list[str]:
        te = a.target_entropy
        return [*super().errors(a), *_positive("algo.alpha_init", a.alpha_init),
                *_need(te is None or -100.0 <= te <= 100.0,
                       f"algo.target_entropy must be null (auto: minus the action's dimension) or lie in [-100, 100] "
                       f"(nats), got {te!r}")]


@dataclass
class TD3Config(OffPolicyConfig):
    name: str = "td3"
    exploration_noise: float = 0.1  # std of the Gaussian added to the action while collecting (fraction of the half-range)
    policy_noise: float = 0.2  # target policy smoothing noise
    noise_clip: float = 0.5
    policy_delay: int = 2  # one actor and target update per policy_delay critic updates

    UPPER: ClassVar[dict] = {**OffPolicyConfig.UPPER,
                             "exploration_noise": (2.0, "twice the action's half-range"),
                             "policy_noise": (2.0, "twice the action's half-range"),
                             "noise_clip": (2.0, "twice the action's half-range"),
                             "policy_delay": (1000, "critic updates per actor update")}

    @classmethod
    def errors(cls, a) -> list[str]:
        return [*super().errors(a), *_positive("algo.exploration_noise", a.exploration_noise, strict=False),
                *_positive("algo.policy_noise", a.policy_noise, strict=False),
                *_positive("algo.noise_clip", a.noise_clip, strict=False), *_positive("algo.policy_delay", a.policy_delay)]


@dataclass
class PPOConfig(AlgoConfig):
    name: str = "ppo"
    hidden_sizes: List[int] = field(default_factory=lambda: [64, 64])
    gae_lambda: float = 0.95
    clip_epsilon: float = 0.2
    frames_per_batch: int = 2048  # on-policy rollout length (all envs together)
    epochs: int = 10
    minibatch_size: int = 64
    entropy_coeff: float = 0.0
    critic_coeff: float = 0.5
    max_grad_norm: float = 0.5
    normalize_advantage: bool = True

    UPPER: ClassVar[dict] = {
        **AlgoConfig.UPPER,
        "frames_per_batch": (2**20, "frames per rollout"),
        "epochs": (1000, "passes over a rollout"),
        "entropy_coeff": (100.0, "a loss coefficient"),
        "critic_coeff": (100.0, "a loss coefficient"),
        "max_grad_norm": (1e3, "a gradient norm"),
    }

    @classmethod
    def errors(cls, a) -> list[str]:
        updates = a.epochs * (a.frames_per_batch // a.minibatch_size) if a.minibatch_size > 0 else 0
        return [*super().errors(a), *_positive("algo.frames_per_batch", a.frames_per_batch),
                *_positive("algo.epochs", a.epochs),
                *_positive("algo.entropy_coeff", a.entropy_coeff, strict=False),
                *_positive("algo.critic_coeff", a.critic_coeff, strict=False),
                *_need(updates <= MAX_PPO_UPDATES,
                       f"algo.epochs x (algo.frames_per_batch // algo.minibatch_size) = {updates:,} gradient updates per "
                       f"rollout, at most {MAX_PPO_UPDATES:,} (a stop request is seen after them)"),
                *_positive("algo.minibatch_size", a.minibatch_size),
                *_need(a.minibatch_size <= a.frames_per_batch,
                       f"algo.minibatch_size ({a.minibatch_size}) must not exceed algo.frames_per_batch ({a.frames_per_batch})"),
                *_need(0.0 < a.clip_epsilon < 1.0, f"algo.clip_epsilon must lie in (0, 1), got {a.clip_epsilon!r}"),
                *_need(0.0 <= a.gae_lambda <= 1.0, f"algo.gae_lambda must lie in [0, 1], got {a.gae_lambda!r}"),
                *_positive("algo.max_grad_norm", a.max_grad_norm)]


@dataclass
class ExItConfig(AlgoConfig):
    """Expert iteration (``billiards.exit``): rounds of ``shots_per_round`` shots labelled by the
    depth-2 lookahead (``search_budget`` simulations per shot: ``k1`` candidates, the ``m1`` best
    expanded) over the current policy as its proposer (the geometric proposer in round 0), each
    label the best-valued candidate nearest the proposer's own shot; under execution noise by
    search.py's default search for that noise at ``search_budget`` (``k1``, ``m1``: h2's only),
    its chosen shot the label. With ``centre_probes`` > 0 (exact play) each label moves to the
    mean of itself and those of ``centre_probes`` Gaussian probes around it (``centre_scale``, in
    the normalised action) that score without a foul, where that mean scores too (the centre of
    the region of good shots; the label stays otherwise). From round 1 on the policy proposes ``policy_share`` of the
    candidates (its shot first), round 0's proposer the rest; after each round,
    ``epochs`` passes (``batch_size`` rows per update) of maximum likelihood on the last
    ``buffer_size`` labelled shots. ``innings``: innings played side by side in one block.
    ``init_policy``: an exported policy file (:func:`billiards.rl.policy.export_policy`, e.g. a
    SAC run's) whose actor has this one's shape, table and observation: the policy starts from
    its weights and proposes from round 0 on (:func:`billiards.rl.policy.init_policy_problem`).
    ``nll_beta``: the loss's beta (:class:`~billiards.rl.learners.ExItAgent`; 0 = maximum likelihood).
    ``label_tolerance`` (under noise): the label is the proposer's own shot (candidate 0) where
    the search's choice beats its statistic over the noisy replays by no more than this
    (:func:`billiards.exit.noisy_labels`; 0: always the search's choice)."""

    name: str = "exit"
    lr: float = 1e-3
    batch_size: int = 512
    buffer_size: int = 200_000
    shots_per_round: int = 20_000
    epochs: float = 10.0
    innings: int = 200
    search_budget: int = 400
    k1: int = 200
    m1: int = 10
    policy_share: float = 1.0
    centre_probes: int = 0
    centre_scale: float = 0.02
    init_policy: Optional[str] = None  # an exported policy file of the same actor: the start (and proposer from round 0)
    nll_beta: float = 0.0  # beta-NLL: each label's likelihood term weighted by scale^(2 beta) (0: the plain likelihood)
    label_tolerance: float = 0.0  # under noise: keep the proposer's own shot where the chosen one beats it by no more

    KEEPS_REPLAY: ClassVar[bool] = True
    UPPER: ClassVar[dict] = {
        **AlgoConfig.UPPER,
        "batch_size": (65_536, "rows per gradient update"),
        "buffer_size": (10**7, "labelled shots kept"),
        "shots_per_round": (10**7, "labelled shots per round"),
        "epochs": (1000.0, "passes over the labelled shots per round"),
        "innings": (65_536, "innings played side by side"),
        "search_budget": (10**6, "simulations per labelled shot"),
        "k1": (10**6, "candidates per shot"), "m1": (10**6, "expanded candidates per shot"),
        "centre_probes": (10**4, "probes per label"), "centre_scale": (1.0, "the probes' standard deviation"),
        "label_tolerance": (1000.0, "the noisy search's statistic"),
    }

    @classmethod
    def most_owed(cls, algo, env) -> float:
        """One round's updates: epochs passes over the labelled shots kept."""
        return float(algo["epochs"]) * int(algo["buffer_size"]) / int(algo["batch_size"])

    @classmethod
    def errors(cls, a) -> list[str]:
        rest = a.search_budget - a.k1
        return [*super().errors(a), *_positive("algo.batch_size", a.batch_size), *_positive("algo.buffer_size", a.buffer_size),
                *_positive("algo.shots_per_round", a.shots_per_round), *_positive("algo.epochs", a.epochs),
                *_positive("algo.innings", a.innings), *_positive("algo.k1", a.k1), *_positive("algo.m1", a.m1, strict=False),
                *_need(a.m1 <= a.k1 and rest >= 0 and (rest % a.m1 == 0 if a.m1 else rest == 0),
                       f"algo.search_budget - algo.k1 ({a.search_budget} - {a.k1}) must be a multiple of algo.m1 ({a.m1}) "
                       f"(0 without expansion), with algo.m1 <= algo.k1"),
                *_need(0.0 < a.policy_share <= 1.0, f"algo.policy_share must lie in (0, 1], got {a.policy_share}"),
                *_positive("algo.centre_probes", a.centre_probes, strict=False), *_positive("algo.centre_scale", a.centre_scale),
                *_need(0.0 <= a.nll_beta <= 1.0, f"algo.nll_beta must lie in [0, 1], got {a.nll_beta}"),
                *_positive("algo.label_tolerance", a.label_tolerance, strict=False),
                *_need(a.innings > 0 and a.shots_per_round % (a.innings * EXIT_SHOTS) == 0,
                       f"algo.shots_per_round ({a.shots_per_round}) must be whole blocks of algo.innings x {EXIT_SHOTS} "
                       f"shots ({a.innings * EXIT_SHOTS})")]


EXIT_SHOTS = 10  # shots of an expert-iteration inning (the benchmark's innings-v1 protocol)


# The algorithms, by algo.name: the one list (the algo group's schemas, validate's "one of ...";
# billiards.rl.learners maps each to its agent). OFF_POLICY: those trained from a collector and a
# replay buffer; REPLAY: those keeping a replay buffer (a checkpoint holds it); EXIT: expert
# iteration (trained from the search's labels, its loop in billiards.exit).
ALGO_SCHEMAS = {"sac": SACConfig, "td3": TD3Config, "ppo": PPOConfig, "exit": ExItConfig}
# Checks an app adds for an algorithm whose loop lives above billiards.rl, by algo.name: a
# function of the resolved config giving its problems (train.py: expert iteration's labelling
# search under noise, composed from search.py's config, which billiards.rl does not import).
ALGO_CHECKS: dict[str, Callable[[DictConfig], list[str]]] = {}
OFF_POLICY = tuple(name for name, schema in ALGO_SCHEMAS.items() if issubclass(schema, OffPolicyConfig))
REPLAY = tuple(name for name, schema in ALGO_SCHEMAS.items() if schema.KEEPS_REPLAY)
EXIT = "exit"


# ----------------------------------------------------------------------------- the rest


@dataclass
class EnvConfig:
    """The training environment (:func:`billiards.envs.make_env`)."""

    paradigm: Paradigm = Paradigm.random_continue
    constrain_aim: bool = False  # AimConstraint: action[0] is an offset inside the first-contact cone
    extra_features: bool = False  # CaromFeatures: observation 28 -> 32
    max_shots: int = 10  # shots per training inning
    num_envs: int = 32  # B innings stepped together by one batched env

    UPPER: ClassVar[dict] = {"num_envs": (65_536, "innings stepped together"),
                             "max_shots": (MAX_INNINGS, "shots of a training inning")}

    @classmethod
    def errors(cls, e) -> list[str]:
        return [*_positive("env.num_envs", e.num_envs), *_positive("env.max_shots", e.max_shots),
                *upper_bound_errors(e, "env.", cls.UPPER)]


@dataclass
class ShapingConfig(ShapingOptions):
    """Reward shaping added to the carom score while training (evaluation never shapes): the
    env's shaping options (:class:`billiards.shaping.ShapingOptions`, the one schema: the keys,
    their types, defaults and meaning), named by the shaping group's option, with the trainer's
    reward model, bounds and checks."""

    name: str = "none"
    # the trainer's reward model is a path (the env's may also be a model object, and defaults to
    # none): the committed one (python -m billiards.rm train); relative paths: cwd, then the repo
    rm_model: str = "results/rm/model.pt"

    UPPER: ClassVar[dict] = {**{key: (100.0, "a reward coefficient; a point is 1")
                                for key in ("foul_penalty", "gentle", "near_miss", "rm")},
                             "near_miss_sigma": (10.0, "metres")}

    @classmethod
    def errors(cls, sh) -> list[str]:
        errs = [m for key in ("foul_penalty", "gentle", "near_miss", "rm") for m in _positive(f"shaping.{key}", sh[key], strict=False)]
        errs += _positive("shaping.near_miss_sigma", sh.near_miss_sigma) + upper_bound_errors(sh, "shaping.", cls.UPPER)
        errs += _need(sh.gentle_kind in ("leave", "power"),
                      f"shaping.gentle_kind must be leave (the paper's leave-position bonus) or power, got {sh.gentle_kind!r}")
        if not sh.rm:
            return errs
        path = resolve_rm_model(sh.rm_model)
        if not (path.is_file() and path.stat().st_size > 0):
            return errs + [f"shaping.rm_model={sh.rm_model!r}: no reward model there; train one with "
                           f"`python -m billiards.rm generate` and `python -m billiards.rm train` (see the README)"]
        from billiards.rm.model import RewardModelError, load_model

        try:  # loaded and checked now, before any directory is written
            load_model(path)
        except RewardModelError as err:
            errs.append(f"shaping.rm_model={sh.rm_model!r}: {err}")
        return errs


@dataclass
class CurriculumConfig:
    """The staged action curriculum (paper 3.1; billiards/rl/curriculum.py). ``stages`` lists
    the free action dimensions of each stage (0 aim, 1 power, 2-3 english a, b); the stage
    changes at the fractions ``switch_at`` of budget.total_steps; held dimensions play
    p = hold_power and a = b = hold_english."""

    name: str = "none"
    stages: List[List[int]] = field(default_factory=lambda: [[0, 1, 2, 3]])
    switch_at: List[float] = field(default_factory=list)
    hold_power: float = 0.5
    hold_english: float = 0.0

    @staticmethod
    def errors(c) -> list[str]:
        if c.name == "none":
            return []
        errs = []
        stages = [list(s) for s in c.stages]
        if not stages or any(not s or any(d not in (0, 1, 2, 3) for d in s) or len(set(s)) != len(s) for s in stages):
            errs.append(f"curriculum.stages must be non-empty lists of distinct action dims in 0..3, got {stages}")
        elif sorted(stages[-1]) != [0, 1, 2, 3]:
            errs.append(f"curriculum.stages: the last stage must free the whole action [0, 1, 2, 3], got {stages[-1]}")
        f = list(c.switch_at)
        if len(f) != len(stages) - 1:
            errs.append(f"curriculum.switch_at needs one fraction per stage boundary ({len(stages) - 1}), got {f}")
        elif not all(0.0 < x < 1.0 for x in f) or any(b <= a for a, b in zip(f, f[1:])):
            errs.append(f"curriculum.switch_at must increase strictly inside (0, 1), got {f}")
        errs += _need(0.0 <= c.hold_power <= 1.0, f"curriculum.hold_power must lie in [0, 1], got {c.hold_power!r}")
        return errs + _need(-1.0 <= c.hold_english <= 1.0, f"curriculum.hold_english must lie in [-1, 1], got {c.hold_english!r}")


@dataclass
class LoggerConfig:
    backend: LoggerBackend = LoggerBackend.csv
    csv: bool = True  # metrics.csv in the run dir (always on for the wandb and tensorboard backends)
    project: str = "billiards"
    entity: Optional[str] = None
    group: Optional[str] = None
    mode: WandbMode = WandbMode.offline  # never asks for a login unless set to online

    @staticmethod
    def errors(lg) -> list[str]:
        """A backend whose optional package is missing fails before the run starts."""
        import importlib.util

        backend = LoggerBackend(lg.backend)
        if backend not in LOGGER_EXTRAS or importlib.util.find_spec(LOGGER_EXTRAS[backend][0]) is not None:
            return []
        module, extra = LOGGER_EXTRAS[backend]
        return [f"logger={backend.value} needs the {module!r} package, which is not installed: "
                f'pip install -e ".[{extra}]" (or pip install {module})']


@dataclass
class BudgetConfig:
    """How long to train and how often to evaluate, log and checkpoint. All counts are env
    frames (shots), the paper's "steps"."""

    name: str = MISSING
    total_steps: int = MISSING
    init_random_steps: int = 5_000  # uniformly random actions before the policy acts (off-policy only)
    eval_every: int = 50_000  # periodic evaluation (0 = only the final one)
    eval_innings: int = 20  # innings of a periodic evaluation
    final_eval_innings: int = 100  # innings of the final evaluation (the paper's protocol: 100)
    checkpoint_every: int = 50_000  # 0 = only at the end
    log_every: int = 5_000
    # also stop training once this run has used this many process CPU minutes (0 = no limit);
    # the final evaluation follows
    cpu_minutes: float = 0.0

    UPPER: ClassVar[dict] = {
        **{key: (MAX_STEPS, "frames") for key in ("total_steps", "init_random_steps", "eval_every", "checkpoint_every",
                                                  "log_every")},
        "eval_innings": (MAX_INNINGS, "innings of an evaluation"), "final_eval_innings": (MAX_INNINGS, "innings of an evaluation"),
        "cpu_minutes": (1e6, "about two years"),
    }

    @classmethod
    def errors(cls, b) -> list[str]:
        errs = _positive("budget.total_steps", b.total_steps)
        for key in ("init_random_steps", "eval_every", "checkpoint_every"):
            errs += _positive(f"budget.{key}", b[key], strict=False)
        errs += [m for key in ("eval_innings", "final_eval_innings", "log_every") for m in _positive(f"budget.{key}", b[key])]
        return errs + _positive("budget.cpu_minutes", b.cpu_minutes, strict=False) + upper_bound_errors(b, "budget.", cls.UPPER)


@dataclass
class EvalConfig:
    """The unified evaluation protocol (:func:`billiards.evaluation.evaluate_policy`): continue-on-miss,
    deterministic policy, innings of ``max_shots`` shots, from every start in ``starts``
    (the first one is the primary metric)."""

    starts: List[Start] = field(default_factory=lambda: [Start.random])
    max_shots: int = 10
    seed: int = 0  # eval racks are the same for every run and every evaluation

    UPPER: ClassVar[dict] = {"max_shots": (MAX_INNINGS, "shots of an evaluation inning")}

    @classmethod
    def errors(cls, ev) -> list[str]:
        # eval.seed: the racks' np.random.default_rng (any integer >= 0), checked here, not at the final evaluation
        return [*_positive("eval.max_shots", ev.max_shots), *upper_bound_errors(ev, "eval.", cls.UPPER),
                *_need(len(ev.starts) > 0, "eval.starts must list at least one start (random, canonical)"),
                *_need(ev.seed >= 0, f"eval.seed must be an integer >= 0 (a numpy seed), got {ev.seed!r}")]


@dataclass
class CheckpointConfig:
    save_buffer: bool = True  # include the replay buffer (what makes a resume match an uninterrupted run most closely)


@dataclass
class TrainConfig(AppConfig):
    """train.py's root schema: the shared keys (:class:`~billiards.app_config.AppConfig`: the
    table and the execution noise of the training and evaluation envs, the seed, the progress
    bar, ``resume=`` from the run's last checkpoint) and training's own."""

    algo: Any = MISSING  # SACConfig | TD3Config | PPOConfig, chosen by the algo group
    env: EnvConfig = field(default_factory=EnvConfig)
    shaping: ShapingConfig = field(default_factory=ShapingConfig)
    curriculum: CurriculumConfig = field(default_factory=CurriculumConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    budget: BudgetConfig = MISSING
    eval: EvalConfig = field(default_factory=EvalConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    threads: int = 1  # torch (intra-op) and numba threads of this run; 1 when jobs run in parallel
    compile: bool = False  # torch.compile the update step (slow to start; see the README)
    # where the networks, losses and replay buffer live: auto (a CUDA GPU when torch sees one,
    # else the CPU), cpu, cuda, cuda:N; the simulator always runs on the CPU
    device: str = "auto"
    table: Optional[str] = None  # the paper table a variant (variant=<table>/<row>) belongs to
    row: Optional[str] = None  # the table's row that variant trains (the report groups runs by table and row)
    paper: Any = None  # an experiment preset's table: the paper's figures (billiards/tables.py reads it)
    paper_steps: int = 1_000_000  # the paper's budget for the table (budget=paper trains this long)

    UPPER: ClassVar[dict] = {"paper_steps": (MAX_STEPS, "frames")}
    RUNTIME = (*AppConfig.RUNTIME, "compile", "device")


Config = TrainConfig  # the former name (billiards/rl/train.py imports it)

# `schema` (the root), schema/algo/<name>, schema/budget, schema/physics and the resolvers
register_app("schema", TrainConfig, {"algo": ALGO_SCHEMAS, "budget": BudgetConfig})


# ----------------------------------------------------------------------------- validation


class ConfigError(ValueError):
    """An invalid training configuration; the message names the key and what is allowed."""


def appended_keys(cfg: DictConfig) -> list[str]:
    """Keys a command line appended (``+algo.foo=1``) that no schema has: Hydra's ``+`` adds
    them even to a closed node, and nothing would ever read them. One message per node."""
    errs = []
    for node, path in [(cfg, ""), *((cfg[k], f"{k}.") for k in cfg if k != "hydra" and isinstance(cfg[k], DictConfig))]:
        schema = OmegaConf.get_type(node)
        if not dataclasses.is_dataclass(schema):
            continue
        own = {f.name for f in dataclasses.fields(schema)}
        extra = [f"{path}{k}" for k in node if k not in own and not (path == "" and k == "hydra")]
        if extra:
            errs.append(f"{', '.join(extra)}: not a key of {schema.__name__} (a '+' override adds a key "
                        f"nothing reads; drop it, or set an existing key without '+')")
    return errs


def config_errors(cfg: DictConfig, init_policy_problem: Callable | None = None,
                  checkpoint_problem: Callable | None = None) -> list[str]:
    """Every problem of the config, checked on its resolved values (:func:`resolved_config`:
    an interpolation is checked as what it yields, one through a resolver the project does not
    allow is refused). The files it names are read by the checks given (``init_policy_problem(path,
    cfg)``, ``checkpoint_problem(run_dir)``: why the file is not usable, or None;
    :mod:`billiards.rl.validation` gives them), else only their presence is checked."""
    cfg, errs = resolved_config(cfg)
    if errs:
        return errs
    errs = numeric_bound_errors(cfg) + appended_keys(cfg) + upper_bound_errors(cfg, "", TrainConfig.UPPER)
    a, e = cfg.algo, cfg.env
    for key, schema in (("budget", BudgetConfig), ("env", EnvConfig), ("eval", EvalConfig), ("shaping", ShapingConfig),
                        ("curriculum", CurriculumConfig), ("logger", LoggerConfig)):
        errs += schema.errors(cfg[key])
    errs += physics_errors(cfg.physics) + noise_errors(cfg.noise)
    if a.name in ALGO_SCHEMAS:
        errs += ALGO_SCHEMAS[a.name].errors(a)
    else:
        errs.append(f"algo.name must be one of {', '.join(ALGO_SCHEMAS)}, got {a.name!r}")
    if a.name in ALGO_SCHEMAS:  # across nodes: a collector batch is whole steps of every inning
        fpb = (a.frames_per_batch or e.num_envs) if a.name in OFF_POLICY else a.frames_per_batch
        errs += _need(e.num_envs <= 0 or fpb % e.num_envs == 0,
                      f"algo.frames_per_batch ({fpb}) must be a multiple of env.num_envs ({e.num_envs})")
    if a.name == EXIT:  # the labels are aim-constrained shots of search.py's search for the noise
        errs += _need(bool(e.constrain_aim), "algo=exit learns aim-constrained shots: it needs env.constrain_aim=true "
                                             "(env=aim or env=aim_features)")
        if not noise_errors(cfg.noise):
            from billiards.physics.noise import noise_from_config

            noise = noise_from_config(cfg.noise)
            errs += _need(not noise.is_variable,
                          "algo=exit under variable noise is not built: its policy does not see the shot's noise level "
                          "(noise=none, fastfiz or fastfiz_x5)")
            errs += _need(not noise.is_exact or not a.label_tolerance,
                          "algo.label_tolerance picks among the noisy search's candidates: under exact play the label is "
                          "already the best-valued shot nearest the policy's own (set algo.label_tolerance=0)")
            errs += _need(noise.is_exact or not a.centre_probes,
                          "algo.centre_probes centres exact play's labels: under noise the label is the noisy "
                          "search's choice (set algo.centre_probes=0)")
        if a.init_policy is not None and init_policy_problem is not None and not physics_errors(cfg.physics):
            errs += [f"algo.init_policy: {why}"] if (why := init_policy_problem(a.init_policy, cfg)) else []
    if a.name in ALGO_CHECKS and not errs:
        errs += ALGO_CHECKS[a.name](cfg)
    if cfg.curriculum.name != "none" and a.name not in OFF_POLICY:
        errs.append(f"curriculum={cfg.curriculum.name} needs an off-policy algorithm ({', '.join(OFF_POLICY)}), got algo={a.name}")
    # seed: random.seed, np.random.seed (which takes [0, 2**32)) and torch
    errs += _need(0 <= cfg.seed < 2**32, f"seed must be an integer in [0, 2**32 - 1] (a numpy seed), got {cfg.seed!r}")
    errs += list(filter(None, [threads_error(cfg.threads), device_error(cfg.device)])) + _positive("paper_steps", cfg.paper_steps)
    if cfg.resume and cfg.resume != RESUME_AUTO:
        run_dir = Path(cfg.resume)
        if not run_dir.is_dir():
            errs.append(f"resume={cfg.resume!r}: no such run directory")
        elif not (run_dir / CHECKPOINT_FILE).is_file():
            errs.append(
                f"resume={cfg.resume!r}: the run directory has no {CHECKPOINT_FILE} "
                f"(a run writes its first checkpoint after budget.checkpoint_every steps); start a new run instead"
            )
        elif (run_dir / CHECKPOINT_FILE).stat().st_size == 0:
            errs.append(f"resume={cfg.resume!r}: {run_dir / CHECKPOINT_FILE} is empty (corrupt); start a new run instead")
        elif checkpoint_problem is not None and (why := checkpoint_problem(run_dir)):  # loaded and checked now
            errs.append(f"resume={cfg.resume!r}: {why}")
    return errs


def resolve_rm_model(path: str) -> Path:
    """A reward-model path as given if it exists (or is absolute), else relative to the repo."""
    return repo_path(path)


def env_paradigm(paradigm: Paradigm | str) -> str:
    """A paradigm as :func:`billiards.envs.make_env` takes it: the one spelling, ``random_continue``."""
    return Paradigm(paradigm).value


def env_options(cfg: DictConfig):
    """What a training config means for its env, as one :class:`billiards.envs.EnvOptions`
    (``make_env(cfg.env.num_envs, env_options(cfg), seed=s)``): the env node, the shaping (the
    reward model's path resolved), the table and the execution noise."""
    from billiards.envs import EnvOptions
    from billiards.physics.config import params_from_config
    from billiards.physics.noise import noise_from_config

    sh = cfg.shaping
    shaping = {f.name: sh[f.name] for f in dataclasses.fields(ShapingOptions)}  # every key of the one schema
    shaping["rm_model"] = str(resolve_rm_model(sh.rm_model)) if sh.rm else None
    return EnvOptions(paradigm=env_paradigm(cfg.env.paradigm), max_shots=cfg.env.max_shots, constrain_aim=cfg.env.constrain_aim,
                      extra_features=cfg.env.extra_features, **shaping,
                      params=params_from_config(cfg.physics), noise=noise_from_config(cfg.noise))


def wandb_env_defaults() -> None:
    """wandb must never prompt: silent, no login, offline unless a run asks for online."""
    os.environ.setdefault("WANDB_SILENT", "true")
    os.environ.setdefault("WANDB_CONSOLE", "off")
    os.environ.setdefault("WANDB_DISABLE_GIT", "true")
