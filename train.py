"""Train SAC, TD3 or PPO on Korean 4-ball billiards. The configuration lives in conf/.

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

import billiards.rl.config  # noqa: F401  (registers the schema and resolvers before Hydra composes)


@hydra.main(version_base="1.3", config_path="conf", config_name="config")
def main(cfg: DictConfig) -> float:
    from billiards.rl.train import train

    return train(cfg)


if __name__ == "__main__":
    main()
