"""Command line of the reward model.

    python -m billiards.rm generate --out DIR --n N --seed S [--chunk C] [--threads T] [--physics P] [--no-progress]
    python -m billiards.rm train --data DIR --out PATH.pt [--epochs E] [--hidden 128 128]
                                 [--max-rows M] [--batch-size B] [--lr LR] [--holdout F]
                                 [--seed S] [--threads T] [--no-progress]
"""

from __future__ import annotations

import argparse
import sys

from billiards.physics import DEFAULT_PRESET

from .data import DEFAULT_CHUNK, DEFAULT_N, DatasetError


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m billiards.rm", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    gen = sub.add_parser("generate", help="generate (or resume) the random-shot data set")
    gen.add_argument("--out", required=True, help="data directory")
    gen.add_argument("--n", type=_positive_int, default=DEFAULT_N, help="number of shots (default %(default)s)")
    gen.add_argument("--seed", type=int, default=0, help="data set seed (default %(default)s)")
    gen.add_argument("--chunk", type=_positive_int, default=DEFAULT_CHUNK, help="rows per chunk (default %(default)s)")
    gen.add_argument("--threads", type=_positive_int, default=None, help="numba threads (default: numba's)")
    gen.add_argument("--physics", default=DEFAULT_PRESET, help="physics preset of the table (default %(default)s)")
    gen.add_argument("--no-progress", action="store_true", help="no progress bar")

    tr = sub.add_parser("train", help="train the reward model on a data set")
    tr.add_argument("--data", required=True, help="data directory made by `generate`")
    tr.add_argument("--out", required=True, help="model file (.pt); metrics.json and calibration.png go next to it")
    tr.add_argument("--epochs", type=_positive_int, default=2)
    tr.add_argument("--hidden", type=_positive_int, nargs="+", default=[128, 128])
    tr.add_argument("--max-rows", type=_positive_int, default=None, help="use only the first rows")
    tr.add_argument("--batch-size", type=_positive_int, default=4096)
    tr.add_argument("--lr", type=float, default=1e-3)
    tr.add_argument("--holdout", type=float, default=0.02, help="held-out fraction (the last rows)")
    tr.add_argument("--seed", type=int, default=0)
    tr.add_argument("--threads", type=_positive_int, default=1, help="torch threads (default %(default)s)")
    tr.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    try:
        if args.command == "generate":
            from .data import generate

            meta = generate(args.out, n=args.n, seed=args.seed, chunk=args.chunk,
                            progress=not args.no_progress, threads=args.threads, physics=args.physics)
            rate = meta["session_shots_per_s"]
            print(f"{args.out}: {meta['rows_done']:,} of {meta['n']:,} shots "
                  f"({meta['chunks_done']}/{meta['n_chunks']} chunks{', finished' if meta['finished'] else ''})")
            if rate:
                print(f"this run: {meta['session_rows']:,} shots in {meta['session_seconds']:.1f} s = {rate:,.0f} shots/s "
                      f"on {meta['sessions'][-1]['threads']} thread(s)")
            else:
                print("nothing to do")
        else:
            from .train import train_rm

            m = train_rm(args.data, args.out, hidden=args.hidden, epochs=args.epochs, batch_size=args.batch_size,
                         lr=args.lr, holdout=args.holdout, seed=args.seed, max_rows=args.max_rows,
                         threads=args.threads, progress=not args.no_progress)
            auc = "n/a" if m["auc"] is None else f"{m['auc']:.4f}"
            print(f"{args.out}: {m['train_rows']:,} training rows x {m['epochs']} epochs in {m['train_seconds']:.1f} s "
                  f"({m['train_rows_per_s']:,.0f} rows/s)")
            print(f"held-out ({m['heldout_rows']:,} rows, positive rate {m['heldout_positive_rate']:.4f}): "
                  f"log loss {m['heldout_log_loss']:.5f} vs base rate {m['base_rate_log_loss']:.5f} "
                  f"({100 * m['log_loss_improvement']:.1f}% better), AUC {auc}, ECE {m['ece']:.5f}")
    except (DatasetError, ValueError, OSError) as err:
        raise SystemExit(f"Error: {err}") from None


if __name__ == "__main__":
    main(sys.argv[1:])
