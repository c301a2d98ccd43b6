"""Meta-World tasks in the ML45 setting: hidden goal, one goal per env, 100-step episodes, seeding."""

import numpy as np
import pytest
from metaworld.policies import ENV_POLICY_MAP

from conftest import rollout
from vintix import list_tasks, make_env


def test_every_task_builds_with_registry_dims_and_a_hidden_goal():
    for spec in list_tasks(domain="metaworld"):
        env = make_env(spec.name, seed=0)
        obs, _ = env.reset()
        obs, reward, *_ = env.step(env.action_space.sample())
        assert obs.shape == (spec.obs_dim,) and env.action_space.shape == (spec.act_dim,), spec.name
        assert np.all(obs[-3:] == 0), f"{spec.name} leaks its goal"
        assert np.isfinite(reward)
        env.close()


def test_episodes_are_truncated_at_100_steps_by_default_and_configurable():
    lengths = []
    for length in (100, 30):
        env = make_env("reach-v3", seed=0, episode_length=length)
        env.reset()
        steps, truncated = 0, False
        while not truncated:
            *_, truncated, _ = env.step(env.action_space.sample())
            steps += 1
        lengths.append(steps)
    assert lengths == [100, 30]


def test_one_goal_per_env_drawn_from_the_seed():
    goal = lambda env: env.unwrapped.true_goal  # noqa: E731
    env = make_env("push-v3", seed=1)
    first = goal(env).copy()
    for _ in range(3):
        env.reset()
        np.testing.assert_array_equal(goal(env), first)
    np.testing.assert_array_equal(goal(make_env("push-v3", seed=1)), first)
    assert not np.allclose(goal(make_env("push-v3", seed=2)), first)


def test_reset_with_seed_equals_a_new_env_with_that_seed():
    reseeded = make_env("door-open-v3", seed=0)
    reseeded.reset()
    trajectory, _ = rollout(reseeded, 120, reset_seed=5)
    fresh, _ = rollout(make_env("door-open-v3", seed=5), 120)
    np.testing.assert_array_equal(trajectory, fresh)


def test_resample_goal_each_episode_draws_new_goals():
    env = make_env("reach-v3", seed=0, resample_goal_each_episode=True)
    goals = []
    for _ in range(3):
        env.reset()
        goals.append(env.unwrapped.true_goal.copy())
    assert not np.allclose(goals[0], goals[1]) and not np.allclose(goals[1], goals[2])


def scripted_episode_succeeds(task: str, show_goal: bool) -> bool:
    env = make_env(task, seed=3)
    policy = ENV_POLICY_MAP[task]()
    obs, _ = env.reset()
    success = False
    for _ in range(100):
        policy_input = env.unwrapped.expert_observation(obs) if show_goal else obs
        obs, _, _, _, info = env.step(policy.get_action(policy_input))
        success = success or bool(info["success"])
    return success


@pytest.mark.parametrize("task", ["reach-v3", "door-open-v3"])
def test_scripted_expert_succeeds_given_the_true_goal(task):
    """The goal the env exposes to demonstrators is the one that counts for reward and success."""
    assert scripted_episode_succeeds(task, show_goal=True)


def test_scripted_expert_fails_on_the_observation_a_model_sees():
    assert not scripted_episode_succeeds("reach-v3", show_goal=False)


def test_an_ml1_test_goal_is_metaworlds_own_hidden_for_the_envs_life():
    """`use_ml1_test_goal(i)` plays metaworld.ML1's test goal i (through metaworld's set_task), keeps it across
    resets, hides it like any goal, and names the range of goals there are."""
    import pickle

    from vintix.tasks.metaworld import ml1_test_tasks

    env = make_env("reach-v3", seed=3)
    drawn = env.unwrapped.true_goal
    env.unwrapped.use_ml1_test_goal(1)
    for _ in range(2):
        obs, _ = env.reset()
        expected = pickle.loads(ml1_test_tasks("reach-v3")[1].data)["rand_vec"][-3:]
        np.testing.assert_allclose(env.unwrapped.true_goal, expected)
        assert not np.allclose(env.unwrapped.true_goal, drawn) and not obs[-3:].any()
    assert len(ml1_test_tasks("reach-v3")) == 50
    with pytest.raises(ValueError, match="ML1 has 50 test goals"):
        env.unwrapped.use_ml1_test_goal(50)
