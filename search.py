"""Inference-time search: `python search.py [proposer=geometric|base|gentle|near_miss|both] [search=h2|puct] [protocol=p1|p3]`.

    python search.py                                   # geometric proposer, h2, P3 on the default (paper's) table
    python search.py physics=international proposer=near_miss search=h2 protocol=p3   # a shipped ensemble, on its table
    python search.py protocol=p1 protocol.n_innings=10 protocol.shots=10              # a quick look
    python search.py resume=<run dir>                  # continue a stopped P3 from its next chain

How long: P3 on defaults plays 10 chains of up to 10,000 shots; what a decision costs at 400
simulations is measured in results/bench_search_korean_medium_1m.json (docs/search.md). The run
prints what it will do and where before it starts, and an upper bound on the time left after
its first chain. Ctrl-C keeps every finished chain (results.json marked partial).

Thin entry point: composes conf/search.yaml and calls billiards.search.run.
"""

import hydra
from hydra.core.hydra_config import HydraConfig

from billiards.app_config import guard_command_line
import billiards.search.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)


@hydra.main(version_base="1.3", config_path="conf", config_name="search")
def main(cfg) -> None:
    from billiards.search.run import run

    run(cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    guard_command_line()  # a command line that names code fails here, before Hydra builds anything
    main()
