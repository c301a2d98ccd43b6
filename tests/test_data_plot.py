"""Figure-3-style plots of a collected dataset."""

import numpy as np

from vintix.collect import CollectionPlan, collect
from vintix.data.plot import normalized_curve, plot_dataset


def test_normalized_curve_bins_episodes_by_their_place_in_the_history():
    returns = np.array([0.0, 0.0, 50.0, 50.0, 100.0, 100.0])  # random 0, expert 100
    np.testing.assert_allclose(normalized_curve(returns, 0.0, 100.0, bins=3), [0.0, 0.5, 1.0])
    assert np.isnan(normalized_curve(returns[:2], 0.0, 100.0, bins=3)[1])  # no episode in the middle bin


def test_plot_dataset_writes_task_and_domain_figures_of_a_real_collection(tmp_path):
    collect(CollectionPlan("reach-v3", histories=2, steps=1000, envs_per_batch=2), tmp_path / "data")
    written = plot_dataset(tmp_path / "data", tmp_path / "figs", bins=10)
    assert sorted(p.relative_to(tmp_path / "figs").as_posix() for p in written) == [
        "metaworld.png", "metaworld/reach-v3.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in written)
    assert not list((tmp_path / "figs").rglob("*.partial"))
