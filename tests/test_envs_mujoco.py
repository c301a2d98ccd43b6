"""MuJoCo tasks through gymnasium: real simulators, registry dims, seeding, physics variations."""

import numpy as np
import pytest

from conftest import rollout
from vintix import list_tasks, make_env
from vintix.errors import UnsupportedOptionError


@pytest.mark.parametrize("task", [t.name for t in list_tasks(domain="mujoco")])
def test_env_dims_match_the_registry(task):
    spec = next(t for t in list_tasks(domain="mujoco") if t.name == task)
    env = make_env(task, seed=0)
    obs, _ = env.reset()
    assert obs.shape == (spec.obs_dim,)
    assert env.action_space.shape == (spec.act_dim,)
    assert env.spec.max_episode_steps == spec.episode_length
    obs, reward, *_ = env.step(env.action_space.sample())
    assert obs.shape == (spec.obs_dim,) and np.isfinite(reward)


def test_same_seed_same_trajectory_and_other_seed_differs():
    first, _ = rollout(make_env("Hopper-v5"), 200, reset_seed=3)
    again, _ = rollout(make_env("Hopper-v5"), 200, reset_seed=3)
    other, _ = rollout(make_env("Hopper-v5"), 200, reset_seed=4)
    np.testing.assert_array_equal(first, again)
    assert not np.allclose(first[0], other[0])


def test_make_env_seed_drives_the_first_reset_and_the_action_space():
    a, b = make_env("Walker2d-v5", seed=7), make_env("Walker2d-v5", seed=7)
    np.testing.assert_array_equal(a.reset()[0], b.reset()[0])
    np.testing.assert_array_equal(a.action_space.sample(), b.action_space.sample())


def test_v4_alias_builds_the_v5_env():
    env = make_env("Ant-v4", seed=0)
    assert env.spec.id == "Ant-v5" and env.reset()[0].shape == (105,)


def test_viscosity_and_gravity_persist_across_resets_and_change_the_dynamics():
    varied = make_env("HalfCheetah-v5", viscosity=0.1, gravity_scale=1.1)
    model = varied.unwrapped.model
    for _ in range(2):
        varied.reset(seed=0)
        assert model.opt.viscosity == pytest.approx(0.1)
        np.testing.assert_allclose(model.opt.gravity, [0, 0, -9.81 * 1.1])
    plain, _ = rollout(make_env("HalfCheetah-v5"), 100, reset_seed=0)
    changed, _ = rollout(varied, 100, reset_seed=0)
    np.testing.assert_array_equal(plain[0], changed[0])  # same start, different physics
    assert np.abs(plain[-1] - changed[-1]).max() > 1e-3


def test_negative_viscosity_is_rejected():
    with pytest.raises(ValueError, match="viscosity must be >= 0"):
        make_env("Hopper-v5", viscosity=-0.1)


def test_non_finite_variations_are_rejected_not_simulated():
    # MuJoCo itself takes NaN and then every observation of the episode is NaN.
    with pytest.raises(UnsupportedOptionError, match="gravity_scale must be finite"):
        make_env("Hopper-v5", gravity_scale=float("nan"))
    with pytest.raises(UnsupportedOptionError, match="viscosity must be >= 0 and finite"):
        make_env("Hopper-v5", viscosity=float("inf"))
