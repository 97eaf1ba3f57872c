"""Search configuration schema (``conf/search.yaml``), registered in Hydra's ConfigStore.

Typed, closed nodes: an unknown key, a wrong type or an enum value outside its set fails while
Hydra composes; :func:`validate` checks the rest (budget split, sizes) before anything runs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional

from hydra.core.config_store import ConfigStore
from hydra.experimental.callback import Callback
from omegaconf import OmegaConf

from billiards.physics.config import PhysicsConfig, physics_errors
from billiards.physics.noise import NoiseConfig, noise_errors, noise_from_config


SEARCH_KINDS = ("h2", "puct", "robust")
PROPOSER_KINDS = ("geometric", "policy")
PROTOCOLS = ("p1", "p3")


@dataclass
class ProposerConfig:
    """``geometric`` needs no training; ``policy`` loads an ensemble of training checkpoints
    (paths relative to the repository root, or absolute)."""

    name: str = "geometric"
    kind: str = "geometric"  # geometric | policy
    checkpoints: List[str] = field(default_factory=list)
    power_low: float = 0.15
    power_high: float = 0.9
    # geometric only: narrower draws for forgiving shots under noise (defaults: the full ranges)
    u_low: float = 0.0  # |u| >= u_low (u: where in the aim cone; 0 full hit, 1 graze)
    u_high: float = 1.0
    spin_low: float = -1.0  # vertical tip offset b in [spin_low, spin_high] (-1 draw, 1 follow)
    spin_high: float = 1.0
    command: Optional[str] = None  # how the checkpoints were trained (documentation)


@dataclass
class SearchConfig:
    """h2: ``budget`` = k1 + m1 * k2 simulations per decision, k2 derived. puct: ``budget``
    simulations per decision with progressive widening (pw_c, pw_alpha) over ``pool`` samples."""

    kind: str = "h2"  # h2 | puct
    budget: int = 400
    k1: int = 200
    m1: int = 10
    gamma: float = 0.99
    foul_penalty: float = 1.0
    c_puct: float = 1.0
    pw_c: float = 1.0
    pw_alpha: float = 0.5
    pool: int = 16
    max_depth: int = 8
    # --- noise-aware search (kind=robust; billiards/search/robust.py): budget = [k1 screen] + noisy samples + m1 * k2
    samples: int = 4  # schedule=uniform: noisy samples per candidate (k1 * samples + m1 * k2 = budget)
    schedule: str = "halving"  # uniform | halving (successive halving over the candidates left)
    screen: bool = True  # one exact simulation per candidate first; only scoring ones get noisy samples
    quantile: Optional[float] = None  # the candidate's statistic over its samples: null = mean, else this quantile
    k2: int = 0  # robust: children per expanded candidate (h2 derives its k2 from the budget)
    target: int = 0  # robust: adaptive screen, stop screening a state once `target` candidates score (0: screen all k1)
    wave: int = 50  # robust: candidates per screening wave when target > 0
    antithetic: bool = False  # robust: noisy samples in antithetic pairs (z, -z)


@dataclass
class ProtocolConfig:
    """p1: ``n_innings`` random-start innings of ``shots`` shots. p3: ``seeds`` canonical-start
    chains capped at ``cap`` shots."""

    name: str = "p3"  # p1 | p3
    n_innings: int = 100
    shots: int = 100
    seeds: int = 10
    cap: int = 10000


@dataclass
class Config:
    proposer: ProposerConfig = field(default_factory=ProposerConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)  # the table: physics=korean_medium|international
    search: SearchConfig = field(default_factory=SearchConfig)
    protocol: ProtocolConfig = field(default_factory=ProtocolConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)  # execution noise: noise=none|fastfiz|fastfiz_x5
    seed: int = 0
    threads: Optional[int] = None  # numba threads for simulate_batch (default: all cores)
    progress: bool = True
    picture: bool = True
    resume: Optional[str] = None  # a stopped search's run dir: continue it (P3: from its next chain)


def validate(cfg) -> None:
    """Checks a type cannot express; raises ValueError with the offending key."""
    s, p = cfg.search, cfg.protocol
    for key, value, allowed in (("search.kind", s.kind, SEARCH_KINDS), ("proposer.kind", cfg.proposer.kind, PROPOSER_KINDS),
                                ("protocol.name", p.name, PROTOCOLS)):
        if value not in allowed:
            raise ValueError(f"{key} must be one of {', '.join(allowed)}; got {value!r}")
    if s.budget < 1:
        raise ValueError(f"search.budget must be >= 1, got {s.budget}")
    if cfg.seed < 0:
        raise ValueError(f"seed must be >= 0 (a numpy seed), got {cfg.seed}")
    try:
        if s.kind == "h2":
            from .lookahead import H2Config

            H2Config.from_budget(s.budget, s.k1, s.m1, gamma=s.gamma, foul_penalty=s.foul_penalty)
        elif s.kind == "robust":
            robust_config(s)
        else:
            from .puct import PUCTConfig

            PUCTConfig(budget=s.budget, c_puct=s.c_puct, pw_c=s.pw_c, pw_alpha=s.pw_alpha, pool=s.pool,
                       max_depth=s.max_depth, gamma=s.gamma, foul_penalty=s.foul_penalty)
    except ValueError as err:
        raise ValueError(f"search ({s.kind}): {err}") from None
    pr = cfg.proposer
    if not 0.0 <= pr.power_low <= pr.power_high <= 1.0:
        raise ValueError(f"proposer.power_low and proposer.power_high must satisfy 0 <= low <= high <= 1, "
                         f"got {pr.power_low}, {pr.power_high}")
    u_low, u_high = pr.get("u_low", 0.0), pr.get("u_high", 1.0)  # absent from configs saved before they existed
    spin_low, spin_high = pr.get("spin_low", -1.0), pr.get("spin_high", 1.0)
    if not 0.0 <= u_low <= u_high <= 1.0:
        raise ValueError(f"proposer.u_low and proposer.u_high must satisfy 0 <= low <= high <= 1, got {u_low}, {u_high}")
    if not -1.0 <= spin_low <= spin_high <= 1.0:
        raise ValueError(f"proposer.spin_low and proposer.spin_high must satisfy -1 <= low <= high <= 1, "
                         f"got {spin_low}, {spin_high}")
    for key in ("n_innings", "shots", "seeds", "cap"):
        if getattr(p, key) < 1:
            raise ValueError(f"protocol.{key} must be >= 1, got {getattr(p, key)}")
    if cfg.proposer.kind == "policy" and not cfg.proposer.checkpoints:
        raise ValueError(f"proposer {cfg.proposer.name!r} is a policy ensemble but lists no checkpoints")
    if cfg.proposer.kind == "policy":
        from pathlib import Path

        from billiards.provenance import ROOT

        missing = [c for c in cfg.proposer.checkpoints if not (Path(c) if Path(c).is_absolute() else ROOT / c).exists()]
        if missing:
            how = f" (trained with: {cfg.proposer.command})" if cfg.proposer.command else ""
            raise ValueError(f"proposer {cfg.proposer.name!r}: no checkpoint at {', '.join(missing)}{how}")
    if cfg.threads is not None and cfg.threads < 1:
        raise ValueError(f"threads must be >= 1, got {cfg.threads}")
    if cfg.get("resume"):
        from pathlib import Path

        if not (Path(cfg.resume) / "config.yaml").is_file():
            raise ValueError(f"resume={cfg.resume!r}: not a search run directory (no config.yaml there)")
    noise = cfg.get("noise")  # absent from configs saved before it existed (exact play)
    errs = physics_errors(cfg.physics) + (noise_errors(noise) if noise is not None else [])
    if errs:
        raise ValueError(errs[0])
    if s.kind == "robust" and noise_from_config(noise).is_exact:
        raise ValueError("search=robust scores candidates over noisy replays: it needs execution noise "
                         "(noise=fastfiz|fastfiz_x5 or noise.aim_deg=...); without noise use search=h2")


def robust_config(s):
    """The RobustConfig of a ``search`` node of kind robust."""
    from .robust import RobustConfig

    return RobustConfig(budget=s.budget, k1=s.k1, samples=s.samples, schedule=s.schedule, screen=s.screen,
                        quantile=s.quantile, m1=s.m1, k2=s.k2, target=s.target, wave=s.wave, antithetic=s.antithetic,
                        gamma=s.gamma, foul_penalty=s.foul_penalty)


def _or(value, default: str) -> str:
    """``${billiards.or:${resume},outputs/...}``: the value unless it is null or empty."""
    return str(value) if value else default


def register() -> None:
    OmegaConf.register_new_resolver("billiards.or", _or, replace=True)
    # a resume keeps the original .hydra and records its own beside it
    OmegaConf.register_new_resolver("billiards.output_subdir", lambda r: ".hydra_resume" if r else ".hydra", replace=True)
    cs = ConfigStore.instance()
    cs.store(name="search_schema", node=Config)
    cs.store(group="proposer", name="proposer_schema", node=ProposerConfig)
    cs.store(group="search", name="search_schema", node=SearchConfig)
    cs.store(group="protocol", name="protocol_schema", node=ProtocolConfig)
    cs.store(group="schema", name="physics", node=PhysicsConfig)  # conf/physics/*.yaml, shared with train.py
    cs.store(group="schema", name="noise", node=NoiseConfig)  # conf/noise/*.yaml, shared with train.py


class ValidateSearchConfig(Callback):
    """Hydra callback (``hydra.callbacks`` in conf/search.yaml): validates before Hydra creates
    the run directory, so a bad command line fails at once and writes nothing."""

    def on_run_start(self, config, **kwargs) -> None:
        try:
            validate(config)
        except ValueError as err:
            raise SystemExit(f"Error: {err}") from None

    def on_multirun_start(self, config, **kwargs) -> None:
        self.on_run_start(config)
