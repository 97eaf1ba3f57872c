"""Training: SAC, TD3 and PPO on the billiards envs with TorchRL, configured by Hydra.

* :mod:`billiards.rl.config` -- the config schema (ConfigStore), validation, Hydra callback;
* :mod:`billiards.rl.learners` -- actors, critics, TorchRL losses, optimizers, target updates;
* :mod:`billiards.rl.train` -- the training loop (:func:`billiards.rl.train.train`);
* :mod:`billiards.rl.checkpoint`, :mod:`billiards.rl.metrics` -- checkpoints and metric logs.

Importing this package is cheap (no torch): ``train.py`` validates a command line before
it pays for importing the rest.
"""
