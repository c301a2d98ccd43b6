"""`vintix collect --plan`: size on disk, rates, and the wall time of batches spread over workers."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from vintix.cli import app
from vintix.collect import CollectionPlan, collect
from vintix.collect.bench import CollectBenchmark, read_rates, write_rates
from vintix.collect.estimate import TaskEstimate, collector_rate, estimate_plans, history_bytes, wall_seconds
from vintix.collect.recipe import load_recipe, shipped_recipes
from vintix.errors import VintixError
from vintix.tasks import get_task


@pytest.mark.parametrize("steps", [250, 1_000, 12_345])
def test_disk_size_is_what_the_collector_writes(tmp_path, steps):
    # Industrial Benchmark's episodes all run their 250 steps, so the episode ends are known in advance
    # (a MuJoCo task whose noised episodes end early writes a few bytes more per episode: `history_bytes`).
    task = "industrial-benchmark-40-v1"
    [summary] = collect(CollectionPlan(task, histories=1, steps=steps), tmp_path)
    written = summary.path.stat().st_size
    assert abs(history_bytes(get_task(task), steps) - written) <= 0.02 * written + 2_000


def test_batches_go_to_the_first_free_worker_in_submission_order():
    tasks = [TaskEstimate("a", 3, 100, 0, [1, 1, 1], 0, steps_per_s=10.0, measured=True),   # batches of 10 s
             TaskEstimate("b", 1, 300, 0, [1], 0, steps_per_s=10.0, measured=True)]          # one of 30 s
    assert wall_seconds(tasks, workers=1) == 60
    assert wall_seconds(tasks, workers=2) == 40  # worker 1: 10 + 10, then b; worker 2: 10
    assert wall_seconds(tasks, workers=8) == 30
    with pytest.raises(VintixError, match="workers must be >= 1, got 0"):
        wall_seconds(tasks, workers=0)
    piloted = TaskEstimate("c", 2, 100, 50, [2], 0, steps_per_s=10.0, measured=True)
    assert piloted.batch_seconds == [30.0] and piloted.steps == 200  # pilots take time, store nothing


def test_a_task_without_a_demonstrator_is_estimated_from_its_raw_rate():
    rates = {"InvertedPendulum-v5": CollectBenchmark("InvertedPendulum-v5", 5, 20_000, 10_000),
             "Hopper-v5": CollectBenchmark("Hopper-v5", 5, 10_000, 8_000),
             "Ant-v5": CollectBenchmark("Ant-v5", 5, 4_000, None)}
    assert collector_rate("Hopper-v5", rates) == (8_000, True)
    assert collector_rate("Ant-v5", rates) == (4_000 * 0.65, False)  # the median ratio of (0.5, 0.8)
    with pytest.raises(VintixError, match="no measured rate for 'Walker2d-v5'.*vintix bench collect Walker2d-v5"):
        collector_rate("Walker2d-v5", rates)


def test_the_shipped_rates_cover_every_task_of_the_paper_recipe():
    estimates = estimate_plans(load_recipe("paper"), read_rates())
    assert len(estimates) == 72 and sum(e.steps for e in estimates) == 191_500_000
    assert all(e.steps_per_s > 0 for e in estimates)


@pytest.mark.parametrize("recipe", shipped_recipes())
def test_every_shipped_recipe_can_be_planned(recipe):
    assert all(e.steps_per_s > 0 and e.bytes > 0 for e in estimate_plans(load_recipe(recipe), read_rates()))


def test_a_measurement_is_added_to_a_rates_table_and_replaces_only_its_own_tasks_rows(tmp_path):
    table = tmp_path / "rates.csv"
    write_rates([CollectBenchmark("reach-v3", 5, 1000.0, 900.0), CollectBenchmark("push-v3", 5, 800.0, 700.0)],
                table, "first")
    write_rates([CollectBenchmark("reach-v3", 5, 1100.0, 950.0)], table, "second")
    rates = read_rates(table)
    assert rates["reach-v3"].collect_steps_per_s == 950.0 and rates["push-v3"].collect_steps_per_s == 700.0
    table.write_text("task,speed\nreach-v3,fast\n")
    with pytest.raises(VintixError, match="not a readable rates table"):
        write_rates([CollectBenchmark("reach-v3", 5, 1100.0, 950.0)], table, "third")


@pytest.mark.parametrize("content", [None, "task,speed\nreach-v3,fast\n", "task,envs_per_batch,raw_steps_per_s,"
                                     "collect_steps_per_s\nreach-v3,5,many,\n"])
def test_a_missing_or_damaged_rates_table_is_named(tmp_path, content):
    path = tmp_path / "rates.csv"
    if content is not None:
        path.write_text(content)
    result = CliRunner().invoke(app, ["collect", "--recipe", "tiny", "--plan", "--rates", str(path)])
    assert result.exit_code == 2 and "not a readable rates table" in result.output and "--out" in result.output


def test_plan_prints_the_totals_and_collects_nothing(tmp_path):
    result = CliRunner().invoke(app, ["collect", "--recipe", "paper", "--plan", "--workers", "16"])
    assert result.exit_code == 0, result.output
    assert "72 tasks, 1,015 histories, 191,500,000 steps" in result.output
    assert "with --workers 16: about" in result.output
    result = CliRunner().invoke(app, ["collect", "--task", "reach-v3", "--histories", "2", "--steps", "1000",
                                      "--pilot-steps", "500", "--plan"])
    assert result.exit_code == 0 and "2,000 steps (+ 1,000 pilot steps, not stored)" in result.output
    result = CliRunner().invoke(app, ["collect", "--task", "reach-v3"])
    assert result.exit_code == 2 and "give --out" in result.output
