"""Korean 4-ball billiards (sagu) as a reinforcement-learning benchmark."""

import os

# numba hands vectorised math to Intel's SVML when the optional icc_rt package is installed, and
# SVML rounds differently from the C library: set before any part of the package loads numba, so
# the simulator and billiards.numerics compute the same bits on every machine
os.environ.setdefault("NUMBA_DISABLE_INTEL_SVML", "1")

__version__ = "0.1.0"
