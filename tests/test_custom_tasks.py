"""Your own environment: a task registered from outside the package (Python, a tasks file, an entry point),
a demonstrator named by a recipe, and the whole pipeline through the CLI on Gymnasium's Pendulum-v1."""

import csv
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import vintix
from conftest import HANG_GUARD_S
from vintix.demonstrators.base import external_demonstrator
from vintix.errors import VintixError
from vintix.tasks import get_task, make_env, registry, resolve_tasks
from vintix.tasks.custom import TaskSpecError, register_tasks_file

PLUGIN = '''
"""A task of one's own: Gymnasium's Pendulum-v1 with a hand-written swing-up controller."""
import numpy as np


class SwingUp:
    """Energy pumping far from upright, a PD balance near it (Pendulum-v1: th'' = 15 sin th + 3 u)."""

    def __init__(self, task):
        self.task = task

    def act(self, observations, envs):
        cos, sin, velocity = observations[:, 0], observations[:, 1], observations[:, 2]
        energy = 0.5 * velocity**2 + 15.0 * cos  # 15 at rest upright
        pump = np.clip(0.5 * (15.0 - energy) * np.sign(velocity + 1e-6), -2.0, 2.0)
        balance = np.clip(-(10.0 * np.arctan2(sin, cos) + 2.0 * velocity), -2.0, 2.0)
        return np.where(cos > 0.85, balance, pump)[:, None].astype(np.float32)


def register():
    import vintix
    vintix.register_task("Pendulum-v1", env_id="Pendulum-v1", obs_dim=3, act_dim=1, episode_length=200,
                         group="pendulum", reward_scale=0.1)
'''
TASKS_FILE = """
tasks:
  Pendulum-v1:
    env_id: Pendulum-v1
    obs_dim: 3
    act_dim: 1
    episode_length: 200
    group: pendulum
    reward_scale: 0.1
    reference_random: -1149
    reference_expert: -132
"""
RECIPE = """
defaults: {histories: 4, steps: 2000, envs_per_batch: 4}
tasks:
  Pendulum-v1: {demonstrator: "pendulum_plugin:SwingUp"}
"""


@pytest.fixture
def no_custom_tasks():
    """Tests that register tasks in this process leave the registry as they found it."""
    yield
    registry._custom.clear()


@pytest.fixture
def plugin(tmp_path):
    (tmp_path / "pendulum_plugin.py").write_text(PLUGIN)
    (tmp_path / "tasks.yaml").write_text(TASKS_FILE)
    (tmp_path / "recipe.yaml").write_text(RECIPE)
    return tmp_path


def vintix_cli(*args, cwd, tasks_file=None):
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    env.pop("VINTIX_TASKS", None)
    if tasks_file:
        env["VINTIX_TASKS"] = str(tasks_file)
    result = subprocess.run([sys.executable, "-m", "vintix", *args], cwd=cwd, env=env, capture_output=True, text=True,
                            timeout=HANG_GUARD_S)
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout


def test_a_task_registered_from_python_makes_its_env_and_joins_the_custom_domain(no_custom_tasks):
    spec = vintix.register_task("Pendulum-v1", env_id="Pendulum-v1", obs_dim=3, act_dim=1, episode_length=50)
    assert get_task("Pendulum-v1") == spec and spec.group == "Pendulum-v1" and spec.domain == "custom"
    assert [t.name for t in resolve_tasks(["custom"])] == ["Pendulum-v1"]
    env = make_env("Pendulum-v1", seed=3)
    first, _ = env.reset()
    steps = 0
    while not any(env.step(env.action_space.sample())[2:4]):
        steps += 1
    assert steps + 1 == 50  # the spec's episode length, not gymnasium's 200
    again, _ = make_env("Pendulum-v1", seed=3).reset()
    np.testing.assert_array_equal(first, again)
    vintix.register_task("Pendulum-v1", env_id="Pendulum-v1", obs_dim=3, act_dim=1, episode_length=50)  # same: no-op


def test_reading_a_task_json_registers_nothing_and_opening_its_dataset_registers_its_task(no_custom_tasks, tmp_path):
    from vintix.data import find_tasks, read_task_metadata, write_task_metadata

    spec = {"env_id": "Pendulum-v1", "obs_dim": 3, "act_dim": 1, "episode_length": 200, "group": "pendulum"}
    folder = write_task_metadata(tmp_path / "custom" / "Pendulum-v1", "Pendulum-v1", 3, 1, custom_task=spec).parent
    assert read_task_metadata(folder)["custom_task"]["env_id"] == "Pendulum-v1"
    assert registry.find_task("Pendulum-v1") is None
    assert [task.task_name for task in find_tasks(tmp_path)] == ["Pendulum-v1"]
    assert get_task("Pendulum-v1").group == "pendulum"


def test_a_spec_that_contradicts_its_env_or_another_task_is_refused(no_custom_tasks):
    vintix.register_task("bad-pendulum", env_id="Pendulum-v1", obs_dim=4, act_dim=1, episode_length=200)
    with pytest.raises(TaskSpecError, match=r"observations of shape \(3,\), the spec says obs_dim 4"):
        make_env("bad-pendulum")
    with pytest.raises(TaskSpecError, match="already task 'reach-v3'"):
        vintix.register_task("reach-v3", env_id="Pendulum-v1", obs_dim=3, act_dim=1, episode_length=200)
    with pytest.raises(TaskSpecError, match="one of env_id"):
        vintix.register_task("x", obs_dim=3, act_dim=1, episode_length=200)
    with pytest.raises(TaskSpecError, match=r"action space Discrete\(2\), the spec says a Box"):
        vintix.register_task("cartpole", env_id="CartPole-v1", obs_dim=4, act_dim=1, episode_length=200)
        make_env("cartpole")


def test_tasks_file_errors_name_the_file_and_the_field(tmp_path, no_custom_tasks):
    path = tmp_path / "tasks.yaml"
    path.write_text("tasks:\n  p:\n    env_id: Pendulum-v1\n    obs_dims: 3\n")
    with pytest.raises(TaskSpecError, match=r"tasks.yaml: task 'p' has unknown field\(s\) \['obs_dims'\]"):
        register_tasks_file(path)
    path.write_text("tasks:\n  p:\n    env_id: Pendulum-v1\n    obs_dim: 3\n")
    with pytest.raises(TaskSpecError, match="act_dim"):
        register_tasks_file(path)
    with pytest.raises(TaskSpecError, match="no-such.yaml"):
        register_tasks_file(tmp_path / "no-such.yaml")


def test_an_entry_point_registers_its_tasks_in_every_process(plugin):
    dist = plugin / "vintix_pendulum-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: vintix-pendulum\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[vintix.tasks]\npendulum = pendulum_plugin:register\n")
    output = vintix_cli("tasks", "--domain", "custom", cwd=plugin)
    assert output.splitlines()[1].startswith("Pendulum-v1\tcustom") and len(output.splitlines()) == 2


def test_a_recipe_demonstrator_and_a_model_file_demonstrator(plugin, no_custom_tasks):
    from stable_baselines3 import SAC

    register_tasks_file(plugin / "tasks.yaml")
    sys.path.insert(0, str(plugin))
    try:
        swing_up = external_demonstrator("Pendulum-v1", "pendulum_plugin:SwingUp")
    finally:
        sys.path.remove(str(plugin))
    assert swing_up.act(np.array([[1.0, 0.0, 0.0]]), []).shape == (1, 1)
    with pytest.raises(VintixError, match="is not callable|cannot be loaded"):
        external_demonstrator("Pendulum-v1", "numpy:no_such_thing")
    SAC("MlpPolicy", make_env("Pendulum-v1"), policy_kwargs={"net_arch": [8]}).save(plugin / "sac.zip")
    os.chmod(plugin / "sac.zip", 0o644)
    model = external_demonstrator("Pendulum-v1", f"sb3:SAC:{plugin / 'sac.zip'}")
    assert model.act(np.zeros((3, 3), np.float32), []).shape == (3, 1)
    os.chmod(plugin / "sac.zip", 0o666)
    with pytest.raises(VintixError, match="writable by other users; it is unpickled"):
        external_demonstrator("Pendulum-v1", f"sb3:SAC:{plugin / 'sac.zip'}")


def test_your_own_environment_end_to_end_through_the_cli(plugin):
    """The README's steps: collect sees the task through a tasks file; every later command through what it
    reads (the dataset's task JSON, the checkpoint, the results), which carries its spec."""
    tasks = plugin / "tasks.yaml"
    collected = vintix_cli("--tasks-file", str(tasks), "collect", "--recipe", "recipe.yaml", "--out", "data",
                           cwd=plugin)
    assert "wrote 4 histories (8,000 steps)" in collected
    vintix_cli("train", "--config", "tiny", "--data", "data", "--out", "run", "--set", "max_steps=20", "--set",
               "batch_size=4", "--set", "window_len=256", "--set", "checkpoint_every=20", cwd=plugin)
    vintix_cli("eval", "--checkpoint", "run", "--tasks", "Pendulum-v1", "--shots", "2", "--seeds", "2", "--out",
               "results", cwd=plugin)
    rows = list(csv.DictReader((plugin / "results" / "episodes.csv").open()))
    assert len(rows) == 4 and {r["task"] for r in rows} == {"Pendulum-v1"} and all(r["normalized_ours"] for r in rows)
    assert "wrote report/report.md" in vintix_cli("report", "results", "--out", "report", cwd=plugin)
    assert "Pendulum-v1" in (plugin / "report" / "report.md").read_text()
    plotted = vintix_cli("data", "plot", "data", "--out", "plots", cwd=plugin)
    assert "wrote 2 figures" in plotted


def test_the_demonstrator_of_a_custom_task_must_be_named(no_custom_tasks, tmp_path):
    from vintix.demonstrators import load_demonstrator

    vintix.register_task("Pendulum-v1", env_id="Pendulum-v1", obs_dim=3, act_dim=1, episode_length=200)
    with pytest.raises(VintixError, match=textwrap.shorten("name one in the recipe, demonstrator:", 60)):
        load_demonstrator("Pendulum-v1")


def array_reward_pendulum(seed=None):
    """A custom env that returns its reward as np.array([r]) (a newcomer's slip)."""
    import gymnasium as gym

    class ArrayReward(gym.Wrapper):
        def step(self, action):
            observation, reward, terminated, truncated, info = self.env.step(action)
            return observation, np.array([reward]), terminated, truncated, info

    return ArrayReward(gym.make("Pendulum-v1"))


def test_a_reward_that_is_not_one_number_is_one_clear_error_and_a_missing_success_flag_a_note(no_custom_tasks):
    from vintix.agent import Agent
    from vintix.evaluate import evaluate_shots
    from vintix.evaluate.run import no_success_notes
    from vintix.model import GroupSpec, ModelConfig, TaskNorm, Vintix

    vintix.register_task("array-pendulum", env_factory="test_custom_tasks:array_reward_pendulum", obs_dim=3,
                         act_dim=1, episode_length=20)
    env = make_env("array-pendulum", seed=0)
    env.reset()
    with pytest.raises(TaskSpecError, match=r"task 'array-pendulum': its env's step returned the reward "
                                            r"array\(\[.*\]\) \(ndarray of shape \(1,\)\); a reward is one number"):
        env.step(env.action_space.sample())
    vintix.register_task("Pendulum-v1", env_id="Pendulum-v1", obs_dim=3, act_dim=1, episode_length=20)
    model = Vintix(ModelConfig(n_layers=1, n_heads=1, obs_emb_dim=6, act_emb_dim=6, rew_emb_dim=4, mlp_dim=8,
                               context_len=64), [GroupSpec("Pendulum-v1", 3, 1)],
                   [TaskNorm("Pendulum-v1", "Pendulum-v1", [0.0] * 3, [1.0] * 3)])
    runs = evaluate_shots(Agent(model), "Pendulum-v1", shots=1, seeds=1)
    assert np.isnan(runs.success).all()
    [note] = no_success_notes([{"task": "Pendulum-v1", "success": ""}])
    assert "Pendulum-v1: its env's step never put 'success' in info" in note and "at any of its steps" in note


def pendulum_with_an_optimum(seed=None):
    """Pendulum-v1 whose env says the most an episode can return under its goal (as the discrete benchmarks' do)."""
    from gymnasium.envs.classic_control.pendulum import PendulumEnv

    class WithOptimum(PendulumEnv):
        best = -99.0  # until the first reset draws the goal, as a newcomer's corridor does

        def reset(self, *, seed=None, options=None):
            if seed is not None:
                self.best = -2.5
            return super().reset(seed=seed, options=options)

        def optimal_return(self):
            return self.best

    return WithOptimum()


def test_a_custom_env_that_offers_its_optimum_fills_the_optimal_column(no_custom_tasks, tmp_path):
    from vintix.agent import Agent
    from vintix.evaluate import evaluate_shots
    from vintix.model import GroupSpec, ModelConfig, TaskNorm, Vintix

    vintix.register_task("optimum-pendulum", env_factory="test_custom_tasks:pendulum_with_an_optimum", obs_dim=3,
                         act_dim=1, episode_length=20)
    model = Vintix(ModelConfig(n_layers=1, n_heads=1, obs_emb_dim=6, act_emb_dim=6, rew_emb_dim=4, mlp_dim=8,
                               context_len=64), [GroupSpec("p", 3, 1)], [TaskNorm("optimum-pendulum", "p", [0.0] * 3,
                                                                                  [1.0] * 3)])
    runs = evaluate_shots(Agent(model), "optimum-pendulum", shots=2, seeds=1)
    # the score is return over the optimum of the env's goal, which its first reset draws
    np.testing.assert_allclose(runs.scores, runs.returns / -2.5)
    from vintix.evaluate import evaluate
    from vintix.evaluate.config import EvalConfig
    from vintix.report import write_report

    evaluate(Agent(model), EvalConfig(tasks=["optimum-pendulum"], shots=2, seeds=1), out=tmp_path / "results")
    write_report([tmp_path / "results"], tmp_path / "report", table="ours")  # scored by the optimum too
    assert (tmp_path / "report" / "report.md").is_file()


def test_a_checkpoint_keeps_its_groups_held_out_task_of_your_own_so_a_new_process_evaluates_it(no_custom_tasks,
                                                                                                tmp_path):
    """A held-out split (its own task, the same group) that no history was collected on travels with the model."""
    from vintix.agent import Agent
    from vintix.evaluate import evaluate_shots
    from vintix.model import GroupSpec, ModelConfig, TaskNorm, Vintix, save_pretrained

    for name, split in (("pendulum-train", "train"), ("pendulum-heldout", "test")):
        vintix.register_task(name, env_factory="test_custom_tasks:pendulum_with_an_optimum", obs_dim=3, act_dim=1,
                             episode_length=20, group="pendulums", split=split)
    model = Vintix(ModelConfig(n_layers=1, n_heads=1, obs_emb_dim=6, act_emb_dim=6, rew_emb_dim=4, mlp_dim=8,
                               context_len=64), [GroupSpec("pendulums", 3, 1)],
                   [TaskNorm("pendulum-train", "pendulums", [0.0] * 3, [1.0] * 3)])
    save_pretrained(model, tmp_path / "model")
    registry._custom.clear()  # a new process: only the checkpoint knows the tasks
    agent = Agent.from_pretrained(tmp_path / "model", trust_code=True)
    runs = evaluate_shots(agent, "pendulum-heldout", shots=1, seeds=2)
    assert runs.returns.shape == (2, 1) and get_task("pendulum-heldout").split == "test"
