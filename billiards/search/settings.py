"""The options of each search method: one dataclass per method, what the search runs with and
the schema ``search.py`` composes (``search=h2|puct|robust``, :data:`billiards.search.config.OPTIONS`).

* :class:`SearchSettings` -- what every method shares (``kind``, ``budget``, ``gamma``,
  ``foul_penalty``) and the checks: :meth:`~SearchSettings.check` raises a ValueError naming
  the first knob out of its range, :meth:`~SearchSettings.errors` lists every problem for the
  app (the budget, each key's upper bound in ``UPPER``, then ``check``);
* :class:`H2Config` (:mod:`billiards.search.lookahead`), :class:`PUCTConfig`
  (:mod:`billiards.search.puct`, :mod:`billiards.search.puct_noise`) and :class:`RobustConfig`
  (:mod:`billiards.search.robust`).

An object is not checked when it is made (the app makes one from a config node to list its
problems); the search functions check the one they are given, and :meth:`~SearchSettings.settings`
is the object checked. The module imports no simulator code, so the app's schema loads fast.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Optional

from billiards.physics.checks import finite_number

VERIFIER_FOUL_PENALTY = 1.0  # the paper's verifier: aim constraint + features + foul penalty 1.0

# ----------------------------------------------------------------------------- bounds
#
# Every count and weight of a search has a finite upper bound, written once in its schema's
# ``UPPER`` (key -> (bound, why); :func:`billiards.app_config.upper_bound_errors`) and listed in
# docs/reliability.md ("Numbers with bounds after resolution").
MAX_SEARCH = 10**5  # simulations per decision, and every count a decision spends them on
MAX_WEIGHT = 100.0  # a weight in points (a score is worth 1)
SIMS = (MAX_SEARCH, "simulations per decision")
COUNT = (MAX_SEARCH, "at most the simulations of a decision")
WEIGHT = (MAX_WEIGHT, "points; a score is worth 1")

SCHEDULES = ("uniform", "halving")
VALUE_COMMAND = "python -m billiards.search.value --out results/values/value.pt --states 100000 --pool 500 --top 24"


@dataclass
class SearchSettings:
    """What every search method's options share: ``kind`` names the method (each subclass
    sets its own), ``budget`` simulations per decision, the discount ``gamma`` and the verifier's
    ``foul_penalty``; and the checks."""

    kind: str
    budget: int = 400
    gamma: float = 0.99
    foul_penalty: float = VERIFIER_FOUL_PENALTY

    UPPER: ClassVar[dict] = {}  # key -> (upper bound, why); each method lists its own

    def check(self) -> None:
        """Raise a ValueError naming the first knob out of the range the search needs."""
        raise NotImplementedError

    def _check_discount(self) -> None:
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must lie in [0, 1], got {self.gamma}")
        finite_number(self.foul_penalty, "foul_penalty", 0.0)  # billiards.domain.check_coefficient

    def settings(self):
        """This object, checked (:meth:`check`): what its actor searches with."""
        self.check()
        return self

    def errors(self) -> list[str]:
        """Every problem for the app, each naming its key: the budget, each key's upper bound
        (``UPPER``), then the knobs' ranges as :meth:`check` sees them."""
        from billiards.app_config import upper_bound_errors

        if self.budget < 1:
            return [f"search.budget must be >= 1, got {self.budget}"]
        errs = upper_bound_errors(self, "search.", self.UPPER)
        try:
            self.check()
        except ValueError as err:
            errs.append(f"search ({self.kind}): {err}")
        return errs


@dataclass
class H2Config(SearchSettings):
    """Greedy depth-2 K-expansion (paper §5, :func:`billiards.search.lookahead.h2_search`):
    ``budget`` = k1 + m1 * k2 simulations per shot, K2 derived from the budget (:attr:`k2`)."""

    kind: str = "h2"
    k1: int = 200
    m1: int = 10

    UPPER = {"budget": SIMS, "k1": COUNT, "m1": COUNT, "foul_penalty": WEIGHT}

    @classmethod
    def from_budget(cls, budget: int, k1: int, m1: int, **kw) -> "H2Config":
        """The checked config splitting ``budget`` simulations per decision: K2 = (budget - K1) / M1."""
        return cls(budget=budget, k1=k1, m1=m1, **kw).settings()

    def split_for(self, budget: int) -> tuple[int, int]:
        """(k1, m1) for ``budget`` simulations per shot, scaled from this split (k1 and m1 in
        proportion, at least one candidate and one expansion where this split expands; k1
        lowered until ``budget - k1`` is a multiple of m1): how a benchmark track's budget sizes
        h2 (400 = 200 + 10 x 20 gives 25 = 12 + 1 x 13, 50 = 25 + 1 x 25, 100 = 50 + 2 x 25)."""
        if budget < 1:
            raise ValueError(f"h2 search needs a budget >= 1, got {budget}")
        ratio = budget / self.budget
        k1 = min(budget, max(1, round(self.k1 * ratio)))
        m1 = 0 if self.m1 == 0 or k1 == budget else min(k1, max(1, round(self.m1 * ratio)))
        if m1 == 0:
            return budget, 0
        while (budget - k1) % m1:
            k1 -= 1
        return k1, m1

    @property
    def k2(self) -> int:
        """Children per expanded candidate: (budget - k1) / m1 (0 without expansion)."""
        return 0 if self.m1 == 0 else (self.budget - self.k1) // self.m1

    @property
    def sims_per_decision(self) -> int:
        return self.k1 + self.m1 * self.k2

    def check(self) -> None:
        if self.m1 == 0:
            if self.budget != self.k1:
                raise ValueError(f"without expansion (m1=0) the budget {self.budget} must equal k1={self.k1}")
        else:
            rest = self.budget - self.k1
            if rest < 0 or rest % self.m1:
                raise ValueError(f"budget {self.budget} - k1 {self.k1} = {rest} is not a non-negative multiple of m1={self.m1}")
        if self.k1 < 1 or self.m1 < 0 or self.k2 < 0:
            raise ValueError(f"h2 search needs k1 >= 1, m1 >= 0, k2 >= 0; got k1={self.k1}, m1={self.m1}, k2={self.k2}")
        if self.m1 > self.k1:
            raise ValueError(f"h2 search cannot expand m1={self.m1} of only k1={self.k1} candidates")
        self._check_discount()


@dataclass
class PUCTConfig(SearchSettings):
    """PUCT over sampled continuous actions (:mod:`billiards.search.puct`): ``budget``
    simulations per shot, progressive widening (pw_c, pw_alpha) over ``pool`` proposer samples
    per node."""

    kind: str = "puct"
    c_puct: float = 1.0
    pw_c: float = 1.0
    pw_alpha: float = 0.5
    pool: int = 16  # prior samples drawn when a node is created (more on demand)
    max_depth: int = 8

    UPPER = {"budget": SIMS, "pool": COUNT, "max_depth": (1000, "plies of a tree"),
             "c_puct": (100.0, "an exploration weight"), "pw_c": (100.0, "a widening coefficient"), "foul_penalty": WEIGHT}

    @property
    def sims_per_decision(self) -> int:
        return self.budget

    def check(self) -> None:
        if self.budget < 1 or self.pool < 1 or self.max_depth < 1:
            raise ValueError(f"PUCT needs budget, pool and max_depth >= 1; got {self.budget}, {self.pool}, {self.max_depth}")
        finite = all(math.isfinite(v) for v in (self.c_puct, self.pw_c, self.pw_alpha, self.gamma))
        if not finite or self.c_puct < 0 or self.pw_c <= 0 or not 0 < self.pw_alpha <= 1:
            raise ValueError(f"PUCT needs finite c_puct >= 0, pw_c > 0 and 0 < pw_alpha <= 1; got c_puct={self.c_puct}, "
                             f"pw_c={self.pw_c}, pw_alpha={self.pw_alpha}")
        self._check_discount()


@dataclass
class RobustConfig(SearchSettings):
    """Noise-aware search (:mod:`billiards.search.robust`): each candidate scored by its verifier
    reward over noisy replays; ``budget`` = [k1 exact screen] + noisy samples + m1 * k2
    simulations per shot. Needs execution noise (``noise=fastfiz|fastfiz_x5|variable``; under
    variable noise it replays each shot at the level the env told with it)."""

    kind: str = "robust"
    k1: int = 300
    samples: int = 4  # schedule=uniform: noisy samples per candidate (k1 * samples + m1 * k2 = budget)
    schedule: str = "halving"  # uniform | halving (successive halving over the candidates left)
    screen: bool = True  # one exact simulation per candidate first; only scoring ones get noisy samples
    quantile: Optional[float] = None  # the candidate's statistic over its samples: null = mean, else this quantile
    m1: int = 0
    k2: int = 0  # children per expanded candidate
    # adaptive screen: stop screening a state once `target` candidates score (0: all k1 at once;
    # no screen, screen=false: unused)
    target: int = 10
    wave: int = 50  # candidates per screening wave when target > 0
    antithetic: bool = False  # noisy samples in antithetic pairs (z, -z)
    position: float = 0.0  # position play: a replay that scores is worth 1 + position * V(its leave)
    leave: float = 0.0  # safety play (two-player): a replay that misses costs leave * V(the opponent's table)
    safeties: int = 0  # safety play: also weigh this many screened misses that leave the opponent the hardest table
    safety_draws: int = 0  # safety play: screen this many soft shots into a red's cone too, as safety candidates
    value: Optional[str] = None  # the table value file (billiards.search.value) that prices the leaves

    UPPER = {"budget": SIMS, **{key: COUNT for key in ("k1", "samples", "m1", "k2", "target", "wave", "safeties", "safety_draws")},
             **{key: WEIGHT for key in ("foul_penalty", "position", "leave")}}

    @property
    def sims_per_decision(self) -> int:
        return self.budget

    def check(self) -> None:
        if not (math.isfinite(self.position) and self.position >= 0 and math.isfinite(self.leave) and self.leave >= 0):
            raise ValueError(f"position and leave must be finite weights >= 0; got position={self.position}, "
                             f"leave={self.leave}")
        if self.safeties < 0 or (self.safeties and not (self.leave and self.screen)):
            raise ValueError(f"safeties (safety shots replayed beside the scoring ones) must be >= 0 and need leave > 0 "
                             f"and the exact screen; got safeties={self.safeties}, leave={self.leave}, screen={self.screen}")
        if self.safety_draws < 0 or (self.safety_draws and not self.safeties):
            raise ValueError(f"safety_draws (soft shots screened as safety candidates) must be >= 0 and need "
                             f"safeties > 0; got safety_draws={self.safety_draws}, safeties={self.safeties}")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"robust search schedule must be one of {', '.join(SCHEDULES)}; got {self.schedule!r}")
        if self.target < 0 or self.wave < 1:
            raise ValueError(f"robust search needs target >= 0 and wave >= 1; got target={self.target}, wave={self.wave}")
        if self.budget < 1 or self.k1 < 1 or self.samples < 1 or self.m1 < 0 or self.k2 < 0:
            raise ValueError(f"robust search needs budget, k1, samples >= 1 and m1, k2 >= 0; got budget={self.budget}, "
                             f"k1={self.k1}, samples={self.samples}, m1={self.m1}, k2={self.k2}")
        if self.m1 > self.k1:
            raise ValueError(f"robust search cannot expand m1={self.m1} of only k1={self.k1} candidates")
        if self.quantile is not None and not (math.isfinite(self.quantile) and 0.0 <= self.quantile <= 1.0):
            raise ValueError(f"quantile must lie in [0, 1] (or be null: the mean), got {self.quantile}")
        self._check_discount()
        expand = self.m1 * self.k2
        if self.schedule == "uniform":
            if self.screen:
                raise ValueError("schedule=uniform gives every candidate `samples` noisy samples, so it takes "
                                 "screen=false (a screen leaves a varying number of candidates)")
            if self.k1 * self.samples + expand != self.budget:
                raise ValueError(f"schedule=uniform spends k1 * samples + m1 * k2 = {self.k1} * {self.samples} + "
                                 f"{self.m1} * {self.k2} = {self.k1 * self.samples + expand}, not the budget {self.budget}")
        else:
            rest = self.budget - expand - (self.k1 + self.safety_draws if self.screen else 0)
            need = 1 if self.screen else self.k1
            if rest < need:
                raise ValueError(f"schedule=halving leaves {rest} simulations for noisy samples after "
                                 f"{'the screen of k1=' + str(self.k1) + ' (+ safety_draws) and ' if self.screen else ''}"
                                 f"m1 * k2 = {expand}: it needs at least {need} of the budget {self.budget}")

    def errors(self) -> list[str]:
        """The knobs, and the table value file (loaded and checked now) where the leaves are priced."""
        errs = super().errors()
        if errs or not (self.position or self.leave):
            return errs
        from billiards.files import repo_path

        if self.value is None:
            return [f"search.position={self.position} / search.leave={self.leave} price the leaves with a table "
                    f"value: name its file, search.value=<file> (made by: {VALUE_COMMAND})"]
        if not Path(str(repo_path(self.value))).is_file():
            return [f"search.value: no table value file at {self.value} (made by: {VALUE_COMMAND})"]
        from .table_value import TableValue, ValueFileError

        try:
            TableValue.load(repo_path(self.value))
        except ValueFileError as err:
            return [f"search.value: {err}"]
        return []

    def table_value(self, params):
        """The table value pricing the leaves (None where no weight is set); one trained on
        another table warns (PhysicsMismatchWarning)."""
        if not (self.position or self.leave):
            return None
        from billiards.files import repo_path
        from billiards.physics.config import warn_physics_mismatch

        from .table_value import TableValue

        value = TableValue.load(repo_path(self.value))
        warn_physics_mismatch(f"search.value ({self.value})", value.params, params)
        return value


__all__ = ["COUNT", "H2Config", "MAX_SEARCH", "MAX_WEIGHT", "PUCTConfig", "RobustConfig", "SCHEDULES", "SIMS",
           "SearchSettings", "VALUE_COMMAND", "VERIFIER_FOUL_PENALTY", "WEIGHT"]
