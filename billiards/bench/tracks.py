"""The benchmark's tracks: named, versioned evaluation protocols (docs/benchmark.md).

A track fixes everything that determines its numbers: the table (physics preset), the execution
noise (and, for ``variable``, that each shot's level is told to the agent), the protocol, how many
innings / chains / matches, the evaluation seeds, what the agent may use at decision time, and
a version. Its name ends in ``-v<N>``, the rule the env IDs follow too (``Billiards4Ball-v0``):
a change to the simulator, the envs or the track that changes any of its numbers gives it a new
``N``. Each track carries a fingerprint of its settings, its first racks and a reference agent's
first decisions (the nearest-red heuristic); ``tests/bench/test_bench.py`` recomputes it, so such a
change cannot go unnoticed.

Protocols:

* ``innings``: the paper's evaluation, ``units`` random-start innings of ``shots`` shots,
  continue-on-miss; points per inning (and per-shot success);
* ``p1``: per-shot success from random racks: ``units`` innings of ``shots`` shots each,
  continue-on-miss (every shot after the first plays from the table the previous one left);
* ``p3``: chains from the opening rack, one per seed, each until its first miss or foul or
  ``shots`` (the cap) scoring shots;
* ``match``: ``units`` matches to ``target`` against each reference opponent (league players of
  ``conf/match.yaml``), the break alternating; win rate and an Elo against the pool's fixed
  ratings (anchored to ``anchor``).

Seeds: inning or chain ``i`` plays with seed ``seed + i``; match ``i`` against opponent ``j``
with ``seed + 1000 j + i``. The seeds are held out: no training, tuning or reported run in the
repository used them (``tests/bench/test_bench.py`` checks every committed record).

Decision-time access: every agent sees the observation (the gymnasium env's); an agent that
searches with the simulator may use up to ``budget`` simulations per decision, counted and
reported on its scorecard (the leaderboard lists the two classes apart).
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

from billiards.protocol import Protocol, get_protocol

VERSION_RE = re.compile(r"^(?P<base>[a-z0-9][a-z0-9-]*?)-v(?P<version>\d+)$")


@dataclass(frozen=True)
class Track:
    """One evaluation protocol, fixed (see the module docstring)."""

    name: str  # "<base>-v<version>"
    protocol: Protocol  # innings | p1 | p3 | match (a name is turned into the member)
    description: str
    units: int  # innings (innings, p1), chains (p3), matches per opponent (match)
    shots: int = 10  # shots per inning (innings, p1); the chain cap (p3)
    seed: int = 0  # the first evaluation seed (held out)
    physics: str = "korean_medium"  # written out: a track fixes its table, whatever the package's default becomes
    noise: str = "none"  # a noise preset of conf/noise/
    tells_level: bool = False  # variable noise: the shot's level is the observation's last entry
    budget: int = 400  # simulations per decision an agent that searches may use
    block: int = 50  # innings per resumable unit (innings, p1), played side by side
    target: int = 10  # match: points to win
    opponents: tuple[str, ...] = ()  # match: the reference pool (league players by name)
    ratings: tuple[tuple[str, float], ...] = ()  # match: the pool's fixed Elo ratings
    anchor: str = ""  # match: the pool player whose rating defines the scale
    max_innings: int = 200  # match: innings before a match is called a draw
    fingerprint: str = ""  # sha256 over the first racks and the reference agent's first decisions

    def __post_init__(self):
        object.__setattr__(self, "protocol", get_protocol(self.protocol))

    @property
    def version(self) -> int:
        return int(VERSION_RE.match(self.name)["version"])

    @property
    def base(self) -> str:
        return VERSION_RE.match(self.name)["base"]

    @property
    def metric(self) -> str:
        """The number the leaderboard ranks this track by."""
        return self.protocol.spec.metric

    def seed_of(self, index: int) -> int:
        """The seed of inning, chain or match ``index`` (match i against opponent j is index
        ``j * units + i``): ``seed + index``, a match ``seed + 1000 j + i``."""
        if self.protocol.spec.two_player:
            j, i = divmod(index, self.units)
            return self.seed + 1000 * j + i
        return self.seed + index

    def seeds(self) -> list[int]:
        """Every evaluation seed the track plays (innings, chains or matches)."""
        n = self.units * (len(self.opponents) if self.protocol.spec.two_player else 1)
        return [self.seed_of(k) for k in range(n)]

    def n_blocks(self) -> int:
        """Resumable units: blocks of innings, chains or matches."""
        if self.protocol.spec.by_innings:
            return -(-self.units // self.block)
        return len(self.seeds())

    def rules(self) -> str:
        """The track's rules in one line (docs, scorecards, ``--help``)."""
        noise = "exact play" if self.noise == "none" else f"noise {self.noise}" + (" (level told)" if self.tells_level else "")
        what = {
            Protocol.INNINGS: f"{self.units} random-start innings x {self.shots} shots, continue-on-miss; points per inning",
            Protocol.P1: f"{self.units} random-start innings x {self.shots} shots, continue-on-miss; per-shot success",
            Protocol.P3: f"{self.units} chains from the opening rack to the first miss or foul, cap {self.shots}; chain length",
            Protocol.MATCH: (f"{self.units} matches to {self.target} against each of {', '.join(self.opponents)} (break "
                             f"alternating); win rate and Elo ({self.anchor} = {dict(self.ratings).get(self.anchor, 0):.0f})"),
        }[self.protocol]
        return f"{what}; {noise}, {self.physics}; seeds from {self.seed:,}; search budget {self.budget} sims/decision"

    def record(self) -> dict:
        """The track as a JSON record (scorecards)."""
        rec = dataclasses.asdict(self)
        rec.update(version=self.version, opponents=list(self.opponents), ratings=dict(self.ratings))
        return rec

    def unit_range(self) -> tuple[float, float, bool]:
        """(lowest, highest, whole numbers only) of one unit's score (a scorecard's ``values``):
        points per inning in [0, shots], an inning's success per shot in [0, 1], a chain's length
        in [0, the cap], a match's score 0, 0.5 or 1."""
        return self.protocol.spec.value_range(self.shots)

    def n_values(self) -> int:
        """How many unit scores a whole evaluation of the track has (innings, chains or matches)."""
        return len(self.seeds())

    def values_problem(self, values, count: int | None = None) -> str | None:
        """What is wrong with ``values`` as this track's per-unit scores, or None: a list of
        ``count`` (when given) real, finite numbers, each within :meth:`unit_range` (and a match's
        0, 0.5 or 1)."""
        if not isinstance(values, list):
            return f"its unit scores must be a list of numbers, not {type(values).__name__}"
        if count is not None and len(values) != count:
            return f"{len(values)} unit scores, but a whole evaluation of {self.name} has {count}"
        lo, hi, whole = self.unit_range()
        for i, v in enumerate(values):
            why = number_problem(v, lo, hi, whole)
            if why is None and self.protocol.spec.two_player and v not in (0, 0.5, 1):
                why = "not a match's score (1 a win, 0.5 a draw, 0 a loss)"
            if why is not None:
                return f"unit score {i} ({str(v)[:40]}): {why} on {self.name}"
        return None

    def scaled(self, units: int) -> Track:
        """The same track cut to its first ``units`` innings / chains / matches per opponent (a
        quick look or a test; its scorecard is marked ``limit`` and never enters the leaderboard)."""
        if not 1 <= units <= self.units:
            raise ValueError(f"limit must lie in 1..{self.units} for track {self.name}, got {units}")
        return dataclasses.replace(self, units=units)


# The match pool's ratings: greedy (robust search over the fastfiz_x5 ranker) anchors the scale at
# 1500; greedy_r's is the rating that explains its score against greedy in the committed league
# results/sagu/fastfiz_x5_run (0.5675 of their 400 matches; billiards.stats.elo_against).
_MATCH_RATINGS = (("greedy", 1500.0), ("greedy_r", 1547.1))

# The ranking match track's pool: the league's strongest players under fastfiz_x5 (each beat greedy
# in 56-63 % of 400 matches; results/sagu/README.md) and greedy, whose rating anchors the scale at
# 1500. Their ratings are the Bradley-Terry fit of their round robin, 100 matches per pair
# (results/sagu/fastfiz_x5_pool, league.json's ``elo`` and ``elo_ci95``), shifted so that greedy
# is 1500; a test recomputes them from that league's matches.
POOL_LEAGUE = "results/sagu/fastfiz_x5_pool"
_POOL_RATINGS = (("greedy", 1500.0), ("greedy_v", 1560.6), ("safety_v", 1552.5), ("greedy_r", 1566.4), ("safety_r", 1580.2),
                 ("safety_rx", 1589.5))

BUDGETS = (25, 50, 100)  # the compute-limited exact tracks' simulations per decision (the others allow 400)
_BUDGET_FINGERPRINTS = {
    "innings-b25-v1": "5e393765cb7f99656c5166009c6b5873b4b6f8870a4b58a7faef86b249c4b68d",
    "innings-b50-v1": "3cb3ad291203d8bfa0bae0f0bb3c599d9be6ea0543c018f3ce2068ab9633c733",
    "innings-b100-v1": "818516af714c22a6b46f5a99e726fa3293d27f9b4fa54da752e069d1ec655d78",
    "p1-exact-b25-v1": "77680b45010cb991750be00b6ae2aa9ca08954f8a0c74c98e8748127e974b634",
    "p1-exact-b50-v1": "c9477ccf6c7f22e75a2f28e8e1ca6171a504a2c946e47d3711fa73e65e4ebe03",
    "p1-exact-b100-v1": "714f019cdf7008dd46f488914351147706663c768f549011f136d34cbcb259a9",
    "p3-exact-b25-v1": "ab8d521d3ef1d636a968069d8c144abc5a5118ae3cd63fb3c969d4c36e98d916",
    "p3-exact-b50-v1": "bac0e970fcf2de07e3cc8c40b54ffa0b4eb96d77622288205efa253f774fbb13",
    "p3-exact-b100-v1": "6b9b5d5865c4b8e2c907389dbec8d047404d92d22a6a1f76e18ebd1b5fdf5e68",
}

_EXACT: tuple[Track, ...] = (
    Track("innings-v1", Protocol.INNINGS, "The paper's evaluation protocol: points per 10-shot inning from random racks, exact play",
          units=100, shots=10, seed=7_100_000,
          fingerprint="a2f0dab7360af71310fa73a116ad68180829a025e5cc4b1c905e7f83fbc0286b"),
    Track("p1-exact-v1", Protocol.P1, "Per-shot success from random racks, exact play",
          units=100, shots=20, seed=7_200_000,
          fingerprint="cfc0f8ff7ff57815fe1d4eda320562dc2d7589f2e553dc96acfc7668c57df251"),
    Track("p3-exact-v1", Protocol.P3, "Chains from the opening rack, exact play",
          units=20, shots=1000, seed=7_300_000,
          fingerprint="ed89d0bb2a977de82ed0d01dcbb269e036fc547adabafb6fdf5f9c326f2bb17b"),
)
# the exact tracks at small budgets: each one's racks and seeds, the search budget cut to 25, 50
# and 100 simulations per decision (how cheaply search solves the game); what each is called there
_LIMITED_WHAT = {"innings": "Points per 10-shot inning from random racks, exact play"}


def _at_budget(t: Track, budget: int) -> Track:
    name = f"{t.base}-b{budget}-v1"
    return dataclasses.replace(t, name=name, budget=budget, fingerprint=_BUDGET_FINGERPRINTS.get(name, ""),
                               description=f"{_LIMITED_WHAT.get(t.base, t.description)} at {budget} simulations per decision")


# each exact track's compute curve: its compute-limited versions, cheapest first, then itself
_CURVES: dict[str, tuple[Track, ...]] = {t.base: (*(_at_budget(t, b) for b in BUDGETS), t) for t in _EXACT}

_REGISTRY: tuple[Track, ...] = (
    *_EXACT,
    *(t for curve in _CURVES.values() for t in curve[:-1]),
    Track("p3-exact-long-v1", Protocol.P3, "Long chains from the opening rack, exact play (for the searches that reach p3-exact-v1's cap)",
          units=10, shots=10_000, seed=7_900_000, fingerprint="a576e51d7fb07fc6b08b022359f57397ab3e058c0bc6056df4e012bc591ec356"),
    Track("p1-fastfiz-v1", Protocol.P1, "Per-shot success from random racks under fastfiz execution noise",
          units=100, shots=20, seed=7_400_000, noise="fastfiz",
          fingerprint="3af43f59e5a5084ad25b11190a174655d1a4abe04fb3bdcabe171e19c4c9c3da"),
    Track("p3-fastfiz-v1", Protocol.P3, "Chains from the opening rack under fastfiz execution noise",
          units=50, shots=1000, seed=7_500_000, noise="fastfiz",
          fingerprint="cd0e39edc0b7e1ff86c825ae55dc85313af0873d4f30995f7808e41000b6c996"),
    Track("p1-x5-v1", Protocol.P1, "Per-shot success from random racks under five times fastfiz's noise",
          units=100, shots=20, seed=7_600_000, noise="fastfiz_x5",
          fingerprint="e0b426743600da4d2ff5c6f179aa4ee38c24114355790ad23298d756757ea22b"),
    Track("p1-variable-v1", Protocol.P1, "Per-shot success from random racks, each shot's noise level drawn in [0, 5] x fastfiz and told",
          units=100, shots=20, seed=7_700_000, noise="variable", tells_level=True,
          fingerprint="21f58dd0847e89d3fe80b44fa3f9a2aef6bfea353ef75824e021e3cb52a1b886"),
    Track("match-x5-v1", Protocol.MATCH, "Matches to 10 under fastfiz_x5 against the reference pool",
          units=10, seed=7_800_000, noise="fastfiz_x5", opponents=("greedy", "greedy_r"), ratings=_MATCH_RATINGS,
          anchor="greedy", fingerprint="5e6bf1ae696bf9691ae21d6706926dd3187da7476a94e0415db3e8d8ce680657"),
    # a match track that ranks: 100 matches against each of the league's strongest (a Wilson
    # half-width of at most 10 points per opponent), Elo against the pool's round-robin ratings
    Track("match-x5-v2", Protocol.MATCH, "Matches to 10 under fastfiz_x5 against the league's strongest players, 100 per opponent",
          units=100, seed=8_000_000, noise="fastfiz_x5", opponents=tuple(n for n, _ in _POOL_RATINGS), ratings=_POOL_RATINGS,
          anchor="greedy", fingerprint="1d022bbde07ca64123d78c68d8ffa62c2103baacbcdd7f1acb027800cb35782a"),
)

TRACKS: dict[str, Track] = {t.name: t for t in _REGISTRY}
# each exact track and its compute-limited versions, cheapest first: one compute curve each
COMPUTE_CURVES: dict[str, tuple[str, ...]] = {base: tuple(t.name for t in curve) for base, curve in _CURVES.items()}


def is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def number_problem(v, lo: float, hi: float, whole: bool) -> str | None:
    """Why ``v`` is not a real, finite number in [lo, hi] (a whole one where ``whole``), or None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return f"not a number but {type(v).__name__}"
    if not math.isfinite(v):
        return "not a finite number"
    if whole and not float(v).is_integer():
        return "not a whole number"
    if not lo <= v <= hi:
        return f"outside [{lo:g}, {hi:g}]"
    return None


def get_track(track) -> Track:
    """A track by name (or the Track itself); an unknown name is an error listing the tracks."""
    if isinstance(track, Track):
        return track
    if track not in TRACKS:
        raise ValueError(f"unknown track {track!r}; tracks: {', '.join(TRACKS)}")
    return TRACKS[track]


def track_help() -> str:
    """One line per track (``python evaluate.py --help``)."""
    return "\n".join(f"  {t.name}: {t.rules()}" for t in TRACKS.values())


__all__ = ["BUDGETS", "COMPUTE_CURVES", "POOL_LEAGUE", "TRACKS", "Track", "get_track", "is_int", "number_problem", "track_help"]
