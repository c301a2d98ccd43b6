"""The `vintix` command line."""

import csv

from typer.testing import CliRunner

from vintix.cli import app

runner = CliRunner()


def test_tasks_lists_all_102():
    result = runner.invoke(app, ["tasks"])
    assert result.exit_code == 0
    assert "102 tasks" in result.output and "Hopper-v5" in result.output and "Hand-Pen" in result.output


def test_tasks_filters_by_domain_and_split():
    result = runner.invoke(app, ["tasks", "--domain", "industrial_benchmark", "--split", "test"])
    assert result.exit_code == 0
    assert "5 tasks" in result.output and "industrial-benchmark-80-v1" in result.output
    assert "industrial-benchmark-75-v1" not in result.output


def test_unknown_filter_exits_with_a_message():
    result = runner.invoke(app, ["tasks", "--domain", "mujuco"])
    assert result.exit_code == 2 and "unknown domain 'mujuco'" in result.output


def test_check_envs_writes_its_results(tmp_path):
    out = tmp_path / "check.csv"
    result = runner.invoke(app, ["check-envs", "InvertedPendulum-v5", "--episodes", "2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(open(out)))
    assert [r["task"] for r in rows] == ["InvertedPendulum-v5"] and float(rows[0]["steps_per_second"]) > 0


def test_check_envs_unknown_task_exits_with_a_message():
    result = runner.invoke(app, ["check-envs", "Hoper-v5"])
    assert result.exit_code == 2 and "Did you mean" in result.output
