"""Figure-3-style plots of a collected dataset."""

import numpy as np

from vintix.collect import CollectionPlan, collect
from vintix.data.plot import normalized_curve, plot_dataset


def test_normalized_curve_spreads_each_episode_over_its_steps():
    returns = np.array([0.0, 0.0, 50.0, 50.0, 100.0, 100.0])  # random 0, expert 100
    np.testing.assert_allclose(normalized_curve(returns, [10] * 6, 0.0, 100.0, bins=3), [0.0, 0.5, 1.0])
    # One long episode fills every bin it spans: no gaps where no episode starts.
    np.testing.assert_allclose(normalized_curve(np.array([0.0, 100.0]), [10, 30], 0.0, 100.0, bins=4), [0, 1, 1, 1])


def test_plot_dataset_writes_task_and_domain_figures_of_a_real_collection(tmp_path):
    collect(CollectionPlan("reach-v3", histories=2, steps=1000, envs_per_batch=2), tmp_path / "data")
    written, skipped = plot_dataset(tmp_path / "data", tmp_path / "figs", bins=10)
    assert skipped == []
    assert sorted(p.relative_to(tmp_path / "figs").as_posix() for p in written) == [
        "metaworld.png", "metaworld/reach-v3.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in written)
    assert not list((tmp_path / "figs").rglob("*.partial"))


def test_plot_skips_tasks_without_a_reference_in_the_chosen_table(tmp_path):
    collect(CollectionPlan("reach-v3", histories=1, steps=200), tmp_path / "data")
    (tmp_path / "data" / "metaworld" / "reach-v3" / "reach-v3.json").write_text(
        '{"task_name": "my-own-task", "observation_shape": {"proprio": [39]}, "action_dim": 4, '
        '"action_type": "continuous"}')
    assert plot_dataset(tmp_path / "data", tmp_path / "figs", bins=10, reference_table="paper") == ([], ["my-own-task"])
