"""Two-player matches and leagues (``python match.py``; docs/matches.md): the players
(:mod:`.agents`), matches, the league and its Elo table (:mod:`.play`), the app's schema
(:mod:`.config`) and the app itself (:func:`run`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

RUNTIME_KEYS = ("threads", "progress", "picture", "resume")  # how a league runs, not what it finds


def run(cfg, out_dir) -> dict:
    """Play the league ``cfg`` describes into ``out_dir`` (or continue it there)."""
    from omegaconf import OmegaConf

    from billiards.device import set_threads
    from billiards.files import LedgerError, display_path, recorded_command, run_identity
    from billiards.physics.config import params_from_config
    from billiards.physics.noise import noise_from_config, noise_record
    from billiards.provenance import git_commit

    from .agents import make_agent
    from .config import MatchAppConfig, agent_config, validate
    from .play import animate_match, play_match, run_league

    started = cfg
    if cfg.resume:  # the league's own settings, this command line's runtime keys
        started = saved = OmegaConf.load(Path(cfg.resume) / ".hydra" / "config.yaml")
        for key in RUNTIME_KEYS:
            saved[key] = cfg[key]
        cfg = OmegaConf.merge(OmegaConf.structured(MatchAppConfig), saved)
    validate(cfg)
    # the run identity every match record carries: the league's settings as it started (its
    # players' own, not every agent the config knows), less the runtime keys
    settings = OmegaConf.to_container(started, resolve=True)
    settings["agents"] = {name: settings["agents"][name] for name in settings["players"]}
    run_id = run_identity(settings, runtime=RUNTIME_KEYS)
    set_threads(cfg.threads)
    out_dir = Path(cfg.resume or out_dir)
    params, noise = params_from_config(cfg.physics), noise_from_config(cfg.noise)
    agents = {name: agent_config(cfg.agents[name], name) for name in cfg.players}
    players = {name: make_agent(agents[name], noise, params) for name in cfg.players}
    # the league's command: this one, or, continuing a league, the one that started it
    if cfg.resume:
        overrides = list(OmegaConf.load(out_dir / ".hydra" / "overrides.yaml"))
    else:
        from hydra.core.hydra_config import HydraConfig

        overrides = list(HydraConfig.get().overrides.task) if HydraConfig.initialized() else []
    command = ["python", "match.py", *overrides, f"hydra.run.dir={display_path(out_dir)}"]
    record = {"command": " ".join(recorded_command(command)), "commit": git_commit(),
              **noise_record(noise), "physics": params.describe(), "target": cfg.target, "start": cfg.start,
              "foul_penalty": cfg.foul_penalty, "max_innings": cfg.max_innings, "matches_per_ordered_pair": cfg.matches,
              "seed": cfg.seed, "agents": {n: dataclasses.asdict(a) for n, a in agents.items()}}
    print(f"league of {', '.join(cfg.players)}: {cfg.matches} matches per ordered pair to {cfg.target} points, "
          f"noise {noise.describe()}; output: {display_path(out_dir)}", flush=True)
    try:
        league = run_league(players, out_dir=out_dir, matches=cfg.matches, seed=cfg.seed, noise_name=noise.describe(),
                            record=record, progress=cfg.progress, target=cfg.target, max_innings=cfg.max_innings,
                            start=cfg.start, foul_penalty=cfg.foul_penalty, noise=noise, physics=params, run=run_id)
    except LedgerError as err:
        raise SystemExit(f"Error: cannot continue the league: {err}; a league continues only a ledger it wrote, "
                         f"sealed (move {display_path(out_dir / 'matches.jsonl')} aside to play every match again)") from None
    for p in league["pairs"]:
        print(f"{p['a']} vs {p['b']}: {p['a_wins']}-{p['b_wins']} ({p['draws']} draws) of {p['matches']}, "
              f"{p['a']}'s score rate {p['a_score_rate']:.3f} [{p['ci95'][0]:.3f}, {p['ci95'][1]:.3f}]", flush=True)
    print("Elo: " + ", ".join(f"{n} {r:.0f}" for n, r in sorted(league["elo"].items(), key=lambda x: -x[1])), flush=True)
    if cfg.picture:  # the league's first match again, shot by shot (the same seed: the same match)
        a, b = cfg.players[0], cfg.players[1]
        frames: list = []
        play_match(players[a], players[b], seed=cfg.seed, first="white", frames=frames, target=cfg.target,
                   max_innings=cfg.max_innings, start=cfg.start, foul_penalty=cfg.foul_penalty, noise=noise, physics=params)
        captions = [f"W {a} {w:g} : Y {b} {y:g} | {mover} plays" for _, (w, y, mover) in frames]
        gif = animate_match([f for f, _ in frames], captions, out_dir / "match.gif")
        print(f"the first match, shot by shot: {display_path(gif)}", flush=True)
    return league
