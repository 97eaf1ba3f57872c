"""``python search.py`` / ``sagu search``: inference-time search on P1 or P3."""

import hydra
from hydra.core.hydra_config import HydraConfig

from billiards.app_config import guard_command_line
from billiards.files import CONF_DIR
import billiards.search.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="search")
def app(cfg) -> None:
    from billiards.search.run import run

    run(cfg, HydraConfig.get().runtime.output_dir)


def main() -> None:
    guard_command_line()  # a command line that names code fails here, before Hydra builds anything
    app()
