"""The report: figures and tables from real eval results of two checkpoints, aggregates that match
the episodes, the reward-use gap of a checkpoint fed true and zero rewards, and clear errors."""

from __future__ import annotations

import csv
import hashlib
import json
import re
import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    DEEP_JSON,
    bad_input_test,
    cli_error,
    empty_dir,
    eval_results,
    invoke,
    missing,
    model_checkpoint,
    not_written,
    once,
    work,
    workspace,
)
from inference_model import one_thread, one_torch_thread, tiny_model  # noqa: F401  (autouse fixture)
from vintix.agent import Agent
from vintix.atomic import file_name
from vintix.cli import app
from vintix.demonstrators.goal_blind import read_goal_blind
from vintix.evaluate import EvalConfig, best_k_plateau, converged_gap_with_ci, evaluate, iqm_with_ci
from vintix.evaluate.summary import estimate_with_ci
from vintix.report import load_results


@pytest.fixture(scope="module")
def two_results(tmp_path_factory):
    """Real cold-start results of an AD-like and an AD-without-reward model on two tasks, and of the
    AD-like one fed zero rewards on one of them."""
    root = tmp_path_factory.mktemp("results")
    config = EvalConfig(tasks=["reach-v3", "InvertedPendulum-v5"], shots=4, seeds=3)
    with one_thread():
        with_reward, without_reward = tiny_model(), tiny_model(seed=1, mask_reward=True)
        evaluate(Agent(with_reward), config, root / "ad", "runs/ad", "AD")
        evaluate(Agent(without_reward), config, root / "ad-no-reward", "runs/ad-no-reward", "AD without reward")
        evaluate(Agent(with_reward), replace(config, tasks=["reach-v3"], reward_input="zero"), root / "ad-zero",
                 "runs/ad")
    return root


def test_report_has_every_figure_and_the_aggregates_of_the_episodes(two_results, tmp_path):
    result = CliRunner().invoke(app, ["report", str(two_results / "ad"), str(two_results / "ad-no-reward"),
                                      "--out", str(tmp_path / "report"), "--plateau-shots", "2",
                                      "--reference", "paper"])
    assert result.exit_code == 0, result.output
    figures = tmp_path / "report" / "figures"
    expected = {f"domain-{file_name('metaworld train')}.png", f"domain-{file_name('mujoco train')}.png",
                "first-vs-converged.png",
                "tasks/reach-v3.png", "tasks/InvertedPendulum-v5.png"}
    assert {str(p.relative_to(figures)) for p in figures.rglob("*.png")} == expected
    assert all((figures / name).read_bytes()[:4] == b"\x89PNG" for name in expected)
    report = (tmp_path / "report" / "report.md").read_text()
    assert "| AD | `runs/ad`" in report and "| AD without reward | `runs/ad-no-reward`" in report
    assert all(f"]({'figures/' + name})" in report for name in expected)
    assert "Reward-use gap" not in report  # two checkpoints, both fed true rewards: no reward ablation

    # the reach-v3 row of AD: first-shot mean over runs with CI (what `vintix eval` prints), best-2-shot
    # plateau, and the same of the success rate, from the episodes themselves
    rows = [r for r in csv.DictReader((two_results / "ad" / "episodes.csv").open()) if r["task"] == "reach-v3"]
    scores = np.array([[float(r["normalized_paper"]) for r in rows if r["seed"] == s] for s in "012"])
    success = np.array([[float(r["success"]) for r in rows if r["seed"] == s] for s in "012"])
    first = estimate_with_ci(scores[:, 0], np.mean)
    assert first[0] == pytest.approx(scores[:, 0].mean())
    plateau, start = best_k_plateau(scores.mean(0), 2)
    line = next(line for line in report.splitlines() if line.startswith("| reach-v3 | AD |"))
    assert line == (f"| reach-v3 | AD | 3 | {first[0]:.2f} [{first[1]:.2f}, {first[2]:.2f}] | {plateau:.2f} | "
                    f"{start + 1} | 1.01 | {success[:, 0].mean():.0%} | {best_k_plateau(success.mean(0), 2)[0]:.0%} | "
                    f"{read_goal_blind()['reach-v3'].goal_blind_success:.0%} |")  # the goal-blind expert's, beside them
    line = next(line for line in report.splitlines() if line.startswith("| InvertedPendulum-v5 | AD |"))
    assert line.endswith("| — | — | — |")  # no success flag in MuJoCo


def test_a_true_and_a_zero_reward_folder_of_one_checkpoint_add_the_reward_use_gap(two_results, tmp_path):
    result = CliRunner().invoke(app, ["report", str(two_results / "ad"), str(two_results / "ad-zero"),
                                      str(two_results / "ad-no-reward"), "--out", str(tmp_path / "report"),
                                      "--plateau-shots", "2"])
    assert result.exit_code == 0, result.output
    report = (tmp_path / "report" / "report.md").read_text()
    assert "## Reward-use gap" in report and "a gap near zero means the improvement over shots is not" in report
    assert "| ad (zero rewards) | `runs/ad` | 4 | 3 | — | cold start | zero | 1 |" in report
    true, _ = load_results(two_results / "ad", "paper")
    zero, _ = load_results(two_results / "ad-zero", "paper")
    assert (true.reward_input, zero.reward_input) == ("true", "zero") and true.seeds["reach-v3"] == [0, 1, 2]
    score = converged_gap_with_ci([(true.scores["reach-v3"], zero.scores["reach-v3"])], 2, paired=True,
                                  same_window=True)
    start = best_k_plateau(true.scores["reach-v3"].mean(0), 2)[1]  # the shots the gap averages, printed
    success = converged_gap_with_ci([(true.success["reach-v3"], zero.success["reach-v3"])], 2, paired=True,
                                    shots=(start + 1, start + 2))
    cells = (f"| AD | zero | 3, paired by seed | {start + 1}–{start + 2} | "
             f"{score[0]:+.2f} [{score[1]:+.2f}, {score[2]:+.2f}] | "
             f"{100 * success[0]:+.0f} pp [{100 * success[1]:+.0f}, {100 * success[2]:+.0f}] |")
    lines = report.split("## Reward-use gap")[1].split("## Between models")[0].splitlines()
    # One task, so its domain's gap is its own; InvertedPendulum was not run with zeros, the other
    # checkpoint is not compared.
    assert [line for line in lines if "| AD |" in line] == [f"| metaworld train {cells}", f"| reach-v3 {cells}"]

    alone = CliRunner().invoke(app, ["report", str(two_results / "ad-zero"), "--out", str(tmp_path / "alone")])
    assert alone.exit_code == 0 and "no folder of its checkpoint 'runs/ad'" in " ".join(alone.output.split())


def test_every_printed_window_is_the_window_computed_for_score_and_success_alike(two_results, tmp_path):
    """Success counted in every shot of the true run and only in shot 1 of the zero run: the success gap over the
    printed window (the score's best) is +100 pp; a best window of its own, shots 1-2, made it +50 pp under the score's
    label."""
    true, zero = tmp_path / "true", tmp_path / "zero"
    shutil.copytree(two_results / "ad", true)
    shutil.copytree(two_results / "ad-zero", zero)
    edit_rows(lambda rows: [{**r, "success": "1.0"} for r in rows])(true)
    edit_rows(lambda rows: [{**r, "success": "1.0" if r["shot"] == "1" else "0.0"} for r in rows])(zero)
    scores, _ = load_results(true, "paper")
    start = best_k_plateau(scores.scores["reach-v3"].mean(0), 2)[1] + 1
    if start == 1:  # the score's best window must leave shot 1 out for the two windows to differ
        edit_rows(lambda rows: [{**r, "return": "-1000"} if r["shot"] == "1" else r for r in rows])(true)
        start = best_k_plateau(load_results(true, "paper")[0].scores["reach-v3"].mean(0), 2)[1] + 1
    result = CliRunner().invoke(app, ["report", str(true), str(zero), "--out", str(tmp_path / "report"),
                                      "--plateau-shots", "2"])
    assert result.exit_code == 0, result.output
    line = next(line for line in result.output.splitlines() if line.startswith("reward-use gap"))
    assert f"+100 pp [+100, +100] success (shots {start}–{start + 1})" in line


def test_a_gap_over_runs_of_different_lengths_compares_the_shots_both_have(two_results, tmp_path):
    """A zero-reward run of 2 shots beside a true run of 4, no window given: the gap is over shots 1-2 and says so
    (the true run's best window, 3-4 say, was checked against the shorter run and stopped the report)."""
    true, zero = tmp_path / "true", tmp_path / "zero"
    shutil.copytree(two_results / "ad", true)
    shutil.copytree(two_results / "ad-zero", zero)
    edit_rows(lambda rows: [r for r in rows if int(r["shot"]) <= 2])(zero)
    result = CliRunner().invoke(app, ["report", str(true), str(zero), "--out", str(tmp_path / "report")])
    assert result.exit_code == 0, result.output
    said = [line for line in result.output.splitlines() if line.startswith("reward-use gap: ")]
    assert said and all(line.endswith("(shots 1–2)") for line in said), said


def test_gap_shots_fix_the_window_of_the_reward_use_gap(two_results, tmp_path):
    """`--gap-shots 2-4`: both runs' mean over shots 2-4, whatever window is best; a window the runs lack is refused."""
    folders = [str(two_results / "ad"), str(two_results / "ad-zero")]
    result = CliRunner().invoke(app, ["report", *folders, "--out", str(tmp_path / "report"), "--gap-shots", "2-4"])
    assert result.exit_code == 0, result.output
    report = (tmp_path / "report" / "report.md").read_text()
    true, _ = load_results(two_results / "ad", "ours")
    zero, _ = load_results(two_results / "ad-zero", "ours")
    gap = true.scores["reach-v3"][:, 1:4].mean() - zero.scores["reach-v3"][:, 1:4].mean()
    line = next(line for line in report.splitlines() if line.startswith("| reach-v3 | AD | zero |"))
    assert f"| 2–4 | {gap:+.2f} [" in line and "fixed window `--gap-shots 2-4`" in report
    said = [line for line in result.output.splitlines() if line.startswith("reward-use gap: ")]
    assert len(said) == 1 and f"true − zero rewards = {gap:+.2f} [" in said[0] and said[0].endswith("(shots 2–4)")
    for bad, says in (("3-9", "must lie within the shots the runs have, 1-4"), ("4-2", "first <= last"),
                      ("2..4", "give FIRST-LAST")):
        refused = CliRunner().invoke(app, ["report", *folders, "--out", str(tmp_path / bad), "--gap-shots", bad])
        assert refused.exit_code == 2 and says in " ".join(refused.output.split()), refused.output
        assert not (tmp_path / bad / "report.md").exists()


def test_two_checkpoints_fed_true_rewards_add_the_first_models_gap_over_the_other(two_results, tmp_path):
    """The paper's ablations (AD − AD without rewards): converged score and success of the first model
    given minus the other's, per domain and task, paired by seed; a zero-reward folder is no model."""
    result = CliRunner().invoke(app, ["report", str(two_results / "ad"), str(two_results / "ad-zero"),
                                      str(two_results / "ad-no-reward"), "--out", str(tmp_path / "report"),
                                      "--plateau-shots", "2"])
    assert result.exit_code == 0, result.output
    report = (tmp_path / "report" / "report.md").read_text()
    assert "## Between models" in report
    ad, _ = load_results(two_results / "ad", "ours")  # the report's default table
    nr, _ = load_results(two_results / "ad-no-reward", "ours")
    lines = report.split("## Between models")[1].splitlines()
    for task in ("reach-v3", "InvertedPendulum-v5"):
        score = converged_gap_with_ci([(ad.scores[task], nr.scores[task])], 2, paired=True)
        success = (converged_gap_with_ci([(ad.success[task], nr.success[task])], 2, paired=True)
                   if task in ad.success else None)
        success_cell = "—" if success is None else \
            f"{signed(100 * success[0], 0)} pp [{signed(100 * success[1], 0)}, {signed(100 * success[2], 0)}]"
        assert (f"| {task} | AD | AD without reward | 3, paired by seed | best 2 of each | "
                f"{signed(score[0], 2)} [{signed(score[1], 2)}, {signed(score[2], 2)}] | {success_cell} |") in lines
    # one row per domain and per task: AD against AD without reward only, never against its own zero run
    assert len([line for line in lines if line.startswith("| ") and "| AD |" in line]) == 4
    assert "| AD (zero rewards)" not in report.split("## Between models")[1]


def signed(value: float, digits: int) -> str:
    """A report's signed number: a value that rounds to zero is +0, not -0."""
    return f"{round(value, digits) + 0.0:+.{digits}f}"


def test_the_converged_gap_pairs_runs_by_seed_and_resamples_within_tasks():
    rng = np.random.default_rng(0)
    goals = rng.normal(0, 1, size=(6, 1))  # each seed's own difficulty, the same in both conditions
    true = goals + np.linspace(0, 1, 8) + rng.normal(0, 0.05, (6, 8))  # improves over shots
    zero = goals + rng.normal(0, 0.05, (6, 8))  # does not
    expected = best_k_plateau(true.mean(0), 3)[0] - best_k_plateau(zero.mean(0), 3)[0]
    point, low, high = converged_gap_with_ci([(true, zero)], 3, paired=True)
    assert point == pytest.approx(expected) and low < point < high
    _, low_unpaired, high_unpaired = converged_gap_with_ci([(true, zero)], 3, paired=False)
    assert high - low < (high_unpaired - low_unpaired) / 5  # pairing keeps the seeds' spread out
    # A domain's gap is the mean of its tasks' gaps; curves are cut to the shots both have.
    assert converged_gap_with_ci([(true, zero), (zero, zero)], 3, paired=True)[0] == pytest.approx(expected / 2)
    cut = best_k_plateau(true[:, :5].mean(0), 3)[0] - best_k_plateau(zero[:, :5].mean(0), 3)[0]
    assert converged_gap_with_ci([(true[:, :5], zero)], 3, paired=True)[0] == pytest.approx(cut)
    one = converged_gap_with_ci([(true[:1], zero[:1])], 3, paired=True)  # nothing to resample
    assert one[0] == one[1] == one[2]


def test_a_reward_ablation_is_scored_over_the_true_runs_best_shots():
    """A probing first episode that does better than the later shots with zeros fed back must not count for the
    zero run when the true run's converged leaves it out."""
    true = np.array([[0.1, 0.9, 1.0, 1.0], [0.1, 0.9, 0.9, 1.0]])  # the probe, then found
    zero = np.array([[0.6, 0.1, 0.1, 0.2], [0.6, 0.2, 0.1, 0.1]])  # the probe is its best shot
    own = converged_gap_with_ci([(true, zero)], 2, paired=True)[0]
    same = converged_gap_with_ci([(true, zero)], 2, paired=True, same_window=True)
    assert own == pytest.approx(0.975 - 0.375)  # the zero run's own best window, shots 1-2
    assert same[0] == pytest.approx(0.975 - 0.125) and same[1] <= same[0] <= same[2]  # shots 3-4 for both


def test_results_from_before_the_reward_ablation_read_as_true_rewards(two_results, tmp_path):
    folder = tmp_path / "old"
    shutil.copytree(two_results / "ad", folder)
    rows = list(csv.DictReader((folder / "episodes.csv").open()))
    columns = [c for c in rows[0] if c != "reward_input"]
    with (folder / "episodes.csv").open("w") as f:
        writer = csv.DictWriter(f, columns, extrasaction="ignore", lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    run = json.loads((folder / "run.json").read_text())
    del run["config"]["reward_input"], run["episodes_sha256"]  # neither was written then
    (folder / "run.json").write_text(json.dumps(run))
    results, _ = load_results(folder, "paper")
    assert results.reward_input == "true" and set(results.success) == {"reach-v3"}
    result = CliRunner().invoke(app, ["report", str(folder), "--out", str(tmp_path / "report")])
    assert result.exit_code == 0, result.output


def test_our_table_normalizes_what_it_has_and_names_what_it_lacks(two_results, tmp_path):
    results, notes = load_results(two_results / "ad", "ours")
    for task in ("reach-v3", "InvertedPendulum-v5"):  # whatever the package's score table holds today
        named = any(task in note and "no 'ours' reference score" in note for note in notes)
        assert (task in results.scores) != named


def test_a_folder_without_results_or_without_references_is_a_clear_error(two_results, tmp_path):
    result = CliRunner().invoke(app, ["report", str(tmp_path), "--out", str(tmp_path / "r")])
    assert result.exit_code == 2 and "written by `vintix eval`" in result.output
    episodes = (two_results / "ad" / "episodes.csv").read_text().splitlines()
    (tmp_path / "bidex").mkdir()
    (tmp_path / "bidex" / "run.json").write_text("{}")
    (tmp_path / "bidex" / "episodes.csv").write_text("\n".join(
        [episodes[0]]
        + [line.replace("reach-v3", "Hand-Block-Stack", 1) for line in episodes[1:] if "reach-v3" in line]))
    result = CliRunner().invoke(app, ["report", str(tmp_path / "bidex"), "--out", str(tmp_path / "r"),
                                      "--reference", "ours"])
    assert result.exit_code == 2 and "no task" in result.output and "'ours' reference" in result.output



def edit_rows(edit):
    """A damage that rewrites the rows of a results folder's episodes.csv with `edit(rows) -> rows`."""
    def damage(folder):
        with (folder / "episodes.csv").open() as f:
            reader = csv.DictReader(f)
            fields, rows = reader.fieldnames, list(reader)
        with (folder / "episodes.csv").open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields)
            writer.writeheader()
            writer.writerows(edit(rows))
        rehash(folder)
    return damage


def rehash(folder):
    """run.json's record of the episodes it describes, after a test wrote other rows in their place."""
    run = json.loads((folder / "run.json").read_text())
    run["episodes_sha256"] = hashlib.sha256((folder / "episodes.csv").read_bytes()).hexdigest()
    (folder / "run.json").write_text(json.dumps(run))


def set_first(column, value):
    return edit_rows(lambda rows: [{**rows[0], column: value}, *rows[1:]])


@pytest.mark.parametrize(("damage", "message"), [
    (lambda f: (f / "episodes.csv").write_text("a,b\n1,2\n"), "not a `vintix eval` episodes table"),
    (lambda f: (f / "run.json").write_text("{"), "run.json: not valid JSON"),
    (lambda f: (f / "episodes.csv").write_text((f / "episodes.csv").read_text().splitlines()[0] + "\n"),
     "holds no episodes"),
    (lambda f: (f / "episodes.csv").write_text(
        (f / "episodes.csv").read_text().replace("metaworld,train,metaworld,0", "metaworld,train,metaworld,x", 1)),
     r"episodes.csv, line 2: invalid literal for int\(\) with base 10: 'x'"),
    (set_first("return", "inf"), "line 2: return 'inf' is not a finite number"),
    (set_first("return", "nan"), "line 2: return 'nan' is not a finite number"),
    (set_first("shot", "-1"), "line 2: shot -1: shots count from 1"),
    (set_first("success", "0.5"), "line 2: success '0.5' is neither 0, 1 nor empty"),
    (edit_rows(lambda rows: rows + rows[-1:]), "a second row for .* shot"),
    (edit_rows(lambda rows: [r for r in rows if not (r["shot"] == "2" and r is rows[1])]),
     "not 1, 2, ... without gaps"),
])
def test_damaged_results_are_named_errors_not_tracebacks(two_results, tmp_path, damage, message):
    folder = tmp_path / "results"
    shutil.copytree(two_results / "ad", folder)
    damage(folder)
    result = CliRunner().invoke(app, ["report", str(folder), "--out", str(tmp_path / "r")])
    assert result.exit_code == 2 and not isinstance(result.exception, Exception), result.output
    assert re.search(message, " ".join(result.output.split())), result.output


def test_report_options_out_of_range_are_refused(two_results, tmp_path):
    for option, message in ((["--plateau-shots", "0"], "Invalid value for '--plateau-shots'"),
                            (["--reference", "bogus"], "unknown reference table 'bogus'")):
        result = CliRunner().invoke(app, ["report", str(two_results / "ad"), "--out", str(tmp_path / "r"), *option])
        assert result.exit_code == 2 and message in result.output, result.output
    assert not (tmp_path / "r").exists()


def test_model_card_option_puts_the_released_models_scores_beside_each_task_and_domain(two_results, tmp_path):
    result = CliRunner().invoke(app, ["report", str(two_results / "ad"), "--out", str(tmp_path / "report"),
                                      "--plateau-shots", "2", "--model-card"])
    assert result.exit_code == 0, result.output
    report = (tmp_path / "report" / "report.md").read_text()
    assert "model card (IQM) |" in report and "| model card |" in report
    assert "paper's Vintix" not in report  # paper-normalized scores beside ours-normalized ones: never
    reach = next(line for line in report.splitlines() if line.startswith("| reach-v3 | AD |"))
    pendulum = next(line for line in report.splitlines() if line.startswith("| InvertedPendulum-v5 | AD |"))
    assert reach.split(" | ")[6] == "1.01"  # the card's reach-v2
    assert pendulum.split(" | ")[6] == "1.00"  # the card's invertedpendulum_v4
    assert next(line for line in report.splitlines() if line.startswith("| mujoco")).endswith("| 0.99 |")


def test_domain_intervals_resample_runs_within_each_task():
    from vintix.evaluate.summary import stratified_iqm_with_ci

    rng = np.random.default_rng(0)
    low_task, high_task = rng.normal(0.0, 0.05, 10), rng.normal(1.0, 0.05, 10)
    point, low, high = stratified_iqm_with_ci([low_task, high_task])
    pooled = iqm_with_ci(np.concatenate([low_task, high_task]))
    assert point == pytest.approx(pooled[0])
    # Pooled resampling also draws how many runs of each task a resample gets; stratified does not.
    assert high - low < 0.5 * (pooled[2] - pooled[1])
    assert stratified_iqm_with_ci([np.array([0.3]), np.array([0.5])]) == (0.4, 0.4, 0.4)


def test_a_task_measured_by_return_shows_how_much_of_it_the_hidden_goal_decides(tmp_path):
    """Ant-Dir flags no success: its row carries the hidden return of the goal-blind table instead, the most a
    reward-use gap can show there, and the columns line up with the header."""
    with one_thread():
        evaluate(Agent(tiny_model(("Ant-Dir-v5",))), EvalConfig(tasks=["Ant-Dir-v5"], shots=1, seeds=2),
                 tmp_path / "ant", "runs/ant", "tiny")
    result = CliRunner().invoke(app, ["report", str(tmp_path / "ant"), "--out", str(tmp_path / "report"),
                                      "--reference", "ours"])
    assert result.exit_code == 0, result.output
    lines = (tmp_path / "report" / "report.md").read_text().splitlines()
    header = next(line for line in lines if line.startswith("| task (ours-normalized)"))
    row = next(line for line in lines if line.startswith("| Ant-Dir-v5 | tiny |"))
    assert header.endswith("| hidden return |") and row.count("|") == header.count("|")
    assert row.endswith(f"| {read_goal_blind()['Ant-Dir-v5'].hidden_return:.2f} |")
    assert "the most a reward-use gap can show" in "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

# Reports
cli_error("report", "a missing folder", ["report", missing("results")], "no episodes.csv")
cli_error("report", "an empty folder", lambda: ["report", empty_dir("empty4")(), "--out", work() / "r0"],
          "no episodes.csv")
cli_error("report", "unknown reference table", lambda: ["report", eval_results(), "--reference", "bogus", "--out",
                                                        work() / "r1"], "bogus")
cli_error("report", "--plateau-shots 0", lambda: ["report", eval_results(), "--plateau-shots", "0", "--out",
                                                 work() / "r2"],
          "--plateau-shots")


def garbage_results(kind: str) -> Callable[[], list[object]]:
    def make() -> list[object]:
        folder = work() / f"results-{kind}"
        shutil.copytree(eval_results(), folder, dirs_exist_ok=True)
        if kind == "garbage-csv":
            (folder / "episodes.csv").write_text("a,b\n1,2\n")
        elif kind == "garbage-run-json":
            (folder / "run.json").write_text("{")
        elif kind == "text-return":
            text = (folder / "episodes.csv").read_text().splitlines()
            header = text[0].split(",")
            row = text[1].split(",")
            row[header.index("return")] = "lots"
            (folder / "episodes.csv").write_text("\n".join([text[0], ",".join(row), *text[2:]]) + "\n")
        elif kind == "no-rows":
            (folder / "episodes.csv").write_text((folder / "episodes.csv").read_text().splitlines()[0] + "\n")
        return ["report", folder, "--out", work() / f"r-{kind}"]

    return make


cli_error("report", "episodes.csv of another tool", garbage_results("garbage-csv"), "episodes.csv")
cli_error("report", "run.json not JSON", garbage_results("garbage-run-json"), "run.json")


def deep_run_json() -> list[object]:
    folder = work() / "results-deep-json"
    shutil.copytree(eval_results(), folder, dirs_exist_ok=True)
    (folder / "run.json").write_text(DEEP_JSON)
    return ["report", folder, "--out", work() / "r-deep-json"]


cli_error("report", "run.json nested 10^5 deep", deep_run_json, "run.json")
cli_error("report", "a return that is text", garbage_results("text-return"), "episodes.csv")
cli_error("report", "episodes.csv without rows", garbage_results("no-rows"), "no episodes")
# Issue 71's red team: one folder given twice counted its runs twice, rc 0.
cli_error("report", "one results folder given twice", lambda: [
    "report", eval_results(), f"{eval_results()}/.", "--out", work() / "r-twice"], "given more than once",
    after=not_written(lambda: work() / "r-twice" / "report.md"))


@once
def results_relabelled() -> Path:
    """Results of zero rewards fed back whose run.json was edited to say true ones."""
    folder = work() / "results-relabelled"
    code, output = invoke("eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "2", "--seeds",
                          "1", "--reward-input", "zero", "--out", folder)
    assert code == 0, output
    run = json.loads((folder / "run.json").read_text())
    run["config"]["reward_input"] = "true"
    (folder / "run.json").write_text(json.dumps(run))
    return folder


cli_error("report", "run.json that contradicts its episodes' reward_input column", lambda: [
    "report", results_relabelled(), "--out", work() / "report-relabelled"], "mixes runs fed different rewards")


test_bad_input_ends_as_expected = bad_input_test("report")


def test_options_mean_one_thing_a_label_from_a_file_is_literal_markdown_in_the_report(two_results, tmp_path):
    folder = tmp_path / "ad"
    shutil.copytree(two_results / "ad", folder)
    run = json.loads((folder / "run.json").read_text())
    run["label"] = "<img src=x onerror=alert(1)>\n# Fake heading | extra cell [link](http://x) \x1b[31m"
    (folder / "run.json").write_text(json.dumps(run))
    result = CliRunner().invoke(app, ["report", str(folder), "--out", str(tmp_path / "report")])
    assert result.exit_code == 0, result.output
    report = (tmp_path / "report" / "report.md").read_text()
    assert not re.search(r"(?<!\\)<img|(?<!\\)\]\(http|\x1b", report)  # no tag, link or escape code
    assert not [line for line in report.splitlines() if line.startswith("# Fake")]
    row = next(line for line in report.splitlines() if "Fake heading" in line)
    header = next(line for line in report.splitlines() if line.startswith("| label |"))
    assert row.count(" | ") == header.count(" | ") and "\\| extra cell" in row  # the | stays inside its cell
    # ...and on the console: its note named the label with a line break of its own (issue 71's red team)
    assert "\x1b" not in result.output and not [line for line in result.output.splitlines() if "# Fake" in line[:8]]


def test_a_results_folder_belongs_to_one_run_episodes_of_one_and_run_json_of_another_are_refused(two_results,
                                                                                                  tmp_path):
    mixed = tmp_path / "mixed"
    shutil.copytree(two_results / "ad", mixed)
    shutil.copy(two_results / "ad-no-reward" / "run.json", mixed / "run.json")  # another model's settings
    result = CliRunner().invoke(app, ["report", str(mixed), "--out", str(tmp_path / "report")])
    assert result.exit_code != 0 and "episodes.csv is not the one run.json describes" in " ".join(result.output.split())


def test_a_report_replaces_the_last_ones_figures_whole_and_a_stopped_ones_leftovers_go(two_results, tmp_path):
    out = tmp_path / "report"
    first = CliRunner().invoke(app, ["report", str(two_results / "ad"), "--out", str(out)])  # two tasks
    assert first.exit_code == 0, first.output
    (out / "figures.stopped.partial").mkdir()  # what a report stopped by a signal leaves
    second = CliRunner().invoke(app, ["report", str(two_results / "ad-zero"), "--out", str(out)])  # reach-v3 only
    assert second.exit_code == 0, second.output
    names = sorted(p.name for p in (out / "figures").rglob("*.png"))
    assert "InvertedPendulum-v5.png" not in names and not list(out.glob("*.partial"))  # the first's are gone
    assert f"and {len(names)} figures under" in " ".join(second.output.split())
