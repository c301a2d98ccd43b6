"""Continuous noise distillation's schedule and action mixing (paper Algorithm 1, Appendix A.3)."""

import numpy as np
import pytest

from vintix.collect import CollectionPlan, NoiseSchedule, collect, mix_action
from vintix.collect.calibrate import fit_schedules, pilot_knots
from vintix.collect.noise import fit_knots


def test_epsilon_starts_at_one_and_reaches_zero_at_the_noise_free_tail():
    schedule = NoiseSchedule(curvature=1.0, noise_free_fraction=0.2)
    eps = schedule.epsilon(np.arange(1000), 1000)
    assert eps[0] == 1.0
    assert eps[799] > 0 and np.all(eps[800:] == 0)
    assert np.all(np.diff(eps) <= 0)


def test_curvature_above_one_keeps_noise_high_for_longer():
    steps = np.arange(100)
    flat_start = NoiseSchedule(curvature=3.0, noise_free_fraction=0.0).epsilon(steps, 100)
    linear = NoiseSchedule(curvature=1.0, noise_free_fraction=0.0).epsilon(steps, 100)
    steep_start = NoiseSchedule(curvature=0.5, noise_free_fraction=0.0).epsilon(steps, 100)
    np.testing.assert_allclose(linear, 1 - steps / 100)
    assert np.all(flat_start[1:] > linear[1:]) and np.all(steep_start[1:] < linear[1:])


def test_the_default_noise_free_tail_is_the_cli_and_recipes_5_percent():
    assert NoiseSchedule().noise_free_fraction == 0.05
    assert not NoiseSchedule().epsilon(np.arange(950, 1000), 1000).any()


def test_a_noise_free_fraction_of_one_is_the_demonstrator_alone():
    """Expert data for the expert-distillation baseline: no step is noised."""
    assert not NoiseSchedule(noise_free_fraction=1.0).epsilon(np.arange(100), 100).any()


def test_knots_replace_the_power_law_before_the_noise_free_tail():
    schedule = NoiseSchedule(knots=[1.0, 0.4, 0.3, 0.0], noise_free_fraction=0.25)
    # 75 noised steps, knots at progress 0, 1/3, 2/3 and 1 of them.
    np.testing.assert_allclose(schedule.epsilon(np.array([0, 25, 50, 75, 99]), 100), [1.0, 0.4, 0.3, 0.0, 0.0])
    assert schedule.knots == (1.0, 0.4, 0.3, 0.0)  # a YAML list becomes the frozen schedule's tuple
    assert NoiseSchedule.from_recorded(schedule.recorded()) == schedule
    assert "knots" not in NoiseSchedule().recorded()  # power-law histories record what they always did


def test_a_noise_free_start_leaves_the_probing_episode_to_the_demonstrator():
    """Only the middle of the history is noised: a probe's first episode, then the last one, stay clean."""
    schedule = NoiseSchedule(knots=[0.5, 0.0], noise_free_start_fraction=0.2, noise_free_fraction=0.2)
    eps = schedule.epsilon(np.arange(500), 500)
    assert not eps[:100].any() and not eps[400:].any()
    np.testing.assert_allclose(eps[[100, 250, 399]], [0.5, 0.25, 0.5 / 300])  # knots over steps 100..400
    assert NoiseSchedule.from_recorded(schedule.recorded()) == schedule
    assert "noise_free_start_fraction" not in NoiseSchedule().recorded()


@pytest.mark.parametrize(("bad", "message"), [
    (dict(curvature=0.0), "curvature p must be > 0"), (dict(noise_free_fraction=1.1), "must lie in"),
    (dict(noise_free_fraction=-0.1), "must lie in"), (dict(knots=[1.0, 0.5]), "fall to 0 from at most 1"),
    (dict(knots=[1.5, 0.0]), "from at most 1"),
    (dict(noise_free_start_fraction=0.8, noise_free_fraction=0.2), r"\[0, 1 − f\)"),
    (dict(noise_free_start_fraction=0.1, noise_free_fraction=1.0), "some of the history is noised"),
    (dict(knots=[1.0, 0.3, 0.4, 0.0]), "never rising"), (dict(knots=[1.0]), "at least two"),
    (dict(knots=[1.0, 0.0], curvature=2.0), "not both"), (dict(knots=["high", 0.0]), "knots must be tuple"),
    (dict(pilot_steps=-1), "pilot_steps must be >= 0"), (dict(pilot_steps=100, curvature=2.0), "not both"),
])
def test_invalid_parameters_are_rejected(bad, message):
    with pytest.raises(ValueError, match=message):
        NoiseSchedule(**bad)


def test_fitted_knots_spend_the_history_where_return_changes():
    rng = np.random.default_rng(0)
    epsilons, steps = rng.uniform(0, 1, 400), np.full(400, 100)
    threshold = (epsilons < 0.3 + rng.normal(0, 0.03, 400)).astype(float)  # balances below ε ≈ 0.3, falls above
    knots = fit_knots(epsilons, 5 * threshold - 2, steps)  # any affine scale of return fits the same
    assert knots[0] == 1.0 and knots[-1] == 0.0 and np.all(np.diff(knots) <= 0)
    assert all(0.2 < k < 0.4 for k in knots[1:-1])
    ramp = fit_knots(epsilons, 1 - epsilons + rng.normal(0, 0.05, 400), steps)  # linear already: stays about linear
    np.testing.assert_allclose(ramp, np.linspace(1, 0, 11), atol=0.06)
    with pytest.raises(ValueError, match="does not fall with noise"):
        fit_knots(epsilons, np.zeros(400), steps)


def test_a_pilot_whose_return_does_not_fall_with_noise_gets_linear_decay():
    steps = np.arange(1000)
    epsilon, step_num = 1 - steps / 1000, steps % 100
    # The demonstrator earns more with less noise.
    rising = pilot_knots(epsilon, (1 - epsilon).astype(np.float32), step_num)
    assert rising[0] == 1.0 and rising[-1] == 0.0 and len(rising) == 11
    assert pilot_knots(epsilon, np.zeros(1000, np.float32), step_num) == (1.0, 0.0)  # a goal it never scores on
    with pytest.raises(ValueError, match="completed 0 episode\\(s\\), too few to fit knots to"):
        pilot_knots(epsilon, np.ones(1000, np.float32), np.arange(1000))  # one episode, cut by the pilot's end


def test_fit_schedules_reads_each_episode_noise_from_the_histories_of_a_real_collection(tmp_path):
    collect(CollectionPlan("InvertedPendulum-v5", histories=2, steps=6000), tmp_path)
    [fitted], skipped = fit_schedules(tmp_path)
    assert skipped == [] and fitted.task == "InvertedPendulum-v5" and fitted.episodes > 20
    assert fitted.knots[0] == 1.0 and fitted.knots[-1] == 0.0 and len(fitted.knots) == 11
    # The pendulum falls at once above some noise: the middle knots sit close together, not 0.1 apart.
    assert fitted.knots[2] - fitted.knots[8] < 0.3


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


def test_a_level_holds_epsilon_constant_and_a_dpt_history_records_the_experts_action_behind_random_ones(tmp_path):
    """DPT's context: every action uniformly random (level 1), the target the goal-aware expert's action."""
    schedule = NoiseSchedule(level=1.0, noise_free_fraction=0.0)
    assert (schedule.epsilon(np.arange(100), 100) == 1.0).all()
    assert NoiseSchedule.from_recorded(schedule.recorded()) == schedule
    with pytest.raises(ValueError, match="level"):
        NoiseSchedule(level=1.0, curvature=2.0)
    from vintix.data import LearningHistory
    from vintix.tasks.discrete_benchmarks import step_towards

    def history_goal(path):
        import vintix

        with LearningHistory(path) as history:
            env = vintix.make_env("DarkRoom-v0", seed=int(history.attrs["env_seed"]))
        return env.unwrapped.true_goal

    [summary] = collect(CollectionPlan("DarkRoom-v0", histories=1, steps=400, schedule=schedule), tmp_path)
    with LearningHistory(summary.path) as history:
        rows = history.read(0, 400, demonstrator_action=True)
    taken, target = rows["action"], rows["demonstrator_action"]
    assert np.bincount(taken, minlength=5).min() > 50  # uniformly random moves, not the expert's
    goal = history_goal(summary.path)
    assert (target == step_towards(rows["observation"], goal)).all()
