"""`vintix report`: a markdown report with PNG figures, regenerated from `vintix eval` result folders.

Scores are renormalized from the raw episode returns with the chosen reference table, so a report
made after our demonstrators are scored uses them even for older results. Aggregation (DESIGN §8):
a task's curve is the IQM over its runs (seeds) at each shot, a domain's the IQM over all runs of
its tasks, each with a percentile-bootstrap 95 % CI over runs; a task's converged score is its best
k-shot plateau (the best mean over k consecutive shots of its mean curve), the paper's "performance
after reaching inference-time convergence". Several result folders (e.g. AD, ED, AD without
reward) share every figure and table, one line or bar each.
"""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure  # figures straight to files: no pyplot state, no GUI backend

from vintix.atomic import atomic_path, atomic_write_text
from vintix.errors import VintixError
from vintix.evaluate.run import EPISODES_FILE, RUN_FILE
from vintix.evaluate.scores import Reference, check_table, missing_reference_note, reference
from vintix.evaluate.summary import best_k_plateau, iqm_with_ci
from vintix.tasks import get_task


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


EPISODE_COLUMNS = {"task", "variation", "seed", "prompt_steps", "shot", "return", "domain", "split"}
"""Columns of `episodes.csv` the report reads."""


def _variant(task: str, variation: str) -> str:
    return f"{task} [{variation}]" if variation else task


def load_results(folder: Path, table: str) -> tuple[Results, list[str]]:
    """Read one results folder and normalize its returns with `table`; notes name tasks it lacks."""
    check_table(table)
    episodes, run_file = folder / EPISODES_FILE, folder / RUN_FILE
    if not episodes.is_file() or not run_file.is_file():
        raise VintixError(f"{folder}: no {EPISODES_FILE} and {RUN_FILE}; point to a folder written by `vintix eval`")
    rewrite = "re-run `vintix eval` into this folder"
    try:
        run = json.loads(run_file.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise VintixError(f"{run_file}: not valid JSON ({error}); {rewrite}") from error
    if not isinstance(run, dict):
        raise VintixError(f"{run_file}: expected a JSON object; {rewrite}")
    runs: dict[str, dict[tuple[int, str], dict[int, float]]] = defaultdict(lambda: defaultdict(dict))
    domains, tasks, refs, missing = {}, {}, {}, []
    with episodes.open() as f:
        reader = csv.DictReader(f)
        lacking = sorted(EPISODE_COLUMNS - set(reader.fieldnames or []))
        if lacking:
            raise VintixError(f"{episodes}: not a `vintix eval` episodes table (no column(s) {lacking}); {rewrite}")
        line = 1
        for line, row in enumerate(reader, start=2):
            task, variant = row["task"], _variant(row["task"], row["variation"])
            try:
                if task not in refs:
                    refs[task] = reference(task, table)
                    if refs[task] is None:
                        missing.append(task)
                ref: Reference | None = refs[task]
                if ref is None:
                    continue
                normalized = float(ref.normalize(float(row["return"])))
                runs[variant][(int(row["seed"]), row["prompt_steps"])][int(row["shot"])] = normalized
            except (ValueError, TypeError) as error:  # a hand-edited or foreign table
                raise VintixError(f"{episodes}, line {line}: {error}; {rewrite}") from error
            domains[variant] = _variant(f"{row['domain']} {row['split']}", row["variation"])
            tasks[variant] = task
    if line == 1:
        raise VintixError(f"{episodes}: holds no episodes; {rewrite}")
    scores = {}
    for variant, by_run in runs.items():
        shots = min(len(s) for s in by_run.values())
        scores[variant] = np.array([[s[k] for k in sorted(s)[:shots]] for s in by_run.values()])
    notes = [f"{folder}: " + missing_reference_note(missing, table)] if missing else []
    return Results(run.get("label") or folder.name, folder, run, scores, domains, tasks), notes


def curve_with_ci(scores: np.ndarray) -> np.ndarray:
    """IQM and 95 % CI over runs at each shot: ``[shots, 3]`` (point, low, high)."""
    return np.array([iqm_with_ci(scores[:, shot]) for shot in range(scores.shape[1])])


def converged(scores: np.ndarray, k: int) -> tuple[float, int]:
    """Best k-shot plateau of the mean curve over runs, and the (1-based) shot it starts at."""
    value, start = best_k_plateau(scores.mean(axis=0), k)
    return value, start + 1


def _save(figure: Figure, path: Path) -> Path:
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=110, bbox_inches="tight")
    return path


def plot_curves(curves: dict[str, tuple[np.ndarray, int]], title: str, path: Path) -> Path:
    """Normalized score vs shot, one IQM line with its CI band per label (label -> (curve, runs))."""
    figure = Figure(figsize=(6, 4))
    axis = figure.subplots()
    for label, (curve, runs) in curves.items():
        shots = np.arange(1, len(curve) + 1)
        axis.plot(shots, curve[:, 0], label=f"{label} ({runs} runs)")
        axis.fill_between(shots, curve[:, 1], curve[:, 2], alpha=0.2)
    axis.axhline(1.0, color="gray", linestyle="--", linewidth=0.8)
    axis.axhline(0.0, color="gray", linestyle=":", linewidth=0.8)
    axis.set(xlabel="shot (episode from an empty context)", ylabel="normalized score (IQM, 95% CI)", title=title)
    axis.legend(fontsize=7)
    return _save(figure, path)


def plot_first_vs_converged(rows: list[tuple[str, str, float, float, float | None]], k: int, path: Path) -> Path:
    """Per task variant and label: the first shot's score next to the converged one (and the paper's)."""
    figure = Figure(figsize=(max(6.0, 0.5 * len(rows) + 2), 4))
    axis = figure.subplots()
    x = np.arange(len(rows))
    axis.bar(x - 0.2, [r[2] for r in rows], width=0.4, label="first shot")
    axis.bar(x + 0.2, [r[3] for r in rows], width=0.4, label=f"converged (best {k}-shot plateau)")
    paper = [(i, r[4]) for i, r in enumerate(rows) if r[4] is not None]
    if paper:
        axis.scatter([i for i, _ in paper], [p for _, p in paper], color="black", marker="_", s=200, zorder=3,
                     label="paper's Vintix (converged)")
    axis.set_xticks(x, [f"{r[1]}\n{r[0]}" for r in rows], rotation=90, fontsize=7)
    axis.axhline(1.0, color="gray", linestyle="--", linewidth=0.8)
    axis.set(ylabel="normalized score (mean over runs)", title="first shot vs converged")
    axis.legend(fontsize=7)
    return _save(figure, path)


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def _ci(point: float, low: float, high: float) -> str:
    return f"{point:.2f} [{low:.2f}, {high:.2f}]"


def write_report(folders: list[Path], out: Path, table: str = "paper", plateau_shots: int = 10) -> tuple[Path, list[str]]:
    """`report.md` and its figures under `out`, from one or more `vintix eval` result folders.
    Returns the report's path and notes (tasks without a reference score)."""
    if plateau_shots < 1:
        raise VintixError(f"plateau_shots must be >= 1, got {plateau_shots}")
    loaded = [load_results(Path(folder), table) for folder in folders]
    results = [r for r, _ in loaded]
    notes = [n for _, ns in loaded for n in ns]
    if not any(r.scores for r in results):
        raise VintixError(f"no task of {', '.join(map(str, folders))} has a '{table}' reference score to normalize "
                          f"with: {' '.join(notes)}")
    labels = [r.label for r in results]
    if len(set(labels)) < len(labels):  # the same checkpoint evaluated twice: tell them apart
        for r in results:
            r.label = f"{r.label} ({r.folder.name})"
    figures = out / "figures"
    lines = ["# In-context evaluation report\n",
             f"Normalized score `(R − random) / (expert − random)` with the **{table}** reference table; "
             f"curves are IQMs over runs with percentile-bootstrap 95 % CIs; *converged* is the best "
             f"{plateau_shots}-shot plateau of a task's mean curve (paper §3).\n",
             "| label | checkpoint | shots | runs/task | variation | prompt steps | tasks |", "|---|---|---|---|---|---|---|"]
    for r in results:
        config = r.run.get("config", {})
        variation = ", ".join(f"{k}={v}" for k, v in config.get("variation", {}).items()) or "—"
        prompt = config.get("prompt_steps") if config.get("prompt_from") else "cold start"
        lines.append(f"| {r.label} | `{r.run.get('checkpoint', '')}` | {config.get('shots', '?')} | "
                     f"{config.get('seeds', '?')} | {variation} | {prompt} | {len(r.scores)} |")
    goal = {r.run.get("goal_protocol") for r in results} - {None}
    if goal:
        lines.append(f"\nMeta-World goal protocol: {'; '.join(sorted(goal))}.\n")

    lines += ["\n## Per domain\n", f"| domain ({table}-normalized) | " + " | ".join(f"{r.label}: shot 1 | {r.label}: converged" for r in results)
              + " |", "|---|" + "---|---|" * len(results)]
    domains = sorted({d for r in results for d in r.domains.values()})
    for domain in domains:
        curves, cells = {}, []
        for r in results:
            variants = [v for v, d in r.domains.items() if d == domain]
            if not variants:
                cells += ["—", "—"]
                continue
            shots = min(r.scores[v].shape[1] for v in variants)
            pooled = np.concatenate([r.scores[v][:, :shots] for v in variants])
            curves[r.label] = (curve_with_ci(pooled), len(pooled))
            plateaus = np.array([converged(r.scores[v], plateau_shots)[0] for v in variants])
            cells += [_ci(*curves[r.label][0][0]), _ci(*iqm_with_ci(plateaus))]
        plot_curves(curves, f"{domain}: normalized score vs shot", figures / f"domain-{_slug(domain)}.png")
        lines.append(f"| {domain} | " + " | ".join(cells) + " |")
    lines.append("")
    for domain in domains:
        lines.append(f"![{domain}](figures/domain-{_slug(domain)}.png)")

    lines += ["\n## Per task\n", f"| task ({table}-normalized) | label | runs | shot 1 | converged | from shot | "
              "paper's Vintix |",
              "|---|---|---|---|---|---|---|"]
    bars = []
    for variant in sorted({v for r in results for v in r.scores}):
        curves = {}
        for r in results:
            if variant not in r.scores:
                continue
            scores = r.scores[variant]
            curves[r.label] = (curve_with_ci(scores), len(scores))
            value, start = converged(scores, plateau_shots)
            spec = get_task(r.tasks[variant])
            paper = spec.paper_vintix_normalized.mean if table == "paper" and "[" not in variant else None
            bars.append((variant, r.label, float(scores[:, 0].mean()), value, paper))
            lines.append(f"| {variant} | {r.label} | {len(scores)} | {_ci(*curves[r.label][0][0])} | {value:.2f} | "
                         f"{start} | {'—' if paper is None else f'{paper:.2f}'} |")
        plot_curves(curves, variant, figures / "tasks" / f"{_slug(variant)}.png")
    plot_first_vs_converged(bars, plateau_shots, figures / "first-vs-converged.png")
    lines += ["\n![first shot vs converged](figures/first-vs-converged.png)\n", "### Curves per task\n"]
    lines += [f"![{v}](figures/tasks/{_slug(v)}.png)" for v in sorted({v for r in results for v in r.scores})]
    if notes:
        lines += ["\n## Notes\n"] + [f"- {n}" for n in notes]
    path = out / "report.md"
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path, notes
