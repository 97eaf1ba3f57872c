"""Inference-time search: `python search.py proposer=near_miss search=h2 protocol=p3`.

Thin entry point: composes conf/search.yaml and calls billiards.search.run.
"""

import hydra
from hydra.core.hydra_config import HydraConfig

from billiards.search.config import register

register()


@hydra.main(version_base="1.3", config_path="conf", config_name="search")
def main(cfg) -> None:
    from billiards.search.run import run

    run(cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    main()
