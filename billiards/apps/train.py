"""``python train.py`` / ``sagu train``: SAC, TD3, PPO or expert iteration (algo=exit)."""

import hydra
from omegaconf import DictConfig

from billiards.app_config import guard_command_line
from billiards.files import CONF_DIR
import billiards.rl.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)
import billiards.search.config  # noqa: F401  (registers the check of expert iteration's labelling search)


class JobFailed(RuntimeError):
    """A multirun job that could not run (an invalid config, a bad checkpoint): the job fails
    on its own and the sweeper decides what happens next (Optuna records the trial as failed)."""


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
def app(cfg: DictConfig) -> float:
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    from billiards.exit import train_exit
    from billiards.rl.train import train

    try:
        return train(cfg, loops={"exit": train_exit})
    except SystemExit as err:
        # train() exits on a bad config; in a multirun that would end every job with this one
        # (Hydra records only Exceptions as failed jobs), so it becomes this job's failure.
        if err.code in (None, 0) or HydraConfig.get().mode != RunMode.MULTIRUN:
            raise
        raise JobFailed(str(err.code)) from None


def main() -> None:
    guard_command_line()  # a command line that names code fails here, before Hydra builds anything
    app()
