"""Command line of the paper's reproduction.

    python -m billiards.campaign commands [--only table4] [--launcher L] [--budget B]   # print each stage's command
    python -m billiards.campaign run [--only table1,table2] [--launcher L] [--budget B] [OVERRIDES]
    python -m billiards.campaign status [-v]
    python -m billiards.campaign report paper [--root outputs/campaign/paper] [--out DIR]

``run`` runs the stages one after the other, each as one Hydra multirun (``--launcher``:
submitit_local, local_parallel (joblib), slurm (submitit), ray_tasks, or Hydra's basic one);
run again, it continues where it stopped (``resume=auto``). Hydra overrides go to every
stage (``hydra.launcher.n_jobs=2``, ``hydra.launcher.partition=cpu``). The state is the run
directories under ``--root`` (default ``outputs/campaign/paper``). ``report`` without
``--root`` regenerates results/reproduction.json / .md from the committed run directories.
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
from pathlib import Path

from billiards.files import OUTPUTS, ROOT, display_path

from .stages import BUDGETS, LAUNCHERS, StageError, check_options, paper_stages

NAME = "paper"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m billiards.campaign", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name, help_ in (("commands", "print each stage's multirun command"), ("run", "run the stages"),
                        ("status", "done / started / not started per stage, CPU-hours"),
                        ("report", "write reproduction.json / .md and the figures")):
        p = sub.add_parser(name, help=help_)
        if name == "report":
            p.add_argument("campaign", nargs="?", default=NAME, choices=[NAME], help="the campaign (paper)")
        p.add_argument("--root", type=Path, default=None,
                       help="where the stages write (default outputs/campaign/paper); report: read a campaign there "
                            "(default: the committed run directories under results/)")
        p.add_argument("--only", default=None, help="comma-separated stages, e.g. table1,table2 (extra: only when named)")
        if name in ("commands", "run"):
            p.add_argument("--launcher", default=None, choices=LAUNCHERS, help="hydra/launcher of every stage")
            p.add_argument("--budget", default=None, choices=BUDGETS, help="training budget (default: the paper's)")
            p.add_argument("overrides", nargs="*", help="Hydra overrides for every stage")
        if name == "status":
            p.add_argument("-v", "--verbose", action="store_true", help="name the runs not done")
        if name == "report":
            p.add_argument("--out", type=Path, default=ROOT / "results",
                           help="where reproduction.json/.md and img/ go (default results/); with --root also the "
                                "finished runs' small files, to training/<name>/ and search/<name>/")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    args.campaign = getattr(args, "campaign", NAME)
    root = (args.root or OUTPUTS / "campaign" / args.campaign).resolve()
    try:
        stages = paper_stages(root, [t for t in args.only.split(",") if t] if args.only else None)
        if args.command == "report":
            from billiards.report.reproduction import Sources, write_report

            if args.root is None:
                src = Sources(args.campaign, ROOT / "results" / "training" / args.campaign, ROOT / "results" / "search" / args.campaign)
            elif not root.is_dir():
                raise StageError(f"{root} does not exist: no stage has run there")
            else:
                src = Sources(args.campaign, root, root, copy_to=args.out.resolve())
            for path in write_report(src, args.out.resolve()):
                print(f"wrote {display_path(path)}")
            return 0
        if args.command == "status":
            from .status import status_text

            sys.stdout.write(status_text(stages, args.verbose))
            return 0
        check_options(args.launcher, args.budget, args.overrides)
        commands = [(s, s.command(args.launcher, args.budget, tuple(args.overrides))) for s in stages]
        if args.command == "commands":
            print("\n".join(shlex.join(c) for _, c in commands))
            return 0
        for stage, cmd in commands:
            print(f"stage {stage.table}: {shlex.join(cmd)}", flush=True)
            code = subprocess.run([sys.executable, *cmd[1:]], cwd=ROOT).returncode
            if code != 0:
                print(f"stage {stage.table} ended with exit status {code}; run the same command again to continue it",
                      file=sys.stderr)
                return code
        return 0
    except StageError as err:
        print(f"Error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
