"""The benchmark: tracks, one evaluation for any agent, scorecards and the leaderboard
(docs/benchmark.md).

    import billiards.bench as bench
    card = bench.evaluate(my_act, "p1-exact-v1")          # a NumPy callable obs -> action: the scorecard, nothing written
    card = bench.evaluate("results/policies/base/seed0.pt", "innings-v1", out="outputs/eval/sac")  # ... and its files

``python evaluate.py track=<name> agent=<spec>`` is the same from the command line, and
``python -m billiards.bench leaderboard`` rebuilds ``results/leaderboard.md`` / ``.json``.
"""

from .adapters import Agent, AgentError, as_agent, resolve_agent
from .run import EvaluationError, evaluate
from .tracks import TRACKS, Track, get_track

__all__ = ["Agent", "AgentError", "EvaluationError", "TRACKS", "Track", "as_agent", "evaluate", "get_track", "resolve_agent"]
