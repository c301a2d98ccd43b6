"""The whole chain keeps the model's use of rewards alive: collect, train, evaluate with the reward ablation.

On the toy hidden-goal task (`vintix.tasks.toy`) only rewards reveal the goal. A small model trained
for a minute and a half on histories of the demonstrator that infers the goal from rewards, by the
shipped `point-goal` recipe and training config, must do much better with the true rewards fed back
than with zeros. A change to the collector, the model, the trainer or the agent that silently cuts
the reward channel (the failure of the first shipped model: it improved over shots exactly as much
with zero rewards) fails this test.
"""

import numpy as np

from vintix.agent import Agent
from vintix.collect import collect, load_recipe
from vintix.evaluate import EvalConfig, evaluate
from vintix.train import load_config, train


def late_means(rows: list[dict], first_shot: int) -> tuple[float, float]:
    """Mean normalized score (our demonstrator's scale) and success rate over shots from `first_shot` on."""
    late = [r for r in rows if r["shot"] >= first_shot]
    return float(np.mean([r["normalized_ours"] for r in late])), float(np.mean([r["success"] for r in late]))


def test_a_model_trained_on_reward_inferred_histories_needs_its_rewards(tmp_path):
    collect(load_recipe("point-goal"), tmp_path / "data")
    run = train(load_config("point-goal", {"data": str(tmp_path / "data"), "out": str(tmp_path / "run")}))
    agent = Agent.from_pretrained(run)
    late = {}
    for reward_input in ("true", "zero"):
        config = EvalConfig(tasks=["point-goal-v1"], shots=4, seeds=30, first_seed=100, reward_input=reward_input)
        late[reward_input] = late_means(evaluate(agent, config)[0], first_shot=2)
    (score, success), (zero_score, zero_success) = late["true"], late["zero"]
    assert score - zero_score >= 0.4 and success - zero_success >= 0.3, late
