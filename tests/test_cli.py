"""The `vintix` command line."""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import HANG_GUARD_S, child_env, fill_up
from vintix.cli import app
from vintix.tasks import list_tasks

runner = CliRunner()


def test_version_prints_the_installed_package_version():
    from importlib.metadata import version

    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.strip() == f"vintix {version('vintix')}"


def test_tasks_lists_the_papers_102_the_packages_hidden_goal_meta_rl_and_discrete_ones():
    result = runner.invoke(app, ["tasks"])
    assert result.exit_code == 0  # 102 + point-goal, Reacher-hidden, 3 meta-RL + 9 discrete
    assert len(result.output.splitlines()) == 1 + 116 and "Hopper-v5" in result.output and "Hand-Pen" in result.output
    assert "point-goal-v1" in result.output and "Reacher-hidden-v5" in result.output
    assert "DarkRoom-heldout-v0" in result.output and "5 discrete" in result.output


def test_tasks_filters_by_domain_and_split():
    result = runner.invoke(app, ["tasks", "--domain", "industrial_benchmark", "--split", "test"])
    assert result.exit_code == 0
    assert len(result.output.splitlines()) == 1 + 5 and "industrial-benchmark-80-v1" in result.output
    assert "industrial-benchmark-75-v1" not in result.output


def test_tasks_piped_is_one_whole_name_a_line_or_json_and_a_narrow_terminal_cuts_no_name():
    """`vintix tasks | grep industrial-benchmark-90` finds it; `COLUMNS=80 vintix tasks` shows every name whole."""
    lines = runner.invoke(app, ["tasks"]).output.splitlines()
    assert lines[0].split("\t")[:2] == ["task", "domain"]
    found = [line.split("\t")[0] for line in lines if "industrial-benchmark-90" in line]
    assert found == ["industrial-benchmark-90-v1"]
    listed = json.loads(runner.invoke(app, ["tasks", "--json", "--domain", "icrl"]).output)
    assert len(listed) == 9 and {"task": "DarkRoom-v0", "act": "5 discrete"} in [
        {"task": t["task"], "act": t["act"]} for t in listed]
    script = ("import sys, vintix.cli as c; c._ON_TERMINAL = True; c.console = c.Console(width=80, "
              "force_terminal=False); sys.argv = ['vintix', 'tasks']; c.app()")
    shown = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=child_env()).stdout

    assert all(task.name in shown for task in list_tasks())


def test_unknown_filter_exits_with_a_message():
    result = runner.invoke(app, ["tasks", "--domain", "mujuco"])
    assert result.exit_code == 2 and "unknown domain 'mujuco'" in result.output


def test_check_envs_writes_its_results(tmp_path):
    out = tmp_path / "check.csv"
    result = runner.invoke(app, ["check-envs", "InvertedPendulum-v5", "--episodes", "2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(open(out)))
    assert [r["task"] for r in rows] == ["InvertedPendulum-v5"] and float(rows[0]["steps_per_second"]) > 0


def test_check_envs_runs_a_task_without_published_scores(tmp_path):
    out = tmp_path / "check.csv"
    result = runner.invoke(app, ["check-envs", "point-goal-v1", "--episodes", "1", "--out", str(out)])
    assert result.exit_code == 0, result.output
    [row] = list(csv.DictReader(open(out)))
    assert row["task"] == "point-goal-v1" and row["paper_mean"] == row["paper_std"] == row["z"] == ""


def test_check_envs_unknown_task_exits_with_a_message():
    result = runner.invoke(app, ["check-envs", "Hoper-v5"])
    assert result.exit_code == 2 and "Did you mean" in result.output


def write_rollout_dataset(root, task="InvertedPendulum-v5", steps=120):
    """A real (random-policy) learning history in the official layout."""
    from vintix import get_task, make_env
    from vintix.data import LearningHistoryWriter, task_directory, write_task_metadata

    spec = get_task(task)
    task_dir = task_directory(root, spec.domain, spec.name)
    write_task_metadata(task_dir, spec.name, spec.obs_dim, spec.act_dim)
    env = make_env(task, seed=0)
    obs, _ = env.reset()
    step = 0
    with LearningHistoryWriter(task_dir / "history_0.h5", spec.obs_dim, spec.act_dim) as writer:
        for _ in range(steps):
            action = env.action_space.sample()
            next_obs, reward, terminated, truncated, _ = env.step(action)
            writer.append(obs, action, reward, step)
            obs, step = next_obs, step + 1
            if terminated or truncated:
                (obs, _), step = env.reset(), 0
    return task_dir / "history_0.h5"


def test_data_validate_and_stats_on_a_real_dataset(tmp_path):
    write_rollout_dataset(tmp_path)
    result = runner.invoke(app, ["data", "validate", str(tmp_path)])
    assert result.exit_code == 0 and "1 task folder(s)" in result.output, result.output
    result = runner.invoke(app, ["data", "stats", str(tmp_path)])
    assert result.exit_code == 0 and "InvertedPendulum-v5" in result.output and "120" in result.output


def test_data_validate_reports_a_truncated_file_by_name(tmp_path):
    path = write_rollout_dataset(tmp_path)
    path.write_bytes(path.read_bytes()[:1000])
    result = runner.invoke(app, ["data", "validate", str(tmp_path)])
    assert result.exit_code == 1
    assert "history_0.h5" in result.output and "truncated or corrupted" in result.output


def test_data_validate_on_an_empty_folder_says_what_to_point_at(tmp_path):
    result = runner.invoke(app, ["data", "validate", str(tmp_path)])
    assert result.exit_code == 2 and "dataset root" in result.output


def test_fit_schedule_prints_recipe_lines_that_collect_accepts(tmp_path):
    result = runner.invoke(app, ["collect", "--task", "InvertedPendulum-v5", "--histories", "2", "--steps", "4000",
                                 "--out", str(tmp_path / "linear")])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["data", "fit-schedule", str(tmp_path / "linear"), "--knots", "5"])
    assert result.exit_code == 0, result.output
    [line] = [line for line in result.output.splitlines() if "{knots: [1, " in line]
    (tmp_path / "fitted.yaml").write_text(f"defaults: {{histories: 1, steps: 2000}}\ntasks:\n{line}\n")
    result = runner.invoke(app, ["collect", "--recipe", str(tmp_path / "fitted.yaml"),
                                 "--out", str(tmp_path / "fitted")])
    assert result.exit_code == 0 and "wrote 1 histories" in result.output, result.output


def test_fit_schedule_on_histories_without_a_recorded_schedule_names_the_file(tmp_path):
    write_rollout_dataset(tmp_path)  # written directly, as published files are: no schedule attributes
    result = runner.invoke(app, ["data", "fit-schedule", str(tmp_path)])
    assert result.exit_code == 2 and "history_0.h5" in result.output and "records no noise schedule" in result.output


def test_collect_a_shipped_recipe_then_rerun_collects_nothing_and_train_the_same_preset_on_it(tmp_path):
    result = runner.invoke(app, ["collect", "--recipe", "tiny", "--out", str(tmp_path / "data")])
    assert result.exit_code == 0, result.output
    assert "wrote 4 histories" in result.output and "collected 4,096 steps" in result.output
    again = runner.invoke(app, ["collect", "--recipe", "tiny", "--out", str(tmp_path / "data")])
    assert again.exit_code == 0 and "collected 0 steps" in again.output
    # collect --recipe tiny composes with train --config tiny: its histories hold the tiny model's window
    trained = runner.invoke(app, ["train", "--config", "tiny", "--data", str(tmp_path / "data"), "--out",
                                  str(tmp_path / "run"), "--set", "max_steps=2", "--set", "batch_size=2"])
    assert trained.exit_code == 0, trained.output


def test_collect_for_a_task_without_demonstrator_says_so_and_writes_nothing(tmp_path, without_shipped_weights):
    result = runner.invoke(app, ["collect", "--task", "Hopper-v5", "--out", str(tmp_path / "data")])
    assert result.exit_code == 2 and "no trained demonstrator for 'Hopper-v5'" in result.output
    assert not (tmp_path / "data").exists()


def test_python_dash_m_vintix_runs_the_cli():
    env = child_env()
    result = subprocess.run([sys.executable, "-m", "vintix", "tasks", "--domain", "mujoco"],
                            capture_output=True, text=True, env=env, timeout=HANG_GUARD_S)
    assert result.returncode == 0, result.stderr
    # a header, then the paper's 11, Reacher-hidden and the 3 meta-RL tasks
    assert len(result.stdout.splitlines()) == 1 + 15 and "Pusher-v5" in result.stdout
    usage = subprocess.run([sys.executable, "-m", "vintix", "--help"], capture_output=True, text=True, env=env,
                           timeout=HANG_GUARD_S)
    assert usage.returncode == 0 and "Usage: vintix" in usage.stdout


def test_help_keeps_the_optional_extra_to_install_for_ray():
    for command in ("collect", "eval"):  # wide enough that the help's box never splits the name
        result = runner.invoke(app, [command, "--help"], env={"COLUMNS": "200"})
        assert result.exit_code == 0 and "'vintix[cluster]'" in result.output  # not eaten as rich markup


def test_collects_options_default_to_the_collection_plan_and_noise_schedule():
    # `vintix --help` must not import the collector (3.5 s, torch), so the options restate these
    # defaults; this keeps the two from drifting apart.
    import inspect
    import typing

    from vintix.cli import collect
    from vintix.collect import CollectionPlan, NoiseSchedule

    options = inspect.signature(collect).parameters
    plan = CollectionPlan("reach-v3", 1, 1)
    assert {name: options[name].default for name in ("curvature", "pilot_steps")} == {
        "curvature": NoiseSchedule().curvature, "pilot_steps": NoiseSchedule().pilot_steps}
    assert {name: options[name].default for name in ("seed", "envs_per_batch")} == {
        "seed": plan.seed, "envs_per_batch": plan.envs_per_batch}
    fraction_help = typing.get_args(typing.get_type_hints(collect, include_extras=True)["noise_free_fraction"])[1].help
    assert options["noise_free_fraction"].default is None and f"{NoiseSchedule().noise_free_fraction}" in fraction_help


def test_collect_into_a_folder_made_with_other_settings_says_so(tmp_path):
    command = ["collect", "--task", "reach-v3", "--histories", "1", "--steps", "100", "--out", str(tmp_path)]
    assert runner.invoke(app, command).exit_code == 0
    result = runner.invoke(app, [*command, "--seed", "3"])
    assert result.exit_code == 2 and "holds histories made with other settings" in " ".join(result.output.split())
    assert "collected 0 steps" not in result.output


def test_collect_with_zero_envs_per_batch_is_a_named_error(tmp_path):
    result = runner.invoke(app, ["collect", "--task", "reach-v3", "--envs-per-batch", "0", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "envs_per_batch=0" in result.output
    assert not any(tmp_path.iterdir())


def test_an_output_path_under_a_file_is_named_not_a_traceback(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    result = runner.invoke(app, ["check-envs", "InvertedPendulum-v5", "--episodes", "1",
                                 "--out", str(blocker / "x.csv")])
    assert result.exit_code == 2 and not isinstance(result.exception, Exception), result.output
    assert f"{blocker} is a file, not a directory" in " ".join(result.output.split())
    result = runner.invoke(app, ["collect", "--task", "reach-v3", "--steps", "10", "--out", str(blocker)])
    assert result.exit_code == 2 and "is a file, not a directory" in " ".join(result.output.split())


def test_commands_given_only_tasks_without_a_simulator_say_so():
    for command in (["check-envs", "Hand-Pen"], ["demonstrator", "eval", "--task", "Hand-Pen"]):
        result = runner.invoke(app, command)
        assert result.exit_code == 2 and "need NVIDIA IsaacGym" in " ".join(result.output.split()), result.output


def test_counts_and_presets_out_of_range_fail_before_any_work():
    for command, message in ((["check-envs", "InvertedPendulum-v5", "--episodes", "0"],
                              "Invalid value for '--episodes'"),
                             (["check-envs", "InvertedPendulum-v5", "--seed", "-1"], "Invalid value for '--seed'"),
                             (["bench", "train", "huge"], "unknown model preset 'huge'"),
                             (["bench", "infer", "tiny", "--envs", "0"], "Invalid value for '--envs'"),
                             (["demonstrator", "train", "--task", "InvertedPendulum-v5", "--timesteps", "0"],
                              "Invalid value for '--timesteps'")):
        result = runner.invoke(app, command)
        assert result.exit_code == 2 and message in result.output, (command, result.output)


HOLDINGS = {
    "dataset": lambda folder: (folder / "metaworld" / "reach-v3").mkdir(parents=True) or
    (folder / "metaworld" / "reach-v3" / "history-0000.h5").write_bytes(b""),
    "run": lambda folder: (folder / "checkpoints").mkdir(parents=True),
    "results": lambda folder: folder.mkdir() or (folder / "episodes.csv").write_text("task\n"),
}



@pytest.mark.parametrize(("holding", "command", "writes"), [
    ("results", ["collect", "--recipe", "tiny"], "a dataset (learning histories)"),
    ("dataset", ["train", "--config", "tiny", "--data", "."], "a training run"),
    ("run", ["eval", "--checkpoint", "point-goal", "--tasks", "point-goal-v1", "--shots", "1", "--seeds", "1"],
     "evaluation results"),
    ("dataset", ["report", "."], "a report"),
])
def test_an_output_folder_holding_another_kind_of_output_is_refused(tmp_path, holding, command, writes):
    folder = tmp_path / "out"
    HOLDINGS[holding](folder)
    before = sorted(folder.rglob("*"))
    result = runner.invoke(app, [*command, "--out", str(folder)])
    output = " ".join(result.output.split())
    assert result.exit_code == 2 and "already holds" in output and f"writing {writes} into it" in output, output
    assert sorted(folder.rglob("*")) == before  # nothing written


def test_a_full_disk_ends_in_one_line_that_says_what_to_do(small_disk):
    fill_up(small_disk)
    result = runner.invoke(app, ["check-envs", "point-goal-v1", "--episodes", "1", "--out", str(small_disk / "t.csv")])
    output = " ".join(result.output.split())  # rich wraps long lines
    assert result.exit_code == 2 and "Traceback" not in output
    assert "No space left on device" in output and "the disk is full: free space or write elsewhere" in output
    assert "t.csv" in output and "resume" not in output  # the file named; no advice that belongs to collect or train
    assert sorted(p.name for p in small_disk.iterdir()) == ["ballast"]  # no t.csv.partial


@pytest.mark.parametrize("command", [
    ["collect", "--task", "reach-v3", "--steps", "100", "--out", "{ro}/data"],
    ["eval", "--checkpoint", "point-goal", "--tasks", "point-goal-v1", "--shots", "1", "--seeds", "1", "--out",
     "{ro}/results"],
    ["demonstrator", "eval", "--task", "reach-v3", "--episodes", "1", "--out", "{ro}/scores.csv"],
    ["check-envs", "InvertedPendulum-v5", "--episodes", "1", "--out", "{ro}/check.csv"],
])
def test_an_output_on_a_read_only_file_system_is_refused_before_any_work(read_only_folder, command):
    """It was found only when the results were written, after the whole measurement."""
    result = runner.invoke(app, [part.format(ro=read_only_folder) for part in command])
    output = " ".join(result.output.split())
    assert result.exit_code == 2 and f"{read_only_folder} is not writable here (a read-only file system" in output
    assert "measured" not in output and "wrote" not in output, output


def test_eval_prints_a_tasks_means_and_a_domains_iqm_as_the_report_gives_them(tmp_path):
    from vintix.evaluate import iqm

    out = tmp_path / "results"
    result = CliRunner().invoke(app, ["eval", "--checkpoint", "point-goal", "--tasks", "point-goal-v1", "--shots", "3",
                                      "--seeds", "5", "--first-seed", "100", "--out", str(out)],
                                env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader((out / "episodes.csv").open()))
    text = " ".join(result.output.split())
    assert "mean over 5 run(s) per task" in text and "mean of all 3 shots" in text  # 10 shots: not a 10-shot plateau
    assert "IQM of the normalized score" in text
    first = np.array([float(r["normalized_ours"]) for r in rows if r["shot"] == "1"])
    assert round(float(np.mean(first)), 2) != round(float(iqm(first)), 2)  # the two statistics tell apart here
    cells = {line.split("│")[1].strip(): line.split("│")[2:] for line in result.output.splitlines() if "│" in line}
    assert cells["point-goal-v1"][1].strip() == f"{np.mean(first):.2f}"  # after the variation column
    assert cells["toy train"][0].strip() == f"{float(iqm(first)):.2f}"


@pytest.mark.parametrize("command", [["collect", "--task", "point-goal-v1", "--histories", "1", "--steps", "20"],
                                     ["demonstrator", "eval", "--task", "point-goal-v1", "--episodes", "1"]])
def test_collect_and_demonstrator_take_threads(tmp_path, command):
    import torch

    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        out = tmp_path / ("data" if command[0] == "collect" else "scores.csv")
        result = runner.invoke(app, [*command, "--threads", "1", "--out", str(out)])
        assert result.exit_code == 0, result.output
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)


OPTIONS_OF_FIELDS = [
    ("eval", "EvalConfig", ["tasks", "shots", "seeds", "first_seed", "ml1", "variation", "prompt_from",
                            "prompt_steps", "batch_envs", "reward_input", "greedy", "sample_noise"]),
    ("train", "TrainConfig", ["data", "out", "threads"]),
    ("collect", "CollectionPlan", ["histories", "steps", "seed", "envs_per_batch", "first_history"]),
    ("collect", "NoiseSchedule", ["curvature", "noise_free_fraction", "pilot_steps"]),
    ("demonstrator histories", "CollectionPlan", ["probe_margin", "aim", "lapse_probability", "reward_tolerance"]),
]
"""(command, the dataclass whose fields some of its options set, those options). demonstrator histories'
--behaviour is not CollectionPlan.behaviour: it takes only the behaviours that never see the goal."""


@pytest.mark.parametrize(("command", "config", "options"), OPTIONS_OF_FIELDS)
def test_an_options_help_is_its_config_fields_docstring(command, config, options):
    import typer

    from vintix.cli import CONFIG_MODULES
    from vintix.fields import field_docs

    docs = field_docs(CONFIG_MODULES[config], config)
    found = typer.main.get_command(app)
    for name in command.split():
        found = found.commands[name]  # type: ignore[attr-defined]
    helps = {param.name: getattr(param, "help", None) for param in found.params}
    assert {option: helps.get(option) for option in options} == {option: docs[option] for option in options}
    result = CliRunner().invoke(app, [*command.split(), "--help"], env={"COLUMNS": "2000"})
    assert docs[options[0]] in " ".join(result.output.split())  # shown as it is written
