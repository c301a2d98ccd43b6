"""Minari export: collected histories (episode ends recorded) load back through `minari.load_dataset` with
the same episodes, steps and values; a file without episode ends is refused by name."""

import gymnasium as gym
import h5py
import minari
import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import fill_up
from vintix.cli import app
from vintix.collect import CollectionPlan, collect
from vintix.collect.export import export_minari
from vintix.data import LearningHistory, LearningHistoryWriter, find_tasks, write_task_metadata
from vintix.data.layout import HISTORY_END, TERMINATED, TRUNCATED
from vintix.data.validate import validate_history
from vintix.errors import DatasetError, VintixError
from vintix.tasks import registry
from vintix.tasks.custom import register_task


@pytest.fixture(scope="module")
def pendulum_data(tmp_path_factory):
    """Histories whose episodes end all three ways: InvertedPendulum terminates when the noised pole falls,
    its 1000-step limit never comes in 400 steps, and the history's end cuts the last episode."""
    root = tmp_path_factory.mktemp("data")
    collect([CollectionPlan("InvertedPendulum-v5", histories=2, steps=400, envs_per_batch=2)], root)
    return root


@pytest.fixture
def minari_home(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return tmp_path / "minari"


def test_collected_histories_record_how_and_after_what_each_episode_ended(pendulum_data):
    [task] = find_tasks(pendulum_data)
    with LearningHistory(task.history_paths[0]) as history:
        rows, kinds, final = history.episode_ends()
        lengths = history.episode_lengths()
        data = history.read(0, history.num_steps)
    assert len(rows) == len(lengths) and rows[-1] == 399 and kinds[-1] == HISTORY_END
    assert (kinds[:-1] == TERMINATED).all() and len(kinds) > 2  # the noised pole falls, again and again
    np.testing.assert_array_equal(np.cumsum(lengths) - 1, rows)
    # The observation after an episode's end is the env's, not the next episode's reset observation.
    assert not np.allclose(final[0], data["observation"][rows[0] + 1])
    assert validate_history(task.history_paths[0], (4, 1)) == []


def test_export_then_minari_load_gives_back_every_episode(pendulum_data, minari_home):
    result = CliRunner().invoke(app, ["data", "export-minari", str(pendulum_data), "--dataset-id",
                                      "vintix/pendulum/test-v0", "--author", "vintix tests"])
    assert result.exit_code == 0, result.output
    dataset = minari.load_dataset("vintix/pendulum/test-v0")
    [task] = find_tasks(pendulum_data)
    expected = []
    for path in task.history_paths:
        with LearningHistory(path) as history:
            expected.append((history.read(0, history.num_steps), *history.episode_ends()))
    assert dataset.total_steps == 800 and dataset.total_episodes == sum(len(e[1]) for e in expected)
    episodes = list(dataset.iterate_episodes())
    metadata = list(dataset.storage.get_episode_metadata(range(dataset.total_episodes)))
    index = 0
    for h, (rows, ends, kinds, final) in enumerate(expected):
        start = 0
        for i, (end, kind) in enumerate(zip(ends, kinds, strict=True)):
            episode, meta = episodes[index], metadata[index]
            np.testing.assert_array_equal(episode.observations[:-1], rows["observation"][start:end + 1])
            np.testing.assert_array_equal(episode.observations[-1], final[i])
            np.testing.assert_array_equal(episode.actions, rows["action"][start:end + 1])
            np.testing.assert_allclose(episode.rewards, rows["reward"][start:end + 1])
            assert episode.terminations[-1] == (kind == TERMINATED) and episode.truncations[-1] == (kind != TERMINATED)
            assert not episode.terminations[:-1].any() and not episode.truncations[:-1].any()
            assert meta["history_index"] == h and meta["episode_in_history"] == i
            assert meta["epsilon_first_step"] >= meta["epsilon_last_step"]  # the noise anneals along a history
            index, start = index + 1, end + 1
    assert dataset.spec.env_spec.id == "InvertedPendulum-v5"  # recover_environment can make it


def test_a_history_without_episode_ends_cannot_become_a_minari_dataset(tmp_path, minari_home):
    task_dir = tmp_path / "data" / "mujoco" / "InvertedPendulum-v5"
    write_task_metadata(task_dir, "InvertedPendulum-v5", 4, 1)
    with LearningHistoryWriter(task_dir / "history-0000.h5", 4, 1) as writer:
        writer.append(np.zeros((3, 4)), np.zeros((3, 1)), np.ones(3), np.arange(3))
    with pytest.raises(DatasetError, match="records no episode ends"):
        export_minari(tmp_path / "data", "vintix/none-v0")


def test_validation_reports_episode_ends_that_are_not_where_episodes_end(pendulum_data, tmp_path):
    import shutil

    [task] = find_tasks(pendulum_data)
    damaged = tmp_path / "history.h5"
    shutil.copy(task.history_paths[0], damaged)
    with h5py.File(damaged, "r+") as f:
        f["0-399"]["episode_end_row"][0] += 1
    assert any("episode ends" in p for p in validate_history(damaged, (4, 1)))


def test_the_writer_refuses_an_unknown_episode_end(tmp_path):
    with LearningHistoryWriter(tmp_path / "h.h5", 2, 1, episode_ends=True) as writer:
        with pytest.raises(DatasetError, match="episode_end must be"):
            writer.append(np.zeros((2, 2)), np.zeros((2, 1)), np.zeros(2), np.arange(2), episode_end=[0, 7],
                          final_observation=np.zeros((2, 2)))
        writer.append(np.zeros((2, 2)), np.zeros((2, 1)), np.zeros(2), np.arange(2), episode_end=[0, TRUNCATED],
                      final_observation=np.ones((2, 2)))
    with LearningHistory(tmp_path / "h.h5") as history:
        rows, kinds, final = history.episode_ends()
    assert rows.tolist() == [1] and kinds.tolist() == [TRUNCATED] and final.tolist() == [[1.0, 1.0]]


def test_an_existing_dataset_is_replaced_only_when_asked(pendulum_data, minari_home):
    export_minari(pendulum_data, "vintix/pendulum/again-v0")
    with pytest.raises(VintixError, match="--overwrite"):
        export_minari(pendulum_data, "vintix/pendulum/again-v0")
    result = CliRunner().invoke(app, ["data", "export-minari", str(pendulum_data), "--dataset-id",
                                      "vintix/pendulum/again-v0", "--overwrite"])
    assert result.exit_code == 0, result.output
    assert "UserWarning" not in result.output  # Minari's advice for datasets published to its server, not printed
    assert minari.load_dataset("vintix/pendulum/again-v0").total_steps == 800


def make_bounded_point(**kwargs):
    """An env factory of the user's: its spaces have bounds, which the export must keep."""
    return BoundedPoint()


class BoundedPoint(gym.Env):
    observation_space = gym.spaces.Box(-2.0, 2.0, (1,), np.float32)
    action_space = gym.spaces.Box(-0.5, 0.5, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x = np.zeros(1, np.float32)
        return self.x.copy(), {}

    def step(self, action):
        self.x = np.clip(self.x + action, -2.0, 2.0).astype(np.float32)
        return self.x.copy(), float(-abs(self.x[0] - 1.0)), False, False, {}


class Toward:
    def __init__(self, task):
        pass

    def act(self, observations, envs):
        return np.clip(1.0 - observations[:, :1], -0.5, 0.5)


def test_your_own_tasks_keep_their_env_or_its_bounds(tmp_path, minari_home):
    """A task made from a Gymnasium id is recorded as that env (recover_environment makes it); one made by
    your factory keeps its env's own observation and action bounds."""
    register_task("mountain-car-mine", env_id="MountainCarContinuous-v0", obs_dim=2, act_dim=1, episode_length=50)
    register_task("bounded-point", env_factory=f"{__name__}:make_bounded_point", obs_dim=1, act_dim=1,
                  episode_length=20)
    try:  # the test module is the user's package here: the collector's workers import it by name
        collect([CollectionPlan("mountain-car-mine", histories=1, steps=100, demonstrator=f"{__name__}:Toward")],
                tmp_path / "car")
        collect([CollectionPlan("bounded-point", histories=1, steps=40, demonstrator=f"{__name__}:Toward")],
                tmp_path / "point")
        car = export_minari(tmp_path / "car", "mine/car-v0")
        assert car.spec.env_spec.id == "MountainCarContinuous-v0"
        assert car.recover_environment().spec.id == "MountainCarContinuous-v0"
        point = export_minari(tmp_path / "point", "mine/point-v0")
        assert point.spec.env_spec is None
        assert point.spec.observation_space == BoundedPoint.observation_space
        assert point.spec.action_space == BoundedPoint.action_space
    finally:
        registry._custom.clear()


def test_a_full_disk_is_said_before_a_minari_export_writes(pendulum_data, small_disk, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(small_disk / "minari"))
    fill_up(small_disk)
    with pytest.raises(OSError, match=r"the Minari dataset 'vintix/pendulum-v0' would need about .* free; free"):
        export_minari(pendulum_data, "vintix/pendulum-v0")
    written = [p.name for p in small_disk.rglob("*") if p.is_file()]
    assert written == ["ballast"]  # nothing begun (Minari's own root folder aside), no h5py traceback
    # One message, its own fix: no errno, no advice of a full disk mid-write that names an option export lacks
    said = CliRunner().invoke(app, ["data", "export-minari", str(pendulum_data), "--dataset-id", "vintix/pendulum-v0"])
    output = " ".join(said.output.split())
    assert said.exit_code == 2 and "free space, or point MINARI_DATASETS_PATH elsewhere" in output, output
    assert "[Errno" not in output and "--out" not in output, output
