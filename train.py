"""Train SAC, TD3, PPO or expert iteration (algo=exit) on Korean 4-ball billiards. The configuration lives in conf/.

    python train.py algo=sac env.paradigm=random_continue
    python train.py algo=td3 env=aim_features shaping=foul_penalty budget=paper seed=1
    python train.py experiment=table4                       # a paper table as one multirun
    python train.py resume=outputs/2026-01-01/12-00-00_sac  # continue a killed run
    python train.py --cfg job                               # print the composed config

Everything happens in :func:`billiards.rl.train.train`; this file only hands Hydra's config
over. Importing the library is deferred so that a bad command line fails within a second.
"""

import hydra
from omegaconf import DictConfig

from billiards.app_config import guard_command_line
import billiards.rl.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)
import billiards.search.config  # noqa: F401  (registers the check of expert iteration's labelling search)


class JobFailed(RuntimeError):
    """A multirun job that could not run (an invalid config, a bad checkpoint): the job fails
    on its own and the sweeper decides what happens next (Optuna records the trial as failed)."""


@hydra.main(version_base="1.3", config_path="conf", config_name="config")
def main(cfg: DictConfig) -> float:
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


if __name__ == "__main__":
    guard_command_line()  # a command line that names code fails here, before Hydra builds anything
    main()
