"""make_env's contract across domains: gymnasium envs, option checking, clear errors."""

import gymnasium as gym
import pytest

import vintix  # noqa: F401  (registers the vintix/ gymnasium ids)
from vintix import make_env
from vintix.errors import MissingDependencyError, UnknownTaskError, UnsupportedOptionError


@pytest.mark.parametrize("task", ["Hopper-v5", "pick-place-v3", "industrial-benchmark-35-v1"])
def test_returns_a_standard_gymnasium_env(task):
    env = make_env(task, seed=0)
    assert isinstance(env, gym.Env)
    obs, info = env.reset()
    assert env.observation_space.contains(obs)
    assert isinstance(info, dict)


def test_our_tasks_are_registered_with_gymnasium():
    env = gym.make("vintix/industrial-benchmark-80-v1")
    assert env.spec.max_episode_steps == 250
    assert gym.make("vintix/door-lock-v3").spec.max_episode_steps == 100


def test_variation_on_a_domain_without_variations_is_a_clear_error():
    with pytest.raises(UnsupportedOptionError, match="viscosity do not apply to metaworld.*exists for mujoco"):
        make_env("pick-place-v3", viscosity=0.05)
    with pytest.raises(UnsupportedOptionError, match="gravity_scale do not apply to industrial_benchmark"):
        make_env("industrial-benchmark-35-v1", gravity_scale=1.1)


def test_unknown_task_is_a_clear_error():
    with pytest.raises(UnknownTaskError, match="Did you mean"):
        make_env("Hoper-v5")


def test_bidexhands_names_isaacgym():
    with pytest.raises(MissingDependencyError, match="IsaacGym.*can still be read"):
        make_env("Hand-Pen")
