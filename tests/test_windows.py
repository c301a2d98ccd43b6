"""The training window loader: windows inside one history, sparsity, sampling weights, statistics, errors."""

from __future__ import annotations

import gc
import json
import os
from collections import Counter

import h5py
import numpy as np
import pytest
import torch

from vintix.data import LearningHistoryWriter, history_paths, task_directory, write_task_metadata
from vintix.errors import DatasetError
from vintix.train.data import (
    TrainingDataError,
    WindowBatches,
    WindowDataset,
    check_finite_rows,
    collate_windows,
    content_fingerprint,
    load_training_data,
)


def write_history(path, episode_lengths, history_id, obs_dim=39, act_dim=4, offset=0.0, demonstrator=False):
    """A history whose obs[:, 0] is the row index and obs[:, 1] the history id, so windows can be traced;
    with `demonstrator`, it stores demonstrator actions whose first entry is minus the row index."""
    n = sum(episode_lengths)
    rows = np.arange(n, dtype=np.float32)
    obs = np.zeros((n, obs_dim), np.float32) + offset
    obs[:, 0], obs[:, 1] = rows, history_id
    obs[:, 2:] += np.sin(rows[:, None] * np.arange(1, obs_dim - 1))
    action = np.zeros((n, act_dim), np.float32)
    action[:, 0] = rows
    step_num = np.concatenate([np.arange(length) for length in episode_lengths])
    with LearningHistoryWriter(path, obs_dim, act_dim, chunk_size=64, demonstrator_actions=demonstrator) as writer:
        writer.append(obs, action, rows / 10, step_num, demonstrator_action=-action if demonstrator else None)


def write_task(root, name, histories, obs_dim=39, act_dim=4, offset=0.0, demonstrator=False, **metadata):
    """histories: one list of episode lengths per history; `offset` is added to every observation."""
    folder = task_directory(root, "metaworld", name)
    write_task_metadata(folder, name, obs_dim, act_dim, **metadata)
    for i, lengths in enumerate(histories):
        write_history(folder / f"history-{i:04d}.h5", lengths, history_id=i, obs_dim=obs_dim, act_dim=act_dim,
                      offset=offset, demonstrator=demonstrator)
    return folder


@pytest.fixture
def dataset(tmp_path):
    root = tmp_path / "data"
    write_task(root, "reach-v3", [[20] * 10, [15] * 8], noise_free_fraction=0.25)
    write_task(root, "push-v3", [[20] * 10] * 3)
    return root


def load(root, tmp_path, **kwargs):
    return load_training_data(root, stats_cache_dir=tmp_path / "cache", **kwargs)


def episode_of(step_num):
    return np.cumsum(step_num == 0)


def test_window_is_consecutive_rows_of_one_history_with_true_previous_action(dataset, tmp_path):
    data = load(dataset, tmp_path)
    windows = WindowDataset(data, window_len=30, seed=3)
    mid_episode_starts = 0
    for i in range(200):
        w = windows[i]
        obs, step = w["obs"], w["step_num"]
        assert len(np.unique(obs[:, 1])) == 1, "one history per window"
        assert np.array_equal(np.diff(obs[:, 0]), np.ones(29)), "consecutive rows"
        rows = obs[:, 0]
        # Targets are a_t; the previous action/reward are row t-1's, at the first token too.
        assert np.array_equal(w["action"][:, 0], rows)
        inside = step != 0
        assert np.array_equal(w["prev_action"][inside, 0], rows[inside] - 1)
        assert np.allclose(w["prev_reward"][inside], (rows[inside] - 1) / 10)
        # An episode start's reward is the previous episode's last (ModelConfig.last_reward); the history's
        # first row has none.
        assert np.allclose(w["prev_reward"][~inside], np.maximum(rows[~inside] - 1, 0) / 10)
        mid_episode_starts += bool(step[0] != 0)
    assert mid_episode_starts > 100, "random offsets start most windows mid-episode"


def test_episode_returns_are_what_each_rows_episode_earned_before_it_also_where_a_window_opens_mid_episode(
        dataset, tmp_path):
    """The rows' rewards are row / 10 (`write_history`): a token's return so far is the sum over its episode's
    earlier rows, which a window opening mid-episode must read from before its own first row."""
    windows = WindowDataset(load(dataset, tmp_path), window_len=30, seed=3, episode_returns=True)
    assert "prev_return" not in WindowDataset(load(dataset, tmp_path), window_len=30, seed=3)[0]
    opened_mid_episode = 0
    for i in range(100):
        w = windows[i]
        rows, step = w["obs"][:, 0].astype(int), w["step_num"]
        expected = [sum(range(row - s, row)) / 10 for row, s in zip(rows, step, strict=True)]
        np.testing.assert_allclose(w["prev_return"], expected, rtol=1e-5)
        opened_mid_episode += bool(step[0] > 1)
    assert opened_mid_episode > 50


def test_every_start_offset_of_a_history_is_reachable(tmp_path):
    root = tmp_path / "data"
    write_task(root, "reach-v3", [[10] * 4])  # 40 rows, windows of 30: starts 0..10
    windows = WindowDataset(load(root, tmp_path), window_len=30, seed=0)
    starts = Counter(int(windows[i]["obs"][0, 0]) for i in range(300))
    assert set(starts) == set(range(11))


def test_sparsity_keeps_every_kth_episode(dataset, tmp_path):
    windows = WindowDataset(load(dataset, tmp_path), window_len=40, sparsity=3, seed=0)
    for i in range(50):
        w = windows[i]
        starts = np.flatnonzero(w["step_num"] == 0)
        assert len(starts) >= 1
        rows = w["obs"][:, 0]
        jumps = np.flatnonzero(np.diff(rows) != 1)
        assert np.array_equal(jumps + 1, starts[starts > 0]), "rows jump only at kept episode starts"
        for j in jumps:
            skipped = rows[j + 1] - rows[j] - 1
            assert skipped in (2 * 20, 2 * 15), "two whole episodes skipped between kept ones"
            # A kept episode's start carries the last reward of the episode before it in the window.
            assert np.isclose(w["prev_reward"][j + 1], rows[j] / 10)


def test_stochastic_sparsity_draws_each_k_up_to_the_maximum(dataset, tmp_path):
    windows = WindowDataset(load(dataset, tmp_path), window_len=40, sparsity=3, stochastic_sparsity=True, seed=0)
    assert Counter(windows.locate(i)[4] for i in range(300)).keys() == {1, 2, 3}


def test_tasks_are_sampled_uniformly_or_by_volume(dataset, tmp_path):
    data = load(dataset, tmp_path)
    steps = {t.name: t.steps for t in data.tasks}
    assert steps == {"push-v3": 600, "reach-v3": 320}
    for sampling, expected in (("uniform", 0.5), ("volume", 600 / 920)):
        windows = WindowDataset(data, window_len=30, task_sampling=sampling, seed=1)
        names = [data.tasks[windows.locate(i)[0]].name for i in range(3000)]
        assert names.count("push-v3") / 3000 == pytest.approx(expected, abs=0.03)


def test_same_index_same_window_and_ranks_never_share_windows(dataset, tmp_path):
    data = load(dataset, tmp_path)
    a, b = WindowDataset(data, 30, seed=5), WindowDataset(data, 30, seed=5)
    assert all(np.array_equal(a[i]["obs"], b[i]["obs"]) for i in range(20))
    assert not np.array_equal(a[0]["obs"], WindowDataset(data, 30, seed=6)[0]["obs"])
    ranks = [WindowBatches(4, start_micro_batch=2, rank=r, world_size=2) for r in range(2)]
    seen = [[i for _, batch in zip(range(5), iter(s), strict=False) for i in batch] for s in ranks]
    assert not set(seen[0]) & set(seen[1])
    assert sorted(seen[0] + seen[1]) == list(range(16, 56))


def test_worker_processes_load_the_same_batches(dataset, tmp_path):
    windows = WindowDataset(load(dataset, tmp_path), 30, seed=0)

    def batches(workers):
        loader = torch.utils.data.DataLoader(windows, batch_sampler=WindowBatches(3), collate_fn=collate_windows,
                                             num_workers=workers)
        return [b for _, b in zip(range(4), loader, strict=False)]

    for inline, forked in zip(batches(0), batches(2), strict=True):
        assert inline.keys() == forked.keys() == {"metaworld"}
        assert all(torch.equal(inline["metaworld"][k], forked["metaworld"][k]) for k in inline["metaworld"])


def test_batches_mix_groups(tmp_path):
    root = tmp_path / "data"
    write_task(root, "reach-v3", [[20] * 5])
    write_task(root, "Hopper-v5", [[25] * 4], obs_dim=11, act_dim=3)
    data = load(root, tmp_path)
    assert [(g.name, g.obs_dim, g.act_dim) for g in data.groups] == [("metaworld", 39, 4), ("mujoco-hopper", 11, 3)]
    # Hopper: from the registry (its JSON has none)
    assert data.task_norms[0].reward_scale == 0.1 and data.tasks[0].name == "Hopper-v5"
    batch = collate_windows([WindowDataset(data, 30, seed=0)[i] for i in range(12)])
    assert set(batch) == {"metaworld", "mujoco-hopper"}
    assert batch["mujoco-hopper"]["obs"].shape[1:] == (30, 11) and batch["metaworld"]["action"].shape[1:] == (30, 4)


def test_expert_distillation_reads_only_the_noise_free_tail(dataset, tmp_path):
    data = load(dataset, tmp_path, expert_distillation=True, tasks=["reach-v3"])
    windows = WindowDataset(data, window_len=30, seed=0)
    # JSON noise_free_fraction 0.25: the episodes that start in the last quarter of each history:
    # history 0 (episodes of 20, 200 rows) from row 160, history 1 (episodes of 15, 120 rows) from 90.
    lowest = {0: 200, 1: 120}
    for i in range(100):
        obs = windows[i]["obs"]
        lowest[int(obs[0, 1])] = min(lowest[int(obs[0, 1])], int(obs[0, 0]))
    assert lowest == {0: 160, 1: 90}
    with pytest.raises(TrainingDataError, match="noise_free_fraction"):
        load(dataset, tmp_path, expert_distillation=True, tasks=["push-v3"])
    half = load(dataset, tmp_path, expert_distillation=True, expert_tail_fraction=0.5, tasks=["push-v3"])
    assert half.tasks[0].steps == 300


def test_expert_distillation_learns_stored_demonstrator_actions_on_every_row(tmp_path):
    root = tmp_path / "data"
    write_task(root, "reach-v3", [[20] * 10, [15] * 8], noise_free_fraction=0.25, demonstrator=True)
    data = load(root, tmp_path, expert_distillation=True, tasks=["reach-v3"])
    assert data.tasks[0].rows == "every row, target the demonstrator's action"
    windows = WindowDataset(data, window_len=30, seed=0)
    starts = []
    for i in range(100):
        w = windows[i]
        rows = w["obs"][:, 0]
        assert np.array_equal(w["action"][:, 0], -rows)  # the target: the demonstrator's action
        inside = w["step_num"] != 0
        assert np.array_equal(w["prev_action"][inside, 0], rows[inside] - 1)  # the context: the executed ones
        starts.append(rows[0])
    assert min(starts) < 90  # not only the noise-free tail
    tail = load(root, tmp_path, expert_distillation=True, expert_rows="tail", tasks=["reach-v3"])
    assert tail.tasks[0].rows == "noise-free tail, target the executed action"
    assert tail.tasks[0].steps == 40 + 30
    plain = WindowDataset(load(root, tmp_path, tasks=["reach-v3"]), window_len=30, seed=0)[0]
    assert np.array_equal(plain["action"][:, 0], plain["obs"][:, 0])  # AD learns the executed actions


def test_obs_statistics_stream_over_all_rows_and_are_cached_by_fingerprint(dataset, tmp_path):
    data = load(dataset, tmp_path)
    reach = data.tasks[[t.name for t in data.tasks].index("reach-v3")]
    obs = np.concatenate([h.history.read(0, h.history.num_steps)["observation"]
                          for h in reach.histories]).astype(np.float64)
    assert np.allclose(reach.norm.obs_mean, obs.mean(axis=0)) and np.allclose(reach.norm.obs_std, obs.std(axis=0))
    [cache] = (tmp_path / "cache").glob("reach-v3-*.json")
    entry = json.loads(cache.read_text())
    entry["obs_mean"] = [123.0] * 39
    cache.write_text(json.dumps(entry))
    assert load(dataset, tmp_path).tasks[1].norm.obs_mean[0] == 123.0, "unchanged files: the cache is used"
    write_history(dataset / "metaworld" / "reach-v3" / "history-0001.h5", [15] * 8, history_id=1, offset=5.0)
    fresh = load(dataset, tmp_path).tasks[1].norm.obs_mean
    assert fresh[0] != 123.0 and fresh[5] == pytest.approx(obs.mean(axis=0)[5] + 5.0 * 120 / 320, abs=1e-4)


def test_task_missing_from_the_registry_is_a_clear_error(tmp_path):
    write_task(tmp_path / "data", "my-own-task", [[10] * 3])
    with pytest.raises(TrainingDataError, match="'my-own-task' is not in the task registry"):
        load(tmp_path / "data", tmp_path)


def test_a_task_whose_data_disagrees_with_the_registrys_dims_is_a_clear_error(tmp_path):
    write_task(tmp_path / "data", "reach-v3", [[10] * 3])
    write_task(tmp_path / "data", "push-v3", [[10] * 3], obs_dim=12)
    with pytest.raises(TrainingDataError, match=r"'push-v3' declares \(obs_dim, act_dim\) = \(12, 4\) but the task "
                                                r"registry's push-v3 \(group 'metaworld'\) has \(39, 4\)"):
        load(tmp_path / "data", tmp_path)


def test_an_industrial_benchmark_folder_claiming_7_dims_in_json_and_data_is_refused(tmp_path):
    # JSON and histories agree with each other (validation's own checks pass), not with the registry.
    root = tmp_path / "data"
    folder = task_directory(root, "industrial_benchmark", "industrial-benchmark-10-v1")
    write_task_metadata(folder, "industrial-benchmark-10-v1", 7, 3)
    write_history(folder / "history-0000.h5", [25] * 4, history_id=0, obs_dim=7, act_dim=3)
    with pytest.raises(TrainingDataError, match=r"\(7, 3\) but the task registry's industrial-benchmark-10-v1 "
                                                r"\(group 'industrial_benchmark'\) has \(6, 3\)") as error:
        load(root, tmp_path, tasks=["industrial_benchmark"])
    assert str(folder) in str(error.value)


def poison(path, key: str, row: int, value: float = np.nan) -> None:
    """Overwrite one value of a history in place with h5py (what a buggy writer or a diverged env leaves)."""
    with h5py.File(path, "r+") as f:
        group = next(name for name in f if int(name.split("-")[0]) <= row <= int(name.split("-")[1]))
        data = f[group][key][()]
        data[row - int(group.split("-")[0])] = value
        f[group][key][...] = data


@pytest.mark.parametrize("key", ["proprio_observation", "reward", "action"])
def test_training_refuses_histories_with_nan_or_inf_before_it_starts(dataset, tmp_path, key):
    path = dataset / "metaworld" / "reach-v3" / "history-0001.h5"
    poison(path, key, 70, np.inf if key == "reward" else np.nan)
    with pytest.raises(TrainingDataError, match=rf"history-0001.h5: NaN/inf in {key} at row 70.*vintix data "
                                                "validate") as error:
        load(dataset, tmp_path)
    assert "reach-v3" in str(error.value)
    assert not list((tmp_path / "cache").glob("reach-v3-*.json")), "no statistics cached for rejected data"


def test_a_cached_entry_from_before_validation_or_with_nan_statistics_is_not_trusted(dataset, tmp_path):
    load(dataset, tmp_path)
    [cache] = (tmp_path / "cache").glob("reach-v3-*.json")
    entry = json.loads(cache.read_text())
    folder = dataset / "metaworld" / "reach-v3"
    poison(folder / "history-0000.h5", "reward", 3)
    # What an older vintix cached for this very data: no validation mark, or statistics already NaN.
    entry["fingerprint"] = content_fingerprint(history_paths(folder))
    unvalidated = {k: v for k, v in entry.items() if k != "validated"}
    for stale in (unvalidated, {**entry, "obs_mean": [float("nan")] * 39}):
        cache.write_text(json.dumps(stale))
        with pytest.raises(TrainingDataError, match="history-0000.h5: NaN/inf in reward at row 3"):
            load(dataset, tmp_path)


def test_a_history_damaged_in_place_is_caught_before_training_and_after_loading(dataset, tmp_path):
    """A NaN written in place with the file's size and mtime kept (h5py, then the mtime restored): the statistics
    cache notices (its key holds the change time) and validation names the file before training; a history damaged
    after the data was loaded ends in an error naming the file and row when a window reads it, not in a NaN loss."""
    load(dataset, tmp_path)  # caches the statistics
    gc.collect()  # closes the files that load opened, so h5py may write to one
    path = dataset / "metaworld" / "reach-v3" / "history-0000.h5"
    stat = path.stat()
    poison(path, "reward", 5)
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    with pytest.raises(TrainingDataError, match=r"history-0000.h5.*reward"):
        load(dataset, tmp_path)  # the cache no longer vouches for the file
    # Damaged after loading (another process writing while training runs): the rows a window reads are checked.
    rows = {"observation": np.zeros((10, 3)), "reward": np.zeros(10), "action": np.zeros((10, 2))}
    rows["reward"][2] = np.nan
    with pytest.raises(DatasetError, match=r"history-0000.h5.*reward at row 7 is NaN or inf.*vintix data validate"):
        check_finite_rows(path, 5, rows)
