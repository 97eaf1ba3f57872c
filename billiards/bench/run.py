"""Scoring an agent on a track: the protocols, the ledger, the scorecard (docs/benchmark.md).

:func:`evaluate` plays a track's units (blocks of innings, chains or matches) in order; with an
output directory each finished unit is appended to ``units.jsonl`` as a sealed record carrying
the run's identity (a hash of the track and the agent), so an interrupted evaluation keeps what
it finished and the same call continues it; a directory that holds another agent's or another
track version's evaluation is refused, as is a ledger line that is torn (dropped and played
again when it is the last), unsealed or foreign. At the end ``scorecard.json`` and
``scorecard.md`` are written there; without an output directory nothing is written and the
scorecard is only returned. A scorecard claims no status: the leaderboard gives it one.

The agent is timed alone (CPU seconds of its own calls) and its simulations counted; its every
answer is checked (real, finite numbers of the right shape) and its counter must never go down.
Every ledger record is held to the track's rules (:func:`~billiards.bench.protocols.record_problem`) when it is
written and when it is read back. A failure is put on the agent only when it is the agent's
(:func:`whose_failure`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path


from billiards import files
from billiards.files import (IDENTITY_FILE, SCORECARD_JSON, SCORECARD_MD, UNITS_FILE, LedgerKind, atomic_write_text,
                             display_path)
from billiards.protocol import Protocol

from .adapters import Agent, AgentError, resolve_agent
from .protocols import fingerprint_data, protocol_of, record_problem
from .text import md_code, md_text, one_line
from .tracks import Track, get_track



class EvaluationError(RuntimeError):
    """An evaluation that cannot go on: the agent failed mid-run (what finished is kept) or the
    directory is not this evaluation's."""


# ----------------------------------------------------------------------------- playing units and the fingerprint


def play_unit(agent: Agent, track: Track, unit: int, on_shot=None) -> dict:
    """One resumable unit of ``track`` (a block of innings, a chain, a match), played by its
    protocol (:mod:`billiards.bench.protocols`); ``on_shot`` as the protocol's own function takes it."""
    return protocol_of(track).play(agent, track, unit, on_shot)


def fingerprint(track: Track) -> str:
    """sha256 of the track's settings (all but the fingerprint) and :func:`fingerprint_data`:
    each track's ``fingerprint`` must equal it, so a change to the track itself or to what its
    first units play changes it."""
    settings = {k: v for k, v in track.record().items() if k != "fingerprint"}
    body = json.dumps({"settings": settings, "play": fingerprint_data(track)}, sort_keys=True)
    return hashlib.sha256(body.encode()).hexdigest()


# ----------------------------------------------------------------------------- the scorecard


def unit_values(track: Track, records: list[dict]) -> list:
    """The per-unit scores the intervals resample (a scorecard's ``values``): points per inning
    (innings), each inning's success rate (P1), chain lengths (P3), match scores (1, 0.5, 0)."""
    return protocol_of(track).values(track, records)


def score_records(track: Track, records: list[dict]) -> dict:
    """The scorecard's figures from the finished units' records (see docs/benchmark.md)."""
    decisions = sum(r["decisions"] for r in records)
    out: dict = {"units_done": len(records), "decisions": decisions,
                 "ms_per_decision": round(1e3 * sum(r["cpu_s"] for r in records) / max(decisions, 1), 4),
                 "sims_per_decision": round(sum(r["sims"] for r in records) / max(decisions, 1), 2)}
    if not records:
        return out
    out.update(protocol_of(track).figures(track, records))
    out["values"] = unit_values(track, records)
    return out


def figures(card: dict) -> list[tuple[str, str, str]]:
    """The scorecard's figures as (what, value, 95 % interval) text, once for both the page and
    the one-line summary."""
    protocol = Protocol(card["track_record"]["protocol"])
    pct = lambda v: f"{100 * v:.2f} %"
    out = []
    if "points_per_inning" in card and protocol is Protocol.INNINGS:
        p = card["points_per_inning"]
        out.append(("points per inning", f"{p['mean']:.3f} (IQM {p['iqm']:.3f})", f"{p['ci95'][0]:.3f} - {p['ci95'][1]:.3f}"))
    if "success_per_shot" in card and "ci95" in card["success_per_shot"]:
        s = card["success_per_shot"]
        out.append(("success per shot", pct(s["mean"]), f"{pct(s['ci95'][0])} - {pct(s['ci95'][1])}"))
    if "chain" in card:
        c = card["chain"]
        out.append(("chain length", f"mean {c['mean']:.2f}, median {c['median']:.1f}, IQM {c['iqm']:.2f}, max {c['max']} "
                    f"({c['reached_cap']} at the cap {c['cap']})", f"{c['ci95'][0]:.2f} - {c['ci95'][1]:.2f}"))
    if "match" in card:
        m = card["match"]
        anchor = card["track_record"]["anchor"]
        out.append(("win rate", f"{pct(m['win_rate'])} of {m['matches']}", f"{pct(m['ci95'][0])} - {pct(m['ci95'][1])}"))
        out.append(("Elo", f"{card['elo']:.0f} ({anchor} = {card['track_record']['ratings'][anchor]:.0f})", ""))
    out.append(("compute per decision", f"{card['ms_per_decision']:.3f} ms, {card['sims_per_decision']:.0f} simulations", ""))
    return out


def scorecard_markdown(card: dict) -> str:
    """``scorecard.md``: the scorecard as a short page."""
    t = card["track_record"]
    lines = [f"# {md_text(card['agent']['name'])} on {t['name']}", "", f"{t['description']}. Rules: {card['rules']}.", "",
             "| figure | value | 95 % interval |", "|---|---|---|"]
    lines += [f"| {what} | {value} | {interval} |" for what, value, interval in figures(card)]
    lines += ["", f"Agent: {md_code(json.dumps(card['agent'], sort_keys=True))}", "",
              f"Command: {md_code(card['command'])} at commit {md_code(card['commit'])}"
              + (" (partial: not every unit finished)" if card.get("partial") else "")
              + (f" (limited to {card['limit']} units per opponent/track: not a leaderboard entry)" if card.get("limit") else ""),
              ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- the ledger


def run_identity(track: Track, agent_record: dict, limit: int | None) -> str:
    """The identity every ledger record carries (:func:`billiards.files.run_identity`): the track
    (its version and fingerprint included), the agent and the limit."""
    return files.run_identity({"track": track.record(), "agent": agent_record, "limit": limit})


def _unit_problem(rec: dict) -> str | None:
    """What is wrong with an evaluation unit record's shape, or None."""
    unit = rec.get("unit")
    if not (isinstance(unit, int) and not isinstance(unit, bool) and unit >= 0):
        return f"its unit must be an integer >= 0, got {str(unit)[:40]!r}"
    for key in ("decisions", "sims"):
        if not (isinstance(rec.get(key), int) and not isinstance(rec.get(key), bool) and rec[key] >= 0):
            return f"its {key} must be an integer >= 0"
    if not (isinstance(rec.get("cpu_s"), (int, float)) and rec["cpu_s"] >= 0):
        return "its cpu_s must be a number >= 0"
    return None


# what a scorecard claims that its ledger gives (every key of score_records)
DERIVED = ("units_done", "decisions", "ms_per_decision", "sims_per_decision", "success_per_shot", "foul_per_shot",
           "points_per_inning", "chain", "match", "elo", "elo_ci95", "values")


def ledger_figures(track: Track, records: list[dict]) -> dict:
    """Every figure of a scorecard as the ledger's records give it (:func:`score_records`, in
    the form a scorecard file holds: through JSON)."""
    return json.loads(json.dumps(score_records(track, sorted(records, key=lambda r: r["unit"]))))


def claim_problems(card: dict, derived: dict, name: str) -> list[str]:
    """Where the scorecard ``card`` (read from the file ``name``) claims a figure its ledger does
    not give (``derived``: :func:`ledger_figures`), one sentence each naming the file and the
    first entry that differs (``match.win_rate``). A figure the card leaves out is no claim."""
    out = []
    for key in DERIVED:
        if key in derived and key in card and card[key] != derived[key]:
            where, claimed, given = _difference(key, card[key], derived[key])
            out.append(f"{name}: its {where} ({_short(claimed)}) differs from what its ledger gives ({_short(given)})")
        elif key not in derived and card.get(key) is not None:
            out.append(f"{name}: it claims a {key}, which no scorecard of its track has")
    return out


def _difference(key: str, claimed, derived) -> tuple[str, object, object]:
    """The first place a claimed figure differs from the derived one: (``match.win_rate``, the
    claimed value, the derived value)."""
    if isinstance(claimed, dict) and isinstance(derived, dict):
        for k in [*derived, *(k for k in claimed if k not in derived)]:
            if claimed.get(k) != derived.get(k):
                return _difference(f"{key}.{k}", claimed.get(k), derived.get(k))
    return key, claimed, derived


def _short(value) -> str:
    """A claimed value in a sentence: one line, at most 60 characters."""
    text = one_line(json.dumps(value) if not isinstance(value, str) else repr(value))
    return text if len(text) <= 60 else text[:57] + "..."


def scorecard_problems(records: list[dict], card: dict, name: str) -> list[str]:
    """``scorecard.json`` checked against its ``units.jsonl`` (``billiards.files verify``, the
    kind's check): every record within the rules of the track the scorecard names (cut to its
    limit), whether it is partial, and every figure it claims (:func:`claim_problems`) --
    the leaderboard's derivation (:func:`billiards.bench.leaderboard.derive`) on one folder."""
    from .tracks import TRACKS

    if card.get("track") not in TRACKS or card.get("version") != TRACKS[card["track"]].version:
        return [f"{name}: its track {_short(card.get('track'))} (version {_short(card.get('version'))}) is not one of this "
                f"version's tracks"]
    track, limit = TRACKS[card["track"]], card.get("limit")
    if limit is not None:
        if not (isinstance(limit, int) and not isinstance(limit, bool) and 1 <= limit <= track.units):
            return [f"{name}: its limit {_short(limit)} is not a whole number in 1..{track.units}"]
        track = track.scaled(limit)
    out = [f"{name}: unit {r['unit']} of its ledger breaks the rules of {track.name}: {why}"
           for r in records if (why := record_problem(track, r)) is not None]
    if out:
        return out
    if "partial" in card and card["partial"] != (len(records) < track.n_blocks()):
        out.append(f"{name}: it says partial={card['partial']}, but its ledger holds {len(records)} of the "
                   f"{track.n_blocks()} units")
    return out + claim_problems(card, ledger_figures(track, records), name)


# the benchmark's ledger, on the one mechanism every ledger of the project uses (billiards.files)
UNITS = LedgerKind(UNITS_FILE, "evaluation unit record", lambda r: r["unit"], lambda r: f"unit {r['unit']}", _unit_problem,
                   SCORECARD_JSON, scorecard_problems)


def read_ledger(path: Path, run_id: str, repair: bool = True, track: Track | None = None) -> dict[int, dict]:
    """The finished units of a ledger by index (:func:`billiards.files.read_ledger`): every record
    sealed, of this run, each unit once; a torn last line (a kill mid-append) is cut off the file
    (``repair``; else left out) so its unit is played again; anything else is refused by name.
    With ``track``, every record is held to the track's rules too (:func:`~billiards.bench.protocols.record_problem`:
    a unit index in range, outcomes the protocol allows): a record that breaks them is refused
    naming the file and the unit, never counted."""
    try:
        scan = files.read_ledger(path, UNITS, run_id, repair=repair)
    except files.LedgerError as err:
        raise EvaluationError(f"{err} (move the directory aside to start the evaluation again)") from None
    if scan.torn is not None and not repair:
        raise EvaluationError(f"{display_path(path)}: its last line is torn (an interrupted append): resume the evaluation")
    if track is not None:
        for rec in scan.records:
            if (why := record_problem(track, rec)) is not None:
                raise EvaluationError(f"{display_path(path)}: unit {rec['unit']} breaks the rules of {track.name}: {why}")
    return {r["unit"]: r for r in scan.records}


def out_problem(out) -> str | None:
    """Why no evaluation can be written at ``out``, or None, looking only (nothing is created):
    :func:`billiards.app_config.path_problem` (a file, under a file, a directory this user cannot
    write, a name too long), or a directory of the system (``/proc``, ``/sys``, ``/dev``, ``/etc``,
    ``/usr`` ...: kernel and device file systems, installed software) or on a read-only file
    system, which even a superuser cannot or should not write into."""
    from billiards.app_config import path_problem

    where = f"out={out}"
    if Path(out).exists() and not Path(out).is_dir():
        return f"{where}: is a file, not a directory; choose an empty or new directory"
    given = Path(os.path.abspath(os.path.expanduser(str(out))))
    absolute = Path(os.path.realpath(given))
    under = lambda path, dirs: any(path == d or d in path.parents for d in map(Path, dirs))  # noqa: E731
    if any(under(p, _SYSTEM_DIRS) and not under(p, _SYSTEM_SCRATCH) for p in (given, absolute)):
        return f"{where}: lies in a system directory ({given}); choose a directory of your own (outputs/evaluate/...)"
    if why := path_problem(str(out), where):
        return why
    existing = absolute
    while not existing.exists() and existing.parent != existing:
        existing = existing.parent
    fs = _file_system(existing)
    if fs in _PSEUDO_FILE_SYSTEMS:
        return f"{where}: lies on the kernel's {fs} file system ({existing}), which holds no files of ours; choose another directory"
    try:
        read_only = bool(os.statvfs(existing).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):
        read_only = False
    if read_only:
        return f"{where}: lies on a read-only file system ({existing}); choose a directory that can be written"
    return None


_SYSTEM_DIRS = ("/proc", "/sys", "/dev", "/boot", "/etc", "/bin", "/sbin", "/lib", "/lib32", "/lib64", "/usr")
_SYSTEM_SCRATCH = ("/dev/shm", "/usr/local", "/usr/src")  # under a system directory, yet where people keep their files
_PSEUDO_FILE_SYSTEMS = ("proc", "sysfs", "devtmpfs", "devpts", "cgroup", "cgroup2", "debugfs", "tracefs", "securityfs",
                        "configfs", "bpf", "pstore", "efivarfs", "mqueue", "hugetlbfs", "fusectl", "binfmt_misc", "autofs")


def _file_system(path: Path) -> str | None:
    """The type of the file system ``path`` lies on (Linux's /proc/self/mountinfo), or None where
    it cannot be read."""
    try:
        lines = Path("/proc/self/mountinfo").read_text().splitlines()
    except OSError:
        return None
    best, kind = "", None
    for line in lines:
        left, _, right = line.partition(" - ")
        fields = left.split()
        if len(fields) < 5 or not right:
            continue
        mount = fields[4].replace("\\040", " ")
        if (str(path) == mount or str(path).startswith(mount.rstrip("/") + "/")) and len(mount) >= len(best):
            best, kind = mount, right.split()[0]
    return kind


def read_identity(out: Path) -> dict:
    """The ``evaluation.json`` of the directory ``out``: a JSON object, or an EvaluationError
    naming the file (damaged, not JSON, not an object)."""
    path = Path(out) / IDENTITY_FILE
    try:
        mine = files.read_run_json(path)  # no link followed, a regular file of bounded size and depth
    except files.RunFileError as err:
        raise EvaluationError(f"{err}; move the directory aside") from None
    except OSError:
        raise EvaluationError(f"{display_path(path)} is damaged; move the directory aside") from None
    if not isinstance(mine, dict):
        raise EvaluationError(f"{display_path(path)} is not an evaluation's identity (a JSON object, not "
                              f"{type(mine).__name__}); move the directory aside")
    return mine


def claim_directory(out: Path, identity: dict) -> None:
    """Make ``out`` this evaluation's, or refuse: a directory holding another evaluation (another
    agent, track version or limit) or anything else that is not an evaluation is never written."""
    path = out / IDENTITY_FILE
    if out.exists() and not out.is_dir():
        raise EvaluationError(f"{display_path(out)} is a file, not a directory; choose an empty or new directory")
    if os.path.lexists(path):  # whatever it is (a link, a FIFO), read_identity refuses what it may not read
        mine = read_identity(out)
        if mine.get("run") != identity["run"]:
            name = lambda key: (mine.get(key) if isinstance(mine.get(key), dict) else {}).get("name")  # noqa: E731
            raise EvaluationError(
                f"{display_path(out)} holds the evaluation of {one_line(repr(name('agent')))[:80]} on "
                f"{one_line(repr(name('track')))[:80]} (limit {one_line(str(mine.get('limit')))[:20]}); this one is "
                f"{identity['agent']['name']!r} on {identity['track']['name']!r} (limit {identity['limit']}): one directory "
                f"holds one agent on one track version; choose another directory")
        return
    try:
        if out.exists() and files.run_folder_names(out):
            raise EvaluationError(f"{display_path(out)} is not empty and holds no evaluation; choose an empty or new directory")
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, json.dumps(identity, indent=2, sort_keys=True) + "\n")
    except OSError as err:
        raise EvaluationError(f"out={out}: cannot be written ({err.strerror or err}); choose a directory of your own") from None


# ----------------------------------------------------------------------------- failures


def _own_file(cls) -> Path | None:
    """The source file of an agent's class, or None for the package's own agents (and classes
    without a file)."""
    import inspect

    try:
        path = Path(inspect.getsourcefile(cls) or inspect.getfile(cls)).resolve()
    except (TypeError, OSError):
        return None
    return None if files.PACKAGE in path.parents else path


def _in_package(filename: str) -> bool:
    return not filename.startswith("<") and files.PACKAGE in Path(filename).resolve().parents


def whose_failure(err: BaseException, agent: Agent) -> str:
    """``"agent"`` when ``err`` is the agent's own failure, ``"framework"`` when it is the
    evaluation's: an import that fails in the package's code (a missing dependency), not in the
    agent's file, or an exception raised outside the agent's ``act`` and ``reset``."""
    frames = []
    tb = err.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    frames.reverse()  # the innermost first
    if isinstance(err, ImportError):
        mine = _own_file(type(agent))
        for frame in frames:
            name = frame.f_code.co_filename
            if mine is not None and not name.startswith("<") and Path(name).resolve() == mine:
                return "agent"
            if _in_package(name):
                return "framework"
    codes = {getattr(getattr(type(agent), m, None), "__code__", None) for m in ("act", "reset")} - {None}
    return "agent" if any(frame.f_code in codes for frame in frames) else "framework"


def failure_message(err: Exception, agent: Agent, where: str, kept: str) -> str:
    """What an evaluation stopped by ``err`` on ``where`` (``"match 3 of match-x5-v1"``) says:
    the agent's failure names the agent; the framework's (a module it needs that is missing, an
    error outside the agent's calls) says what failed and, for a module, how to install it."""
    from .extras import import_name, install_hint

    what = f"{type(err).__name__}: {err}"
    if whose_failure(err, agent) == "agent":
        return f"agent {agent.name} failed on {where}: {what} ({kept})"
    if isinstance(err, ImportError):
        module = err.name or str(err)
        needs = (f"it needs {import_name(module)}, which is not installed" if isinstance(err, ModuleNotFoundError)
                 else f"importing {module} failed (a broken or mismatched install)")
        return (f"the evaluation cannot play {where}: {needs} ({what}); install it: {install_hint(module)}. "
                f"Not a failure of agent {agent.name} ({kept})")
    return f"the evaluation failed on {where}, outside agent {agent.name}'s calls: {what} ({kept})"


# ----------------------------------------------------------------------------- evaluate


_COMMIT: list[str] = []


def _commit() -> str:
    """The commit the code runs at, read once a process."""
    if not _COMMIT:
        from billiards.provenance import git_commit

        _COMMIT.append(git_commit())
    return _COMMIT[0]


def _cpu() -> str:
    """The processor the agent's time was measured on (:func:`billiards.provenance.cpu`)."""
    from billiards.provenance import cpu

    return cpu()


def agent_record(agent: Agent, spec) -> dict:
    rec = agent.describe()
    if isinstance(spec, (str, Path)):
        rec["spec"] = str(spec)
    return rec


def evaluate(agent, track, *, out: str | Path | None = None, limit: int | None = None, progress: bool = True,
             name: str | None = None, command: str | None = None, group: str | None = None, spec: str | None = None) -> dict:
    """Score ``agent`` on ``track`` and return the scorecard (a dict; see docs/benchmark.md).

    ``agent``: any agent :func:`billiards.bench.adapters.as_agent` adapts or a spec string of
    :func:`~billiards.bench.adapters.resolve_agent`. ``track``: a track name or :class:`Track`.
    ``out``: a directory for the ledger and the scorecard (resumable); None writes nothing, the
    scorecard is only returned.
    ``limit``: only the first ``limit`` innings / chains / matches per opponent (a quick look;
    the scorecard says so). ``group``: the leaderboard row this scorecard pools into with others
    (the training seeds of one setting). ``spec``: the spec to record when ``agent`` is already built.
    One process writes ``out`` at a time (:func:`billiards.files.run_lock`)."""
    if out is not None and (why := out_problem(out)) is not None:  # before anything is built or written
        raise EvaluationError(why)
    commit = _commit()
    full = get_track(track)
    track = full.scaled(limit) if limit is not None else full
    spec = agent if spec is None else spec
    agent = resolve_agent(agent, track, name)
    identity_agent = agent_record(agent, spec)
    if group:
        identity_agent["group"] = group
    run_id = run_identity(full, identity_agent, limit)
    if command is None:
        command = (f"billiards.bench.evaluate({identity_agent.get('spec', identity_agent['name'])!r}, {full.name!r}"
                   + (f", limit={limit}" if limit else "") + ")")
    identity = {"run": run_id, "track": full.record(), "agent": identity_agent, "limit": limit}
    done: dict[int, dict] = {}
    ledger = None
    lock = contextlib.ExitStack()
    if out is not None:
        out = Path(out)
        claim_directory(out, identity)
        try:  # one writer per run folder, until the scorecard is written
            lock.enter_context(files.run_lock(out, command=command))
        except files.RunLockedError as err:
            raise EvaluationError(str(err)) from None
        ledger = out / UNITS_FILE
    with lock:
        if ledger is not None:
            done = read_ledger(ledger, run_id, track=track)
        return _play(agent, track, full, out, ledger, done, identity_agent, run_id, command, commit, limit, progress)


def _play(agent, track, full, out, ledger, done, identity_agent, run_id, command, commit, limit, progress) -> dict:
    """The units still to play, then the scorecard (:func:`evaluate`'s body, under the run folder's lock)."""
    from tqdm.auto import tqdm

    n_units = track.n_blocks()
    todo = [u for u in range(n_units) if u not in done]
    one, several = track.protocol.spec.unit
    if progress:
        print(f"evaluate: {agent.name} on {full.name} ({track.rules()}); {len(done)} of {n_units} {several} done"
              + (f"; output {display_path(out)}" if out is not None else ""), flush=True)
    bar = tqdm(total=n_units, initial=len(done), desc=full.name, unit=several.split()[-1], disable=not progress,
               mininterval=1.0)
    interrupted = False
    try:
        for unit in todo:
            kept = f"{len(done)} finished units kept{' in ' + display_path(ledger) if ledger else ''}"
            try:
                rec = play_unit(agent, track, unit)
            except AgentError as err:
                raise EvaluationError(f"{err} (on {one} {unit} of {full.name}; {kept})") from err
            except KeyboardInterrupt:
                raise
            except Exception as err:
                raise EvaluationError(failure_message(err, agent, f"{one} {unit} of {full.name}", kept)) from err
            rec = {"unit": unit, **rec}
            if (why := record_problem(track, rec)) is not None:  # what the reader would refuse is never written
                raise EvaluationError(f"agent {agent.name} broke the rules of {full.name} on {one} {unit}: {why} ({kept})")
            if ledger is not None:
                rec = files.append_record(ledger, rec, run_id)
            done[unit] = rec
            bar.update(1)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
    records = [done[u] for u in sorted(done)]
    card = {"track": full.name, "version": full.version, "rules": track.rules(), "agent": identity_agent,
            **score_records(track, records), "command": command, "commit": commit, "cpu": _cpu(), "limit": limit,
            "partial": len(records) < n_units, "run": run_id}
    card["track_record"] = full.record()
    card = _ordered(card)
    if out is not None:
        try:
            atomic_write_text(out / SCORECARD_JSON, json.dumps(card, indent=2) + "\n")
            atomic_write_text(out / SCORECARD_MD, scorecard_markdown(card))
        except OSError as err:
            raise EvaluationError(f"out={out}: the scorecard cannot be written ({err.strerror or err}); the finished units "
                                  f"are kept in {display_path(ledger)}") from None
    if progress:
        print(headline(card) + (f"\nscorecard: {display_path(out / SCORECARD_JSON)}" if out is not None else ""), flush=True)
    if interrupted:
        raise KeyboardInterrupt
    return card


def _ordered(card: dict) -> dict:
    first = ["track", "version", "agent", "success_per_shot", "points_per_inning", "chain", "match", "elo",
             "ms_per_decision", "sims_per_decision", "command", "commit", "cpu"]
    return {**{k: card[k] for k in first if k in card}, **{k: v for k, v in card.items() if k not in first}}


def headline(card: dict) -> str:
    """The scorecard in one line."""
    parts = [f"{what} {value}" + (f" [{interval}]" if interval else "") for what, value, interval in figures(card)]
    return f"{one_line(card['agent']['name'])} on {card['track']}: " + "; ".join(parts) + (" (partial)" if card.get("partial") else "")


__all__ = ["DERIVED", "EvaluationError", "IDENTITY_FILE", "UNITS_FILE", "SCORECARD_JSON", "SCORECARD_MD", "UNITS",
           "claim_directory", "claim_problems", "evaluate", "failure_message", "figures", "fingerprint", "fingerprint_data",
           "headline", "ledger_figures", "out_problem", "play_unit", "read_identity", "read_ledger", "run_identity",
           "score_records", "scorecard_markdown", "scorecard_problems", "unit_values", "whose_failure"]
