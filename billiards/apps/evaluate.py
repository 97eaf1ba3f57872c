"""``python evaluate.py`` / ``sagu evaluate``: score any agent on a track of the benchmark."""

import hydra
from hydra.core.hydra_config import HydraConfig

from billiards.app_config import guard_command_line
from billiards.files import CONF_DIR
import billiards.bench.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="evaluate")
def app(cfg) -> None:
    from billiards.bench.cli import run

    run(cfg, HydraConfig.get().runtime.output_dir)


def main() -> None:
    guard_command_line()  # a command line that names code through Hydra fails here, before Hydra builds anything
    app()
