"""DPT's target without a hand-written search: histories whose rows record the goal-aware expert's action behind
contexts that other behaviour made, here a model's own rollouts (DAgger's rounds, `vintix.agent.rollouts`)."""

from __future__ import annotations

import numpy as np
import pytest

from inference_model import one_torch_thread  # noqa: F401  (autouse fixture)
from vintix.agent import Agent
from vintix.agent.rollouts import ModelRollouts
from vintix.cli import app
from vintix.collect import CollectionPlan, NoiseSchedule, collect
from vintix.data import LearningHistory
from vintix.demonstrators import load_demonstrator
from vintix.tasks import make_env


def test_a_models_rollouts_record_its_own_actions_and_the_experts_as_the_target(tmp_path):
    """The shipped point-goal model plays; each row's target is what the goal-aware expert does at that row."""
    player = ModelRollouts("point-goal", "point-goal-v1")
    plan = CollectionPlan("point-goal-v1", histories=2, steps=30, schedule=NoiseSchedule(noise_free_fraction=1.0),
                          demonstrator=player.source, first_history=5)
    summaries = collect(plan, tmp_path, demonstrator=player)
    assert [s.path.name for s in summaries] == ["history-0005.h5", "history-0006.h5"]
    expert = load_demonstrator("point-goal-v1")
    for summary in summaries:
        with LearningHistory(summary.path) as history:
            rows = history.read(0, 30, demonstrator_action=True)
            env = make_env("point-goal-v1", seed=int(history.attrs["env_seed"]))
            assert str(history.attrs["demonstrator"]).startswith("rollouts:")
        env.reset()
        np.testing.assert_allclose(rows["demonstrator_action"], expert.act(rows["observation"], [env] * 30),
                                   atol=1e-6)
        assert not np.allclose(rows["action"], rows["demonstrator_action"], atol=1e-3)  # the model's, not the expert's


def test_a_rollout_is_what_the_agent_plays_on_the_same_env(tmp_path):
    player = ModelRollouts("point-goal", "point-goal-v1")
    plan = CollectionPlan("point-goal-v1", histories=1, steps=20, schedule=NoiseSchedule(noise_free_fraction=1.0),
                          demonstrator=player.source)
    [summary] = collect(plan, tmp_path, demonstrator=player)
    with LearningHistory(summary.path) as history:
        rows = history.read(0, 20)
        env = make_env("point-goal-v1", seed=int(history.attrs["env_seed"]))
    agent = Agent.from_pretrained("point-goal")
    agent.seed = player._agent.seed if player._agent is not None else 0
    agent.reset(["point-goal-v1"])
    obs, _ = env.reset()
    reward, start = 0.0, True
    for t in range(20):
        action = agent.act([obs], [reward], [start])[0]
        np.testing.assert_allclose(action, rows["action"][t], atol=1e-6)
        obs, reward, terminated, truncated, _ = env.step(action)
        start = terminated or truncated
        if start:
            obs, _ = env.reset()


def test_collect_rollouts_of_names_the_model_and_joins_a_folder_at_the_next_index(tmp_path):
    from typer.testing import CliRunner

    result = CliRunner().invoke(app, ["collect", "--task", "point-goal-v1", "--histories", "1", "--steps", "20",
                                      "--out", str(tmp_path), "--rollouts-of", "point-goal", "--first-history", "3"])
    assert result.exit_code == 0, result.output
    assert "wrote 1 rollouts of point-goal" in " ".join(result.output.split())
    assert (tmp_path / "toy" / "point-goal-v1" / "history-0003.h5").is_file()


def test_first_history_below_zero_is_refused():
    with pytest.raises(ValueError, match="first_history"):
        CollectionPlan("point-goal-v1", histories=1, steps=10, first_history=-1)
