"""Two-player Korean 4-ball: a league of players under execution noise (docs/matches.md).

    python match.py                                           # greedy vs safety-aware search vs random, fastfiz_x5
    python match.py noise=fastfiz target=30 matches=200 players=[greedy,safety]
    python match.py resume=<run dir>                          # play the league's missing matches

Thin entry point: composes conf/match.yaml and calls billiards.league.run.
"""

import hydra
from hydra.core.hydra_config import HydraConfig

from billiards.app_config import guard_command_line
import billiards.league.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)


@hydra.main(version_base="1.3", config_path="conf", config_name="match")
def main(cfg) -> None:
    from billiards.league import run

    run(cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    guard_command_line()  # a command line that names code fails here, before Hydra builds anything
    main()
