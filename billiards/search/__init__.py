"""Inference-time search with the simulator as verifier: depth-2 lookahead and PUCT."""

from .actors import LookaheadActor, PUCTActor, SearchActor, make_search_collector
from .lookahead import H2Config, SearchResult, h2_search, verifier_reward
from .proposers import GeometricProposer, PolicyProposer, Proposer
from .puct import PUCTConfig, puct_search

__all__ = [
    "GeometricProposer", "H2Config", "LookaheadActor", "PUCTActor", "PUCTConfig", "PolicyProposer", "Proposer",
    "SearchActor", "SearchResult", "h2_search", "make_search_collector", "puct_search", "verifier_reward",
]
