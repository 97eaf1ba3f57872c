"""``python search.py``: build the proposer and the search actor from a config, run a protocol,
write ``results.json`` (and a picture of the longest chain's last shots) into the run dir."""

from __future__ import annotations

import json
from pathlib import Path

import numba
from omegaconf import OmegaConf

from billiards.physics import DEFAULT_PARAMS, PhysicsParams
from billiards.physics.config import params_from_config
from billiards.provenance import ROOT, git_commit

from .actors import LookaheadActor, PUCTActor, SearchActor
from .config import validate
from .lookahead import H2Config
from .proposers import GeometricProposer
from .protocols import ProtocolResult, run_p1, run_p3
from .puct import PUCTConfig

RESULTS_FILE = "results.json"


def make_proposer(cfg, params: PhysicsParams = DEFAULT_PARAMS):
    """The proposer a ``proposer`` config node describes, for the table ``params``."""
    if cfg.kind == "geometric":
        return GeometricProposer(power_low=cfg.power_low, power_high=cfg.power_high, R=params.ball_radius)
    from billiards.rl.policy import load_policy_proposer

    paths = [p if Path(p).is_absolute() else str(ROOT / p) for p in cfg.checkpoints]
    return load_policy_proposer(paths, name=cfg.name, params=params)


def make_actor(cfg, proposer, params: PhysicsParams = DEFAULT_PARAMS) -> SearchActor:
    s = cfg.search
    if s.kind == "h2":
        h2 = H2Config.from_budget(s.budget, s.k1, s.m1, gamma=s.gamma, foul_penalty=s.foul_penalty)
        return LookaheadActor(proposer, h2, seed=cfg.seed, params=params)
    puct = PUCTConfig(budget=s.budget, c_puct=s.c_puct, pw_c=s.pw_c, pw_alpha=s.pw_alpha, pool=s.pool,
                      max_depth=s.max_depth, gamma=s.gamma, foul_penalty=s.foul_penalty)
    return PUCTActor(proposer, puct, seed=cfg.seed, params=params)


def run(cfg, out_dir: str | Path) -> ProtocolResult:
    validate(cfg)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if cfg.threads is not None:
        numba.set_num_threads(cfg.threads)
    params = params_from_config(cfg.physics)
    actor = make_actor(cfg, make_proposer(cfg.proposer, params), params)
    proto = cfg.protocol.name
    if proto == "p1":
        result = run_p1(actor, cfg.protocol.n_innings, cfg.protocol.shots, seed=cfg.seed, params=params, progress=cfg.progress)
    else:
        seeds = range(cfg.seed, cfg.seed + cfg.protocol.seeds)
        picture = out_dir / "longest_chain.png" if cfg.picture else None
        result = run_p3(actor, seeds, cfg.protocol.cap, params=params, progress=cfg.progress, picture=picture)
    summary = json.loads(result.to_json())
    summary.update(
        proposer=cfg.proposer.name,
        search=cfg.search.kind,
        physics=params.describe(),
        physics_params=params.to_dict(),
        config=OmegaConf.to_container(cfg, resolve=True),
        commit=git_commit(),
    )
    (out_dir / RESULTS_FILE).write_text(json.dumps(summary, indent=2) + "\n")
    print(f"{proto} {summary['search']} proposer={cfg.proposer.name}: mean {result.mean:.2f} ± {result.std:.2f}, "
          f"max {result.max:.0f}, {result.ms_per_decision:.1f} ms/shot, {result.sims_per_decision:.0f} sims/shot -> {out_dir}")
    return result
