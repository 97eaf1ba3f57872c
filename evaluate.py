"""Score any agent on a track of the benchmark: `python evaluate.py track=<name> agent=<spec>`.

    python evaluate.py track=p1-exact-v1 agent=my_agent.py:act          # a NumPy function obs -> action
    python evaluate.py track=innings-v1 agent=results/policies/base/seed0.pt
    python evaluate.py track=p3-fastfiz-v1 agent=search:default          # the position-aware search
    python evaluate.py track=match-x5-v1 agent=league:safety_r
    python evaluate.py track=p1-exact-v1 agent=my_agent.py:act out=<dir>   # the same out resumes a stopped run

Writes scorecard.json and scorecard.md (and the ledger units.jsonl) into its run directory.
Thin entry point: composes conf/evaluate.yaml and calls billiards.bench.
"""

import hydra
from hydra.core.hydra_config import HydraConfig

from billiards.app_config import guard_command_line
import billiards.bench.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)


@hydra.main(version_base="1.3", config_path="conf", config_name="evaluate")
def main(cfg) -> None:
    from billiards.bench.cli import run

    run(cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    guard_command_line()  # a command line that names code through Hydra fails here, before Hydra builds anything
    main()
