"""Aggregate training runs into the paper's tables: ``python -m billiards.report DIR...``.

Every finished run (``config.yaml`` and ``eval.json`` written by ``train.py``) under the given
folders is read and grouped by its table and row (:mod:`.runs`); the paper's tables are laid out
with the paper's figures beside ours (:mod:`.markdown`, the figures from :mod:`billiards.tables`),
search runs (``results.json``) as Table 6 (:mod:`billiards.search.report`). The markdown goes to
stdout and to ``--out`` (default: ``DIR/report.md`` for one DIR, else ``./report.md``).
``--curves``: the learning curves (every periodic evaluation, unfinished runs included);
``--cpu-budget MIN``: per run, the last evaluation within MIN CPU minutes; ``--plot FILE.png``:
the curves drawn (:mod:`.plots`). The paper's reproduction (``results/reproduction.json``) is
:mod:`.reproduction`'s, run by ``python -m billiards.campaign report``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .markdown import COLUMN_TITLES, curves_markdown, render_table, report
from .runs import (SMALL_RUN_FILES, Curve, Run, aggregate, copy_runs, find_curves, find_runs, flatten_config,
                   mean_curve, read_curve, read_run)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m billiards.report", description=__doc__.split("\n\n")[0])
    parser.add_argument("dirs", nargs="+", type=Path, help="run or sweep directories (searched recursively)")
    parser.add_argument("--out", type=Path, default=None, help="markdown file (default DIR/report.md or ./report.md)")
    parser.add_argument("--copy-to", type=Path, default=None,
                        help="also copy each finished run's small files (config, evaluations, summary, metrics) "
                             "to COPY_TO/<run name>/, e.g. to commit them under results/")
    parser.add_argument("--curves", action="store_true",
                        help="learning curves: every periodic evaluation per variant (unfinished runs included)")
    parser.add_argument("--cpu-budget", type=float, default=None, metavar="MIN",
                        help="with --curves: each run's last evaluation within MIN CPU minutes of training")
    parser.add_argument("--plot", type=Path, default=None, metavar="FILE.png",
                        help="draw the learning curves against env steps and CPU minutes")
    args = parser.parse_args(argv)
    if args.cpu_budget is not None and (not args.curves or not args.cpu_budget > 0):
        parser.error("--cpu-budget needs --curves and a positive number of minutes")
    if args.copy_to is not None:
        copy_runs(args.dirs, args.copy_to)
    if args.curves or args.plot:
        curves = find_curves(args.dirs)
        if not curves:
            raise SystemExit(f"Error: no eval_history.jsonl under {', '.join(map(str, args.dirs))}")
    if args.plot:
        from .plots import plot_curves

        print(f"(learning curves drawn to {plot_curves(curves, args.plot)})", file=sys.stderr)
    if args.curves:
        text = curves_markdown(curves, args.cpu_budget)
    else:
        text = report(args.dirs)
    out = args.out or (args.dirs[0] / "report.md" if len(args.dirs) == 1 else Path("report.md"))
    out.write_text(text)
    sys.stdout.write(text)
    print(f"\n(written to {out})", file=sys.stderr)



__all__ = ["COLUMN_TITLES", "SMALL_RUN_FILES", "Curve", "Run", "aggregate", "copy_runs", "curves_markdown", "find_curves",
           "find_runs", "flatten_config", "main", "mean_curve", "read_curve", "read_run", "render_table", "report"]
