"""Inference-time search with the simulator as verifier: depth-2 lookahead and PUCT.

Names are imported lazily (PEP 562), so ``billiards.search.report`` -- used by
``python -m billiards.report`` -- loads without torch, TorchRL or the simulator.
"""

from importlib import import_module

_WHERE = {
    "LookaheadActor": "actors", "PUCTActor": "actors", "SearchActor": "actors", "make_search_collector": "actors",
    "SearchResult": "lookahead", "h2_search": "lookahead", "verifier_reward": "lookahead",
    "GeometricProposer": "proposers", "PolicyProposer": "proposers", "Proposer": "proposers",
    "load_policy_proposer": "proposers",
    "puct_search": "puct", "puct_reference": "puct_reference",
    "NoisyPUCTActor": "actors", "RobustActor": "actors", "robust_search": "robust",
    "noisy_puct_search": "puct_noise",
    "H2Config": "settings", "PUCTConfig": "settings", "RobustConfig": "settings", "SearchSettings": "settings",
}
__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{_WHERE[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
