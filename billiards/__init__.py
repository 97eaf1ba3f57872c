"""Korean 4-ball billiards (sagu) as a reinforcement-learning benchmark."""

import os

# numba hands vectorised math to Intel's SVML when the optional icc_rt package is installed, and
# SVML rounds differently from the C library: set before any part of the package loads numba, so
# the simulator and billiards.numerics compute the same bits on every machine
os.environ.setdefault("NUMBA_DISABLE_INTEL_SVML", "1")

__version__ = "0.2.0"

# The gymnasium env IDs, registered on ``import billiards`` (so ``gym.make("billiards:Billiards4Ball-v0")``
# works without another import) by name only: the env's modules load when an env is made. IDs
# and benchmark tracks share one versioning rule: ``<name>-v<N>``, N bumped by any change that
# changes an agent's score (docs/benchmark.md).
GYM_ID = "Billiards4Ball-v0"


def _register_envs() -> None:
    import gymnasium

    if GYM_ID not in gymnasium.registry:
        gymnasium.register(id=GYM_ID, entry_point="billiards.envs.gym_env:Billiards4BallInningEnv",
                           vector_entry_point="billiards.envs.gym_vector:Billiards4BallVectorEnv")


_register_envs()
