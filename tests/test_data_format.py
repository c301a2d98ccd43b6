"""The official HDF5 format: writer -> reader round trips, official-spec files, atomicity, fork safety."""

from __future__ import annotations

import json
import multiprocessing
import os
import pickle

import h5py
import numpy as np
import pytest

from conftest import flip_a_byte_of_data
from vintix.atomic import atomic_write_text
from vintix.data import (
    DatasetError,
    LearningHistory,
    LearningHistoryWriter,
    find_tasks,
    read_task_metadata,
    task_directory,
    write_task_metadata,
)


def make_rows(n: int, obs_dim: int = 3, act_dim: int = 2, episode_len: int = 8, seed: int = 0) -> dict:
    """n rows of a history with episodes of ``episode_len`` steps, in float64/int64 (the writer must cast)."""
    rng = np.random.default_rng(seed)
    return {
        "observation": rng.normal(size=(n, obs_dim)),
        "action": rng.uniform(-1, 1, size=(n, act_dim)),
        "reward": rng.normal(size=n),
        "step_num": np.arange(n) % episode_len,
    }


def write(path, rows: dict, chunk_size: int = 10_000, batch: int | None = None) -> None:
    obs_dim, act_dim = rows["observation"].shape[1], rows["action"].shape[1]
    n = len(rows["step_num"])
    with LearningHistoryWriter(path, obs_dim, act_dim, chunk_size=chunk_size) as writer:
        for start in range(0, n, batch or n):
            writer.append(*(v[start : start + (batch or n)] for v in rows.values()))


def assert_rows_equal(got: dict, rows: dict, start: int = 0, stop: int | None = None) -> None:
    expected_dtypes = {"observation": np.float32, "action": np.float32, "reward": np.float32, "step_num": np.int32}
    assert set(got) == set(expected_dtypes)
    for key, dtype in expected_dtypes.items():
        assert got[key].dtype == dtype, key
        np.testing.assert_array_equal(got[key], rows[key][start:stop].astype(dtype), err_msg=key)


def test_round_trip_across_small_groups(tmp_path):
    rows = make_rows(30)
    path = tmp_path / "h.h5"
    with LearningHistoryWriter(path, obs_dim=3, act_dim=2, chunk_size=7) as writer:
        for i in range(3):  # single steps ...
            writer.append(*(v[i] for v in rows.values()))
        writer.append(*(v[3:13] for v in rows.values()))  # ... then batches that straddle groups
        writer.append(*(v[13:] for v in rows.values()))
        assert writer.num_steps == 30
    with h5py.File(path) as f:
        assert sorted(f, key=lambda name: int(name.split("-")[0])) == ["0-6", "7-13", "14-20", "21-27", "28-29"]
        assert f["0-6/proprio_observation"].dtype == np.float32 and f["0-6/step_num"].dtype == np.int32
    history = LearningHistory(path)
    assert (history.num_steps, history.obs_dim, history.act_dim) == (30, 3, 2)
    assert_rows_equal(history.read(0, 30), rows)
    for start in range(31):  # empty, one row, across one or more group boundaries, to the end
        for stop in {start, min(start + 1, 30), min(start + 8, 30), min(start + 16, 30), 30}:
            assert_rows_equal(history.read(start, stop), rows, start, stop)
    np.testing.assert_array_equal(history.episode_starts, [0, 8, 16, 24])
    expected_returns = [rows["reward"][s : s + 8].astype(np.float32).sum() for s in (0, 8, 16, 24)]
    np.testing.assert_allclose(history.episode_returns(), expected_returns, rtol=1e-6)
    with pytest.raises(IndexError):
        history.read(5, 31)


def test_round_trip_default_group_size(tmp_path):
    rows = make_rows(25_000, obs_dim=5, act_dim=3, episode_len=1000)
    path = tmp_path / "h.h5"
    write(path, rows, batch=1_500)
    with h5py.File(path) as f:
        assert set(f) == {"0-9999", "10000-19999", "20000-24999"}
    history = LearningHistory(path)
    assert history.num_steps == 25_000
    assert_rows_equal(history.read(0, 25_000), rows)
    assert_rows_equal(history.read(9_990, 20_010), rows, 9_990, 20_010)
    assert len(history.episode_starts) == 25


def official_file(path, n: int, chunk: int, obs_dim: int, act_dim: int, episode_len: int) -> dict:
    """Write ``path`` straight from the spec with h5py, groups created in lexicographic name order."""
    rows = make_rows(n, obs_dim, act_dim, episode_len)
    names = {f"{s}-{min(s + chunk, n) - 1}": (s, min(s + chunk, n)) for s in range(0, n, chunk)}
    on_disk = {"proprio_observation": "observation", "action": "action", "reward": "reward", "step_num": "step_num"}
    dtypes = {"proprio_observation": "f4", "action": "f4", "reward": "f4", "step_num": "i4"}
    with h5py.File(path, "w") as f:
        for name in sorted(names):  # "0-9", "10-19", "100-109", "110-119", "120-124", "20-29": the trap
            start, stop = names[name]
            group = f.create_group(name)
            for disk, key in on_disk.items():
                group.create_dataset(disk, data=rows[key][start:stop].astype(dtypes[disk]))
    return rows


def test_reads_a_file_written_from_the_official_spec(tmp_path):
    task_dir = task_directory(tmp_path, "mujoco", "halfcheetah")
    task_dir.mkdir(parents=True)
    rows = official_file(task_dir / "0.h5", n=125, chunk=10, obs_dim=4, act_dim=2, episode_len=50)
    meta = {"task_name": "HalfCheetah-v5", "observation_shape": {"proprio": [4]}, "action_dim": 2,
            "action_type": "continuous", "reward_scale": 0.1, "group": "halfcheetah"}
    (task_dir / "halfcheetah.json").write_text(json.dumps(meta))
    with h5py.File(task_dir / "0.h5") as f:
        assert list(f)[:3] == ["0-9", "10-19", "100-109"]  # HDF5 iterates names lexicographically
    history = LearningHistory(task_dir / "0.h5")
    assert_rows_equal(history.read(0, 125), rows)
    assert_rows_equal(history.read(95, 112), rows, 95, 112)
    np.testing.assert_array_equal(history.episode_starts, [0, 50, 100])
    assert read_task_metadata(task_dir) == meta
    task = find_tasks(tmp_path)[0]
    assert (task.domain, task.task_dir, task.task_name, task.obs_dim, task.act_dim) == (
        "mujoco", task_dir, "HalfCheetah-v5", 4, 2)
    assert task.metadata["reward_scale"] == 0.1 and task.history_paths == [task_dir / "0.h5"]


def test_demonstrator_actions_round_trip_beside_the_official_rows(tmp_path):
    rows = make_rows(30)
    proposed = np.random.default_rng(1).uniform(-1, 1, size=(30, 2))
    path = tmp_path / "h.h5"
    with LearningHistoryWriter(path, obs_dim=3, act_dim=2, chunk_size=7, demonstrator_actions=True) as writer:
        writer.append(*(v[0] for v in rows.values()), demonstrator_action=proposed[0])  # one step, then a batch
        writer.append(*(v[1:] for v in rows.values()), demonstrator_action=proposed[1:])
    history = LearningHistory(path)
    assert history.has_demonstrator_action
    assert_rows_equal(history.read(3, 20), rows, 3, 20)  # official readers see the official rows only
    got = history.read(3, 20, demonstrator_action=True)
    assert got["demonstrator_action"].dtype == np.float32
    np.testing.assert_array_equal(got["demonstrator_action"], proposed[3:20].astype(np.float32))


@pytest.mark.parametrize("spelling", ["demonstrator_actions", "expert_action"])
def test_other_spellings_of_demonstrator_actions_are_read(tmp_path, spelling):
    rows = official_file(tmp_path / "0.h5", n=25, chunk=10, obs_dim=4, act_dim=2, episode_len=50)
    with h5py.File(tmp_path / "0.h5", "r+") as f:
        for name in f:
            f[name].create_dataset(spelling, data=f[name]["action"][()] * 2)
    got = LearningHistory(tmp_path / "0.h5").read(5, 25, demonstrator_action=True)
    np.testing.assert_array_equal(got["demonstrator_action"], rows["action"][5:25].astype(np.float32) * 2)


def test_a_file_without_demonstrator_actions_says_so_when_asked_for_them(tmp_path):
    official_file(tmp_path / "0.h5", n=25, chunk=10, obs_dim=4, act_dim=2, episode_len=50)
    history = LearningHistory(tmp_path / "0.h5")
    assert not history.has_demonstrator_action
    with pytest.raises(DatasetError, match="stores no demonstrator actions"):
        history.read(0, 5, demonstrator_action=True)


def test_writer_asks_for_demonstrator_actions_exactly_when_made_with_them(tmp_path):
    rows = make_rows(4)
    with LearningHistoryWriter(tmp_path / "a.h5", 3, 2, demonstrator_actions=True) as writer:
        with pytest.raises(DatasetError, match="made with demonstrator_actions, so append\\(\\) needs"):
            writer.append(*rows.values())
        with pytest.raises(DatasetError, match=r"demonstrator_action of shape \(4, 3\), expected \(4, 2\)"):
            writer.append(*rows.values(), demonstrator_action=np.zeros((4, 3)))
        with pytest.raises(DatasetError, match="NaN/inf in demonstrator_action"):
            writer.append(*rows.values(), demonstrator_action=np.full((4, 2), np.nan))
        writer.append(*rows.values(), demonstrator_action=rows["action"])
    with LearningHistoryWriter(tmp_path / "b.h5", 3, 2) as writer:
        with pytest.raises(DatasetError, match="made without demonstrator_actions, so append\\(\\) takes no"):
            writer.append(*rows.values(), demonstrator_action=rows["action"])
        writer.append(*rows.values())


def test_find_tasks_lists_finished_histories_only(tmp_path):
    task_dir = task_directory(tmp_path, "metaworld", "door-open")
    write_task_metadata(task_dir, "door-open-v3", obs_dim=3, act_dim=2, group="metaworld")
    write(task_dir / "b.h5", make_rows(10))
    write(task_dir / "a.h5", make_rows(10))
    (task_dir / "c.h5.partial").write_bytes(b"unfinished")
    tasks = find_tasks(tmp_path)
    assert [p.name for p in tasks[0].history_paths] == ["a.h5", "b.h5"]
    assert sorted(p.name for p in task_dir.iterdir()) == ["a.h5", "b.h5", "c.h5.partial", "door-open.json"]
    assert tasks[0].metadata["group"] == "metaworld"


def test_writer_is_atomic(tmp_path):
    path = tmp_path / "h.h5"
    rows = make_rows(20)
    with pytest.raises(RuntimeError, match="collector crashed"):
        with LearningHistoryWriter(path, 3, 2, chunk_size=7) as writer:
            writer.append(*(v[:15] for v in rows.values()))  # two full groups already on disk
            assert not path.exists() and len(list(tmp_path.glob("h.h5.*.partial"))) == 1
            raise RuntimeError("collector crashed")
    assert list(tmp_path.iterdir()) == []
    write(path, rows, chunk_size=7)
    assert [p.name for p in tmp_path.iterdir()] == ["h.h5"]


def test_a_writer_whose_first_writes_fail_leaves_no_file_behind(tmp_path):
    """The file exists from the writer's first line on; a failure while it writes its attributes (here an
    attribute HDF5 cannot store, in a collection a disk filling up at that moment) must remove it."""
    with pytest.raises(TypeError):
        LearningHistoryWriter(tmp_path / "h.h5", 3, 2, attrs={"settings": object()})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda r: {**r, "observation": r["observation"][:, :2]}, r"observation of shape \(5, 2\), expected \(5, 3\)"),
        (lambda r: {**r, "action": r["action"][:4]}, r"action of shape \(4, 2\), expected \(5, 2\)"),
        (lambda r: {**r, "step_num": r["step_num"] + 1}, "step_num 1 after -1"),
        (lambda r: {**r, "step_num": np.array([0, 1, 3, 4, 5])}, "step_num 3 after 1"),
        (lambda r: {**r, "step_num": r["step_num"].astype(float)}, "expected an integer"),
        (lambda r: {**r, "reward": np.where(np.arange(5) == 2, np.nan, r["reward"])}, "NaN/inf in reward"),
    ],
)
def test_writer_rejects_bad_rows(tmp_path, change, message):
    path = tmp_path / "h.h5"
    with pytest.raises(DatasetError, match=message) as error:
        with LearningHistoryWriter(path, 3, 2) as writer:
            writer.append(*change(make_rows(5)).values())
    assert str(path) in str(error.value)
    assert list(tmp_path.iterdir()) == []


def test_writer_single_step_shape_error_names_dims(tmp_path):
    with LearningHistoryWriter(tmp_path / "h.h5", obs_dim=17, act_dim=6) as writer:
        with pytest.raises(DatasetError, match=r"observation of shape \(11,\), expected \(17,\)"):
            writer.append(np.zeros(11), np.zeros(6), 0.0, 0)
        writer.append(np.zeros(17), np.zeros(6), 0.0, 0)  # a rejected call left the writer usable
    assert LearningHistory(tmp_path / "h.h5").num_steps == 1


def test_writer_rejects_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="chunk_size"):
        LearningHistoryWriter(tmp_path / "h.h5", 3, 2, chunk_size=10_001)  # official groups hold <= 10,000 rows
    with pytest.raises(DatasetError, match="must end in .h5"):
        LearningHistoryWriter(tmp_path / "h.hdf5", 3, 2)
    with pytest.raises(DatasetError, match="no steps were appended"):
        with LearningHistoryWriter(tmp_path / "h.h5", 3, 2):
            pass
    assert list(tmp_path.iterdir()) == []


def test_metadata_round_trip_and_errors(tmp_path):
    task_dir = tmp_path / "industrial_benchmark" / "ib-p10"
    path = write_task_metadata(task_dir, "ib-p10", obs_dim=6, act_dim=3, reward_scale=1.0)
    assert path == task_dir / "ib-p10.json" and [p.name for p in task_dir.iterdir()] == ["ib-p10.json"]
    meta = read_task_metadata(task_dir)
    assert meta == {"task_name": "ib-p10", "observation_shape": {"proprio": [6]}, "action_dim": 3,
                    "action_type": "continuous", "reward_scale": 1.0}
    path.write_text('{"task_name": "ib-p10", "observation_shape": {"proprio": [6]}, "action_dim": 3')
    with pytest.raises(DatasetError, match="not valid JSON") as error:
        read_task_metadata(task_dir)
    assert error.value.path == path
    path.write_text(json.dumps({**meta, "action_dim": "3"}))
    with pytest.raises(DatasetError, match="field 'action_dim' must be int, got \"3\""):
        read_task_metadata(task_dir)
    path.write_text(json.dumps({**meta, "action_dim": 0}))
    with pytest.raises(DatasetError, match="action_dim must be a positive integer"):
        read_task_metadata(task_dir)


def test_truncated_file_raises_dataset_error(tmp_path):
    path = tmp_path / "h.h5"
    write(path, make_rows(50), chunk_size=7)
    with open(path, "r+b") as f:
        f.truncate(path.stat().st_size // 2)
    with pytest.raises(DatasetError, match="not a readable HDF5 file") as error:
        LearningHistory(path).read(0, 10)
    assert str(path) in str(error.value) and "re-collect or delete it" in str(error.value)
    assert pickle.loads(pickle.dumps(error.value)).path == path  # survives DataLoader workers


def test_histories_carry_checksums_and_a_corrupted_block_names_its_file(tmp_path):
    path = tmp_path / "h.h5"
    rows = make_rows(30)
    write(path, rows, chunk_size=7)
    with h5py.File(path) as f:
        assert all(f[f"{g}/{k}"].fletcher32 for g in f for k in f[g])
    flip_a_byte_of_data(path)
    history = LearningHistory(path)
    assert history.num_steps == 30  # still opens and indexes: only the damaged block's rows fail
    assert_rows_equal(history.read(7, 30), rows, 7, 30)
    with pytest.raises(DatasetError, match="failed its checksum") as error:
        history.read(0, 10)
    assert error.value.path == path and "re-collect or delete it" in str(error.value)


def _read_in_child(history: LearningHistory, conn) -> None:
    inherited = history._handle
    rows = history.read(3, 17)
    conn.send((rows, inherited is not None and history._handle is not inherited))
    conn.close()


def test_reader_reopens_after_fork(tmp_path):
    rows = make_rows(20)
    write(tmp_path / "h.h5", rows, chunk_size=7)
    history = LearningHistory(tmp_path / "h.h5")
    assert_rows_equal(history.read(3, 17), rows, 3, 17)  # the parent holds an open handle now
    context = multiprocessing.get_context("fork")
    receiver, sender = context.Pipe(duplex=False)
    child = context.Process(target=_read_in_child, args=(history, sender))
    child.start()
    from_child, reopened = receiver.recv()
    child.join(timeout=30)
    assert child.exitcode == 0
    assert reopened, "the child must open its own HDF5 handle, never use the one inherited through fork"
    assert_rows_equal(from_child, rows, 3, 17)
    assert_rows_equal(history.read(0, 20), rows)  # the parent's handle still works after the child exits


def test_reader_pickles_without_its_handle(tmp_path):
    rows = make_rows(12)
    write(tmp_path / "h.h5", rows, chunk_size=5)
    history = LearningHistory(tmp_path / "h.h5")
    history.read(0, 1)
    copy = pickle.loads(pickle.dumps(history))
    assert_rows_equal(copy.read(0, 12), rows)


def test_files_written_atomically_get_the_permissions_a_plain_open_gives(tmp_path):
    """Temporaries are created exclusively (mkstemp, 0600); the published file must not stay private."""
    umask = os.umask(0o022)
    os.umask(umask)
    path = tmp_path / "h.h5"
    write(path, make_rows(5), chunk_size=5)
    atomic_write_text(tmp_path / "t.json", "{}")
    assert {oct(p.stat().st_mode & 0o777) for p in (path, tmp_path / "t.json")} == {oct(0o666 & ~umask)}
