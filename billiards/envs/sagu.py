"""Two-player Korean 4-ball (sagu): a match, as a PettingZoo AEC environment (``billiards.envs.sagu_v0``).

Each player has a cue ball: ``white`` (ball 0) and ``yellow`` (ball 1); the two reds are
balls 2 and 3. The player to move strikes their own cue ball; the other cue ball is their foul
ball. One shot of a player scores a point when their cue ball touches both reds and never the
opponent's ball, is a foul when it touches the opponent's ball, and is a miss otherwise
(:func:`billiards.physics.rules.carom_outcome`, the same rule as the single-player envs).

**Either cue ball strikes** without a second simulator: the simulator's shooter is ball 0, so
a yellow shot is simulated on the table with the two cue balls' slots swapped
(:func:`shooter_view`) and swapped back afterwards. The balls are identical in mass and size, so
the swap only relabels them; a white shot is exactly the single-player env's shot.

**Turns**: a player shoots until a miss or a foul, then the turn passes (an *inning*). A foul
costs ``foul_penalty`` points (never below 0). The first to ``target`` points wins (the match
terminates); after ``max_innings`` innings it is truncated (a draw unless the scores differ).

**Observation** of each player, from their own point of view (own cue ball first): the
single-player observation of that view (:func:`billiards.domain.observation`: 28 floats, 32 with
``extra_features``), then own score / target, the opponent's score / target, and the execution
noise's level (its aim sigma over fastfiz's: 0 exact, 1 fastfiz, 5 fastfiz_x5). Under variable
noise (``noise="variable"``) it is the level of the next shot (fastfiz's sigmas times a level
drawn per shot from [0, 5]), drawn from the match's generator as the table is set (on reset and
after each shot) and played by that shot.

**Action**: the normalised x in [-1, 1]^4 of the gymnasium env (theta, power, tip a, b; with
``constrain_aim`` the first coordinate is u, the aim relative to the shooter's nearest red).

**Reward**: zero-sum, the change of (own score - opponent's score) by the shot: a score is +1
for the shooter and -1 for the other, a foul -penalty and +penalty (as far as the shooter had
points to lose).
"""

from __future__ import annotations

import gymnasium
import numpy as np

from billiards import domain
from billiards.physics import get_params
from billiards.physics.checks import integer, one_of
from billiards.physics.noise import get_noise, noise_level

from ._common import MAX_SHOTS, check_flag, initial_racks, play_shots, unnormalize_checked, validate_action

AGENTS = ("white", "yellow")
SWAP = np.array([1, 0, 2, 3])  # the cue balls' slots exchanged: yellow's view, and back
STARTS = ("canonical", "random")
EXTRA_OBS = 3  # own score / target, opponent score / target, noise level
MAX_NOISE_LEVEL = 10.0


def shooter_view(positions: np.ndarray, shooter: int) -> np.ndarray:
    """The table with ``shooter``'s cue ball in slot 0 (0: white, as is; 1: yellow, the cue balls
    swapped). Its own inverse; works on (..., 4, 2) arrays."""
    return positions if shooter == 0 else positions[..., SWAP, :]


def noise_cap_error(noise) -> str | None:
    """What is wrong with a match's noise (a noise model) if its highest level passes the
    observation's bound (:data:`MAX_NOISE_LEVEL` times fastfiz's aim sigma), else None."""
    top = noise_level(noise) * (noise.level_range[1] if noise.is_variable else 1.0)
    return f"noise: at most {MAX_NOISE_LEVEL:g} times fastfiz's aim sigma, got {top:g}" if top > MAX_NOISE_LEVEL else None


class SaguEnv:
    """The match; wrapped as a PettingZoo ``AECEnv`` by :func:`billiards.envs.sagu_v0.raw_env`
    (this class holds the game, the wrapper the API). See the module docstring for the rules."""

    def __init__(self, *, target: int = 10, max_innings: int = 200, start: str = "canonical", foul_penalty: float = 1.0,
                 noise=None, physics=None, constrain_aim: bool = False, extra_features: bool = False):
        self.target = integer(target, "target", 1, MAX_SHOTS)
        self.max_innings = integer(max_innings, "max_innings", 1, MAX_SHOTS)
        self.start = one_of(start, "start", STARTS)
        self.foul_penalty = domain.check_coefficient("foul_penalty", foul_penalty)
        self.noise, self.params = get_noise(noise), get_params(physics)
        self.constrain_aim = check_flag("constrain_aim", constrain_aim)
        self.extra_features = check_flag("extra_features", extra_features)
        low, high = domain.action_bounds(self.constrain_aim, True)
        self.action_space = gymnasium.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        low, high = domain.observation_bounds(self.params, self.extra_features)
        self.observation_space = gymnasium.spaces.Box(
            np.concatenate([low, np.zeros(EXTRA_OBS, np.float32)]),
            np.concatenate([high, np.array([1.0, 1.0, MAX_NOISE_LEVEL], np.float32)]), dtype=np.float32)
        self.base_level = noise_level(self.noise)
        if err := noise_cap_error(self.noise):
            raise ValueError(err)
        # variable noise: the next shot's multiplier of the noise's sigmas (None for fixed noise)
        self.shot_level = 0.0 if self.noise.is_variable else None
        self.positions = initial_racks(np.random.default_rng(0), "canonical", 1, self.params)[0]
        self.scores = [0.0, 0.0]
        self.mover, self.innings, self.shots = 0, 1, 0
        self.last_shot = None

    @property
    def level(self) -> float:
        """The noise level the observations tell (fastfiz's aim sigma = 1): of the next shot under
        variable noise."""
        return self.base_level * (1.0 if self.shot_level is None else self.shot_level)

    def _draw_level(self, rng: np.random.Generator) -> None:
        if self.noise.is_variable:
            self.shot_level = float(self.noise.draw_levels((1,), rng)[0])

    def reset(self, rng: np.random.Generator, first: int = 0) -> None:
        self.positions = initial_racks(rng, self.start, 1, self.params)[0]
        self._draw_level(rng)
        self.scores, self.mover, self.innings, self.shots, self.last_shot = [0.0, 0.0], int(first), 1, 0, None

    def observe(self, player: int) -> np.ndarray:
        view = shooter_view(self.positions, player)
        base = domain.observation(view[None], self.extra_features)[0]
        own, other = self.scores[player] / self.target, self.scores[1 - player] / self.target
        return np.concatenate([base, np.array([min(own, 1.0), min(other, 1.0), self.level], np.float32)]).astype(np.float32)

    def shoot(self, action, rng: np.random.Generator) -> dict:
        """The mover plays ``action``; returns the shot's facts (score, foul, the points changed,
        whether the turn passes and whether the match is over)."""
        player = self.mover
        view = shooter_view(self.positions, player)
        act = unnormalize_checked(validate_action(action, (domain.ACTION_DIM,))[None], self.constrain_aim)
        commanded = domain.raw_action(act, view[None], self.params.ball_radius, self.constrain_aim)
        shots = play_shots(view[None], commanded, np.array([0]), params=self.params, noise=self.noise, rng=rng,
                           on_miss="continue", max_shots=2,
                           levels=None if self.shot_level is None else np.array([self.shot_level]))
        self._draw_level(rng)
        res = shots.result
        score, foul = bool(res.score[0]), bool(res.foul[0])
        before = self.scores[player]
        if score:
            self.scores[player] += 1.0
        elif foul:
            self.scores[player] = max(0.0, before - self.foul_penalty)
        gained = self.scores[player] - before
        self.last_shot = (self.positions, shots.played[0], player)
        self.positions = shooter_view(res.positions[0], player)
        self.shots += 1
        won = self.scores[player] >= self.target
        passes = not score and not won
        if passes:
            self.mover, self.innings = 1 - player, self.innings + 1
        return {"player": player, "score": score, "foul": foul, "gained": gained, "passes": passes, "won": won,
                "over_limit": passes and self.innings > self.max_innings,
                "hits": res.hits[0].astype(bool), "raw_action": shots.played[0].astype(np.float64),
                "commanded_action": commanded[0].astype(np.float64)}


__all__ = ["AGENTS", "MAX_NOISE_LEVEL", "SWAP", "SaguEnv", "noise_cap_error", "noise_level", "shooter_view"]
