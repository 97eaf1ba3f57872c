"""Two-player matches and leagues (``python match.py``; docs/matches.md): the players
(:mod:`.players`), matches, the league and its Elo table (:mod:`.play`), the app's schema
(:mod:`.config`) and the app itself (:func:`run`)."""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path

def league_settings(cfg):
    """``(config, settings as started, the starting command's overrides)`` of the league ``cfg``
    asks for: with ``resume=<dir>`` the league's own settings -- what Hydra saved in
    ``<dir>/.hydra/`` when it started -- with this command line's runtime keys (ValueError naming
    the file if they cannot be read); else ``cfg`` itself (overrides None: this invocation's)."""
    from omegaconf import DictConfig, ListConfig, OmegaConf

    from billiards.files import display_path, read_run_text

    from .config import MatchAppConfig

    if not cfg.resume:
        return cfg, cfg, None
    run_dir = Path(cfg.resume)
    path = run_dir / ".hydra" / "config.yaml"
    try:  # read as a run folder's files are (billiards.files.read_run_text: no link, no FIFO, bounded)
        saved = OmegaConf.load(io.StringIO(read_run_text(path, "config", within=run_dir)))
        if not isinstance(saved, DictConfig):
            raise ValueError("not a mapping")
        for key in MatchAppConfig.RUNTIME:  # the league's own settings, this command line's runtime keys
            saved[key] = cfg[key]
        merged = OmegaConf.merge(OmegaConf.structured(MatchAppConfig), saved)
        path = path.with_name("overrides.yaml")
        overrides = OmegaConf.load(io.StringIO(read_run_text(path, "config", within=run_dir)))
        if not isinstance(overrides, ListConfig):
            raise ValueError("not a list")
    except Exception as err:  # missing, refused, not YAML (nested past the stack too), not a league's settings
        first = "nested too deep" if isinstance(err, RecursionError) else (str(err).strip().splitlines() or [type(err).__name__])[0]
        raise ValueError(f"{display_path(path)} cannot be read as a league's record ({first}); a league continues "
                         f"with the settings Hydra saved there when it started") from None
    return merged, saved, [str(o) for o in overrides]


def league_run_identity(started) -> str:
    """The identity every match record of a league carries: a hash of its settings as it
    started (its players' own agents, not every agent the config knows), less the runtime keys."""
    from omegaconf import OmegaConf

    from billiards.files import run_identity

    from .config import MatchAppConfig

    settings = OmegaConf.to_container(started, resolve=True)
    settings["agents"] = {name: settings["agents"][name] for name in settings["players"]}
    return run_identity(settings, runtime=MatchAppConfig.RUNTIME)


def resume_state(run_dir: Path, config, finished: bool) -> str | None:
    """The directory check's look at the league in ``run_dir`` before a resume
    (:class:`billiards.app_config.RunKind`): its saved settings must load (ValueError naming the
    file otherwise); with ``finished``, the line a resume says when every match of the league is
    in its ledger, none torn, and ``league.json`` holds the tables those matches give
    (:func:`billiards.files.stale_summary`: an edited one is written again), else None."""
    from omegaconf import OmegaConf

    from billiards.app_config import RESUME_AUTO
    from billiards.files import LEAGUE_FILE, MATCHES, MATCHES_FILE, display_path, read_ledger, stale_summary

    run_dir = Path(run_dir)
    if config.get("resume") == RESUME_AUTO and not (run_dir / MATCHES_FILE).is_file():
        return None  # resume=auto starts it afresh
    probe = OmegaConf.masked_copy(config, [k for k in config if k != "hydra"])
    probe.resume = str(run_dir)
    cfg, started, _ = league_settings(probe)
    if not finished or not (run_dir / LEAGUE_FILE).is_file():
        return None
    try:
        scan = read_ledger(run_dir / MATCHES_FILE, MATCHES, league_run_identity(started))
        names, matches = list(cfg.players), int(cfg.matches)
    except Exception:  # a ledger or settings the resume refuses, naming the problem
        return None
    have = {(r["a"], r["b"], r["i"]) for r in scan.records}
    todo = [(a, b, i) for a in names for b in names if a != b for i in range(matches) if (a, b, i) not in have]
    if scan.torn is not None or todo or stale_summary(run_dir, MATCHES, scan.records) is not None:
        return None  # a league.json its matches do not give (edited) is not finished: the resume writes it again
    return f"{display_path(run_dir)} is finished ({len(have)} matches, {LEAGUE_FILE}): nothing to do"


def run(cfg, out_dir) -> dict:
    """Play the league ``cfg`` describes into ``out_dir`` (or continue it there: ``resume=<dir>``,
    or ``resume=auto`` for a league an earlier attempt of this job started in ``out_dir``)."""
    from billiards.app_config import RESUME_AUTO
    from billiards.device import set_threads
    from billiards.files import MATCHES_FILE, LedgerError, RunLockedError, display_path, recorded_command
    from billiards.physics.config import params_from_config
    from billiards.physics.noise import noise_from_config, noise_record
    from billiards.provenance import git_commit

    from .players import make_agent, player_config
    from .config import validate
    from .play import animate_match, play_match, run_league

    if cfg.resume == RESUME_AUTO:  # this job's own directory: the league an earlier attempt started there, or a new one
        cfg.resume = str(out_dir) if (Path(out_dir) / MATCHES_FILE).is_file() else None
    try:
        cfg, started, started_overrides = league_settings(cfg)
    except ValueError as err:
        raise SystemExit(f"Error: resume={cfg.resume}: {err}") from None
    validate(cfg)
    run_id = league_run_identity(started)
    set_threads(cfg.threads)
    out_dir = Path(cfg.resume or out_dir)
    params, noise = params_from_config(cfg.physics), noise_from_config(cfg.noise)
    agents = {name: player_config(cfg.agents[name], name) for name in cfg.players}
    players = {name: make_agent(agents[name], noise, params) for name in cfg.players}
    # the league's command: this one, or, continuing a league, the one that started it
    if started_overrides is not None:
        overrides = started_overrides
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
    except RunLockedError as err:
        raise SystemExit(f"Error: {err}") from None
    except LedgerError as err:
        raise SystemExit(f"Error: cannot continue the league: {err}; a league continues only a ledger it wrote, "
                         f"sealed (move {display_path(out_dir / 'matches.jsonl')} aside to play every match again)") from None
    for p in league["pairs"]:
        print(f"{p['a']} vs {p['b']}: {p['a_wins']}-{p['b_wins']} ({p['draws']} draws) of {p['matches']}, "
              f"{p['a']}'s score rate {p['a_score_rate']:.3f} [{p['ci95'][0]:.3f}, {p['ci95'][1]:.3f}]", flush=True)
    ci = league["elo_ci95"]
    print("Elo [95 %]: " + ", ".join(f"{n} {r:.0f} [{ci[n][0]:.0f}, {ci[n][1]:.0f}]"
                                      for n, r in sorted(league["elo"].items(), key=lambda x: -x[1])), flush=True)
    if cfg.picture:  # the league's first match again, shot by shot (the same seed: the same match)
        a, b = cfg.players[0], cfg.players[1]
        frames: list = []
        play_match(players[a], players[b], seed=cfg.seed, first="white", frames=frames, target=cfg.target,
                   max_innings=cfg.max_innings, start=cfg.start, foul_penalty=cfg.foul_penalty, noise=noise, physics=params)
        captions = [f"W {a} {w:g} : Y {b} {y:g} | {mover} plays" for _, (w, y, mover) in frames]
        gif = animate_match([f for f, _ in frames], captions, out_dir / "match.gif")
        print(f"the first match, shot by shot: {display_path(gif)}", flush=True)
    return league
