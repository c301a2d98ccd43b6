"""The whole chain keeps the model's use of rewards alive: collect, train, evaluate with the reward ablation.

On the toy hidden-goal task (`vintix.tasks.toy`) only rewards reveal the goal. A small model trained
for a minute and a half on histories of the demonstrator that infers the goal from rewards, by the
shipped `point-goal` recipe and training config, must end its episodes at the goal from its second
episode on with the true rewards fed back, and not with zeros. A change to the collector, the model,
the trainer or the agent that silently cuts the reward channel (the failure of the first shipped
model: it improved over shots exactly as much with zero rewards) fails this test.
"""

import numpy as np
import pytest

from vintix.agent import Agent
from vintix.collect import collect, load_recipe
from vintix.evaluate import EvalConfig, evaluate
from vintix.train import load_config, train


def mean_over_shots(rows: list[dict], shots: range) -> tuple[float, float]:
    """Mean normalized score (our demonstrator's scale) and success rate over `shots`."""
    chosen = [r for r in rows if r["shot"] in shots]
    return float(np.mean([r["normalized_ours"] for r in chosen])), float(np.mean([r["success"] for r in chosen]))


@pytest.mark.slow
def test_a_model_trained_on_reward_inferred_histories_needs_its_rewards(tmp_path):
    collect(load_recipe("point-goal"), tmp_path / "data")
    run = train(load_config("point-goal", {"data": str(tmp_path / "data"), "out": str(tmp_path / "run")}))
    agent = Agent.from_pretrained(run)
    rows = {reward_input: evaluate(agent, EvalConfig(tasks=["point-goal-v1"], shots=4, seeds=30, first_seed=100,
                                                     reward_input=reward_input))[0]
            for reward_input in ("true", "zero")}
    _, probing = mean_over_shots(rows["true"], range(1, 2))
    score, success = mean_over_shots(rows["true"], range(2, 5))
    zero_score, zero_success = mean_over_shots(rows["zero"], range(2, 5))
    assert success - probing >= 0.5  # it finds the goal after its first, probing episode...
    assert score - zero_score >= 0.5 and success - zero_success >= 0.5  # ...from that episode's rewards
