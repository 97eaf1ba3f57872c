"""``python -m billiards.bench``: the leaderboard's tools.

    python -m billiards.bench leaderboard                # rebuild results/leaderboard.md / .json / .png from the scorecards
    python -m billiards.bench leaderboard --out /tmp/lb  # ... elsewhere (CI diffs it against the committed one)
    python -m billiards.bench leaderboard --scorecards DIR --out /tmp/lb  # from another folder of scorecards
    python -m billiards.bench campaign                   # play every missing scorecard of the project's own entries
    python -m billiards.bench campaign --only h2_ --tracks p3-exact-v1
    python -m billiards.bench campaign --multirun --launcher slurm   # ... as Hydra multiruns on a launcher
    python -m billiards.bench record-training results/training/paper/table1/sac --row "SAC plain (Table 1)"
    python -m billiards.bench fingerprint                # each track's fingerprint, recomputed
    python -m billiards.bench compare <scorecard> <scorecard>  # two agents on one track, paired by unit
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from billiards.files import IN_CHECKOUT, ROOT, read_run_json

SCORECARDS = Path("results/bench/scorecards")


def _checkout_only(what: str) -> None:
    """Commands that write under the repository's results/ run in a source checkout only (an
    installed package's files are never written)."""
    if not IN_CHECKOUT:
        raise SystemExit(f"Error: {what} writes under the repository's results/; run it in a source checkout of the project")


def campaign(only: str | None, tracks: list[str] | None, progress: bool) -> None:
    from billiards.device import set_threads

    from .run import evaluate

    set_threads(1)
    jobs = _missing(only, tracks)
    warmed: set[str] = set()
    for i, (entry, track) in enumerate(jobs, 1):
        if entry.spec not in warmed:  # what the agent compiles on first use is not its time per decision
            warm_up_agent(entry.spec, track)
            warmed.add(entry.spec)
        out = SCORECARDS / track / entry.slug
        command = f"python evaluate.py track={track} agent={entry.spec} name={entry.slug} \"group='{entry.row}'\" out={out}"
        print(f"[{i}/{len(jobs)}] {command}", flush=True)
        evaluate(entry.spec, track, out=ROOT / out, name=entry.slug, group=entry.row, command=command, progress=progress)


def warm_up_agent(spec: str, track: str) -> None:
    """Play ``spec`` for a decision or two on a cut-down copy of ``track`` (one unit of two shots,
    a match to one point), writing nothing: the kernels it compiles on first use (the
    simulator's, a search's tree, a network's) are compiled before the campaign times it. The
    agent is built afresh for the scorecard (each unit reseeds it: the scores do not depend on
    this)."""
    import dataclasses

    from .run import evaluate
    from .tracks import get_track

    t = get_track(track).scaled(1)
    t = dataclasses.replace(t, target=1, max_innings=1) if t.protocol.spec.two_player else dataclasses.replace(t, shots=2)
    evaluate(spec, t, progress=False)


def _missing(only: str | None, tracks: list[str] | None) -> list:
    """(entry, track) of every scorecard of the project's own entries not finished yet."""
    from .entries import ENTRIES, check_entries
    from .run import SCORECARD_JSON

    check_entries()
    jobs = [(e, t) for e in ENTRIES for t in e.tracks if (only is None or only in e.slug) and (tracks is None or t in tracks)]
    out = []
    for entry, track in jobs:
        card = ROOT / SCORECARDS / track / entry.slug / SCORECARD_JSON
        if not (card.is_file() and not read_run_json(card).get("partial")):
            out.append((entry, track))
    return out


def multirun_commands(only: str | None, tracks: list[str] | None, launcher: str | None = None) -> list[str]:
    """The campaign as Hydra multiruns of ``evaluate.py``: one command per entry, sweeping the
    tracks it has yet to play, each job writing (and, run again, resuming) its scorecard folder;
    ``launcher`` a Hydra launcher option (``local_parallel``, ``slurm``, ``ray_tasks``) to run the jobs
    on."""
    by_entry: dict = {}
    for entry, track in _missing(only, tracks):
        by_entry.setdefault(entry, []).append(track)
    out = []
    for entry, missing in by_entry.items():
        command = (f"python evaluate.py -m track={','.join(missing)} agent={entry.spec} name={entry.slug} "
                   f"\"group='{entry.row}'\" 'out={SCORECARDS.as_posix()}/${{track}}/{entry.slug}'")
        out.append(command + (f" hydra/launcher={launcher}" if launcher else ""))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m billiards.bench", description="The benchmark's leaderboard tools.")
    sub = parser.add_subparsers(dest="command", required=True)
    lb = sub.add_parser("leaderboard", help="rebuild the leaderboard from the committed scorecards")
    lb.add_argument("--scorecards", type=Path, default=ROOT / "results" / "bench" if IN_CHECKOUT else Path.cwd() / "results" / "bench",
                    help="the folder of scorecards/, recorded/ and submissions/ (default the repository's results/bench; "
                         "outside a checkout, results/bench in the working directory)")
    lb.add_argument("--out", type=Path, default=None,
                    help="folder for leaderboard.md/.json/.png (default the repository's results/; required outside a checkout)")
    lb.add_argument("--no-figure", action="store_true", help="skip the PNG")
    cp = sub.add_parser("campaign", help="play the project's missing scorecards (resumable)")
    cp.add_argument("--only", help="entries whose slug contains this")
    cp.add_argument("--tracks", nargs="*", help="only these tracks")
    cp.add_argument("--quiet", action="store_true")
    cp.add_argument("--multirun", action="store_true",
                    help="print the missing scorecards as Hydra multiruns of evaluate.py (one per entry) instead of playing them")
    cp.add_argument("--launcher", help="with --multirun: the Hydra launcher to run them on (local_parallel, slurm, ray_tasks)")
    rt = sub.add_parser("record-training", help="a recorded scorecard from a training setting's committed evaluations")
    rt.add_argument("setting", type=Path, help="a folder of seed<k>/ training run dirs with eval.json")
    rt.add_argument("--row", required=True)
    rt.add_argument("--slug", required=True)
    sub.add_parser("fingerprint", help="recompute each track's fingerprint")
    co = sub.add_parser("compare", help="two scorecards of one track, unit by unit: the paired difference and its interval")
    co.add_argument("first", type=Path, help="a scorecard (scorecard.json or its folder)")
    co.add_argument("second", type=Path, help="another agent's scorecard on the same track")
    co.add_argument("--json", action="store_true", help="print the comparison as JSON")
    args = parser.parse_args(argv)
    if args.command == "compare":
        from .leaderboard import compare

        try:
            c = compare(args.first, args.second)
        except ValueError as err:
            raise SystemExit(f"Error: {err}") from None
        if args.json:
            print(json.dumps(c, indent=2))
        else:
            pct = c["unit"] == "success per shot"
            f = (lambda v: f"{100 * v:+.2f} points" if pct else f"{v:+.3f}")
            g = (lambda v: f"{100 * v:.2f} %" if pct else f"{v:.3f}")
            print(f"{c['track']}, {c['unit']}: {c['first']} {g(c['first_mean'])} - {c['second']} {g(c['second_mean'])} = "
                  f"{f(c['difference'])}, paired 95 % interval [{f(c['ci95'][0])}, {f(c['ci95'][1])}] over {c['units']} units "
                  f"({c['first']} ahead on {c['first_better']}, behind on {c['second_better']})")
        return 0
    if args.command == "leaderboard":
        from .leaderboard import leaderboard, write

        try:  # each scorecard left out (partial, limited) is said on stderr
            board = leaderboard(args.scorecards, report=lambda line: print(line, file=sys.stderr))
        except ValueError as err:
            raise SystemExit(f"Error: {err}") from None
        if args.out is None and not IN_CHECKOUT:
            raise SystemExit("Error: outside a source checkout give --out DIR (the installed package's files are never written)")
        paths = write(board, args.out or ROOT / "results", figure=not args.no_figure)
        print("\n".join(str(p) for p in paths))
    elif args.command == "campaign":
        _checkout_only("campaign")
        if args.multirun:
            print("\n".join(multirun_commands(args.only, args.tracks, args.launcher)))
        else:
            campaign(args.only, args.tracks, not args.quiet)
    elif args.command == "record-training":
        from .leaderboard import record_training

        _checkout_only("record-training")
        print(record_training(args.setting, args.row, args.slug))
    else:
        from .run import fingerprint
        from .tracks import TRACKS

        for t in TRACKS.values():
            now = fingerprint(t)
            print(f"{t.name}: {now} {'ok' if now == t.fingerprint else 'CHANGED (bump the version)'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
