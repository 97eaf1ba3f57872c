"""``python search.py``: build the proposer and the search actor from a config, run a protocol,
write ``results.json`` (and a picture of the longest chain's last shots) into the run dir.

The config's option nodes build what they describe (:mod:`billiards.search.config`): a
proposer node ``.build(params)``; a search node's settings make their actor through
:func:`billiards.search.actors.build_actor`."""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

from omegaconf import OmegaConf

from billiards.app_config import RESUME_AUTO
from billiards.device import resolve_device, set_threads
from billiards.files import (CHAINS, CONFIG_FILE, RESULTS_FILE, LedgerError, RunFileError, RunLockedError, atomic_write_text,
                             display_path, read_ledger, read_run_bytes, read_run_json, read_run_text, run_identity, run_lock, stale_summary)
from billiards.physics import DEFAULT_PARAMS, PhysicsParams
from billiards.physics.config import params_from_config, physics_record
from billiards.physics.noise import noise_from_config, noise_record
from billiards.physics.warmup import warm_up
from billiards.provenance import git_commit
from billiards.protocol import Protocol, find_protocol

from .actors import SearchActor, build_actor
from .config import SearchAppConfig, option, saved_config, typed, validate
from .protocols import CHAINS_FILE, ProtocolResult, partial_p3, run_p1, run_p3
from .ranker import noise_mismatch

__all__ = ["CONFIG_FILE", "RESULTS_FILE", "describe", "make_actor", "make_proposer", "resume_config", "resume_state", "run",
           "search_identity"]


def make_proposer(cfg, params: PhysicsParams = DEFAULT_PARAMS, device=None):
    """The proposer a ``proposer`` config node describes, for the table ``params``; a policy
    ensemble's networks on ``device`` (a :class:`torch.device`, default the CPU)."""
    return option("proposer", cfg).build(params, device=device)


def make_actor(cfg, proposer, params: PhysicsParams = DEFAULT_PARAMS, noise=None) -> SearchActor:
    """The search actor ``cfg.search`` describes, seeded with ``cfg.seed``, over ``proposer``,
    for the execution noise ``noise`` (a NoiseModel the caller built; default: ``cfg.noise``'s)
    -- under noise PUCT's revisits are noisy replays (:mod:`billiards.search.puct_noise`) and
    ``robust`` samples the noise model."""
    noise = noise_from_config(cfg.noise) if noise is None else noise  # the caller's, where it has built it
    return build_actor(option("search", cfg.search), proposer, cfg.seed, params, noise=noise)


RUNTIME_KEYS = SearchAppConfig.RUNTIME  # taken from the command line when resuming


def search_identity(out_dir: Path) -> str:
    """The run identity of the search in ``out_dir`` (every chain record of its ledger carries
    it): a hash of its ``config.yaml`` as written when it started -- the resolved config -- less
    the runtime keys and ``resume``. Read from the file both when the run starts and when it is
    resumed, so the identity does not depend on how today's code would fill in that config."""
    saved = OmegaConf.to_container(_load_config(out_dir), resolve=True)
    if not isinstance(saved, dict):
        raise SystemExit(f"Error: {display_path(out_dir / CONFIG_FILE)} is not a search config")
    return run_identity(saved, runtime=(*RUNTIME_KEYS, "resume"))


def _load_config(out_dir: Path):
    """The search run's ``config.yaml`` as OmegaConf loads it, read as a run folder's files are
    (:func:`billiards.files.read_run_text`: no link, no FIFO, bounded; RunFileError otherwise)."""
    path = Path(out_dir) / CONFIG_FILE
    text = read_run_text(path, "config")
    try:
        return OmegaConf.load(io.StringIO(text))
    except RecursionError:
        raise RunFileError(f"{display_path(path)} is not a search config: it nests too deep") from None


def _saved_config(out_dir: Path):
    """:func:`billiards.search.config.saved_config`, its file looked at first by the run-folder
    reader (a link, a FIFO, a file past its bound: RunFileError, never opened by YAML)."""
    if os.path.lexists(Path(out_dir) / CONFIG_FILE):  # a missing one: saved_config says so
        read_run_text(Path(out_dir) / CONFIG_FILE, "config")
    return saved_config(out_dir)


def describe(cfg, params, noise) -> str:
    """What a search run will do, in one line (printed before it starts)."""
    s, p = cfg.search, cfg.protocol
    what = (f"P1: {p.n_innings} random-start innings x {p.shots} shots" if Protocol(p.name) is Protocol.P1
            else f"P3: {p.seeds} chains from the opening rack, each up to {p.cap:,} shots")
    return (f"{what}; {s.kind} search, {s.budget} simulations per shot, proposer {cfg.proposer.name}, physics {params.describe()}"
            f", noise {noise.describe()}")


def resume_config(out_dir: Path, current):
    """A stopped search's own config (in whatever form it was saved), with this command line's
    runtime keys."""
    saved = _saved_config(out_dir)
    for key in RUNTIME_KEYS:
        saved[key] = current[key]
    saved.resume = str(out_dir)
    return saved


def finished_run(out_dir: Path) -> dict | None:
    """The ``results.json`` of a search that finished in ``out_dir`` (not a partial one), or
    None. A P3's must be what its ledger gives (:func:`billiards.files.stale_summary`: every
    chain, its values, mean and spread): one its chains do not give (edited) is not finished,
    and its resume writes it again from the ledger."""
    out_dir = Path(out_dir)
    try:
        res = read_run_json(out_dir / RESULTS_FILE, "summary")
    except (OSError, ValueError):
        return None
    extra = res.get("extra") if isinstance(res, dict) else None
    if not isinstance(res, dict) or (isinstance(extra, dict) and extra.get("partial")):
        return None
    if find_protocol(res.get("protocol")) is Protocol.P3 or (out_dir / CHAINS_FILE).exists():
        try:
            records = read_ledger(out_dir / CHAINS_FILE, CHAINS, search_identity(out_dir)).records
        except (LedgerError, SystemExit, ValueError, OSError):  # the resume refuses it, naming the line
            return None
        if stale_summary(out_dir, CHAINS, records) is not None:
            return None
    return res


def resume_state(out_dir: Path, config, finished: bool) -> str | None:
    """The directory check's look at the search in ``out_dir`` before a resume
    (:class:`billiards.app_config.RunKind`): its saved config must load (ValueError naming it
    otherwise); with ``finished``, the line a resume says when nothing is left to play there --
    ``results.json`` final and, for a P3, every chain in its ledger, none torn, and
    ``results.json`` what those chains give (:func:`finished_run`) -- else None."""
    out_dir = Path(out_dir)
    if not os.path.lexists(out_dir / CONFIG_FILE):
        return None  # nothing to continue: validate refuses resume=<dir>, resume=auto starts afresh
    try:
        saved = _saved_config(out_dir)
    except ValueError:
        raise
    except Exception as err:  # a config.yaml that is not YAML, cannot be read, ...
        first = (str(err).strip().splitlines() or [type(err).__name__])[0]
        raise ValueError(f"{display_path(out_dir / CONFIG_FILE)} cannot be read as a search config ({first})") from None
    done = finished_run(out_dir) if finished else None
    if done is None:
        return None
    if Protocol(saved.protocol.name) is Protocol.P3:
        try:
            scan = read_ledger(out_dir / CHAINS_FILE, CHAINS, search_identity(out_dir))
        except (LedgerError, SystemExit, ValueError, OSError):  # the resume refuses it, naming the line
            return None
        if scan.torn is not None or len(scan.records) < saved.protocol.seeds:
            return None
    mean = done.get("mean")
    return (f"{display_path(out_dir)} is finished" + (f" (mean {mean:.2f})" if isinstance(mean, (int, float)) else "")
            + ": nothing to do")


def run(cfg, out_dir: str | Path) -> ProtocolResult | None:
    """Run the configured protocol into ``out_dir``: ``config.yaml`` at start, each finished P3
    chain in ``chains.jsonl`` as it ends, ``results.json`` at the end. Ctrl-C writes
    ``results.json`` from what finished, marked ``partial``; ``resume=<out_dir>`` continues a
    stopped P3 from its next chain. ``resume=auto``: a search finished in ``out_dir`` is left
    as it is (None is returned), a stopped P3 there continues, anything else starts fresh.

    Every chain record carries the run's identity (:func:`search_identity`) and a seal; a resume
    refuses a ledger line that is unsealed, edited,
    of another run or a repeated seed, and cuts a torn last line off (its chain is played again).
    ``results.json`` is always written from the ledger's chains (a finished run's that they do
    not give is not finished: :func:`finished_run`). The run holds ``out_dir``'s lock while it
    writes there (:func:`billiards.files.run_lock`): a second search started on the folder
    meanwhile is refused at once, naming this one."""
    commit = git_commit()  # the code that runs (read before anything runs: files may change meanwhile)
    out_dir = Path(out_dir)
    cfg = typed(cfg)
    if cfg.get("resume") and cfg.resume != RESUME_AUTO:
        out_dir = Path(cfg.resume)  # the stopped run resume= names (hydra.run.dir is it unless given apart)
    if cfg.get("resume") == RESUME_AUTO:
        if (done := finished_run(out_dir)) is not None:
            print(f"{display_path(out_dir)} is finished (mean {done['mean']:.2f}): nothing to do", flush=True)
            return None
        stopped = (out_dir / CONFIG_FILE).is_file() and (out_dir / CHAINS_FILE).is_file()
        cfg.resume = str(out_dir) if stopped and Protocol(cfg.protocol.name) is Protocol.P3 else None
    if cfg.get("resume"):
        try:
            cfg = resume_config(out_dir, cfg)
        except RunFileError as err:
            raise SystemExit(f"Error: resume={display_path(out_dir)}: {err}") from None
    validate(cfg)
    try:  # one writer per run folder: a second search started on it meanwhile is refused, naming this one
        with run_lock(out_dir, say=lambda line: print(line, flush=True)):
            return _run(cfg, out_dir, commit)
    except RunLockedError as err:
        raise SystemExit(f"Error: {err}") from None


def _run(cfg, out_dir: Path, commit: str) -> ProtocolResult:
    """:func:`run`'s work, with the run folder's lock held."""
    if not cfg.get("resume"):
        old = out_dir / CHAINS_FILE
        if os.path.lexists(old):  # a fresh run never counts another run's chains (only resume= continues them)
            try:
                kept = sum(1 for line in read_run_bytes(old, "ledger").splitlines() if line.strip())
            except (OSError, ValueError):  # a link, a FIFO, too large: removed unread
                kept = "the"
            print(f"fresh run: discarding {kept} chains of an earlier run in {display_path(out_dir)} "
                  f"(resume=<dir> continues a stopped one)", flush=True)
            old.unlink()
        atomic_write_text(out_dir / CONFIG_FILE, OmegaConf.to_yaml(cfg, resolve=True))
    proto = Protocol(cfg.protocol.name)
    ledger = out_dir / CHAINS_FILE
    run_id = search_identity(out_dir)  # every chain record carries it, and results.json
    if cfg.get("resume") and proto is Protocol.P3:  # checked before anything is built: a bad ledger fails at once
        try:  # every line sealed, of this run, each seed once; a torn last line is cut (its chain played again)
            scan = read_ledger(ledger, CHAINS, run_id, repair=True)
        except LedgerError as err:
            raise SystemExit(f"Error: cannot resume: {err}; a resume continues only a ledger this run wrote, "
                             f"sealed (move {CHAINS_FILE} aside to play every chain again)") from None
        if scan.cut:
            print(f"resume: cut the torn last line of {CHAINS_FILE} (a kill mid-append); its chain is played again",
                  flush=True)
        print(f"resume: {len(scan.records)} of {cfg.protocol.seeds} chains already finished", flush=True)
        if len(scan.records) >= cfg.protocol.seeds and os.path.lexists(out_dir / RESULTS_FILE) \
                and (why := stale_summary(out_dir, CHAINS, scan.records)) is not None:
            print(f"note: {why}; {RESULTS_FILE} is written again from {CHAINS_FILE}", flush=True)
    if cfg.threads is not None:
        set_threads(cfg.threads)
    params = params_from_config(cfg.physics)
    noise = noise_from_config(cfg.noise)
    print(f"search: {describe(cfg, params, noise)}\noutput: {display_path(out_dir)}", flush=True)
    warm_up(params, log=lambda msg: print(msg, flush=True))
    device = resolve_device(cfg.get("device", "auto"))
    proposer = make_proposer(cfg.proposer, params, device=device)
    if (warning := noise_mismatch(proposer, noise)) is not None:
        print(f"warning: {warning}", flush=True)
    actor = make_actor(cfg, proposer, params, noise)
    interrupted = False
    if proto is Protocol.P1:
        result = run_p1(actor, cfg.protocol.n_innings, cfg.protocol.shots, seed=cfg.seed, params=params, progress=cfg.progress,
                        noise=noise)
        interrupted = bool(result.extra.get("partial"))
    else:
        seeds = range(cfg.seed, cfg.seed + cfg.protocol.seeds)
        picture = out_dir / "longest_chain.png" if cfg.picture else None
        try:
            result = run_p3(actor, seeds, cfg.protocol.cap, params=params, progress=cfg.progress, picture=picture,
                            ledger=ledger, noise=noise, run=run_id)
        except KeyboardInterrupt:
            interrupted = True
            result = partial_p3(ledger, seeds, cfg.protocol.cap, actor.cfg.sims_per_decision, run=run_id)
    summary = json.loads(result.to_json())
    summary.update(
        proposer=cfg.proposer.name,
        search=cfg.search.kind,
        **physics_record(params),
        **noise_record(noise),
        device=str(device),
        config=OmegaConf.to_container(cfg, resolve=True),
        commit=commit,
        run=run_id,
    )
    atomic_write_text(out_dir / RESULTS_FILE, json.dumps(summary, indent=2) + "\n")
    if interrupted:
        kept = (f"{len(result.values)} of {cfg.protocol.seeds} chains" if proto is Protocol.P3
                else f"{result.extra['shots_done']} of {cfg.protocol.shots} shots per inning")
        more = f"; continue with: python search.py resume={out_dir}" if proto is Protocol.P3 else " (a P1 restarts from scratch)"
        print(f"interrupted: {kept} finished, written to {out_dir / RESULTS_FILE} (partial){more}", flush=True)
        raise SystemExit(130)
    print(f"{proto} {summary['search']} proposer={cfg.proposer.name}: mean {result.mean:.2f} ± {result.std:.2f}, "
          f"max {result.max:.0f}, {result.ms_per_decision:.1f} ms/shot, {result.sims_per_decision:.0f} sims/shot\n"
          f"results: {display_path(out_dir / RESULTS_FILE)}", flush=True)
    return result
