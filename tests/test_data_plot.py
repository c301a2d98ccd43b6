"""Figure-3-style plots of a collected dataset, and the smoothness criterion over the same curves."""

import numpy as np
import pytest

from vintix.collect import CollectionPlan, NoiseSchedule, collect
from vintix.collect.calibrate import noise_free_return
from vintix.data import DatasetError, LearningHistoryWriter, task_directory, write_task_metadata
from vintix.data.plot import normalized_curve, plot_dataset, smoothness, task_curves
from vintix.tasks.scores import reference


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


def write_history_with_returns(path, returns, episode_len=10):
    """A reach-v3-shaped history whose episodes return exactly `returns`."""
    n = len(returns) * episode_len
    with LearningHistoryWriter(path, 39, 4) as writer:
        writer.append(np.zeros((n, 39)), np.zeros((n, 4)), np.repeat(np.asarray(returns) / episode_len, episode_len),
                      np.tile(np.arange(episode_len), len(returns)))


def test_smoothness_tells_a_steady_rise_from_a_jump(tmp_path):
    ref = reference("reach-v3", "ours")
    folder = task_directory(tmp_path, "metaworld", "reach-v3")
    write_task_metadata(folder, "reach-v3", 39, 4)
    ramp = ref.random + (ref.expert - ref.random) * np.linspace(0, 1, 21)  # the last episode is dropped (cut short)
    write_history_with_returns(folder / "history-0000.h5", ramp)
    [steady], skipped = smoothness(tmp_path, bins=10)
    assert skipped == [] and steady.histories == 1
    assert abs(steady.rank_correlation - 1.0) < 1e-9 and abs(steady.largest_jump - 0.1) < 0.01 and steady.smooth()
    assert abs(steady.start - 0.025) < 1e-6 and abs(steady.end - 0.925) < 1e-6  # two episodes per bin
    write_history_with_returns(folder / "history-0001.h5", [ref.random] * 10 + [ref.expert] * 11)
    [worst], _ = smoothness(tmp_path, bins=10)
    assert worst.histories == 2 and abs(worst.largest_jump - 1.0) < 1e-6 and not worst.smooth()
    for path in folder.glob("*.h5"):
        path.unlink()
    write_history_with_returns(folder / "history-0000.h5", ramp / 2 + ref.expert / 2)  # starts halfway: rises 0.45
    [halfway], _ = smoothness(tmp_path, bins=10)
    assert halfway.rank_correlation > 0.99 and halfway.largest_jump < 0.06 and not halfway.smooth()


def test_history_expert_scales_each_history_by_its_noise_free_episodes(tmp_path):
    """Two reach-v3 histories play different hidden goals, so their demonstrator returns differ; scaled by
    their own noise-free episodes, the bin that lies inside that tail reads exactly 1 for both."""
    collect(CollectionPlan("reach-v3", histories=2, steps=2000, schedule=NoiseSchedule(1.0, 0.5)), tmp_path / "data")
    by_table = task_curves(tmp_path / "data", bins=4)[0]["metaworld"]["reach-v3"]
    by_own = task_curves(tmp_path / "data", bins=4, history_expert=noise_free_return)[0]["metaworld"]["reach-v3"]
    assert abs(by_table[0, -1] - by_table[1, -1]) > 0.02  # the goals' demonstrator returns differ (0.99, 0.96)
    np.testing.assert_allclose(by_own[:, -1], 1.0, rtol=1e-9)  # the scripted expert repeats its episode exactly
    np.testing.assert_allclose(by_own[:, 0], by_table[:, 0] * (by_own[:, 1] / by_table[:, 1]), rtol=1e-9)  # a rescale

    collect(CollectionPlan("reach-v3", histories=1, steps=500, schedule=NoiseSchedule(1.0, 0.0)), tmp_path / "no-tail")
    with pytest.raises(DatasetError, match="no complete noise-free episode"):
        smoothness(tmp_path / "no-tail", history_expert=noise_free_return)
