"""``python match.py`` / ``sagu match``: a league of two-player matches under execution noise."""

import hydra
from hydra.core.hydra_config import HydraConfig

from billiards.app_config import guard_command_line
from billiards.files import CONF_DIR
import billiards.league.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="match")
def app(cfg) -> None:
    from billiards.league import run

    run(cfg, HydraConfig.get().runtime.output_dir)


def main() -> None:
    guard_command_line()  # a command line that names code fails here, before Hydra builds anything
    app()
