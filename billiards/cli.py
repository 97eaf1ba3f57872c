"""``sagu``: the benchmark's one console command, installed with the package (``pip install sagu-bench``).

    sagu evaluate track=p1-exact-v1 agent=my_agent.py:act name=my-agent   # score an agent, then where it would rank
    sagu train algo=sac env.paradigm=random_continue                       # the same overrides as python train.py
    sagu search proposer=near_miss                                         # ... as python search.py
    sagu match players=[greedy,safety] matches=10                          # ... as python match.py
    sagu view                                                              # the viewer (python -m billiards.web)
    sagu leaderboard                                                       # the leaderboard's tools (python -m billiards.bench)
    sagu render shot --out shot.png                                        # pictures (python -m billiards.pictures)

Each subcommand is the repository's script or module of the same job, with the same arguments and
``--help``; the Hydra apps compose the configs the package carries (:data:`billiards.files.CONF_DIR`),
and write their run directories under the working directory (``outputs/``), as the scripts do.
"""

from __future__ import annotations

import importlib
import sys

# subcommand -> (module, what it does, how its arguments are read)
COMMANDS: dict[str, tuple[str, str, str]] = {
    "evaluate": ("billiards.apps.evaluate", "score an agent on a benchmark track (as python evaluate.py)", "hydra"),
    "train": ("billiards.apps.train", "train SAC, TD3, PPO or expert iteration (as python train.py)", "hydra"),
    "search": ("billiards.apps.search", "inference-time search on P1 or P3 (as python search.py)", "hydra"),
    "match": ("billiards.apps.match", "a league of two-player matches under noise (as python match.py)", "hydra"),
    "view": ("billiards.web.__main__", "serve the viewer: replays, the shot lab, matches (as python -m billiards.web)", "argv"),
    "leaderboard": ("billiards.bench.__main__", "the leaderboard's tools: leaderboard, compare, fingerprint, ... "
                    "(as python -m billiards.bench)", "argv"),
    "render": ("billiards.pictures", "pictures of shots and innings (as python -m billiards.pictures)", "argv"),
}

def usage() -> str:
    from billiards import __version__

    width = max(map(len, COMMANDS))
    lines = [f"sagu {__version__}: Korean 4-ball billiards (sagu) as a reinforcement-learning benchmark", "",
             "usage: sagu <command> [arguments ...]     (sagu <command> --help: that command's options)", "", "commands:"]
    lines += [f"  {name:<{width}}  {what}" for name, (_, what, _) in COMMANDS.items()]
    lines += ["", "evaluate, train, search and match take Hydra's overrides (key=value, group=option; -m: a multirun)",
              "and list their options with --help; the docs are the docs/ folder of the source distribution."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0
    if argv[0] in ("-V", "--version"):
        from billiards import __version__

        print(f"sagu-bench {__version__}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"Error: unknown command {name!r}; the commands are: {', '.join(COMMANDS)} (sagu --help)", file=sys.stderr)
        return 2
    module_name, _, kind = COMMANDS[name]
    module = importlib.import_module(module_name)
    if kind == "hydra":
        # Hydra reads sys.argv itself: the subcommand's arguments, under the name the user typed
        sys.argv = [f"sagu {name}", *rest]
        module.main()
        return 0
    if name == "leaderboard" and (not rest or rest[0].startswith("-")):
        rest = ["leaderboard", *rest]  # `sagu leaderboard [--out D]` rebuilds the board; `sagu leaderboard compare A B` compares
    result = module.main(rest)
    return int(result or 0)


if __name__ == "__main__":
    raise SystemExit(main())
