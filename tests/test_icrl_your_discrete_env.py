"""docs/icrl-your-discrete-env.md, followed as a user would: its files written out as the page shows them, both
routes' shell commands run as written, and each discrete model they make must find the lucky lever from its
rewards (from shot 3 on with the true rewards fed back, not with zeros): the one learnt from an expert alone (DPT's
target) and the one learnt from a search."""

from pathlib import Path

import numpy as np
import pytest

from test_icrl_your_env import follow_page, mean_by_shot

PAGE = Path(__file__).parents[1] / "docs" / "icrl-your-discrete-env.md"


@pytest.mark.slow
def test_following_the_page_gives_discrete_models_that_find_the_lucky_lever_from_their_rewards(tmp_path):
    assert follow_page(PAGE, tmp_path) == {"levers.py", "tasks.yaml", "recipe-dpt.yaml", "recipe.yaml", "train.yaml"}
    later = [3, 4, 5, 6]
    # Route 1, DPT: measured success 0.89 fed true rewards, 0.64 fed zeros; lucky pulls 1.69 of 3 against 0.78
    true, zero = (mean_by_shot(tmp_path / "results-dpt" / r, "return") for r in ("true", "zero"))
    assert np.mean([true[s] - zero[s] for s in later]) >= 0.4
    success = mean_by_shot(tmp_path / "results-dpt" / "true")
    assert np.mean([success[s] for s in later]) >= 0.75
    assert (tmp_path / "report-dpt" / "report.md").is_file()
    # Route 2, a search
    true, zero = mean_by_shot(tmp_path / "results" / "true"), mean_by_shot(tmp_path / "results" / "zero")
    # measured 0.84 (0.86 drawing from one stream for the batch, 0.94 on 2026-12-06): its draws miss a pull now and
    # then, and 40 runs of 4 shots vary by a few points; fed zeros, 0.16
    assert np.mean([true[s] for s in later]) >= 0.75
    assert np.mean([true[s] - zero[s] for s in later]) >= 0.5  # the rewards, not the context's length, do it
    assert (tmp_path / "report" / "report.md").is_file()
