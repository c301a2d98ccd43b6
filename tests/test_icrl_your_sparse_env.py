"""docs/icrl-your-sparse-env.md, followed as a user would: its files written out as the page shows them, its shell
commands run as written, and the model they make, from the package's own sparse-reward search (no demonstrator of
the user's), must find the goal from its rewards: success from shot 2 on with the true rewards fed back, not with
zeros."""

from pathlib import Path

import numpy as np
import pytest

from test_icrl_your_env import follow_page, mean_by_shot

PAGE = Path(__file__).parents[1] / "docs" / "icrl-your-sparse-env.md"


@pytest.mark.slow
def test_following_the_page_gives_a_model_that_finds_a_sparse_goal_from_its_rewards(tmp_path):
    assert follow_page(PAGE, tmp_path) == {"sparse_goal.py", "tasks.yaml", "recipe.yaml", "train.yaml"}
    true, zero = mean_by_shot(tmp_path / "results" / "true"), mean_by_shot(tmp_path / "results" / "zero")
    later = [2, 3, 4, 5, 6]
    assert np.mean([true[s] - zero[s] for s in later]) >= 0.5  # the rewards, not the context's length, do it
    assert (tmp_path / "report" / "report.md").is_file() and (tmp_path / "goal-blind.csv").is_file()
