"""docs/icrl-your-discrete-env.md, followed as a user would: its files written out as the page shows them, its
shell commands run as written, and the discrete model they make must find the lucky lever from its rewards (from
shot 2 on with the true rewards fed back, not with zeros)."""

from pathlib import Path

import numpy as np
import pytest

from test_icrl_your_env import follow_page, success_by_shot

PAGE = Path(__file__).parents[1] / "docs" / "icrl-your-discrete-env.md"


@pytest.mark.slow
def test_following_the_page_gives_a_discrete_model_that_finds_the_lucky_lever_from_its_rewards(tmp_path):
    assert follow_page(PAGE, tmp_path) == {"levers.py", "tasks.yaml", "recipe.yaml", "train.yaml"}
    true, zero = success_by_shot(tmp_path / "results" / "true"), success_by_shot(tmp_path / "results" / "zero")
    later = [3, 4, 5, 6]
    # measured 0.84 (0.86 drawing from one stream for the batch, 0.94 on 2026-12-06): its draws miss a pull now and
    # then, and 40 runs of 4 shots vary by a few points; fed zeros, 0.16
    assert np.mean([true[s] for s in later]) >= 0.75
    assert np.mean([true[s] - zero[s] for s in later]) >= 0.5  # the rewards, not the context's length, do it
    assert (tmp_path / "report" / "report.md").is_file()
