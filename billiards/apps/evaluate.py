"""``python evaluate.py`` / ``sagu evaluate``: score any agent on a track of the benchmark."""

import hydra
from hydra.core.hydra_config import HydraConfig

from billiards.app_config import guard_command_line
from billiards.files import CONF_DIR
import billiards.bench.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="evaluate")
def app(cfg) -> None:
    from hydra.types import RunMode

    from billiards.bench.cli import run

    hydra_cfg = HydraConfig.get()
    if hydra_cfg.mode == RunMode.MULTIRUN:  # a job of a sweep: its own out= (an interpolation of the swept keys), its own command
        job = [f"out={cfg.out}" if o.startswith("out=") else o for o in hydra_cfg.overrides.task]  # out= resolved
        run(cfg, cfg.out or hydra_cfg.runtime.output_dir, job_overrides=job)
    else:
        run(cfg, hydra_cfg.runtime.output_dir)


def main() -> None:
    guard_command_line()  # a command line that names code through Hydra fails here, before Hydra builds anything
    app()
