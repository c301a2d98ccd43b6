"""Reacher-hidden-v5: Reacher with its target hidden, so only the rewards reveal it; its scripted expert, its
goal-inferring demonstrator and its success flag."""

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from vintix.demonstrators import load_demonstrator
from vintix.demonstrators.goal_blind import goal_blind_baseline, read_goal_blind
from vintix.demonstrators.scores import history_outcomes
from vintix.errors import VintixError
from vintix.tasks import get_task, gymnasium_id, make_env
from vintix.tasks.reacher_hidden import SUCCESS_RADIUS, fingertip_position, joint_angles

TASK = "Reacher-hidden-v5"


def test_the_observation_holds_the_arm_only_and_the_reward_is_reachers():
    hidden = make_env(TASK, seed=5)
    obs, _ = hidden.reset()
    target = hidden.unwrapped.true_goal
    assert obs.shape == (6,) == (get_task(TASK).obs_dim,)
    action = np.array([0.3, -0.2])
    obs, reward, terminated, truncated, info = hidden.step(action)
    fingertip = fingertip_position(*joint_angles(obs))
    # Reacher-v5's reward: minus the distance to the target, minus the squared action
    assert reward == pytest.approx(-np.linalg.norm(fingertip - target) - np.square(action).sum(), abs=1e-6)
    assert reward == pytest.approx(hidden.unwrapped.rewards_under_goals(target[None], action)[0])
    assert not terminated and not truncated and info["success"] == 0.0


def test_the_target_is_kept_for_the_envs_life_drawn_from_its_seed_and_never_in_the_observation():
    env = make_env(TASK, seed=3)
    env.reset()
    target = env.unwrapped.true_goal
    assert np.linalg.norm(target) < 0.2
    env.reset()
    np.testing.assert_array_equal(env.unwrapped.true_goal, target)
    np.testing.assert_array_equal(make_env(TASK, seed=3).unwrapped.true_goal, target)
    other = make_env(TASK, seed=4)
    assert not np.allclose(other.unwrapped.true_goal, target)
    # same arm start, another target: the observations cannot tell the targets apart
    np.testing.assert_array_equal(other.reset(seed=3)[0], make_env(TASK, seed=3).reset()[0])


def test_success_is_the_fingertip_at_the_target_when_the_episode_ends():
    env = make_env(TASK, seed=1)
    expert = load_demonstrator(TASK)
    obs, _ = env.reset()
    flags = []
    truncated = False
    while not truncated:
        obs, _, _, truncated, info = env.step(expert.act(obs[None], [env])[0])
        flags.append(info["success"])
    assert flags[-1] == 1.0 and info["obj_to_target"] < SUCCESS_RADIUS
    assert not any(flags[:-1])  # passing by the target on the way does not count
    assert len(flags) == get_task(TASK).episode_length


def test_the_expert_succeeds_and_the_goal_blind_one_does_not():
    result = goal_blind_baseline(TASK, seeds=10)
    assert result.true_goal_success == 1.0 and result.goal_blind_success <= 0.1
    shipped = read_goal_blind()[TASK]
    assert shipped.hidden_information >= 0.9


def test_a_demonstrator_that_never_sees_the_target_finds_it_from_the_rewards_of_its_probe():
    demonstrator = load_demonstrator(TASK, behaviour="probe-then-sample")
    outcomes = history_outcomes(TASK, demonstrator, range(100, 110), episodes=3)
    assert outcomes.success[:, 0].mean() <= 0.2  # the probe sweeps the arm at full stretch
    assert outcomes.success[:, 1:].mean() >= 0.9
    assert np.median(outcomes.end_distance[:, 1:]) < 0.02


def test_physics_variations_apply_and_the_gymnasium_id_makes_the_same_task():
    env = make_env(TASK, seed=0, viscosity=0.1)
    assert env.unwrapped.model.opt.viscosity == pytest.approx(0.1)
    assert gymnasium_id(get_task(TASK)) == "vintix/Reacher-hidden-v5"
    direct = gym.make("vintix/Reacher-hidden-v5", seed=0)
    np.testing.assert_array_equal(direct.unwrapped.true_goal, make_env(TASK, seed=0).unwrapped.true_goal)


def test_its_expert_is_scripted_so_trained_weights_are_refused():
    with pytest.raises(VintixError, match="scripted"):
        load_demonstrator(TASK, weights=Path("weights"))
