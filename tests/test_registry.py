"""The task registry: all 102 tasks of the paper (and the package's own hidden-goal tasks), their dims, groups,
splits and names."""

import os
from pathlib import Path

import pytest

from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    api_error,
    bad_input_test,
    cli_error,
    documented,
    file_at,
    work,
    workspace,
)
from vintix.errors import UnknownTaskError
from vintix.tasks import get_task, list_tasks, make_env, resolve_tasks


def test_registry_has_every_task_of_the_paper():
    paper = [t for t in list_tasks() if t.paper_expert is not None]
    counts = {d: len([t for t in paper if t.domain == d]) for d in ("mujoco", "metaworld", "industrial_benchmark",
                                                                      "bidexhands")}
    assert counts == {"mujoco": 11, "metaworld": 50, "industrial_benchmark": 21, "bidexhands": 20}
    # and the package's own hidden-goal tasks, which have no published scores
    icrl = {t.name for t in list_tasks(domain="icrl")}  # the discrete benchmarks: tests/test_envs_icrl.py
    assert {t.name for t in list_tasks()} - {t.name for t in paper} - icrl == {
        "point-goal-v1", "Reacher-hidden-v5", "HalfCheetah-Vel-v5", "HalfCheetah-Dir-v5", "Ant-Dir-v5"}
    toy = get_task("point-goal-v1")
    assert toy.domain == "toy" and toy.paper_expert is None and toy.paper_vintix_normalized is None
    hidden = get_task("Reacher-hidden-v5")
    assert hidden.domain == "mujoco" and hidden.group != get_task("Reacher-v5").group and hidden.paper_expert is None


def test_splits_follow_the_paper():
    metaworld_test = {t.name for t in list_tasks(domain="metaworld", split="test")}
    assert metaworld_test == {"bin-picking-v3", "box-close-v3", "door-lock-v3", "door-unlock-v3", "hand-insert-v3"}
    ib_test = [int(t.name.split("-")[2]) for t in list_tasks(domain="industrial_benchmark", split="test")]
    assert ib_test == [80, 85, 90, 95, 100]
    assert len(list_tasks(domain="bidexhands", split="train")) == 15
    assert not list_tasks(domain="mujoco", split="test")  # MuJoCo's held-out set is physics variations


def test_dims_are_gymnasium_v5_dims():
    assert (get_task("Ant-v5").obs_dim, get_task("Ant-v5").act_dim) == (105, 8)
    assert get_task("Humanoid-v5").obs_dim == 348
    assert get_task("InvertedDoublePendulum-v5").obs_dim == 9
    assert get_task("Reacher-v5").obs_dim == 10
    assert (get_task("pick-place-v3").obs_dim, get_task("pick-place-v3").act_dim) == (39, 4)
    assert (get_task("industrial-benchmark-0-v1").obs_dim, get_task("industrial-benchmark-0-v1").act_dim) == (6, 3)


def test_groups_share_dims_and_mujoco_has_one_group_per_env():
    by_group = {}
    for task in list_tasks():
        by_group.setdefault(task.group, set()).add((task.obs_dim, task.act_dim))
    assert all(len(dims) == 1 for dims in by_group.values())
    assert len({t.group for t in list_tasks(domain="mujoco")}) == 12  # the paper's 11 and Reacher-hidden-v5
    assert {t.group for t in list_tasks(domain="metaworld")} == {"metaworld"}


@pytest.mark.parametrize(
    "alias, name",
    [("Hopper-v4", "Hopper-v5"), ("pick-place-v2", "pick-place-v3"), ("assembly", "assembly-v3"),
     ("IB-p-35", "industrial-benchmark-35-v1"), ("shadowhandpen", "Hand-Pen")],
)
def test_paper_names_are_aliases(alias, name):
    assert get_task(alias).name == name


def test_reference_scores_carry_provenance():
    hopper = get_task("Hopper-v5")
    assert (hopper.paper_random.mean, hopper.paper_expert.mean) == (16.2, 3237.8)
    assert hopper.paper_expert.provenance.startswith("paper")


def test_unknown_task_lists_close_matches():
    with pytest.raises(UnknownTaskError, match="Did you mean: .*pick-place-v3"):
        get_task("pick-plcae-v3")


def test_pusher_v4_of_the_published_dataset_is_the_v5_task():
    # The published dataset names its folder Pusher-v4: training on it and filters must find it.
    assert get_task("Pusher-v4").name == "Pusher-v5"
    assert [t.name for t in resolve_tasks(["Pusher-v4"])] == ["Pusher-v5"]
    env = make_env("Pusher-v4", seed=0)
    assert env.observation_space.shape == (23,) and env.spec.id == "Pusher-v5"
    env.close()


def test_unknown_filter_value_is_an_error_not_an_empty_list():
    with pytest.raises(UnknownTaskError, match="unknown domain 'mujuco'"):
        list_tasks(domain="mujuco")


def test_resolve_tasks_expands_domains_and_splits_without_repeats():
    names = [t.name for t in resolve_tasks(["industrial_benchmark", "test", "Hopper-v4", "Hopper-v5"])]
    assert len(names) == len(set(names))
    assert "industrial-benchmark-0-v1" in names and "door-lock-v3" in names and "Hopper-v5" in names


# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

cli_error("tasks", "unknown domain", ["tasks", "--domain", "mujuco"], "unknown domain 'mujuco'")
cli_error("tasks", "unknown split", ["tasks", "--split", "validation"], "unknown split")
cli_error("tasks", "unknown group", ["tasks", "--group", "nope"], "unknown group")
cli_error("check-envs", "misspelled task", ["check-envs", "Hoper-v5"], "Did you mean")
cli_error("check-envs", "zero episodes", ["check-envs", "InvertedPendulum-v5", "--episodes", "0"], "--episodes")
cli_error("check-envs", "negative seed", ["check-envs", "InvertedPendulum-v5", "--seed", "-1"], "--seed")
cli_error("check-envs", "only Bi-DexHands tasks (no simulator)", ["check-envs", "Hand-Pen"], "IsaacGym")
cli_error("check-envs", "--out under a file", lambda: ["check-envs", "InvertedPendulum-v5", "--episodes", "1",
                                                                         "--out", file_at("a-file", "x")() / "x.csv"],
          "not a directory")

# Envs and the task registry from Python
api_error("tasks", "make_env of a Bi-DexHands task", lambda: __import__("vintix").make_env("Hand-Pen"), "IsaacGym")
api_error("tasks", "make_env with a variation the domain lacks", lambda: __import__("vintix").make_env(
    "reach-v3", viscosity=0.05), "viscosity")
api_error("tasks", "make_env with a negative viscosity", lambda: __import__("vintix").make_env(
    "HalfCheetah-v5", viscosity=-1.0), "viscosity must be >= 0")
api_error("tasks", "make_env with a NaN gravity scale", lambda: __import__("vintix").make_env(
    "HalfCheetah-v5", gravity_scale=float("nan")), "gravity_scale")
documented("tasks", "get_task('Pusher-v4') is Pusher-v5",
           lambda: None if __import__("vintix").get_task("Pusher-v4").name == "Pusher-v5" else "not the v5 task")



def a_fifo(name: str) -> Path:
    path = work() / name
    if not path.exists():
        os.mkfifo(path)
    return path


# No blocking open of what is not a regular file (issue 71, class 6): a tasks file that is a FIFO hung every command.
cli_error("tasks", "--tasks-file naming a FIFO", lambda: ["--tasks-file", a_fifo("tasks-fifo.yaml"), "tasks"],
          "not a regular file")


test_bad_input_ends_as_expected = bad_input_test("tasks", "check-envs")
