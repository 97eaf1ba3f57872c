"""billiards.domain: hand-computed values of every formula."""

import math

import numpy as np
import pytest

from billiards import domain
from billiards.physics import DEFAULT_PARAMS, canonical_rack

R = DEFAULT_PARAMS.ball_radius


def rack(white, yellow, red1, red2):
    return np.array([white, yellow, red1, red2], dtype=np.float64)


# A hand-built rack: white (0.3, 0.3); red1 0.4 m straight up the table; red2 at (0.7, 0.7),
# i.e. a quarter turn clockwise from the white->red1 direction.
HAND = rack((0.3, 0.3), (1.1, 2.5), (0.3, 0.7), (0.7, 0.7))


def test_rest_observation_layout():
    obs = domain.rest_observation(HAND)
    assert obs.shape == (28,) and obs.dtype == np.float32
    per_ball = obs.reshape(4, 7)
    np.testing.assert_array_equal(per_ball[:, :2], HAND.astype(np.float32))
    np.testing.assert_array_equal(per_ball[:, 2:], 0.0)
    assert domain.rest_observation(np.stack([HAND] * 3)).shape == (3, 28)


def test_observed_positions_are_the_tables_an_observation_holds():
    batch = np.stack([HAND, HAND[[0, 1, 3, 2]]])
    for extra in (False, True):
        seen = domain.observed_positions(domain.observation(batch, extra))
        assert seen.shape == (2, 4, 2) and seen.dtype == np.float64
        np.testing.assert_array_equal(seen, batch.astype(np.float32))
    with pytest.raises(ValueError, match="at least 28"):
        domain.observed_positions(np.zeros((2, 27)))


def test_observation_is_the_rest_floats_then_the_carom_features():
    batch = np.stack([HAND, HAND[[0, 1, 3, 2]]])
    np.testing.assert_array_equal(domain.observation(batch), domain.rest_observation(batch))
    full = domain.observation(batch, extra_features=True)
    assert full.shape == (2, 32) and full.dtype == np.float32
    np.testing.assert_array_equal(full[:, :28], domain.rest_observation(batch))
    np.testing.assert_array_equal(full[:, 28:], domain.carom_features(batch).astype(np.float32))
    np.testing.assert_array_equal(domain.feature_observation(batch), full[:, 28:])
    np.testing.assert_array_equal(domain.observation(HAND, True), full[0])
    low, high = domain.observation_bounds(DEFAULT_PARAMS, extra_features=True)
    assert low.dtype == high.dtype == np.float32 and low.shape == high.shape == (32,)
    assert ((low <= full) & (full <= high)).all()
    v_max = 2 * DEFAULT_PARAMS.cue_speed_max / (1 + DEFAULT_PARAMS.ball_mass / DEFAULT_PARAMS.cue_mass)
    assert high[:7].tolist() == pytest.approx([1.27, 2.54, v_max, v_max] + [2.5 * v_max / R] * 3, rel=1e-6)
    assert high[28:].tolist() == pytest.approx([math.hypot(1.27, 2.54)] * 2 + [1, 1], rel=1e-6)
    assert domain.observation_bounds(DEFAULT_PARAMS)[0].shape == (28,)


def test_action_bounds_and_the_map_to_the_played_shot():
    assert domain.action_bounds()[0].tolist() == [0, 0, -1, -1] and domain.action_bounds()[1][0] == 2 * math.pi
    assert domain.action_bounds(True)[0].tolist() == [-1, 0, -1, -1] and domain.action_bounds(True)[1].tolist() == [1] * 4
    for aim in (False, True):
        assert [b.tolist() for b in domain.action_bounds(aim, normalized=True)] == [[-1] * 4, [1] * 4]
    batch = np.stack([HAND, HAND[[0, 1, 3, 2]]])
    x = np.array([[0.5, -0.2, 0.3, -0.9], [-1.0, 1.0, 0.0, 0.1]])
    np.testing.assert_array_equal(domain.raw_action(x, batch, R), x)
    np.testing.assert_array_equal(domain.raw_action(x, batch, R, normalized=True), domain.unnormalize_action(x))
    aimed = domain.aim_action(x, batch, R)
    np.testing.assert_array_equal(aimed[:, 0], domain.constrained_theta(batch, x[:, 0], R))
    np.testing.assert_array_equal(aimed[:, 1:], x[:, 1:])
    np.testing.assert_array_equal(domain.raw_action(x, batch, R, constrain_aim=True), aimed)
    both = domain.raw_action(x, batch, R, constrain_aim=True, normalized=True)  # unnormalise, then aim
    np.testing.assert_array_equal(both, domain.aim_action(domain.unnormalize_action(x, True), batch, R))
    assert both[0, 1] == pytest.approx(0.4) and both[1, 0] == domain.constrained_theta(batch[1], -1.0, R)
    assert not np.shares_memory(domain.raw_action(x, batch, R), x)


def test_normalized_aim_action_inverts_the_aim_constrained_map():
    """raw_action(normalized_aim_action(shot)) is the shot again, for angles given in any turn;
    a shot outside the window has |u| > 1 (on HAND red1 lies straight up: u = 0 is pi / 2)."""
    batch = np.stack([HAND, HAND[[0, 1, 3, 2]]])
    x = np.array([[0.5, -0.2, 0.3, -0.9], [-1.0, 1.0, 0.0, 0.1]])
    raw = domain.raw_action(x, batch, R, constrain_aim=True, normalized=True)
    for turns in (-1, 0, 1):
        shifted = raw + np.array([2 * math.pi * turns, 0, 0, 0])
        np.testing.assert_allclose(domain.normalized_aim_action(batch, shifted, R), x, atol=1e-12)
    u = domain.normalized_aim_action(HAND, np.array([math.pi / 2 + 0.5, 0.5, 0.0, 0.0]), R)[0]
    assert u == pytest.approx(0.5 / math.asin(2 * R / 0.4))
    assert abs(domain.normalized_aim_action(HAND, np.array([-math.pi / 2, 0.5, 0.0, 0.0]), R)[0]) > 1

def test_nearest_red_and_ties():
    assert domain.nearest_red(HAND) == 2
    swapped = HAND[[0, 1, 3, 2]]
    assert domain.nearest_red(swapped) == 3
    tie = rack((0.7, 1.0), (0.2, 0.2), (0.7, 1.5), (0.7, 0.5))  # both 0.5 m away
    assert domain.nearest_red(tie) == 2
    np.testing.assert_array_equal(domain.nearest_red(np.stack([HAND, swapped])), [2, 3])


def test_aim_window_hand_values():
    theta, half = domain.aim_window(HAND, R)
    assert theta == pytest.approx(math.pi / 2)
    assert half == pytest.approx(math.asin(2 * R / 0.4))
    # red along -x at d = 0.25: theta = pi, half = asin(2R/0.25)
    left = rack((0.9, 1.0), (0.2, 2.6), (0.65, 1.0), (1.2, 2.5))
    theta, half = domain.aim_window(left, R)
    assert abs(theta) == pytest.approx(math.pi)
    assert half == pytest.approx(math.asin(2 * R / 0.25))
    # touching balls: 2R/d = 1, the half-width is capped at the paper's 80 degrees
    touching = rack((0.5, 0.5), (1.2, 2.4), (0.5 + 2 * R, 0.5), (1.0, 2.0))
    assert domain.aim_window(touching, R)[1] == pytest.approx(math.radians(80))
    # the cap binds from d = 2R / sin(80 deg) on and not before it
    d_cap = 2 * R / math.sin(math.radians(80))
    near = rack((0.5, 0.5), (1.2, 2.4), (0.5 + 1.001 * d_cap, 0.5), (1.0, 2.0))
    assert domain.aim_window(near, R)[1] == pytest.approx(math.asin(2 * R / (1.001 * d_cap)))
    assert domain.aim_window(near, R)[1] < math.radians(80)
    assert domain.aim_window(touching, R, max_half_width=math.pi / 2)[1] == pytest.approx(math.pi / 2)


def test_constrained_theta_is_target_plus_u_halfwidth():
    batch = np.stack([HAND, HAND[[0, 1, 3, 2]]])
    u = np.array([-0.5, 0.75])
    theta, half = domain.aim_window(batch, R)
    np.testing.assert_allclose(domain.constrained_theta(batch, u, R), theta + u * half)
    assert domain.constrained_theta(HAND, 0.0, R) == pytest.approx(math.pi / 2)
    assert domain.constrained_theta(HAND, 1.0, R) == pytest.approx(math.pi / 2 + math.asin(2 * R / 0.4))


def test_carom_features_hand_values():
    d1, d2, s, c = domain.carom_features(HAND)
    assert d1 == pytest.approx(0.4)
    assert d2 == pytest.approx(math.hypot(0.4, 0.4))
    # white->red1 is +y, red1->red2 is +x: a clockwise quarter turn, phi = -pi/2
    assert s == pytest.approx(-1.0) and c == pytest.approx(0.0, abs=1e-12)
    # mirror: red2 at (-0.1 + 0.3...) left of red1 -> counter-clockwise, phi = +pi/2
    mirror = rack((0.3, 0.3), (1.1, 2.5), (0.3, 0.7), (0.1, 0.7))
    assert tuple(domain.carom_features(mirror)[2:]) == pytest.approx((1.0, 0.0), abs=1e-12)
    # the nearest red is red2 here, so d1/d2 and the angle are measured from it
    far = rack((0.5, 0.5), (1.2, 2.6), (0.5, 2.0), (0.8, 0.9))  # red2 at 0.5 m, red1 at 1.5 m
    d1, d2, s, c = domain.carom_features(far)
    u1, u2 = np.array([0.3, 0.4]), np.array([-0.3, 1.1])
    phi = math.atan2(u1[0] * u2[1] - u1[1] * u2[0], u1 @ u2)
    assert (d1, d2) == pytest.approx((0.5, 1.5))
    assert (s, c) == pytest.approx((math.sin(phi), math.cos(phi)))
    # straight on: phi = 0; straight back: phi = pi
    line = rack((0.5, 0.5), (1.2, 2.6), (0.5, 1.0), (0.5, 1.8))
    assert tuple(domain.carom_features(line)[2:]) == pytest.approx((0.0, 1.0))
    back = rack((0.5, 1.0), (1.2, 2.6), (0.5, 1.5), (0.5, 0.2))
    assert tuple(domain.carom_features(back)) == pytest.approx((0.5, 0.8, 0.0, -1.0))


def test_carom_features_batched_shapes():
    rng = np.random.default_rng(0)
    from billiards.physics import random_racks

    racks = random_racks(rng, 6).reshape(2, 3, 4, 2)
    feats = domain.carom_features(racks)
    assert feats.shape == (2, 3, 4)
    for idx in np.ndindex(2, 3):
        np.testing.assert_allclose(feats[idx], domain.carom_features(racks[idx]))
    np.testing.assert_allclose(feats[..., 2] ** 2 + feats[..., 3] ** 2, 1.0)


def test_foul_penalty_formula():
    foul = np.array([True, False, True])
    np.testing.assert_array_equal(domain.foul_penalty(foul, 1.5), [-1.5, 0.0, -1.5])


def test_gentle_bonus_is_the_papers_leave_position_bonus():
    # the white rests 0.2 m from red2 (the second red it hit): the peak 0.2; 0.5 m from red1:
    # 0.2 exp(-0.3^2 / 0.02); a miss earns nothing whatever the leave
    at_peak = rack((0.5, 0.5), (1.2, 2.4), (1.0, 2.0), (0.5, 0.7))
    far = rack((0.5, 0.5), (1.2, 2.4), (0.5, 1.0), (1.0, 2.0))
    positions = np.stack([at_peak, far, at_peak])
    score = np.array([True, True, False])
    second = np.array([3, 2, -1])
    np.testing.assert_allclose(domain.gentle_bonus(score, positions, second, 0.2),
                               [0.2, 0.2 * math.exp(-0.3 ** 2 / (2 * 0.1 ** 2)), 0.0])


def test_gentle_power_bonus_formula():
    score = np.array([True, True, False])
    power = np.array([0.25, 1.0, 0.1])
    np.testing.assert_allclose(domain.gentle_power_bonus(score, power, 0.4), [0.4 * 0.75, 0.0, 0.0])


def test_near_miss_bonus_formula():
    #            yellow red1  red2
    hits = np.array([
        [False, True, False],   # hit red1 only, missed red2 by 0.02 m -> eligible
        [False, False, True],   # hit red2 only, missed red1 by 0.10 m -> eligible
        [False, True, True],    # score -> 0
        [True, True, False],    # foul -> 0
        [False, False, False],  # no red -> 0
    ])
    closest = np.array([[0.0, 0.02], [0.10, 0.0], [0.0, 0.0], [0.0, 0.001], [0.01, 0.03]])
    score = hits[:, 1] & hits[:, 2] & ~hits[:, 0]
    foul = hits[:, 0]
    bonus = domain.near_miss_bonus(score, foul, hits, closest, beta=0.3, sigma=0.05)
    np.testing.assert_allclose(bonus, [0.3 * math.exp(-0.02 / 0.05), 0.3 * math.exp(-0.10 / 0.05), 0, 0, 0])
    with pytest.raises(ValueError):
        domain.near_miss_bonus(score, foul, hits, closest, beta=1.0, sigma=0.0)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, -0.5, "x", None])
def test_shaping_coefficients_must_be_finite_and_non_negative(bad):
    """NaN, inf, a negative or a non-number never reaches a reward: every shaping function
    refuses it with a ValueError naming the coefficient (and a length scale must be > 0)."""
    score, foul = np.array([True, False]), np.array([False, True])
    hits, closest, power = np.array([[False, True, True], [True, False, False]]), np.zeros((2, 2)), np.array([0.5, 0.5])
    positions, second_red = np.stack([canonical_rack()] * 2), np.array([3, -1])
    with pytest.raises(ValueError, match="foul penalty c must be a"):
        domain.foul_penalty(foul, bad)
    with pytest.raises(ValueError, match="gentle beta must be a"):
        domain.gentle_bonus(score, positions, second_red, bad)
    with pytest.raises(ValueError, match="gentle beta must be a"):
        domain.gentle_power_bonus(score, power, bad)
    with pytest.raises(ValueError, match="near-miss beta must be a"):
        domain.near_miss_bonus(score, foul, hits, closest, bad)
    with pytest.raises(ValueError, match="near-miss sigma must be a"):
        domain.near_miss_bonus(score, foul, hits, closest, 1.0, sigma=bad)
    for key in ("foul_c", "gentle_beta", "near_miss_beta", "near_miss_sigma"):
        for kind in domain.GENTLE_KINDS:
            with pytest.raises(ValueError, match="must be a"):
                domain.shaped_reward(score, foul, power, hits, closest, positions, second_red, gentle_kind=kind, **{key: bad})
    assert domain.check_coefficient("c", 0) == 0.0 and domain.check_coefficient("c", np.float32(2.5)) == 2.5
    with pytest.raises(ValueError, match="sigma must be a finite number > 0, got 0.0"):
        domain.check_coefficient("sigma", 0.0, strict=True)


def test_shaped_reward_sums_the_terms():
    score = np.array([True, False, False])
    foul = np.array([False, True, False])
    hits = np.array([[False, True, True], [True, False, False], [False, True, False]])
    closest = np.array([[0, 0], [0.2, 0.3], [0, 0.04]])
    power = np.array([0.2, 0.9, 0.5])
    positions = np.stack([rack((0.5, 0.5), (1.2, 2.4), (0.5, 0.85), (1.0, 2.0))] * 3)  # white 0.35 m from red1
    second = np.array([2, -1, -1])
    reward = domain.shaped_reward(score, foul, power, hits, closest, positions, second,
                                  foul_c=1.0, gentle_beta=0.2, near_miss_beta=0.05)
    leave = 0.2 * math.exp(-0.15 ** 2 / (2 * 0.1 ** 2))
    np.testing.assert_allclose(reward, [1 + leave, -1.0, 0.05 * math.exp(-0.04 / 0.03)])
    power_kind = domain.shaped_reward(score, foul, power, hits, closest, foul_c=1.0, gentle_beta=0.5,
                                      gentle_kind="power", near_miss_beta=0.2, near_miss_sigma=0.05)
    np.testing.assert_allclose(power_kind, [1 + 0.5 * 0.8, -1.0, 0.2 * math.exp(-0.04 / 0.05)])
    np.testing.assert_array_equal(domain.shaped_reward(score, foul, power, hits, closest), score.astype(float))
    with pytest.raises(ValueError, match="gentle_kind"):
        domain.shaped_reward(score, foul, power, hits, closest, positions, second, gentle_beta=0.2, gentle_kind="soft")
