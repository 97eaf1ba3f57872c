"""Train SAC, TD3, PPO or expert iteration (algo=exit) on Korean 4-ball billiards. The configuration lives in conf/.

    python train.py algo=sac env.paradigm=random_continue
    python train.py algo=td3 env=aim_features shaping=foul_penalty budget=paper seed=1
    python train.py experiment=table4                       # a paper table as one multirun
    python train.py resume=outputs/2026-01-01/12-00-00_sac  # continue a killed run
    python train.py --cfg job                               # print the composed config

Everything happens in :func:`billiards.rl.train.train`; the app (:mod:`billiards.apps.train`, the
same as ``sagu train`` after ``pip install sagu-bench``) only hands Hydra's config over.
"""

from billiards.apps.train import main

if __name__ == "__main__":
    main()
