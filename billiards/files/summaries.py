"""A run's summary checked against its ledger: :func:`read_summary`, :func:`summary_problems`
(the kind's check), :func:`stale_summary` (a resume never trusts a summary, it recomputes it
from the ledger) and :func:`verify`, which checks a run directory's ledger of any kind record
by record and its summary (``results.json``, ``league.json``, ``scorecard.json``) against it;
:func:`main` is ``python -m billiards.files verify RUN_DIR...``."""

from __future__ import annotations

import os
from pathlib import Path

from .describe import _shown_ident
from .ledgers import _UNAVAILABLE, RUN_KEY, LedgerKind, ledger_kinds, scan_ledger
from .lock import lock_holder
from .paths import display_path
from .runfiles import RunFileError, read_run_bytes, read_run_json

def read_summary(run_dir, kind: LedgerKind) -> tuple[dict | None, str | None]:
    """The run's summary file (``kind.summary`` in ``run_dir``) read through
    :func:`read_run_json`: (the summary, None), or (None, a sentence: missing, refused, damaged,
    not an object)."""
    spath = Path(run_dir) / kind.summary
    try:
        summary = read_run_json(spath, "summary")
    except FileNotFoundError:
        return None, f"{display_path(spath)} does not exist: the run did not finish (its resume finishes it)"
    except RunFileError as err:
        return None, str(err)
    except OSError as err:
        return None, f"{display_path(spath)} cannot be read ({err.strerror or type(err).__name__})"
    if not isinstance(summary, dict):
        return None, f"{display_path(spath)} is not a JSON object"
    return summary, None


def summary_problems(kind: LedgerKind, records: list[dict], summary: dict, name: str) -> list[str]:
    """Where a run's summary (read from the file ``name``) disagrees with its ledger's records,
    one sentence each (the kind's :attr:`LedgerKind.check`); [] when it agrees or the kind has no check."""
    try:
        check = kind.summary_check()
    except (ImportError, AttributeError) as err:
        return [f"{name} cannot be checked against its ledger: {kind.check} cannot be loaded ({type(err).__name__})"]
    return [] if check is None else list(check(records, summary, name))


def stale_summary(run_dir, kind: LedgerKind, records: list[dict]) -> str | None:
    """Why the summary a finished run left in ``run_dir`` cannot stand for its ledger's
    ``records`` -- missing, refused, damaged, or not what the records give (edited) -- or None
    if it can. A resume asks this before it calls a run finished: a summary is never trusted,
    only recomputed from the ledger (the apps write it again when this says why)."""
    summary, problem = read_summary(run_dir, kind)
    if problem is not None:
        return problem
    name = display_path(Path(run_dir) / kind.summary)
    if (ident := summary.get(RUN_KEY)) is not None and records and ident != records[0].get(RUN_KEY):
        return f"{name} names another run than its ledger's records"
    problems = summary_problems(kind, records, summary, name)
    return problems[0] + (f" (and {len(problems) - 1} more)" if len(problems) > 1 else "") if problems else None


def verify(run_dir, strict: bool = False) -> tuple[list[str], list[str]]:
    """Check a run directory's ledger -- every kind the package writes (:func:`ledger_kinds`:
    ``chains.jsonl``, ``matches.jsonl``, the benchmark's ``units.jsonl``) -- record by record
    and its summary against it (the kind's check: ``results.json``'s values are the ledger's
    chain lengths in seed order; ``league.json``'s pair tables and Elo ratings are the ones its
    matches give). Every file is read through :func:`read_run_bytes`: a link, a FIFO, a file
    past its bound or JSON nested too deep is a problem, named, never read. Returns (problems,
    notes), one sentence each. Records whose seal or run identity is missing are checked on
    their shape and are a note (a problem with ``strict``, or when the summary names the run's
    identity: such a run seals every record with it)."""
    run_dir = Path(run_dir)
    known = ledger_kinds()
    kinds = [k for k in known if os.path.lexists(run_dir / k.file)]
    if not kinds:
        missing = [f"{display_path(run_dir)}: no ledger ({' or '.join(k.file for k in known)}) there"]
        return missing + [f"the ledger kind {p} could not be loaded ({why})" for p, why in _UNAVAILABLE.items()], []
    problems: list[str] = []
    notes: list[str] = []
    if (holder := lock_holder(run_dir)) is not None:
        notes.append(f"{display_path(run_dir)} is being written now ({holder.describe()}): its ledger may grow and its "
                     f"summary be written again")
    for kind in kinds:
        path, spath = run_dir / kind.file, run_dir / kind.summary
        summary, problem = read_summary(run_dir, kind)
        if problem is not None:
            problems.append(problem)
        run = summary.get(RUN_KEY) if summary is not None else None
        run = run if isinstance(run, str) else None
        try:
            data = read_run_bytes(path, "ledger")
        except RunFileError as err:
            problems.append(str(err))
            continue
        except OSError as err:
            problems.append(f"{display_path(path)} cannot be read ({err.strerror or type(err).__name__})")
            continue
        scan = scan_ledger(data, display_path(path), kind, run, unchecked=run is None)
        problems += scan.problems
        if scan.torn is not None:
            problems.append(f"{display_path(path)}: line {scan.torn} is torn (no newline: a kill mid-append); "
                            f"resume cuts it off and plays its unit again")
        if summary is not None:
            if kind.check is None:
                notes.append(f"{display_path(spath)}: its figures are not checked against the ledger (the {kind.what} "
                             f"kind registers no check)")
            problems += summary_problems(kind, scan.records, summary, display_path(spath))
        if scan.unchecked:
            n, unsealed = len(scan.unchecked), len(scan.unsealed)
            what = ("carry no seal: their shape is checked, their content cannot be" if unsealed == n else
                    f"carry a seal but no run identity{f' ({unsealed} no seal either)' if unsealed else ''}: "
                    f"their shape and seals are checked, which run wrote them cannot be")
            say = f"{display_path(path)}: {n} of {len(scan.records)} records {what}; such a run is not resumed"
            (problems if strict else notes).append(say)
        else:
            notes.append(f"{display_path(path)}: {len(scan.records)} sealed records"
                         + (f" of run {_shown_ident(scan.records[0][RUN_KEY])}" if scan.records else ""))
    return problems, notes


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m billiards.files", description="Verify run directories' ledgers.")
    sub = ap.add_subparsers(dest="command", required=True)
    vp = sub.add_parser("verify", help="check each run directory's ledger (every kind the package writes: chains.jsonl, "
                                       "matches.jsonl, units.jsonl) record by record and its summary (results.json, "
                                       "league.json, scorecard.json) against it; one line per problem, exit status 1 if any")
    vp.add_argument("dirs", nargs="+", type=Path, metavar="RUN_DIR")
    vp.add_argument("--strict", action="store_true", help="records without a seal or a run identity are problems too")
    args = ap.parse_args(argv)
    bad = 0
    for d in args.dirs:
        problems, notes = verify(d, strict=args.strict)
        for line in problems:
            print(f"problem: {line}")
        for line in notes:
            print(f"note: {line}")
        print(f"{display_path(d)}: " + (f"{len(problems)} problems" if problems else "ledger and summary agree"))
        bad += len(problems)
    return 1 if bad else 0
