"""Continuous noise distillation's schedule and action mixing (paper Algorithm 1, Appendix A.3)."""

import numpy as np
import pytest

from vintix.collect import NoiseSchedule, mix_action


def test_epsilon_starts_at_one_and_reaches_zero_at_the_noise_free_tail():
    schedule = NoiseSchedule(curvature=1.0, noise_free_fraction=0.2)
    eps = schedule.epsilon(np.arange(1000), 1000)
    assert eps[0] == 1.0
    assert eps[799] > 0 and np.all(eps[800:] == 0)
    assert np.all(np.diff(eps) <= 0)


def test_curvature_above_one_keeps_noise_high_for_longer():
    steps = np.arange(100)
    flat_start = NoiseSchedule(curvature=3.0).epsilon(steps, 100)
    linear = NoiseSchedule(curvature=1.0).epsilon(steps, 100)
    steep_start = NoiseSchedule(curvature=0.5).epsilon(steps, 100)
    np.testing.assert_allclose(linear, 1 - steps / 100)
    assert np.all(flat_start[1:] > linear[1:]) and np.all(steep_start[1:] < linear[1:])


def test_a_noise_free_fraction_of_one_is_the_demonstrator_alone():
    """Expert data for the expert-distillation baseline: no step is noised."""
    assert not NoiseSchedule(noise_free_fraction=1.0).epsilon(np.arange(100), 100).any()


@pytest.mark.parametrize("bad", [dict(curvature=0.0), dict(noise_free_fraction=1.1), dict(noise_free_fraction=-0.1)])
def test_invalid_parameters_are_rejected(bad):
    with pytest.raises(ValueError):
        NoiseSchedule(**bad)


def test_mixed_actions_stay_inside_the_bounds():
    rng = np.random.default_rng(0)
    low, high = np.array([-1.0, 0.0, -2.0]), np.array([1.0, 0.5, 2.0])
    for epsilon in np.linspace(0, 1, 11):
        expert = np.clip(rng.normal(0, 3, size=(50, 3)), low, high)  # the collector clips what it proposes
        action = mix_action(expert, epsilon, rng.uniform(low, high, size=(50, 3)))
        assert np.all(action >= low) and np.all(action <= high)


def test_mixing_is_the_expert_at_zero_noise_and_uniform_at_full_noise():
    rng = np.random.default_rng(0)
    expert = np.array([0.3, -0.2])
    noise = rng.uniform(-1, 1, size=(2000, 2))
    np.testing.assert_array_equal(mix_action(expert, 0.0, noise), np.broadcast_to(expert, noise.shape))
    samples = mix_action(expert, 1.0, noise)
    assert abs(samples.mean()) < 0.05 and samples.min() < -0.95 and samples.max() > 0.95
