"""Korean 4-ball billiards (sagu) as a reinforcement-learning benchmark."""

__version__ = "0.1.0"
