"""Dataset validation: a clean dataset passes, each kind of damage gives one clear problem naming the file."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    DAMAGE_NAMES,
    DATA,
    DEEP_JSON,
    api_error,
    bad_input_test,
    clean_data,
    cli_error,
    collected,
    damaged_data,
    documented,
    empty_dir,
    ib7_data,
    missing,
    work,
    workspace,
)
from conftest import flip_a_byte_of_data
from vintix.cli import app
from vintix.data import (
    LearningHistory,
    LearningHistoryWriter,
    summarize_dataset,
    task_directory,
    validate_dataset,
    write_task_metadata,
)

OBS_DIM, ACT_DIM, EPISODE_LEN = 3, 2, 8


@pytest.fixture
def dataset(tmp_path):
    """Two tasks, three histories of 30 steps in groups of 7 ("0-6", ..., "28-29")."""
    rng = np.random.default_rng(0)
    for domain, task in [("mujoco", "hopper"), ("metaworld", "reach")]:
        task_dir = task_directory(tmp_path, domain, task)
        write_task_metadata(task_dir, f"{task}-v5", OBS_DIM, ACT_DIM)
        for seed in range(2 if task == "hopper" else 1):
            with LearningHistoryWriter(task_dir / f"{seed}.h5", OBS_DIM, ACT_DIM, chunk_size=7) as writer:
                writer.append(rng.normal(size=(30, OBS_DIM)), rng.normal(size=(30, ACT_DIM)),
                              rng.normal(size=30), np.arange(30) % EPISODE_LEN)
    return tmp_path


def hopper_file(root):
    return root / "mujoco" / "hopper" / "0.h5"


def only_problem(root, **kwargs):
    problems = validate_dataset(root, **kwargs)
    assert len(problems) == 1, problems
    return problems[0]


def test_clean_dataset_has_no_problems(dataset):
    assert validate_dataset(dataset) == []
    assert validate_dataset(dataset, expected_dims=lambda name: (OBS_DIM, ACT_DIM)) == []
    assert validate_dataset(dataset, expected_dims=lambda name: None) == []  # unknown to the registry


def test_dims_disagree_with_json(dataset):
    write_task_metadata(dataset / "mujoco" / "hopper", "hopper-v5", OBS_DIM + 1, ACT_DIM)
    problems = validate_dataset(dataset)
    assert [p.path.name for p in problems] == ["0.h5", "1.h5"]
    assert "(obs_dim, act_dim) = (3, 2)" in problems[0].message and "declares (4, 2)" in problems[0].message


def test_a_history_in_another_tasks_folder_is_named(dataset):
    with h5py.File(hopper_file(dataset), "a") as file:
        file.attrs["task"] = "reach-v5"  # what our collector records; published files record nothing
    problem = only_problem(dataset)
    assert problem.path == hopper_file(dataset)
    assert "collected on task 'reach-v5' but sits in the folder of task 'hopper-v5'" in problem.message


def test_an_episode_longer_than_the_tasks_is_named(dataset):
    problem = only_problem(dataset, episode_limit=lambda name: 5 if name == "reach-v5" else None)
    assert problem.path.parent.name == "reach"
    assert "step_num 5 at row 5: an episode longer than the task's 5 steps" in problem.message
    assert validate_dataset(dataset, episode_limit=lambda name: EPISODE_LEN) == []  # full-length episodes are fine


def test_dims_disagree_with_registry(dataset):
    expected = {"hopper-v5": (11, 3)}
    problem = only_problem(dataset, expected_dims=expected.get)
    assert problem.path == dataset / "mujoco" / "hopper" / "hopper.json"
    assert "(3, 2)" in problem.message and "registry expects (11, 3)" in problem.message


def start_mid_episode(f: h5py.File) -> None:
    """Step numbers 1..8 then 0, 1, ...: a history recorded from the second step of its first episode."""
    f["0-6/step_num"][:] = np.arange(1, 8)
    f["7-13/step_num"][0] = 8


@pytest.mark.parametrize(
    ("damage", "expected"),
    [
        (lambda f: f["7-13/reward"].__setitem__(2, np.nan), "NaN/inf in reward at row 9;"),
        (lambda f: f.__delitem__("14-20"), "gap before group '21-27': expected a group starting at step 14"),
        (start_mid_episode, "starts at step_num 1, expected 0"),
        (lambda f: f["7-13/step_num"].__setitem__(3, 4), "step_num jumps from 1 to 4 at row 10"),
        (lambda f: f.move("28-29", "28-30"), "group '28-30' is named for 3 steps but holds 2"),
        (lambda f: f["0-6"].__delitem__("action"), "group '0-6' lacks dataset(s) ['action']"),
    ],
)
def test_damage_is_reported_once_with_its_file(dataset, damage, expected):
    with h5py.File(hopper_file(dataset), "r+") as f:
        damage(f)
    problem = only_problem(dataset)
    assert problem.path == hopper_file(dataset)
    assert expected in problem.message


def add_demonstrator_actions(f: h5py.File, name: str = "demonstrator_action") -> None:
    for group in f:
        f[group].create_dataset(name, data=f[group]["action"][()])


@pytest.mark.parametrize(
    ("damage", "expected"),
    [
        (lambda f: f["7-13/demonstrator_action"].__setitem__(2, np.nan), "NaN/inf in demonstrator_action at row 9;"),
        (lambda f: f["0-6"].__delitem__("demonstrator_action"),
         "groups disagree on their demonstrator-action dataset (None, demonstrator_action)"),
        (lambda f: f["0-6"].move("demonstrator_action", "expert_action"),
         "groups disagree on their demonstrator-action dataset (demonstrator_action, expert_action)"),
        (lambda f: [f["0-6"].__delitem__("demonstrator_action"), f["0-6"].create_dataset("demonstrator_action",
                                                                                        data=np.zeros((7, 5)))],
         "group '0-6' has demonstrator_action of shape (7, 5), expected the action's (7, 2)"),
    ],
)
def test_demonstrator_actions_are_checked_like_actions(dataset, damage, expected):
    with h5py.File(hopper_file(dataset), "r+") as f:
        add_demonstrator_actions(f)
    assert validate_dataset(dataset) == []
    with h5py.File(hopper_file(dataset), "r+") as f:
        damage(f)
    problem = only_problem(dataset)
    assert problem.path == hopper_file(dataset)
    assert expected in problem.message


def test_wrong_dtype(dataset):
    with h5py.File(hopper_file(dataset), "r+") as f:
        for name in ("0-6", "7-13"):
            rewards = f[f"{name}/reward"][()]
            del f[f"{name}/reward"]
            f[f"{name}/reward"] = rewards.astype(np.float64)
    problem = only_problem(dataset)
    assert "reward is float64 in group '0-6', expected float32 (2 occurrences in this file)" in problem.message


def test_repeated_problems_are_capped(dataset):
    with h5py.File(hopper_file(dataset), "r+") as f:
        for name in f:
            f[f"{name}/proprio_observation"][...] = np.inf
    problem = only_problem(dataset)
    assert problem.message.startswith("NaN/inf in proprio_observation at row 0 (30 occurrences in this file)")


def test_oversized_group(tmp_path):
    task_dir = task_directory(tmp_path, "mujoco", "big")
    write_task_metadata(task_dir, "big", 1, 1)
    n = 10_001
    with h5py.File(task_dir / "0.h5", "w") as f:
        group = f.create_group(f"0-{n - 1}")
        group["proprio_observation"] = np.zeros((n, 1), np.float32)
        group["action"] = np.zeros((n, 1), np.float32)
        group["reward"] = np.zeros(n, np.float32)
        group["step_num"] = (np.arange(n) % 100).astype(np.int32)
    assert "holds 10001 rows, more than 10000" in only_problem(tmp_path).message


def test_truncated_file(dataset):
    path = hopper_file(dataset)
    with open(path, "r+b") as f:
        f.truncate(path.stat().st_size - 100)
    problem = only_problem(dataset)
    assert problem.path == path
    assert "not a readable HDF5 file (truncated or corrupted?)" in problem.message
    assert str(path) in str(problem)


def test_a_file_another_process_is_writing_is_not_called_damaged(dataset):
    writer = subprocess.Popen([sys.executable, "-c", "import h5py, sys, time\n"
                               f"f = h5py.File({str(hopper_file(dataset))!r}, 'a'); "
                               "print('open', flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline().strip() == "open"
        problem = only_problem(dataset)
    finally:
        writer.kill()
        writer.wait()
    assert problem.path == hopper_file(dataset) and "another process has it open for writing" in problem.message
    assert "not damaged" in problem.message and "delete" not in problem.message
    assert validate_dataset(dataset) == []  # the writer gone, the file reads


def test_a_corrupted_data_block_is_reported_with_its_file(dataset):
    path = hopper_file(dataset)
    flip_a_byte_of_data(path, "7-13/reward")
    problem = only_problem(dataset)
    assert problem.path == path and "failed its checksum" in problem.message


def test_folder_level_problems(dataset):
    hopper = dataset / "mujoco" / "hopper"
    (hopper / "hopper.json").unlink()
    (hopper / "2.h5.partial").write_bytes(b"")
    (dataset / "mujoco" / "empty").mkdir()
    found = [(p.path.relative_to(dataset).as_posix(), p.message.split(";")[0]) for p in validate_dataset(dataset)]
    assert found == [
        ("mujoco/empty/empty.json", "missing task metadata (keys ['task_name', 'observation_shape', 'action_dim', "
                                    "'action_type'])"),
        ("mujoco/empty", "no learning histories (*.h5)"),
        ("mujoco/hopper/hopper.json", "missing task metadata (keys ['task_name', 'observation_shape', 'action_dim', "
                                      "'action_type'])"),
        ("mujoco/hopper/2.h5.partial", "leftover of an interrupted write"),
    ]
    assert "not a directory" in only_problem(dataset / "nowhere").message


def test_summary(dataset):
    summary = {s.task_name: s for s in summarize_dataset(dataset)}
    hopper = summary["hopper-v5"]
    assert (hopper.domain, hopper.histories, hopper.steps, hopper.episodes) == ("mujoco", 2, 60, 8)
    assert math.isclose(hopper.mean_episode_length, 7.5)
    assert (summary["reach-v5"].histories, summary["reach-v5"].steps, summary["reach-v5"].episodes) == (1, 30, 4)
    # Returns by episode index: each history's i-th episode, averaged over the histories.
    per_history = [LearningHistory(hopper_file(dataset).with_name(f"{seed}.h5")).episode_returns() for seed in (0, 1)]
    assert np.allclose(hopper.return_by_episode, np.mean(per_history, axis=0)) and len(hopper.return_by_episode) == 4


def test_vintix_data_stats_prints_the_return_of_each_episode_index(dataset):
    result = CliRunner().invoke(app, ["data", "stats", str(dataset)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    hopper = {s.task_name: s for s in summarize_dataset(dataset)}["hopper-v5"]
    row = next(line for line in result.output.splitlines() if line.lstrip("│ ").startswith("hopper-v5"))
    assert [cell.strip() for cell in row.split("│")[2:-1]] == [f"{v:.3g}" for v in hopper.return_by_episode]


# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

# Dataset tools
cli_error("data", "validate a missing folder", ["data", "validate", missing("data")], "not a directory")
cli_error("data", "validate an empty folder", lambda: ["data", "validate", empty_dir("empty")()], "dataset root")
for damage, (needle, _) in DAMAGE_NAMES.items():
    cli_error("data", f"validate: {damage}", lambda d=damage: ["data", "validate", DATA[d]()], needle)
cli_error("data", "validate: dims differ from the registry (IB, 7 obs dims)", lambda: ["data", "validate", ib7_data()],
          "registry expects (6, 3)")
cli_error("data", "stats of a missing folder", ["data", "stats", missing("data")], "not a directory")
cli_error("data", "stats: garbage task JSON", lambda: ["data", "stats", DATA["garbage-json"]()], "not valid JSON")
cli_error("data", "stats: truncated history", lambda: ["data", "stats", DATA["truncated"]()], "history-0000.h5")
cli_error("data", "plot: unknown reference table", lambda: ["data", "plot", clean_data(), "--reference", "bogus",
                                                            "--out", work() / "figs"], "bogus")
cli_error("data", "plot: zero bins", lambda: ["data", "plot", clean_data(), "--bins", "0", "--out", work() / "figs0"],
          "--bins")
cli_error("data", "plot: corrupted block", lambda: ["data", "plot", DATA["corrupted-block"](), "--reference", "paper",
                                                    "--out", work() / "figs1"], "failed its checksum")

cli_error("data", "fit-schedule: histories without a recorded schedule", lambda: ["data", "fit-schedule", clean_data()],
          "records no noise schedule")
cli_error("data", "fit-schedule: one knot", lambda: ["data", "fit-schedule", clean_data(), "--knots", "1"], "--knots")
cli_error("data", "smoothness --own-expert: histories without a recorded schedule",
          lambda: ["data", "smoothness", clean_data(), "--own-expert"], "records no noise schedule")
cli_error("data", "smoothness --own-expert: no complete noise-free episode",
          lambda: ["data", "smoothness", collected(), "--own-expert"], "no complete noise-free episode")


def corrupted_block_read() -> object:
    from vintix.data import LearningHistory

    return LearningHistory(DATA["corrupted-block"]() / "metaworld" / "reach-v3" / "history-0000.h5").read(0, 300)


api_error("data", "LearningHistory.read over a corrupted block", corrupted_block_read, "history-0000.h5")
def read_out_of_range() -> str | None:
    from vintix.data import LearningHistory

    path = clean_data() / "metaworld" / "reach-v3" / "history-0000.h5"
    try:
        LearningHistory(path).read(250, 400)
    except IndexError as error:  # a sequence's error, naming the file and its rows
        return None if str(path) in str(error) and "[0, 300)" in str(error) else str(error)
    return "no error"


documented("data", "LearningHistory.read past the end: IndexError naming file and rows", read_out_of_range)
api_error("data", "writer: append after close", lambda: _append_after_close(), "after close")
api_error("data", "LearningHistory of a missing file",
          lambda: __import__("vintix.data", fromlist=["x"]).LearningHistory(missing("h.h5")).num_steps, "no such file")


def _append_after_close() -> object:
    from vintix.data import LearningHistoryWriter

    writer = LearningHistoryWriter(work() / "writer" / "closed.h5", 3, 2)
    writer.append(np.zeros(3), np.zeros(2), 0.0, 0)
    writer.close()
    return writer.append(np.zeros(3), np.zeros(2), 0.0, 1)


def writer_call(**kwargs: object) -> Callable[[], object]:
    def call() -> object:
        from vintix.data import LearningHistoryWriter

        arguments = {"obs_dim": 3, "act_dim": 2, **kwargs}
        rows = arguments.pop("rows", None)
        with LearningHistoryWriter(work() / "writer" / "h.h5", **arguments) as writer:
            writer.append(*(rows or (np.zeros((4, 3)), np.zeros((4, 2)), np.zeros(4), np.arange(4))))
        return writer.path

    return call


api_error("data", "writer: NaN observation", writer_call(rows=(np.full((4, 3), np.nan), np.zeros((4, 2)), np.zeros(4),
                                                              np.arange(4))), "NaN/inf in observation")
api_error("data", "writer: step_num starting at 3", writer_call(rows=(np.zeros((4, 3)), np.zeros((4, 2)), np.zeros(4),
                                                                    np.arange(3, 7))), "step_num 3 after -1")
api_error("data", "writer: obs_dim 0", writer_call(obs_dim=0), "obs_dim")
api_error("data", "writer: chunk_size 0", writer_call(chunk_size=0), "chunk_size")
api_error("data", "writer: float step_num", writer_call(rows=(np.zeros((4, 3)), np.zeros((4, 2)), np.zeros(4),
                                                              np.arange(4.0))), "expected an integer")
cli_error("data", "a task JSON nested 10^5 deep", lambda: [
    "data", "validate", damaged_data("deep-json", lambda f: (f / "reach-v3.json").write_text(DEEP_JSON))()],
    "reach-v3.json")

# The rest of the old list (issue 47, class 8).
def minari_root() -> None:
    os.environ["MINARI_DATASETS_PATH"] = str(work() / "minari" / "datasets")  # never the user's own


cli_error("data", "export-minari with a dataset id that climbs out of Minari's root", lambda: [
    "data", "export-minari", clean_data(), "--dataset-id", "../../escaped/x-v0"], "expected [namespace/]name-vN",
    setup=minari_root,
    after=lambda: "a folder was made outside Minari's root" if (work() / "escaped").exists() else None)
# Issue 55, class 8: ids Minari itself refuses are refused before any folder is made.
for bad_id in ("vintix/reach.v3-v0", "vintix//reach-v0", "vintix/reach v3-v0", "_/reach-v0"):
    cli_error("data", f"export-minari with the id {bad_id!r}, which Minari refuses", lambda bad_id=bad_id: [
        "data", "export-minari", clean_data(), "--dataset-id", bad_id], "expected [namespace/]name-vN",
        setup=minari_root, after=lambda: "a folder was made under Minari's root" if any(
            (work() / "minari" / "datasets").glob("*/*")) else None)



def dataset_with_a_fifo_history() -> Path:
    """A clean dataset plus a FIFO named like a history, which the readers skipped."""
    root = work() / "data-fifo-history"
    if not root.exists():
        shutil.copytree(clean_data(), root)
        os.mkfifo(root / "metaworld" / "reach-v3" / "history-0009.h5")
    return root


cli_error("data", "validate a dataset holding a FIFO named like a history (it passed as clean)",
          lambda: ["data", "validate", dataset_with_a_fifo_history()], "not a regular file")
# ...and stats and training, which open the dataset for use, skipped it without a word (issue 71's red team)
cli_error("data", "stats of a dataset holding a FIFO named like a history",
          lambda: ["data", "stats", dataset_with_a_fifo_history()], "history-0009.h5: named like a history")


test_bad_input_ends_as_expected = bad_input_test("data")
