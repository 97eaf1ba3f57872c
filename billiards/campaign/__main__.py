"""Command line of the campaign runner.

    python -m billiards.campaign run paper [--jobs 2] [--hours H | --until HH:MM] [--only table1,table2] [--dry-run]
    python -m billiards.campaign status paper [--only ...] [-v]
    python -m billiards.campaign stop paper [--now]   # the active runner drains (or stops all now) and exits
    python -m billiards.campaign report paper [--out DIR]  # reproduction.json / .md from the committed runs
    python -m billiards.campaign report paper --root outputs/campaign/paper  # ... from a live campaign
    python -m billiards.campaign run --spec tiny.yaml --root /tmp/tiny

``paper`` is the built-in campaign (billiards/campaign/spec.py); ``--spec FILE`` reads another
from YAML or JSON. The state lives under ``--root`` (default ``outputs/campaign/<name>`` in the
repository).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from billiards.files import display_path
from billiards.provenance import ROOT

from .ledger import STOP, STOP_NOW, Ledger, entry_dir
from .runner import Runner, command, parse_deadline
from .spec import SpecError, campaign_named, load_spec
from .status import entry_states, status_text


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m billiards.campaign", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name, help_ in (("run", "run the unfinished entries"), ("status", "done / running / left, CPU-hours"),
                        ("stop", "ask the active runner to drain and exit"),
                        ("report", "write reproduction.json / .md and copy the finished runs' small files")):
        p = sub.add_parser(name, help=help_)
        p.add_argument("campaign", nargs="?", default=None, help="built-in campaign name (paper)")
        p.add_argument("--spec", type=Path, default=None, help="a campaign definition file (YAML or JSON)")
        p.add_argument("--root", type=Path, default=None,
                       help="state directory (default outputs/campaign/<name>); report: read a live campaign there "
                            "(default: the committed run directories under results/)")
        p.add_argument("--only", default=None, help="comma-separated tables, e.g. table1,table2")
        p.add_argument("--jobs", type=int, default=2, help="processes at a time (default 2)")
        if name == "run":
            p.add_argument("--hours", type=float, default=None, help="stop within H hours from now")
            p.add_argument("--until", default=None, help="stop by HH:MM (this machine's local time)")
            p.add_argument("--grace-minutes", type=float, default=5.0,
                           help="drain this long before the deadline: start nothing new and stop each training run "
                                "right after its next checkpoint; longer than one checkpoint interval (about 1.5 min "
                                "of one core for algo=sac at budget=paper) loses nothing, longer still only idles the "
                                "cores; a run with longer intervals (algo=sac_paper: ~13 min) drains that much earlier "
                                "on its own")
            p.add_argument("--dry-run", action="store_true", help="list what would run, run nothing, write nothing")
            p.add_argument("--restart-stale", action="store_true",
                           help="re-run from scratch entries whose arguments changed since they started")
            p.add_argument("--retry-failed", action="store_true", help="try entries that failed repeatedly again")
            p.add_argument("--poll", type=float, default=2.0, help=argparse.SUPPRESS)
        if name == "stop":
            p.add_argument("--now", action="store_true",
                           help="stop every process at once (training loses up to budget.checkpoint_every steps)")
        if name == "report":
            p.add_argument("--out", type=Path, default=ROOT / "results",
                           help="where reproduction.json/.md and img/ go (default results/); with --root also the "
                                "finished runs' small files, to training/<name>/ and search/<name>/")
        if name == "status":
            p.add_argument("-v", "--verbose", action="store_true", help="one line per entry")
            p.add_argument("--check-config", action="store_true",
                           help="compare each started training run's config.yaml with what its arguments compose to now")
    return parser


def _campaign(args):
    if args.spec is not None and args.campaign is not None:
        raise SpecError("give a campaign name or --spec FILE, not both")
    campaign = load_spec(args.spec) if args.spec is not None else campaign_named(args.campaign or "paper")
    root = args.root if args.root is not None else ROOT / "outputs" / "campaign" / campaign.name
    only = [t for t in args.only.split(",") if t] if args.only else None
    if args.jobs < 1:
        raise SpecError(f"--jobs must be >= 1, got {args.jobs}")
    return campaign, root.resolve(), only


def dry_run(campaign, root: Path, only) -> str:
    """What ``run`` would do now, entry by entry; reads the state, writes nothing."""
    selected = campaign.select(only)
    lines = [f"dry run: campaign {campaign.name}, {len(selected)} entries, state in {root}"]
    for s in entry_states(campaign, root, selected):
        e = s.entry
        if s.state in ("done", "shared", "left (shared)", "running", "failed", "stale"):
            note = f" = {e.same_as}" if e.same_as else ""
            lines.append(f"  {s.state:<13} {e.key}{note}")
        elif s.state == "waiting":
            lines.append(f"  waiting       {e.key} (needs {', '.join(e.needs())})")
        else:
            cmd, mode = command(e, entry_dir(root, campaign, e), root)
            lines.append(f"  {mode:<13} {e.key}: {' '.join(cmd[1:])}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        campaign, root, only = _campaign(args)
        if args.command == "status":
            Ledger(root, campaign.name)  # a ledger of another campaign fails here, clearly
            sys.stdout.write(status_text(campaign, root, campaign.select(only), args.jobs, args.verbose))
            if args.check_config:
                from .drift import config_drift, drift_text

                entries = campaign.select(only)
                drift = config_drift(campaign, root, entries)
                checked = sum((entry_dir(root, campaign, e) / "config.yaml").is_file()
                              for e in entries if e.kind == "train" and not e.same_as)
                sys.stdout.write(drift_text(drift, checked))
                return 4 if drift else 0
            return 0
        if args.command == "report":
            from .reproduction import write_report

            if args.root is None:  # the committed run directories
                paths = write_report(campaign, None, args.out.resolve(), results=ROOT / "results")
            else:
                if not root.is_dir():
                    raise SpecError(f"{root} does not exist: the campaign has not started")
                Ledger(root, campaign.name)
                paths = write_report(campaign, root, args.out.resolve())
            for path in paths:
                print(f"wrote {display_path(path)}")
            return 0
        if args.command == "stop":
            if not root.is_dir():
                raise SpecError(f"{root} does not exist: no runner to stop")
            if args.now:
                (root / STOP_NOW).touch()
                print(f"asked the runner of {root} to stop every process now")
                return 0
            (root / STOP).touch()
            print(f"asked the runner of {root} to drain: it starts nothing new, stops each training run "
                  f"after its next checkpoint and waits for running searches (stop --now stops them)")
            return 0
        if args.dry_run:
            campaign.select(only)
            sys.stdout.write(dry_run(campaign, root, only))
            return 0
        if not args.grace_minutes >= 0:
            raise SpecError(f"--grace-minutes must be >= 0, got {args.grace_minutes}")
        deadline = parse_deadline(args.hours, args.until)
        runner = Runner(campaign, root, jobs=args.jobs, deadline=deadline, grace=60.0 * args.grace_minutes,
                        only=only, restart_stale=args.restart_stale, retry_failed=args.retry_failed, poll=args.poll)
        left = runner.run()
        return 0 if left == 0 else 3
    except SpecError as err:
        print(f"Error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
