"""Industrial Benchmark: the IDS simulator as a gymnasium env, reproducible per env."""

import sys

import numpy as np
import pytest

from conftest import rollout
from vintix import make_env
from vintix.errors import MissingDependencyError
from vintix.tasks import industrial_benchmark


def test_spaces_setpoint_and_episode_length():
    env = make_env("industrial-benchmark-35-v1", seed=0)
    obs, _ = env.reset()
    assert obs.shape == (6,) and obs[0] == 35.0
    assert env.action_space.shape == (3,) and env.action_space.low.min() == -1 and env.action_space.high.max() == 1
    steps, truncated = 0, False
    while not truncated:
        *_, truncated, _ = env.step(env.action_space.sample())
        steps += 1
    assert steps == 250


def test_reward_is_the_classic_cost_over_100_and_delta_is_its_change():
    classic_env = make_env("industrial-benchmark-50-v1", reward_type="classic")
    delta_env = make_env("industrial-benchmark-50-v1", reward_type="delta")
    classic_env.reset(seed=1)
    delta_env.reset(seed=1)
    previous = -classic_env.unwrapped._ids.state["cost"] / 100
    for action in np.random.default_rng(0).uniform(-1, 1, size=(20, 3)):
        _, classic, *_, info = classic_env.step(action)
        _, delta, *_, delta_info = delta_env.step(action)
        assert classic == pytest.approx(-classic_env.unwrapped._ids.state["cost"] / 100)
        assert classic == info["classic_reward"] == delta_info["classic_reward"]
        assert delta == pytest.approx(classic - previous)
        previous = classic


def test_same_seed_same_trajectory_and_other_seed_differs():
    first, rewards = rollout(make_env("industrial-benchmark-20-v1"), 300, reset_seed=3)
    again, rewards_again = rollout(make_env("industrial-benchmark-20-v1"), 300, reset_seed=3)
    _, other_rewards = rollout(make_env("industrial-benchmark-20-v1"), 300, reset_seed=4)
    np.testing.assert_array_equal(first, again)
    np.testing.assert_array_equal(rewards, rewards_again)
    assert not np.allclose(rewards, other_rewards)


def test_envs_stepped_alternately_match_envs_run_alone_and_leave_the_global_rng_alone():
    """IDS draws from NumPy's global RNG; each env must still be reproducible on its own."""
    actions = np.random.default_rng(0).uniform(-1, 1, size=(300, 3))

    def run_alone(seed):
        env = make_env("industrial-benchmark-60-v1")
        env.reset(seed=seed)
        return [env.step(a)[1] for a in actions]

    alone_a, alone_b = run_alone(1), run_alone(2)
    env_a, env_b = make_env("industrial-benchmark-60-v1"), make_env("industrial-benchmark-60-v1")
    np.random.seed(123)
    expected_global_draw = np.random.rand()
    np.random.seed(123)
    env_a.reset(seed=1)
    env_b.reset(seed=2)
    interleaved_a, interleaved_b = [], []
    for action in actions:
        interleaved_a.append(env_a.step(action)[1])
        interleaved_b.append(env_b.step(action)[1])
    assert interleaved_a == alone_a and interleaved_b == alone_b
    assert np.random.rand() == expected_global_draw


def test_missing_package_names_the_install_command(monkeypatch):
    monkeypatch.setitem(sys.modules, "industrial_benchmark_python", None)
    industrial_benchmark._ids_module.cache_clear()
    try:
        with pytest.raises(MissingDependencyError, match="pip install --no-deps industrial-benchmark-python"):
            make_env("industrial-benchmark-35-v1")
    finally:
        industrial_benchmark._ids_module.cache_clear()
