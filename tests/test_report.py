"""The report: figures and tables from real eval results of two checkpoints, aggregates that match
the episodes, and clear errors."""

from __future__ import annotations

import csv
import re
import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from inference_model import one_thread, one_torch_thread, tiny_model  # noqa: F401  (autouse fixture)
from vintix.agent import Agent
from vintix.cli import app
from vintix.evaluate import EvalConfig, best_k_plateau, evaluate, iqm_with_ci
from vintix.report import load_results


@pytest.fixture(scope="module")
def two_results(tmp_path_factory):
    """Real cold-start results of an AD-like and an AD-without-reward model on two tasks."""
    root = tmp_path_factory.mktemp("results")
    config = EvalConfig(tasks=["reach-v3", "InvertedPendulum-v5"], shots=4, seeds=3)
    with one_thread():
        with_reward, without_reward = tiny_model(), tiny_model(seed=1, mask_reward=True)
        evaluate(Agent(with_reward), config, root / "ad", "runs/ad", "AD")
        evaluate(Agent(without_reward), config, root / "ad-no-reward", "runs/ad-no-reward", "AD without reward")
    return root


def test_report_has_every_figure_and_the_aggregates_of_the_episodes(two_results, tmp_path):
    result = CliRunner().invoke(app, ["report", str(two_results / "ad"), str(two_results / "ad-no-reward"),
                                      "--out", str(tmp_path / "report"), "--plateau-shots", "2"])
    assert result.exit_code == 0, result.output
    figures = tmp_path / "report" / "figures"
    expected = {"domain-metaworld_train.png", "domain-mujoco_train.png", "first-vs-converged.png",
                "tasks/reach-v3.png", "tasks/InvertedPendulum-v5.png"}
    assert {str(p.relative_to(figures)) for p in figures.rglob("*.png")} == expected
    assert all((figures / name).read_bytes()[:4] == b"\x89PNG" for name in expected)
    report = (tmp_path / "report" / "report.md").read_text()
    assert "| AD | `runs/ad`" in report and "| AD without reward | `runs/ad-no-reward`" in report
    assert all(f"]({'figures/' + name})" in report for name in expected)

    # the reach-v3 row of AD: first-shot IQM with CI, and best-2-shot plateau, from the episodes themselves
    rows = [r for r in csv.DictReader((two_results / "ad" / "episodes.csv").open()) if r["task"] == "reach-v3"]
    scores = np.array([[float(r["normalized_paper"]) for r in rows if r["seed"] == s] for s in "012"])
    first = iqm_with_ci(scores[:, 0])
    plateau, start = best_k_plateau(scores.mean(0), 2)
    line = next(line for line in report.splitlines() if line.startswith("| reach-v3 | AD |"))
    assert line == (f"| reach-v3 | AD | 3 | {first[0]:.2f} [{first[1]:.2f}, {first[2]:.2f}] | {plateau:.2f} | "
                    f"{start + 1} | 1.01 |")


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
        [episodes[0]] + [line.replace("reach-v3", "Hand-Block-Stack", 1) for line in episodes[1:] if "reach-v3" in line]))
    result = CliRunner().invoke(app, ["report", str(tmp_path / "bidex"), "--out", str(tmp_path / "r"), "--reference", "ours"])
    assert result.exit_code == 2 and "no task" in result.output and "'ours' reference" in result.output



@pytest.mark.parametrize(("damage", "message"), [
    (lambda f: (f / "episodes.csv").write_text("a,b\n1,2\n"), "not a `vintix eval` episodes table"),
    (lambda f: (f / "run.json").write_text("{"), "run.json: not valid JSON"),
    (lambda f: (f / "episodes.csv").write_text((f / "episodes.csv").read_text().splitlines()[0] + "\n"),
     "holds no episodes"),
    (lambda f: (f / "episodes.csv").write_text((f / "episodes.csv").read_text().replace("metaworld,train,metaworld,0",
                                                                                        "metaworld,train,metaworld,x", 1)),
     r"episodes.csv, line 2: invalid literal for int\(\) with base 10: 'x'"),
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
