"""The meta-RL locomotion tasks (HalfCheetah-Vel, HalfCheetah-Dir, Ant-Dir): a hidden parameter drawn from the env's
seed, kept across episodes, never observed, and the reward the literature defines."""

import numpy as np
import pytest

from vintix import make_env
from vintix.demonstrators import load_demonstrator
from vintix.demonstrators.trained import MissingDemonstratorError
from vintix.errors import VintixError
from vintix.tasks import get_task
from vintix.tasks.meta_mujoco import with_goal_observed

TASKS = ["HalfCheetah-Vel-v5", "HalfCheetah-Dir-v5", "Ant-Dir-v5"]


def play(task: str, seed: int, actions: np.ndarray, parameter: float | None = None
         ) -> tuple[list[np.ndarray], list[float], list[dict]]:
    """An episode of `actions` on the env of `seed`, its hidden parameter replaced by `parameter` if given."""
    env = make_env(task, seed=seed)
    observations, rewards, infos = [env.reset()[0]], [], []
    if parameter is not None:
        env.unwrapped._parameter = parameter
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        infos.append(info)
        if terminated or truncated:
            break
    return observations, rewards, infos


@pytest.mark.parametrize("task", TASKS)
def test_the_parameter_is_drawn_from_the_seed_kept_for_life_and_never_observed(task):
    spec = get_task(task)
    env = make_env(task, seed=5)
    first = env.unwrapped.true_goal
    env.reset()
    env.reset()
    assert np.array_equal(env.unwrapped.true_goal, first)  # resets keep it
    assert np.array_equal(make_env(task, seed=5).unwrapped.true_goal, first)  # the seed decides it
    goals = {float(make_env(task, seed=s).unwrapped.true_goal[0]) for s in range(12)}
    assert len(goals) > 1  # and different seeds differ
    # The same env with another parameter sees the same observations under the same actions: nothing shows it.
    other = 2.0 if spec.name == "HalfCheetah-Vel-v5" and first[0] != 2.0 else -first[0]
    actions = np.random.default_rng(0).uniform(-1, 1, (30, spec.act_dim))
    a, b = play(task, 5, actions), play(task, 5, actions, parameter=float(other))
    assert len(a[0]) == len(b[0]) and all(np.array_equal(x, y) for x, y in zip(a[0], b[0], strict=True))
    assert a[1] != b[1]  # only the rewards tell them apart
    assert a[0][0].shape == (spec.obs_dim,) and spec.episode_length == 200


def test_the_rewards_are_the_literatures():
    actions = np.random.default_rng(1).uniform(-1, 1, (20, 6))
    for task, reward in (("HalfCheetah-Vel-v5", lambda goal, info, a: -abs(info["x_velocity"] - goal)
                          - 0.05 * np.square(a).sum()),
                         ("HalfCheetah-Dir-v5", lambda goal, info, a: goal * info["x_velocity"]
                          - 0.05 * np.square(a).sum())):
        goal = float(make_env(task, seed=3).unwrapped.true_goal[0])
        _, rewards, infos = play(task, 3, actions)
        assert rewards == pytest.approx([reward(goal, i, a) for i, a in zip(infos, actions, strict=False)])
    velocity = float(make_env("HalfCheetah-Vel-v5", seed=3).unwrapped.true_goal[0])
    assert 0.0 <= velocity <= 3.0
    goal = float(make_env("Ant-Dir-v5", seed=3).unwrapped.true_goal[0])
    _, rewards, infos = play("Ant-Dir-v5", 3, np.random.default_rng(2).uniform(-1, 1, (20, 8)))
    assert goal in (-1.0, 1.0) and rewards == pytest.approx(
        [goal * i["x_velocity"] + i["reward_ctrl"] + i["reward_contact"] + i["reward_survive"] for i in infos])


def test_a_goal_aware_expert_sees_the_parameter_and_trains_on_a_new_one_each_episode():
    """What a goal-aware expert trains on: the observation with the parameter appended, the parameter redrawn at
    every reset (`resample_goal_each_episode`); a task without a hidden parameter refuses the option."""
    env = with_goal_observed(make_env("HalfCheetah-Vel-v5", seed=4, resample_goal_each_episode=True))
    seen = []
    for _ in range(3):
        obs, _ = env.reset()
        assert obs.shape == (18,) and obs[-1] == env.unwrapped.true_goal[0]
        seen.append(obs[-1])
    assert seen[0] == make_env("HalfCheetah-Vel-v5", seed=4).unwrapped.true_goal[0]  # the seed's first
    assert len(set(seen)) == 3 and env.observation_space.shape == (18,) and env.observation_space.high[-1] == 3.0
    with pytest.raises(VintixError, match="'HalfCheetah-v5' has no hidden parameter to redraw"):
        make_env("HalfCheetah-v5", resample_goal_each_episode=True)
    with pytest.raises(TypeError, match="hides no parameter"):
        with_goal_observed(make_env("Reacher-hidden-v5"))


def test_a_task_whose_expert_is_not_trained_says_how_to_train_it(tmp_path):
    with pytest.raises(MissingDemonstratorError, match="'halfcheetah-vel'.*vintix demonstrator train --task "
                                                       "HalfCheetah-Vel-v5"):
        load_demonstrator("HalfCheetah-Vel-v5", tmp_path)  # a folder without its weights
