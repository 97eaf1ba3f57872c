"""The evaluation protocols, defined once: a StrEnum of their names and one description each.

Four protocols score an agent (docs/benchmark.md, docs/search.md):

* ``innings``: random-start innings of ``shots`` shots, continue-on-miss; points per inning
  (the paper's evaluation, and training's);
* ``p1``: the same innings, scored as success per shot (the paper's search protocol P1);
* ``p3``: chains from the opening rack, each until its first miss or foul or a cap; chain length;
* ``match``: two-player matches to a target under the rules of sagu; win rate and Elo.

Every package that plays, scores, reports or shows a protocol asks this registry what it needs
(how a unit starts, what one is called, which figure ranks it, what range one unit's score
takes) instead of comparing the protocol's name as a string: a new protocol is a member of
:class:`Protocol` and an entry of :data:`PROTOCOLS`, and the code that plays it (the benchmark's
``billiards.bench.protocols.PROTOCOLS``, keyed by this enum). The values are the names written in
configs, tracks, scorecards and run records, so reading a record needs no upgrade.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class Protocol(StrEnum):
    """A protocol's name (a ``str``: it compares, hashes and serialises as its value)."""

    INNINGS = "innings"
    P1 = "p1"
    P3 = "p3"
    MATCH = "match"

    @property
    def spec(self) -> ProtocolSpec:
        return PROTOCOLS[self]


@dataclass(frozen=True)
class ProtocolSpec:
    """What every user of a protocol needs to know of it."""

    kind: Protocol
    title: str  # how reports and logs name it
    start: str  # how a unit's table starts: random | canonical
    on_miss: str | None  # the env's on_miss for one-player protocols: continue | reset
    by_innings: bool  # units are innings played side by side in blocks (one value per inning)
    item: tuple[str, str]  # what one value is: (one, several)
    unit: tuple[str, str]  # what one resumable unit of the benchmark is: (one, several)
    metric: str  # the scorecard figure a leaderboard ranks it by
    metric_name: str  # that figure in words
    whole: bool  # one unit's score is a whole number
    two_player: bool = False

    def value_range(self, shots: int) -> tuple[float, float, bool]:
        """(lowest, highest, whole numbers only) of one value (an inning's points, an inning's
        success per shot, a chain's length, a match's score) when a unit plays ``shots`` shots
        (the chain cap for P3)."""
        if self.kind is Protocol.P1:
            return 0.0, 1.0, False
        if self.two_player:
            return 0.0, 1.0, False
        return 0, shots, True

    def words(self, n: int) -> str:
        """``n`` values in words: "1 chain", "40 matches"."""
        return f"{n:,} {self.item[0] if n == 1 else self.item[1]}"


PROTOCOLS: dict[Protocol, ProtocolSpec] = {
    Protocol.INNINGS: ProtocolSpec(Protocol.INNINGS, "innings", "random", "continue", True, ("inning", "innings"),
                                   ("inning block", "inning blocks"), "points_per_inning", "points per inning", True),
    Protocol.P1: ProtocolSpec(Protocol.P1, "P1", "random", "continue", True, ("inning", "innings"),
                              ("inning block", "inning blocks"), "success_per_shot", "success per shot", False),
    Protocol.P3: ProtocolSpec(Protocol.P3, "P3", "canonical", "reset", False, ("chain", "chains"), ("chain", "chains"),
                              "chain", "chain length (mean)", True),
    Protocol.MATCH: ProtocolSpec(Protocol.MATCH, "match", "canonical", None, False, ("match", "matches"),
                                 ("match", "matches"), "elo", "Elo", False, two_player=True),
}


def get_protocol(name) -> Protocol:
    """The protocol called ``name`` (a :class:`Protocol` or its value); a ValueError listing the
    protocols otherwise."""
    try:
        return Protocol(name)
    except ValueError:
        raise ValueError(f"unknown protocol {str(name)[:40]!r}; the protocols are {', '.join(p.value for p in Protocol)}") from None


def find_protocol(name) -> Protocol | None:
    """The protocol called ``name``, or None (a record read from a file may name anything)."""
    return Protocol._value2member_map_.get(name) if isinstance(name, str) else None
