"""`vintix report`: a markdown report with PNG figures, regenerated from `vintix eval` result folders.

Scores are renormalized from the raw episode returns with the chosen reference table, so a report
made after our demonstrators are scored uses them even for older results. Aggregation:
a task's curve is the mean over its runs (seeds) at each shot, as `vintix eval` prints it, a domain's the
IQM over all runs of its tasks, each with a percentile-bootstrap 95 % CI over runs; a task's converged score is its best
k-shot plateau (the best mean over k consecutive shots of its mean curve), the paper's "performance
after reaching inference-time convergence". Several result folders (e.g. AD, ED, AD without
reward) share every figure and table, one line or bar each. Tasks with a success flag (Meta-World)
also get their success rate (a plain mean over runs, shot 1 and converged).

Folders of one checkpoint evaluated with true rewards and with zero or shuffled rewards fed back
(`vintix eval --reward-input`) add a reward-use gap section: how much of the converged score the
rewards earn. Folders of other checkpoints fed true rewards on the same prompt add a between-models
section: the first model's converged score and success minus each other's (the paper's ablations).
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import re
import shutil
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure  # figures straight to files: no pyplot state, no GUI backend
from matplotlib.ticker import MaxNLocator

from vintix.atomic import (
    PARTIAL_SUFFIX,
    atomic_directory,
    atomic_path,
    atomic_write_text,
    check_output_kind,
    file_name,
    folder_lock,
    not_a_file,
)
from vintix.demonstrators.goal_blind import read_goal_blind
from vintix.errors import VintixError, at_file, printable
from vintix.evaluate.config import PLATEAU_SHOTS, RunFile
from vintix.evaluate.run import EPISODES_FILE, RUN_FILE
from vintix.evaluate.summary import (
    best_k_plateau,
    check_shot_window,
    converged_gap_with_ci,
    estimate_with_ci,
    iqm_with_ci,
    stratified_iqm_with_ci,
)
from vintix.fields import read_json_file
from vintix.tasks import get_task
from vintix.tasks.custom import register_specs
from vintix.tasks.scores import (
    MODEL_CARD_DOMAIN_IQM,
    Reference,
    check_table,
    missing_reference_note,
    model_card_scores,
    reference,
)


@dataclass
class Results:
    """One `vintix eval` output folder: normalized scores per task variant, ``[runs, shots]``."""

    label: str
    folder: Path
    run: dict
    scores: dict[str, np.ndarray]
    """variant ('task' or 'task [variation]') -> normalized score per run (row) and shot (column)"""
    domains: dict[str, str]
    """variant -> its domain and split, and variation: held-out tasks and physics aggregate apart"""
    tasks: dict[str, str]
    """variant -> task name"""
    success: dict[str, np.ndarray]
    """variant -> success flag (0/1) per run and shot, like `scores`; only variants whose task has one"""
    seeds: dict[str, list[int]]
    """variant -> env seed of each run (row), in order: runs of two folders pair by seed"""
    reward_input: str
    """the rewards fed back to the model (`EvalConfig.reward_input`; 'true' for folders from before it)"""


EPISODE_COLUMNS = {"task", "variation", "seed", "prompt_steps", "shot", "return", "domain", "split"}
"""Columns of `episodes.csv` the report reads."""


def _variant(task: str, variation: str) -> str:
    return f"{task} [{variation}]" if variation else task


def load_results(folder: Path, table: str) -> tuple[Results, list[str]]:
    """Read one results folder and normalize its returns with `table`; notes name tasks it lacks."""
    check_table(table)
    episodes, run_file = folder / EPISODES_FILE, folder / RUN_FILE
    if why := not_a_file(episodes) or not_a_file(run_file):
        raise VintixError(why)
    if not episodes.is_file() or not run_file.is_file():
        raise VintixError(f"{folder}: no {EPISODES_FILE} and {RUN_FILE}; point to a folder written by `vintix eval`")
    rewrite = "re-run `vintix eval` into this folder"
    run = dataclasses.asdict(read_json_file(run_file, RunFile, at_file(VintixError), rewrite))
    register_specs(run.get("custom_tasks", {}), str(run_file))  # your own tasks travel with their results
    # variant -> run (seed, prompt) -> shot -> (normalized score, success flag or NaN)
    runs: dict[str, dict[tuple[int, str], dict[int, tuple[float, float]]]] = defaultdict(lambda: defaultdict(dict))
    domains, tasks, refs, missing = {}, {}, {}, []
    fed: set[str] = set()  # the reward_input column's values
    content = episodes.read_bytes()  # read once: parsed here, its hash checked against run.json below
    with io.TextIOWrapper(io.BytesIO(content)) as f:
        reader = csv.DictReader(f)
        lacking = sorted(EPISODE_COLUMNS - set(reader.fieldnames or []))
        if lacking:
            raise VintixError(f"{episodes}: not a `vintix eval` episodes table (no column(s) {lacking}); {rewrite}")
        line = 1
        for line, row in enumerate(reader, start=2):
            task, variant = row["task"], _variant(row["task"], row["variation"])
            try:
                if task not in refs:
                    refs[task] = reference(task, table, env_optimum=bool(row.get("optimal")))
                    if refs[task] is None:
                        missing.append(task)
                ref: Reference | None = refs[task]
                if ref is None:
                    continue
                episode_return, shot, succeeded = _checked_episode(row)
                by_shot = runs[variant][(int(row["seed"]), row["prompt_steps"])]
                if shot in by_shot:
                    raise ValueError(f"a second row for {variant}, seed {row['seed']}, shot {shot}")
                optimal = float(row["optimal"]) if row.get("optimal") else None
                by_shot[shot] = float(ref.normalize(episode_return, optimal)), succeeded
            except (ValueError, TypeError) as error:  # a hand-edited or foreign table
                raise VintixError(f"{episodes}, line {line}: {error}; {rewrite}") from error
            if row.get("reward_input"):
                fed.add(row["reward_input"])
            domains[variant] = _variant(f"{row['domain']} {row['split']}", row["variation"])
            tasks[variant] = task
    if line == 1:
        raise VintixError(f"{episodes}: holds no episodes; {rewrite}")
    scores: dict[str, np.ndarray] = {}
    success: dict[str, np.ndarray] = {}
    seeds: dict[str, list[int]] = {}
    for variant, by_run in runs.items():
        for (seed, _), by_shot in by_run.items():
            if sorted(by_shot) != list(range(1, len(by_shot) + 1)):
                raise VintixError(f"{episodes}: {variant}, seed {seed} has shots {sorted(by_shot)}, not 1, 2, ... "
                                  f"without gaps; {rewrite}")
        shots = min(len(s) for s in by_run.values())
        ordered = sorted(by_run)
        both = np.array([[by_run[r][k] for k in range(1, shots + 1)] for r in ordered])  # [runs, shots, 2]
        scores[variant], seeds[variant] = both[..., 0], [seed for seed, _ in ordered]
        if not np.isnan(both[..., 1]).any():
            success[variant] = both[..., 1]
    notes = [f"{folder}: " + missing_reference_note(missing, table)] if missing else []
    reward_input = _reward_input(episodes, fed, run)
    recorded = run.get("episodes_sha256")  # results written before the hash existed are read as they are
    if recorded is not None and recorded != hashlib.sha256(content).hexdigest():
        raise VintixError(f"{folder}: {EPISODES_FILE} is not the one {RUN_FILE} describes (its sha256 differs): the "
                          f"folder mixes the files of two runs, so its results would be reported under the wrong "
                          f"model or settings; {rewrite}")
    # A label is a file's text: it never starts a line of its own in a note, a console line or a figure.
    return Results(printable(run.get("label") or folder.name, breaks=False), folder, run, scores, domains, tasks,
                   success, seeds,
                   reward_input), notes


def _reward_input(episodes: Path, fed: set[str], run: dict[str, Any]) -> str:
    """What the folder's runs were fed back: the episodes' own column, which must hold one value and agree with
    run.json; run.json alone for tables from before the column ('true' before either existed)."""
    said = run.get("config", {}).get("reward_input")
    if len(fed) > 1 or (fed and said is not None and fed != {said}):
        raise VintixError(f"{episodes}: its reward_input column holds {sorted(fed)}, its run.json says {said!r}: the "
                          "folder mixes runs fed different rewards; evaluate each into a folder of its own")
    return next(iter(fed), said or "true")


def _checked_episode(row: dict[str, str]) -> tuple[float, int, float]:
    """One row's return, shot and success flag (NaN for envs without one), or a ValueError naming
    what a `vintix eval` table can never hold: a non-finite return, a shot below 1, a flag not 0/1."""
    episode_return, shot = float(row["return"]), int(row["shot"])
    success = float(row.get("success") or "nan")  # empty for envs without a success flag
    if not np.isfinite(episode_return):
        raise ValueError(f"return {row['return']!r} is not a finite number")
    if shot < 1:
        raise ValueError(f"shot {shot}: shots count from 1")
    if not (np.isnan(success) or success in (0.0, 1.0)):
        raise ValueError(f"success {row['success']!r} is neither 0, 1 nor empty")
    return episode_return, shot, success


def curve_with_ci(scores: np.ndarray | list[np.ndarray]) -> np.ndarray:
    """The score and its 95 % CI over runs at each shot: ``[shots, 3]`` (point, low, high). One task's
    ``[runs, shots]`` array: the mean over runs (what `vintix eval` prints, and what *converged* averages). A
    list of several tasks' arrays (a domain): the IQM over their runs pooled, with a bootstrap stratified by
    task, robust to one task's failed runs."""
    if isinstance(scores, np.ndarray):
        return np.array([estimate_with_ci(scores[:, shot], np.mean) for shot in range(scores.shape[1])])
    shots = min(s.shape[1] for s in scores)
    return np.array([stratified_iqm_with_ci([s[:, shot] for s in scores]) for shot in range(shots)])


FEW_RUNS = 5
"""Below this many runs a bootstrap CI says little: figures and tables say so"""


def converged(scores: np.ndarray, k: int) -> tuple[float, int]:
    """Best k-shot plateau of the mean curve over runs, and the (1-based) shot it starts at."""
    value, start = best_k_plateau(scores.mean(axis=0), k)
    return value, start + 1


def _save(figure: Figure, path: Path) -> Path:
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=110, bbox_inches="tight")
    return path


def plot_curves(curves: dict[str, tuple[np.ndarray, int]], title: str, path: Path, statistic: str) -> Path:
    """Normalized score vs shot, one line (`statistic`: 'IQM' or 'mean') with its CI band per label (label ->
    (curve, runs))."""
    figure = Figure(figsize=(6, 4))
    axis = figure.subplots()
    for label, (curve, runs) in curves.items():
        shots = np.arange(1, len(curve) + 1)
        few = f"; fewer than {FEW_RUNS}: the band says little" if runs < FEW_RUNS else ""
        axis.plot(shots, curve[:, 0], marker="o" if len(shots) < 12 else None, markersize=3,
                  label=f"{label} ({runs} runs{few})")
        axis.fill_between(shots, curve[:, 1], curve[:, 2], alpha=0.2)
    axis.axhline(1.0, color="gray", linestyle="--", linewidth=0.8)
    axis.axhline(0.0, color="gray", linestyle=":", linewidth=0.8)
    axis.xaxis.set_major_locator(MaxNLocator(integer=True))  # shots are whole episodes
    axis.set(xlabel="shot (episode from an empty context)", ylabel=f"normalized score ({statistic}, 95% CI)",
             title=printable(title, breaks=False))
    _legend_below(axis)
    return _save(figure, path)


def _legend_below(axis: Axes) -> None:
    """The legend under the plot, where it cannot cover a curve or a marker."""
    axis.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)


def plot_first_vs_converged(rows: list[tuple[str, str, float, float, float | None]], k: int, path: Path) -> Path:
    """Per task variant and label: the first shot's score next to the converged one (and the paper's)."""
    figure = Figure(figsize=(max(6.0, 0.5 * len(rows) + 2), 4))
    axis = figure.subplots()
    x = np.arange(len(rows))
    axis.bar(x - 0.2, [r[2] for r in rows], width=0.4, label="first shot")
    axis.bar(x + 0.2, [r[3] for r in rows], width=0.4, label=f"converged (best {k}-shot mean)")
    paper = [(i, r[4]) for i, r in enumerate(rows) if r[4] is not None]
    if paper:
        axis.scatter([i for i, _ in paper], [p for _, p in paper], color="black", marker="_", s=200, zorder=3,
                     label="paper's Vintix (converged)")
    axis.set_xticks(x, [f"{r[1]}\n{r[0]}" for r in rows], rotation=90, fontsize=7)
    axis.axhline(1.0, color="gray", linestyle="--", linewidth=0.8)
    axis.set(ylabel="normalized score (mean over runs)", title="first shot vs converged")
    axis.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return _save(figure, path)


_MARKDOWN_SPECIAL = re.compile(r"([\\`*_\[\]<>#|~&])")


def markdown_text(text: str) -> str:
    """Text that a file supplied (a label, a task or domain name, a path) as literal Markdown: each character that
    Markdown or HTML reads (a heading's #, a cell's |, a tag's <, a link's [, emphasis) backslash-escaped, every line
    break and control character a space, so that report.md shows it as written and nothing else."""
    return _MARKDOWN_SPECIAL.sub(r"\\\1", " ".join("".join(c if c.isprintable() else " " for c in text).split()))


FIGURES = "figures"
"""The folder of a report's figures, beside its report.md"""


def markdown_code(text: str) -> str:
    """A path or name as a code span, where nothing in it can end the span or the table cell (else `markdown_text`)."""
    plain = text.isprintable() and not any(c in text for c in "`|")
    return f"`{text}`" if plain else markdown_text(text)


def _ci(point: float, low: float, high: float) -> str:
    return f"{point:.2f} [{low:.2f}, {high:.2f}]"


def _rate(rate: float) -> str:
    return f"{rate:.0%}"


def _signed(value: float, digits: int) -> str:
    """`value` with its sign, and no "-0" for a value that rounds to zero."""
    rounded = round(value, digits) + 0.0  # + 0.0 turns -0.0 into 0.0
    return f"{rounded:+.{digits}f}"


def _score_gap(point: float, low: float, high: float) -> str:
    return f"{_signed(point, 2)} [{_signed(low, 2)}, {_signed(high, 2)}]"


def _success_gap(point: float, low: float, high: float) -> str:
    """A success-rate difference in percentage points."""
    return f"{_signed(100 * point, 0)} pp [{_signed(100 * low, 0)}, {_signed(100 * high, 0)}]"


def _same_runs(r: Results) -> tuple[str, str, Any]:
    """What must match for two folders to differ only in the rewards fed back: the checkpoint and the
    prompt (variation and seeds are matched per task variant and run)."""
    config = r.run.get("config", {})
    prompt_from = config.get("prompt_from")
    return r.run.get("checkpoint", ""), str(prompt_from), config.get("prompt_steps") if prompt_from else None


def reward_ablations(results: list[Results]) -> tuple[list[tuple[Results, Results]], list[str]]:
    """Every (true, ablated) pair of folders that differ only in the rewards fed back (the same
    checkpoint and prompt, one fed the true rewards, the other zeros or shuffled ones), in the order
    given, and notes on ablated folders without a true-reward folder to compare with."""
    trues = [r for r in results if r.reward_input == "true" and r.run.get("checkpoint")]  # unnamed: unmatchable
    pairs, notes = [], []
    for other in (r for r in results if r.reward_input != "true"):
        matches = [(true, other) for true in trues if _same_runs(true) == _same_runs(other)]
        if not matches:
            notes.append(f"{other.folder} was fed {other.reward_input} rewards, but no folder of its checkpoint "
                         f"{other.run.get('checkpoint', '')!r} (and prompt) fed the true ones was given: no "
                         "reward-use gap for it")
        pairs += matches
    return pairs, notes


def _shots_both_have(first: Results, other: Results, variants: list[str]) -> int:
    """The shots every run of `first` and `other` has in `variants`: a gap compares those only (runs of different
    lengths)."""
    return min(min(first.scores[v].shape[1], other.scores[v].shape[1]) for v in variants)


def _score_window(first: Results, variants: list[str], k: int, available: int) -> tuple[int, int] | None:
    """The true run's best `k` shots of normalized score among its first `available` (1-based, inclusive), where
    every variant's is the same window; None where they differ."""
    starts = {best_k_plateau(first.scores[v][:, :available].mean(axis=0), k)[1] for v in variants}
    if len(starts) > 1:
        return None
    start, length = starts.pop(), min(k, available)
    return start + 1, start + length


def _window_shots(first: Results, variants: list[str], k: int, same_window: bool,
                  shots: tuple[int, int] | None, available: int) -> str:
    """The shots a gap averages, as its table prints them: the fixed window, the true run's best `k` shots (one
    window, or "best k per task" where the tasks' differ), or each model's own best `k`."""
    if shots is None and same_window:
        shots = _score_window(first, variants, k, available)
        if shots is None:
            return f"best {k} per task"
    if shots is not None:
        return f"{shots[0]}–{shots[1]}"
    return f"best {k} of each"


def _gap_cells(first: Results, other: Results, variants: list[str], k: int, same_window: bool,
               shots: tuple[int, int] | None = None) -> list[str]:
    """Runs, the shots averaged, and the mean over `variants` of converged(first) − converged(other) with its CI,
    for the normalized score and (where every variant has one) the success rate; `first` is the true-reward
    folder of a reward ablation (`same_window`: the ablated run over the true run's best window), or the
    first model of a comparison; `shots`: a fixed window of shots instead of the best. Success is averaged over the
    score's window where the printed window is one, so the shots printed are the shots of both gaps."""
    paired = all(first.seeds[v] == other.seeds[v] for v in variants)
    if paired:
        runs = f"{sum(len(first.seeds[v]) for v in variants)}, paired by seed"
    else:
        runs = f"{sum(len(first.seeds[v]) for v in variants)} vs {sum(len(other.seeds[v]) for v in variants)}"
    score = converged_gap_with_ci([(first.scores[v], other.scores[v]) for v in variants], k, paired,
                                  same_window=same_window, shots=shots)
    with_success = all(v in first.success and v in other.success for v in variants)
    available = _shots_both_have(first, other, variants)
    success_shots = shots if shots is not None or not same_window else _score_window(first, variants, k, available)
    success = (_success_gap(*converged_gap_with_ci([(first.success[v], other.success[v]) for v in variants], k, paired,
                                                   same_window=same_window, shots=success_shots))
               if with_success else "—")
    return [runs, _window_shots(first, variants, k, same_window, shots, available), _score_gap(*score), success]


def model_comparisons(results: list[Results]) -> list[tuple[Results, Results]]:
    """(first model, other model) for each other checkpoint fed the true rewards on the same prompt as the
    first true-reward folder given: the paper's ablations (AD against expert distillation, AD without
    rewards) as differences of converged score and success."""
    trues = [r for r in results if r.reward_input == "true" and r.run.get("checkpoint")]
    if not trues:
        return []
    first, *others = trues
    checkpoint, *prompt = _same_runs(first)
    pairs = []
    for other in others:
        other_checkpoint, *other_prompt = _same_runs(other)
        if other_checkpoint != checkpoint and other_prompt == prompt:
            pairs.append((first, other))
    return pairs


def _gap_tables(pairs: list[tuple[Results, Results]], other_column: str, other_cell: Callable[[Results], str],
                table: str, k: int, same_window: bool, shots: tuple[int, int] | None = None,
                summary: list[str] | None = None) -> list[str]:
    """Per-domain and per-task tables (markdown lines) of converged(first) − converged(other) with CIs
    for (first, other) folder pairs; `other_cell` names the other folder in its column. `summary` gets one line
    per domain row, for a console."""
    columns = (f"model (true rewards) | {other_column} | runs | shots | Δ converged score ({table}) | "
               "Δ converged success |\n|---|---|---|---|---|---|---|")
    domain_lines, task_lines = [f"| domain | {columns}"], [f"| task | {columns}"]
    for first, other in pairs:
        common = sorted(set(first.scores) & set(other.scores))
        for domain in sorted({first.domains[v] for v in common}):
            variants = [v for v in common if first.domains[v] == domain]
            cells = _gap_cells(first, other, variants, k, same_window, shots)
            domain_lines.append(f"| {markdown_text(domain)} | {markdown_text(first.label)} | {other_cell(other)} | "
                                + " | ".join(cells) + " |")
            if summary is not None:
                _, window, score, success = cells
                summary.append(f"{first.label}, {domain}: true − {other_cell(other)} rewards = {score} score"
                               + (f", {success} success" if success != "—" else "") + f" (shots {window})")
        for variant in common:
            task_lines.append(f"| {markdown_text(variant)} | {markdown_text(first.label)} | {other_cell(other)} | "
                              + " | ".join(_gap_cells(first, other, [variant], k, same_window, shots)) + " |")
    return ["### Per domain\n"] + domain_lines + ["\n### Per task\n"] + task_lines


def _fed_instead(other: Results) -> str:
    """What an ablated folder was fed, and its label where the label does not already say it."""
    label = markdown_text(other.label)
    return other.reward_input if other.reward_input in other.label else f"{other.reward_input}: {label}"


def reward_gap_section(pairs: list[tuple[Results, Results]], table: str, k: int,
                       shots: tuple[int, int] | None = None, summary: list[str] | None = None) -> list[str]:
    """The report's reward-use gap section (markdown lines) for (true, ablated) folder pairs; `shots`: a fixed
    window of shots (first, last) instead of the true run's best `k`; `summary` gets a line per domain."""
    lines = ["\n## Reward-use gap\n",
             "In-context RL means the rewards do the work: the same model with zeros or shuffled rewards fed back "
             "should do worse; a gap near zero means the improvement over shots is not reward-driven. "
             "Shuffled rewards keep each episode's own reward values but break their link to the states and "
             "actions that earned them; other-goal rewards are what each step would have earned under another "
             "seed's hidden goal, as consistent as the true ones but pointing elsewhere. Every score below comes "
             "from the true returns; only what the model was "
             f"fed differs. Δ = converged(true) − the ablated run's mean over the same shots, *converged* the best "
             f"{k}-shot plateau of a task's mean curve (so shots the true run's converged leaves out, a probing "
             "first episode, count for neither); a domain's Δ is the mean of its tasks' Δ. 95 % CIs: percentile "
             "bootstrap resampling runs within each task, a seed's two runs (same env, same Meta-World goal) "
             "together when both folders ran the same seeds. The *shots* column says which shots each Δ averages"
             + (f": here the fixed window `--gap-shots {shots[0]}-{shots[1]}`, both runs' mean over it"
                if shots else "; `--gap-shots FIRST-LAST` fixes them") + ".\n"]
    return lines + _gap_tables(pairs, "fed back instead", _fed_instead, table, k, same_window=True, shots=shots,
                               summary=summary)


def model_comparison_section(pairs: list[tuple[Results, Results]], table: str, k: int) -> list[str]:
    """The report's section (markdown lines) comparing the first true-reward model with the others."""
    lines = ["\n## Between models\n",
             "The first model given against each other model, all fed their true rewards on the same prompt: "
             "the paper's ablations (AD against expert distillation, AD without rewards). "
             f"Δ = converged(first) − converged(other), *converged* the best {k}-shot plateau of a task's mean "
             "curve; a domain's Δ is the mean of its tasks' Δ; CIs as for the reward-use gap, runs paired by "
             "seed when both folders ran the same seeds.\n"]
    return lines + _gap_tables(pairs, "compared with", lambda other: markdown_text(other.label), table, k,
                               same_window=False)


class WrittenReport(NamedTuple):
    """What `write_report` wrote, and what a console should show of it."""

    path: Path
    notes: list[str]
    """tasks without a reference score, ablated folders without a true-reward folder, too few runs"""
    gaps: list[str]
    """one line per reward ablation and domain: its reward-use gap with CI, and the shots it averages"""


def write_report(folders: list[Path], out: Path, table: str = "paper", plateau_shots: int | None = None,
                 model_card: bool = False, gap_shots: tuple[int, int] | None = None) -> WrittenReport:
    """`report.md` and its figures under `out`, from one or more `vintix eval` result folders.
    `model_card`: put the released model's model-card scores beside each task and domain (for results of
    the imported official model). `gap_shots`: the reward-use gap over these shots (first, last; 1-based,
    inclusive) instead of the true run's best `plateau_shots`. `plateau_shots` None: `PLATEAU_SHOTS`, or all the shots
    of a shorter run; a number given must fit the longest run."""
    if plateau_shots is not None and plateau_shots < 1:
        raise VintixError(f"plateau_shots must be >= 1, got {plateau_shots}")
    if gap_shots is not None and not 1 <= gap_shots[0] <= gap_shots[1]:  # the runs' own length is checked later
        raise VintixError(f"--gap-shots {gap_shots[0]}-{gap_shots[1]}: shots count from 1, first <= last")
    resolved = [Path(f).resolve() for f in folders]
    twice = sorted({str(f) for f, r in zip(folders, resolved, strict=True) if resolved.count(r) > 1})
    if twice:  # counted twice, a run's rows would be two runs in every table and mean
        raise VintixError(f"{', '.join(twice)}: given more than once; give each results folder once")
    if gap_shots is not None and len(folders) < 2:
        raise VintixError("--gap-shots sets the shots of the reward-use gap, which compares a true-reward folder with "
                          "a zero or shuffled one of the same checkpoint: give both folders")
    check_output_kind(out, "report")
    with folder_lock(out, "vintix report"):  # a second report into `out` is refused, not mixed with this one
        for leftover in out.glob(f"{FIGURES}.*{PARTIAL_SUFFIX}"):  # of a report a signal stopped
            shutil.rmtree(leftover, ignore_errors=True)
        # The figures are drawn into a folder of their own that replaces the old one whole once report.md is
        # written: a stopped report leaves the last one as it was, and no figure of another report stays.
        with atomic_directory(out / FIGURES) as figures:
            return _write_report(folders, out, figures, table, plateau_shots, model_card, gap_shots)


def _header_lines(results: list[Results], table: str, plateau_shots: int, with_success: bool) -> list[str]:
    """The report's title, what its numbers are, and one row per results folder: its label, checkpoint and run."""
    lines = ["# In-context evaluation report\n",
             f"Normalized score `(R − random) / (expert − random)` with the **{table}** reference table; "
             "a task's scores are means over its runs (as `vintix eval` prints them), a domain's are IQMs over its "
             "runs (shot 1) and over its tasks' converged scores, each with a percentile-bootstrap 95 % CI; "
             f"*converged* is the best {plateau_shots}-shot plateau of a task's mean curve (paper §3)."
             + (" Success rates (tasks with a success flag) are means over runs." if with_success else "") + "\n",
             "| label | checkpoint | shots | runs/task | variation | prompt steps | rewards fed back | tasks |",
             "|---|---|---|---|---|---|---|---|"]
    for r in results:
        config = r.run.get("config", {})
        variation = ", ".join(f"{k}={v}" for k, v in config.get("variation", {}).items()) or "—"
        prompt = config.get("prompt_steps") if config.get("prompt_from") else "cold start"
        lines.append(f"| {markdown_text(r.label)} | {markdown_code(str(r.run.get('checkpoint', '')))} | "
                     f"{config.get('shots', '?')} | "
                     f"{config.get('seeds', '?')} | {variation} | {prompt} | {r.reward_input} | {len(r.scores)} |")
    goal = {str(protocol) for r in results if (protocol := r.run.get("goal_protocol")) is not None}
    if goal:
        lines.append(f"\nHidden-goal protocol: {'; '.join(sorted(goal))}.\n")
    return lines


def _domain_lines(results: list[Results], table: str, plateau_shots: int, with_success: bool, model_card: bool,
                  figures: Path) -> list[str]:
    """The per-domain section: each folder's shot-1 and converged IQM per domain, and the domain's figure."""
    lines: list[str] = []
    per_label = ["shot 1", "converged"] + (["success shot 1", "success converged"] if with_success else [])
    lines += ["\n## Per domain\n",
              f"| domain ({table}-normalized) | "
              + " | ".join(f"{markdown_text(r.label)}: {c}" for r in results for c in per_label)
              + (" | model card (IQM) |" if model_card else " |"),
              "|---|" + "---|" * (len(per_label) * len(results) + model_card)]
    domains = sorted({d for r in results for d in r.domains.values()})
    for domain in domains:
        curves, cells = {}, []
        for r in results:
            variants = [v for v, d in r.domains.items() if d == domain]
            if not variants:
                cells += ["—"] * len(per_label)
                continue
            shots = min(r.scores[v].shape[1] for v in variants)
            per_task = [r.scores[v][:, :shots] for v in variants]
            curves[r.label] = (curve_with_ci(per_task), sum(len(runs) for runs in per_task))
            plateaus = np.array([converged(r.scores[v], plateau_shots)[0] for v in variants])
            cells += [_ci(*curves[r.label][0][0]), _ci(*iqm_with_ci(plateaus))]
            if with_success:
                cells += _success_cells(r, variants, plateau_shots)
        plot_curves(curves, f"{domain}: normalized score vs shot", figures / f"domain-{file_name(domain)}.png", "IQM")
        if model_card:
            iqm = MODEL_CARD_DOMAIN_IQM.get(domain.removesuffix(" train"))  # the card's IQMs are of training tasks
            cells.append("—" if iqm is None else f"{iqm:.2f}")
        lines.append(f"| {markdown_text(domain)} | " + " | ".join(cells) + " |")
    lines.append("")
    for domain in domains:
        lines.append(f"![{markdown_text(domain)}](figures/domain-{file_name(domain)}.png)")
    return lines


def _write_report(folders: list[Path], out: Path, figures: Path, table: str, given_plateau_shots: int | None,
                  model_card: bool, gap_shots: tuple[int, int] | None) -> WrittenReport:
    loaded = [load_results(Path(folder), table) for folder in folders]
    results = [r for r, _ in loaded]
    notes = [n for _, ns in loaded for n in ns]
    if not any(r.scores for r in results):
        raise VintixError(f"no task of {', '.join(map(str, folders))} has a '{table}' reference score to normalize "
                          f"with: {' '.join(notes)}")
    most = max(scores.shape[1] for r in results for scores in r.scores.values())
    if given_plateau_shots is not None and given_plateau_shots > most:
        raise VintixError(f"--plateau-shots {given_plateau_shots} is more shots than the runs have (at most {most}); "
                          f"choose at most {most} (left out, it is {PLATEAU_SHOTS}, or all the shots of a shorter run)")
    plateau_shots = given_plateau_shots or PLATEAU_SHOTS
    labels = [r.label for r in results]
    if len(set(labels)) < len(labels):  # the same checkpoint evaluated twice: tell them apart
        for r in results:
            r.label = f"{r.label} ({r.folder.name})"
    with_success = any(r.success for r in results)
    lines = _header_lines(results, table, plateau_shots, with_success)
    lines += _domain_lines(results, table, plateau_shots, with_success, model_card, figures)
    card = model_card_scores() if model_card else {}

    # The goal-blind expert's success (demonstrators/goal_blind.csv) beside shot 1 and converged: what a
    # model reaches without reading a single reward; and, for tasks measured by return (the meta-RL ones), the
    # share of the expert's return only the hidden parameter buys: the most a reward-use gap can show.
    goal_blind = read_goal_blind()
    hidden_returns = {r.tasks[v]: goal_blind[r.tasks[v]].hidden_return for r in results for v in r.scores
                      if r.tasks[v] in goal_blind and np.isfinite(goal_blind[r.tasks[v]].hidden_return)}
    success_columns = " success shot 1 | success converged | goal-blind success |" if with_success else ""
    with_paper = table == "paper"  # the paper's Vintix scores are paper-normalized: beside such scores only
    extra_columns = with_paper + model_card + 3 * with_success + bool(hidden_returns)
    lines += ["\n## Per task\n", f"| task ({table}-normalized) | label | runs | shot 1 | converged | from shot |"
              + (" paper's Vintix |" if with_paper else "") + (" model card |" if model_card else "") + success_columns
              + (" hidden return |" if hidden_returns else ""),
              "|---|---|---|---|---|---|" + "---|" * extra_columns]
    bars = []
    for variant in sorted({v for r in results for v in r.scores}):
        curves = {}
        for r in results:
            if variant not in r.scores:
                continue
            scores = r.scores[variant]
            curves[r.label] = (curve_with_ci(scores), len(scores))
            value, start = converged(scores, plateau_shots)
            published = get_task(r.tasks[variant]).paper_vintix_normalized
            paper = published.mean if table == "paper" and "[" not in variant and published is not None else None
            bars.append((variant, r.label, float(scores[:, 0].mean()), value, paper))
            cells = [markdown_text(variant), markdown_text(r.label), str(len(scores)), _ci(*curves[r.label][0][0]),
                     f"{value:.2f}", str(start)]
            if with_paper:
                cells.append("—" if paper is None else f"{paper:.2f}")
            if model_card:
                published_card = card.get(r.tasks[variant]) if "[" not in variant else None
                cells.append("—" if published_card is None else f"{published_card:.2f}")
            if with_success:
                blind = goal_blind.get(r.tasks[variant])
                cells += _success_cells(r, [variant], plateau_shots)
                cells.append("—" if blind is None else _rate(blind.goal_blind_success))
            if hidden_returns:
                hidden = hidden_returns.get(r.tasks[variant])
                cells.append("—" if hidden is None else f"{hidden:.2f}")
            lines.append("| " + " | ".join(cells) + " |")
        plot_curves(curves, variant, figures / "tasks" / f"{file_name(variant)}.png", "mean")
    if hidden_returns:
        lines.append("\n*hidden return*: the goal-aware expert's return aimed at the true goal minus aimed blind, over "
                     "its return minus a random policy's (`vintix demonstrator goal-blind`): the score only the hidden "
                     "goal buys, and so the most a reward-use gap can show on the task.")
    longest = max(scores.shape[1] for r in results for scores in r.scores.values())
    plot_first_vs_converged(bars, min(plateau_shots, longest), figures / "first-vs-converged.png")
    lines += ["\n![first shot vs converged](figures/first-vs-converged.png)\n", "### Curves per task\n"]
    lines += [f"![{markdown_text(v)}](figures/tasks/{file_name(v)}.png)"
              for v in sorted({v for r in results for v in r.scores})]
    ablations, unmatched = reward_ablations(results)
    gaps: list[str] = []
    notes += unmatched
    few = sorted({f"{v} ({r.label}: {len(r.scores[v])})" for r in results for v in r.scores
                  if len(r.scores[v]) < FEW_RUNS})
    if few:
        notes.append(f"fewer than {FEW_RUNS} runs, so confidence intervals that say little: {', '.join(few)}")
    if ablations:
        if gap_shots is not None:  # before any table is drawn: a window the runs do not have is the user's to fix
            try:
                check_shot_window(gap_shots, min(r.scores[v].shape[1] for pair in ablations for r in pair
                                                 for v in r.scores))
            except ValueError as error:
                raise VintixError(f"--gap-shots: {error}") from None
        lines += reward_gap_section(ablations, table, plateau_shots, gap_shots, gaps)
    comparisons = model_comparisons(results)
    if comparisons:
        lines += model_comparison_section(comparisons, table, plateau_shots)
    if notes:
        lines += ["\n## Notes\n"] + [f"- {markdown_text(n)}" for n in notes]  # they quote labels and paths
    path = out / "report.md"
    atomic_write_text(path, "\n".join(lines) + "\n")
    return WrittenReport(path, notes, gaps)


def _success_cells(r: Results, variants: list[str], k: int) -> list[str]:
    """The success rate of a task variant, or of a domain's `variants`, at shot 1 (over all their runs)
    and converged (the mean of their converged rates); dashes where none has a success flag."""
    rated = [v for v in variants if v in r.success]
    if not rated:
        return ["—", "—"]
    first = np.concatenate([r.success[v][:, 0] for v in rated]).mean()
    return [_rate(first), _rate(float(np.mean([converged(r.success[v], k)[0] for v in rated])))]
