"""The `vintix` command line: a thin layer over the package's stages."""

from __future__ import annotations

import csv
import dataclasses
import errno
import importlib.util
import io
import json
import os
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import click
import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from tqdm import tqdm
from typer.core import TyperGroup

from vintix.atomic import atomic_write_text, byte_size, check_output_path
from vintix.errors import VintixError, json_loads, printable
from vintix.evaluate.config import (
    ML1_ADAPTATION_SHOTS,
    ML1_SCORED_SHOTS,
    ML1_SHOTS,
    PLATEAU_SHOTS,
    EvalConfig,
)
from vintix.fields import MAX_THREADS, capped_threads, field_help
from vintix.tasks import ReferenceScore, TaskSpec, find_task, list_tasks, resolve_tasks

if TYPE_CHECKING:  # the CLI imports heavy modules inside its commands, so that --help stays fast
    from vintix.collect import CollectionPlan, HistorySummary


def _refuse_repeated_options(group: Any, args: list[str]) -> None:
    """A usage error where `args` give one of their command's single-valued options twice (click keeps the last
    without a word: `--reward-input zero ... --reward-input true` would run with true rewards)."""
    command, rest = group, list(args)
    while hasattr(command, "commands"):  # a group: its options, then a command's name
        index = next((i for i, arg in enumerate(rest) if arg in command.commands), None)
        if index is None:
            return
        command, rest = command.commands[rest[index]], rest[index + 1:]
    rest = rest[: rest.index("--")] if "--" in rest else rest
    for param in command.params:
        if getattr(param, "multiple", True) or not getattr(param, "opts", None):
            continue  # an argument, or an option given once per value (--tasks-file, --set)
        names = [*param.opts, *param.secondary_opts]
        given = [arg if arg not in names or getattr(param, "is_flag", False) or i + 1 == len(rest)
                 else f"{arg} {rest[i + 1]}" for i, arg in enumerate(rest)
                 if arg in names or any(arg.startswith(f"{n}=") for n in names if n[:2] == "--")]
        if len(given) > 1:
            raise VintixError(f"{param.opts[0]} is given {len(given)} times ({', '.join(given)}); it takes one value: "
                              "give it once")


class _Commands(TyperGroup):
    """A safety net under every command's own error handling: a VintixError raised anywhere in a
    command (or a file-system error, whose message names its path) ends as ``error: ...`` and exit
    code 2, never as a traceback. Before any command runs, an option it takes once given twice is refused."""

    def parse_args(self, ctx: typer.Context, args: list[str]) -> list[str]:  # type: ignore[override]
        try:
            _refuse_repeated_options(self, args)
        except VintixError as error:
            raise _fail(error) from None
        return super().parse_args(ctx, args)

    # TyperGroup declares the context as the click Context typer vendors (typer._click, not exported);
    # typer hands its own subclass, typer.Context.
    def invoke(self, ctx: typer.Context) -> object:  # type: ignore[override]
        try:
            return super().invoke(ctx)
        except (VintixError, OSError) as error:
            raise _fail(error, ctx.invoked_subcommand) from None
        except KeyboardInterrupt as interrupt:  # Ctrl-C, or `kill` during a command that takes it as one
            # An `Interrupted` says what its command saved; a bare KeyboardInterrupt, what every command keeps.
            console.print(str(interrupt) or "interrupted: files finished before are kept, and collect and train "
                          "resume from them when re-run")
            raise typer.Exit(code=130) from None


app = typer.Typer(help="Vintix: in-context RL by Algorithm Distillation, end to end.", no_args_is_help=True,
                  cls=_Commands)
data_app = typer.Typer(
    help="Inspect learning-history datasets (ours or the published one; format: docs/data-format.md).",
    no_args_is_help=True)
app.add_typer(data_app, name="data")
demonstrator_app = typer.Typer(help="Train and score the experts that learning histories are distilled from.",
                               no_args_is_help=True)
app.add_typer(demonstrator_app, name="demonstrator")
bench_app = typer.Typer(help="Speed benchmarks (not tests): training and inference throughput.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")
# The backslash keeps typer's rich help from reading "[cluster]" as markup and dropping it.
_RAY_HELP = ("spread the work over a Ray cluster: 'auto' (the running one, else a local instance) or its address, "
             "e.g. host:6379 or ray://host:10001; needs pip install 'vintix\\[cluster]'")
CONFIG_MODULES = {"EvalConfig": "vintix.evaluate.config", "TrainConfig": "vintix.train.config",
                  "CollectionPlan": "vintix.collect.collector", "NoiseSchedule": "vintix.collect.noise"}
"""The settings dataclasses whose fields are also command-line options, and where each is defined."""


def _doc(config: str, field: str) -> str:
    """The help of the option for `field` of the dataclass `config`: that field's docstring, written once."""
    return field_help(CONFIG_MODULES[config], config, field)


ThreadsOption = Annotated[int | None, typer.Option(
    min=1, max=MAX_THREADS, help="torch CPU threads of this process (default: torch's, one per core; 1 leaves the "
    "other cores to other work)")]
"""`--threads` of the commands whose work is torch's (a trained demonstrator's policy) beside the simulator's."""


def _use_threads(threads: int | None) -> None:
    if threads is not None:
        import torch

        torch.set_num_threads(capped_threads(threads, _note))


def _note(text: str) -> None:
    console.print(f"[yellow]note:[/yellow] {escape(printable(text))}", highlight=False)


def _shown(text: object) -> str:
    """Text a file supplied (a task name, a dataset's problem) as the console prints it: control characters and line
    breaks escaped (`printable`), and no rich markup taken from it (``[bold]`` stays text)."""
    return escape(printable(str(text), breaks=False))


# Piped or logged output gets room for the wide tables instead of rich's default 80 columns, and its lines of
# text are never hard-wrapped: an error naming a long path stays one line that a log or a grep sees whole.
_ON_TERMINAL = sys.stdout.isatty()
console = Console(width=None if _ON_TERMINAL else 160, soft_wrap=not _ON_TERMINAL)


_RESUMING_COMMANDS = ("collect", "train")
"""The commands that, re-run, go on from the files a stopped run kept (a full disk's advice says so for them only)."""
_OS_ERROR_FIXES = {
    errno.ENOSPC: "the disk is full: free space or write elsewhere (--out)",
    errno.EDQUOT: "the disk quota is used up: free space or write elsewhere (--out)",
    errno.EROFS: "the file system is read-only: write elsewhere (--out)",
    errno.EACCES: "no permission: write elsewhere (--out) or fix the folder's permissions",
    errno.EPERM: "not permitted: write elsewhere (--out) or fix the folder's permissions",
}


def _fail(error: Exception, command: str | None = None) -> typer.Exit:
    """Print `error` as one line with its fix; `command`: the vintix command it ended, where its context is gone (an
    error that reached the group), else the current context's."""
    message = str(error)
    if isinstance(error, OSError) and not isinstance(error, VintixError) and error.errno in _OS_ERROR_FIXES:
        if error.filename is not None and str(error.filename) not in message:  # name the file it could not write
            message += f": {error.filename}"
        message += f"; {_OS_ERROR_FIXES[error.errno]}"
        if command is None and (context := click.get_current_context(silent=True)) is not None:
            command = context.info_name
        if error.errno in (errno.ENOSPC, errno.EDQUOT) and command in _RESUMING_COMMANDS:
            message += f"; the finished files are kept, and the same `vintix {command}` resumes from them"
    # escape: a message quoting "list[str]" or "[reach-v3]" would otherwise lose it as rich markup; printable: text
    # that a file supplied (a task name, a lock's holder) must not send escape codes to the terminal.
    console.print(f"[red]error:[/red] {escape(printable(message))}")
    return typer.Exit(code=2)


def _print_version(value: bool) -> None:
    """`vintix --version`: the installed package's version (its metadata), then exit."""
    if not value:
        return
    from importlib.metadata import PackageNotFoundError, version

    try:
        installed = version("vintix")
    except PackageNotFoundError:  # imported from a source tree that was never installed
        from vintix import __version__ as installed
    typer.echo(f"vintix {installed}")
    raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[bool | None, typer.Option("--version", callback=_print_version, is_eager=True,
                                                    help="print the installed vintix version and exit")] = None,
    tasks_file: Annotated[list[Path] | None, typer.Option(
        help="a YAML file of your own tasks to register before the command (repeatable; the environment "
             "variable VINTIX_TASKS does the same for every process): docs/tasks.md#your-own-environment")] = None,
    trust_code: Annotated[bool, typer.Option(
        "--trust-code", help="run the code (env factories, module:EnvId ids) that a checkpoint's or dataset's custom "
                             "task specs name; without it only tasks you registered yourself run code "
                             "(VINTIX_TRUST_CODE=1 does the same): docs/tasks.md#trust")] = False,
) -> None:
    from vintix.tasks.custom import TRUST_VARIABLE, register_tasks_file

    if trust_code:  # in the environment, so that Ray workers and forked collectors trust it too
        os.environ[TRUST_VARIABLE] = "1"

    # Simulator warnings that say nothing to a user of the CLI, once for every command (and the worker
    # processes it forks): metaworld's scripted policies warn on every batch that the env clips their
    # actions to [-1, 1], which it does by design.
    warnings.filterwarnings("ignore", message=r"Constant\(s\) may be too high", category=UserWarning)
    try:
        for path in tasks_file or []:
            register_tasks_file(path)
    except VintixError as error:
        raise _fail(error) from None


def _shipped_recipes() -> list[str]:
    """The shipped recipes' names, found without importing vintix.collect (seconds of imports that
    `vintix --help` should not pay); `vintix.collect.recipe.shipped_recipes` is the same list."""
    spec = importlib.util.find_spec("vintix.collect")
    folder = Path(next(iter(spec.submodule_search_locations or []))) / "recipes" if spec else None
    return sorted(p.stem for p in folder.glob("*.yaml")) if folder and folder.is_dir() else []


def _runnable_tasks(selectors: list[str]) -> list[TaskSpec]:
    """The selected tasks that have a simulator here (Bi-DexHands tasks need IsaacGym); none is an error,
    not an empty table."""
    specs = resolve_tasks(selectors)
    runnable = [t for t in specs if t.domain != "bidexhands"]
    if not runnable:
        raise VintixError(f"none of {', '.join(t.name for t in specs)} can run here: Bi-DexHands tasks need NVIDIA "
                          "IsaacGym, which no package registry serves; choose MuJoCo, Meta-World or Industrial "
                          "Benchmark tasks")
    return runnable


def _score(mean: float, std: float | None) -> str:
    return f"{mean:.1f}±{std:.1f}" if std is not None else f"{mean:.1f}"


def _paper_score(score: ReferenceScore | None) -> str:
    """A published score, or a dash for a task that is not the paper's."""
    return "—" if score is None else _score(score.mean, score.std)


@app.command()
def tasks(
    domain: Annotated[str | None, typer.Option(help="mujoco, metaworld, industrial_benchmark, bidexhands, toy, icrl "
                                                    "(the discrete benchmarks) or custom")] = None,
    split: Annotated[str | None, typer.Option(help="train or test")] = None,
    group: Annotated[str | None, typer.Option(help="encoder/head group, e.g. metaworld")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="a JSON list of the tasks, one object each")] = False,
) -> None:
    """List the task registry (reference scores are the paper's). On a terminal a table that never cuts a name;
    piped, plain tab-separated text, one task a line under a header, for grep and cut."""
    try:
        selected = list_tasks(domain=domain, split=split, group=group)
    except VintixError as error:
        raise _fail(error) from None
    columns = ("task", "domain", "group", "obs", "act", "episode", "reward_scale", "split", "random", "expert")
    rows = [(t.name, t.domain, t.group, str(t.obs_dim), f"{t.act_dim} discrete" if t.discrete else str(t.act_dim),
             str(t.episode_length), f"{t.reward_scale:g}", t.split, _paper_score(t.paper_random),
             _paper_score(t.paper_expert)) for t in selected]
    if as_json:
        typer.echo(json.dumps([dict(zip(columns, row, strict=True)) for row in rows], indent=1))
    elif not _ON_TERMINAL:
        typer.echo("\n".join("\t".join(row) for row in [columns, *rows]))
    else:
        table = Table(title=f"{len(selected)} tasks (random/expert: paper's published scores)")
        for column in columns:
            # The name never folds or cuts (a narrow terminal folds the other columns instead).
            table.add_column(column, justify="right" if column in ("obs", "act", "episode", "reward_scale") else "left",
                             no_wrap=column == "task", min_width=max(len(r[0]) for r in rows) if column == "task" else
                             None, overflow="fold")
        for row in rows:
            table.add_row(*row)
        console.print(table)


DEFAULT_CHECK_TASKS = ["Hopper-v5", "HalfCheetah-v5", "Reacher-v5", "pick-place-v3", "door-open-v3",
                       "industrial-benchmark-35-v1", "industrial-benchmark-90-v1"]


@app.command("check-envs")
def check_envs(
    task_names: Annotated[list[str] | None, typer.Argument(
        metavar="[TASKS]...",
        help="task names, domains or splits (default: a few tasks of each runnable domain)")] = None,
    episodes: Annotated[int, typer.Option(min=1, help="random-policy episodes per task")] = 10,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    out: Annotated[Path | None, typer.Option(help="also write the results to this CSV file")] = None,
) -> None:
    """Run a uniform-random policy on real envs; compare its return with the paper's and time the env."""
    from vintix.tasks.check import random_policy_returns

    try:
        specs = _runnable_tasks(task_names or DEFAULT_CHECK_TASKS)
        if out is not None:
            check_output_path(out)  # before the rollouts, not after them
    except VintixError as error:
        raise _fail(error) from None
    results = [random_policy_returns(t.name, episodes, seed) for t in tqdm(specs, desc="random rollouts", disable=None)]
    table = Table(title=f"uniform-random policy, {episodes} episodes, seed {seed}")
    for column in ("task", "ours", "paper", "z", "env steps/s"):
        table.add_column(column, justify="left" if column == "task" else "right")
    for result, spec in zip(results, specs, strict=True):
        z = result.paper_z
        table.add_row(spec.name, _score(result.mean, result.std), _paper_score(spec.paper_random),
                      "—" if z is None else f"{z:+.2f}", f"{result.steps_per_second:,.0f}")
    console.print(table)
    if out is not None:
        buffer = io.StringIO()
        writer = csv.writer(buffer)
        writer.writerow(["task", "episodes", "seed", "mean", "std", "paper_mean", "paper_std", "z", "steps_per_second"])
        for result, spec in zip(results, specs, strict=True):
            paper = spec.paper_random  # None for a task that is not the paper's (the toy)
            writer.writerow([spec.name, episodes, seed, f"{result.mean:.3f}", f"{result.std:.3f}",
                             "" if paper is None else paper.mean,
                             "" if paper is None or paper.std is None else paper.std,
                             "" if result.paper_z is None else f"{result.paper_z:.3f}",
                             f"{result.steps_per_second:.0f}"])
        atomic_write_text(out, buffer.getvalue())
        console.print(f"wrote {out}")


@app.command()
def collect(
    out: Annotated[Path | None, typer.Option(help="dataset root to write <domain>/<task>/history-NNNN.h5 under "
                                                "(not needed with --plan)")] = None,
    task: Annotated[str | None, typer.Option(help="one task (or use --recipe)")] = None,
    recipe: Annotated[str | None, typer.Option(
        help=f"a recipe YAML file, or a shipped one: {', '.join(_shipped_recipes())}")] = None,
    histories: Annotated[int, typer.Option(help=_doc("CollectionPlan", "histories"))] = 1,
    steps: Annotated[int, typer.Option(help=_doc("CollectionPlan", "steps"))] = 10_000,
    curvature: Annotated[float, typer.Option(help=_doc("NoiseSchedule", "curvature"))] = 1.0,
    noise_free_fraction: Annotated[float | None, typer.Option(help=_doc("NoiseSchedule", "noise_free_fraction"))
                                   ] = None,
    pilot_steps: Annotated[int, typer.Option(help=_doc("NoiseSchedule", "pilot_steps"))] = 0,
    envs_per_batch: Annotated[int, typer.Option(help=_doc("CollectionPlan", "envs_per_batch"))] = 16,
    seed: Annotated[int, typer.Option(help=_doc("CollectionPlan", "seed"))] = 0,
    workers: Annotated[int, typer.Option(help="processes (one per core)")] = 1,
    ray: Annotated[str | None, typer.Option(help=_RAY_HELP)] = None,
    plan: Annotated[bool, typer.Option("--plan", help="print what would be collected, its size on disk and the wall "
                                       "time estimated from measured rates (for --workers), then stop")] = False,
    rates: Annotated[Path | None, typer.Option(help="rates table for --plan (default: the package's, measured by "
                                                  "`vintix bench collect`)")] = None,
    rollouts_of: Annotated[str | None, typer.Option(
        help="the model (checkpoint, run folder or shipped name) plays the histories, sampled and without noise, and "
             "each row records the goal-aware expert's action as its target: DPT's DAgger round "
             "(vintix.agent.rollouts)")] = None,
    first_history: Annotated[int | None, typer.Option(help=_doc("CollectionPlan", "first_history"))] = None,
    threads: ThreadsOption = None,
    print_config: Annotated[bool, typer.Option(
        "--print-config", help="print the recipe with its base: resolved (the whole it collects), then stop")] = False,
) -> None:
    """Collect noise-distilled learning histories (paper Algorithm 1). Re-running finishes only what is missing."""
    _use_threads(threads)
    import time

    from vintix.collect import CollectionPlan, NoiseSchedule, check_demonstrators
    from vintix.collect import collect as collect_histories
    from vintix.collect.recipe import load_recipe, resolved_recipe

    try:
        if print_config:
            if recipe is None:
                raise VintixError("--print-config shows a recipe: give --recipe")
            return _print_yaml(resolved_recipe(recipe))
        if recipe is not None and task is None:
            plans = load_recipe(recipe)
        elif task is not None and recipe is None:
            schedule = (NoiseSchedule(curvature, pilot_steps=pilot_steps) if noise_free_fraction is None
                        else NoiseSchedule(curvature, noise_free_fraction, pilot_steps=pilot_steps))
            plans = [CollectionPlan(task, histories, steps, schedule, seed, envs_per_batch)]
        else:
            raise VintixError("give exactly one of --task or --recipe")
        if first_history is not None:
            plans = [dataclasses.replace(p, first_history=first_history) for p in plans]
        if rollouts_of is not None:
            return _collect_rollouts(rollouts_of, plans, out, workers)
        if plan:
            untrained = check_demonstrators(plans, untrained_ok=True)  # what collect would refuse, --plan refuses too
            _print_collection_plan(plans, workers, rates)
            for note in untrained:
                console.print(f"[yellow]note:[/yellow] collect needs it first: {note}", highlight=False)
            return
        if out is None:
            raise VintixError("give --out, the dataset root to collect into (or --plan to only see the plan)")
        start = time.perf_counter()
        summaries = collect_histories(plans, out, workers=workers, ray=ray)
    except (VintixError, ValueError, FileNotFoundError, NotImplementedError) as error:
        raise _fail(error) from None
    seconds = time.perf_counter() - start
    console.print(_collection_summary(summaries))
    new = sum(s.steps for s in summaries if s.collected_now)
    speed = f", {new / seconds:,.0f} steps/s" if new else ""
    console.print(f"wrote {len(summaries)} histories ({sum(s.steps for s in summaries):,} steps) under {out}; "
                  f"this run collected {new:,} steps in {seconds:.1f} s{speed}")


def _collect_rollouts(checkpoint: str, plans: list[CollectionPlan], out: Path | None, workers: int) -> None:
    """`vintix collect --rollouts-of`: each plan's histories played by the model, noise-free, the expert's actions
    recorded as targets (`vintix.agent.rollouts.ModelRollouts`)."""
    from vintix.agent.rollouts import ModelRollouts
    from vintix.collect import NoiseSchedule
    from vintix.collect import collect as collect_histories

    if out is None:
        raise _fail(VintixError("give --out, the dataset root the rollouts join"))
    summaries = []
    try:
        for plan in plans:
            player = ModelRollouts(checkpoint, plan.task, expert=plan.demonstrator)
            # No noise: the model's context must hold the actions it took.
            played = dataclasses.replace(plan, behaviour="expert", schedule=NoiseSchedule(noise_free_fraction=1.0),
                             demonstrator=player.source)
            summaries += collect_histories(played, out, workers=workers, demonstrator=player)
    except (VintixError, ValueError, FileNotFoundError) as error:
        raise _fail(error) from None
    console.print(_collection_summary(summaries))
    console.print(f"wrote {len(summaries)} rollouts of {checkpoint} ({sum(s.steps for s in summaries):,} steps) under "
                  f"{out}, histories {plans[0].indices.start}-{plans[0].indices.stop - 1} of each task")


def _collection_summary(summaries: list[HistorySummary]) -> Table:
    """Per task: its histories, and the mean return of each history's first and last 10 % of complete episodes
    (an episode the history's end cut short would pull its last 10 % down), averaged over the histories."""
    import numpy as np

    table = Table(title="learning histories per task: mean return of the first vs the last 10 % of each history's "
                        "complete episodes, over its histories")
    for column in ("task", "histories", "steps", "complete episodes", "first 10%", "last 10%"):
        table.add_column(column, justify="left" if column == "task" else "right", no_wrap=column == "task")
    for task in dict.fromkeys(s.task for s in summaries):
        mine = [s for s in summaries if s.task == task]
        first, last = (np.nanmean([s.mean_return(first=f) for s in mine]) for f in (True, False))
        table.add_row(task, f"{len(mine):,}", f"{sum(s.steps for s in mine):,}",
                      f"{sum(len(s.episode_returns) for s in mine):,}", f"{first:.1f}", f"{last:.1f}")
    return table


def _print_collection_plan(plans: list[CollectionPlan], workers: int, rates_file: Path | None) -> None:
    """The `--plan` table: per task what would be collected and what it costs; totals and wall time."""
    from vintix.collect.bench import read_rates
    from vintix.collect.estimate import estimate_plans, wall_seconds

    estimates = estimate_plans(plans, read_rates(rates_file))
    table = Table(title=f"collection plan: {len(estimates)} tasks")
    for column in ("task", "histories", "steps each", "steps", "batches", "disk", "steps/s", "core-hours"):
        table.add_column(column, justify="left" if column == "task" else "right")
    for e in estimates:
        table.add_row(e.task, str(e.histories), f"{e.steps_per_history:,}", f"{e.steps:,}", str(len(e.batches)),
                      byte_size(e.bytes), ("" if e.measured else "≈") + f"{e.steps_per_s:,.0f}",
                      f"{sum(e.batch_seconds) / 3600:.2f}")
    console.print(table)
    steps = sum(e.steps for e in estimates)
    core_hours = sum(sum(e.batch_seconds) for e in estimates) / 3600
    pilots = sum(e.histories * e.pilot_steps for e in estimates)
    steps_line = f"{steps:,} steps" + (f" (+ {pilots:,} pilot steps, not stored)" if pilots else "")
    console.print(f"total: {len(estimates)} tasks, {sum(e.histories for e in estimates):,} histories, {steps_line}, "
                  f"{byte_size(sum(e.bytes for e in estimates))} on disk, {core_hours:.1f} core-hours; with --workers "
                  f"{workers}: about {wall_seconds(estimates, workers) / 3600:.1f} h wall time")
    estimated = [e.task for e in estimates if not e.measured]
    if estimated:
        console.print(f"≈: no demonstrator yet, so the rate is the raw env rate times the median collector/raw ratio: "
                      f"{', '.join(estimated)}; train them first (`vintix demonstrator train --task TASK`)")


@demonstrator_app.command("train")
def demonstrator_train(
    task: Annotated[str, typer.Option(help="a task of the group to train for (one policy per encoder group)")],
    timesteps: Annotated[int | None, typer.Option(min=1, help="env steps (default: the group's recipe)")] = None,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    out: Annotated[Path | None, typer.Option(
        help="folder for the weights (default: ~/.cache/vintix/demonstrators)")] = None,
    update_package_weights: Annotated[bool, typer.Option(
        "--update-package-weights", help="write the weights into the package instead, replacing the shipped "
        "demonstrator of the group that every collection uses")] = False,
    threads: ThreadsOption = None,
) -> None:
    """Train a MuJoCo or Industrial Benchmark demonstrator with Stable-Baselines3 and save its weights."""
    _use_threads(threads)
    from stable_baselines3.common.callbacks import BaseCallback

    from vintix.demonstrators.trained import shipped_weights_dir
    from vintix.demonstrators.training import recipe_for, train_demonstrator

    class SayWhereItStarts(BaseCallback):
        def _on_training_start(self) -> None:
            if self.model.num_timesteps:
                console.print(f"resuming a saved run at step {self.model.num_timesteps:,}")

        def _on_step(self) -> bool:
            return True

    try:
        recipe = recipe_for(task)
        until = ("" if recipe.stop_at_score is None
                 else f", or until it scores {recipe.stop_at_score} of the paper's expert")
        console.print(f"training {recipe.algorithm} for {timesteps or recipe.timesteps:,} steps on {task}{until}")
        if update_package_weights and out is not None:
            raise VintixError("give --out or --update-package-weights, not both")
        target = shipped_weights_dir() if update_package_weights else out
        path = train_demonstrator(task, timesteps, seed, target, callback=SayWhereItStarts(), report=console.print)
    except VintixError as error:
        raise _fail(error) from None
    meta = json_loads(path.with_suffix(".json").read_text())
    if stopped := meta.get("stopped_at_score"):
        console.print(f"stopped at step {stopped['step']:,} of {stopped['budget']:,}: normalized score "
                      f"{stopped['normalized_score']} ≥ {stopped['target']}")
    if short := meta.get("short_of_target"):
        kept = (f": the run stays saved under {short['state']}; a larger --timesteps goes on from there"
                if "state" in short else "")
        console.print(f"[yellow]the budget of {short['budget']:,} steps ended below the target score "
                      f"{short['target']}[/]{kept}")
    shipped = path.parent == shipped_weights_dir()
    use = "" if shipped else (f"; collect with it through a recipe's `demonstrator: weights:{path.parent}`, ship it "
                              "with --update-package-weights")
    console.print(f"wrote {path} and {path.with_suffix('.json')}; score it with `vintix demonstrator eval --task "
                  f"{task}{'' if shipped else f' --weights {path.parent}'}`{use}", highlight=False)


@demonstrator_app.command("eval")
def demonstrator_eval(
    task: Annotated[list[str], typer.Option(help="task, domain or split; repeat for several")],
    episodes: Annotated[int, typer.Option(min=1, help="episodes per policy, each in its own env (seed + i)")] = 20,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    out: Annotated[Path, typer.Option(help="score table to add the measured rows to (created if missing)")] = Path(
        "demonstrator-scores.csv"),
    update_package_table: Annotated[bool, typer.Option(
        "--update-package-table", help="also rewrite the package's reference table (demonstrators/scores.csv), "
        "which normalizes every 'ours' result")] = False,
    weights: Annotated[Path | None, typer.Option(
        help="score the trained weights in this folder instead of the shipped ones (e.g. a run's best check, "
        "`vintix demonstrator runs`)")] = None,
    threads: ThreadsOption = None,
) -> None:
    """Score demonstrators and a uniform-random policy; record both in a score table (--out)."""
    _use_threads(threads)
    from vintix.demonstrators import load_demonstrator
    from vintix.demonstrators.scores import UniformRandomPolicy, measure
    from vintix.tasks.scores import read_scores, record_scores, reference, scores_path

    if weights is not None and update_package_table:
        raise _fail(VintixError(f"--update-package-table records the shipped demonstrators, not those in {weights}: "
                                "copy its files into the package's weights folder first, then score without --weights"))
    try:
        specs = _runnable_tasks(task)
        demonstrators = [load_demonstrator(spec.name, weights) for spec in specs]
        check_output_path(out)
        read_scores(out)  # a file already there must be a score table: said before any episode is played
    except VintixError as error:
        raise _fail(error) from None
    command = f"vintix demonstrator eval --task {{task}} --episodes {episodes} --seed {seed}"
    command += f" --weights {weights}" if weights else ""
    rows = []
    for spec, demonstrator in tqdm(list(zip(specs, demonstrators, strict=True)), desc="scoring", disable=None):
        line = command.format(task=spec.name)
        rows += [measure(spec.name, "demonstrator", demonstrator, episodes, seed, line),
                 measure(spec.name, "random", UniformRandomPolicy(), episodes, seed, line)]
    result = Table(title=f"{episodes} episodes per policy, seed {seed}; normalized by the paper's random/expert")
    for column in ("task", "demonstrator", "random", "paper expert", "paper random", "normalized"):
        result.add_column(column, justify="left" if column == "task" else "right")
    for spec, (ours, random) in zip(specs, zip(rows[::2], rows[1::2], strict=True), strict=True):
        paper = reference(spec.name, "paper")
        result.add_row(spec.name, _score(ours.mean, ours.std), _score(random.mean, random.std),
                       _paper_score(spec.paper_expert), _paper_score(spec.paper_random),
                       "—" if paper is None else f"{float(paper.normalize(ours.mean)):.2f}")
    console.print(result)
    console.print(f"wrote {len(rows)} scores to {record_scores(rows, out)}")
    if update_package_table:
        console.print(f"updated the package's reference table {record_scores(rows, scores_path())}")


@demonstrator_app.command("goal-blind")
def demonstrator_goal_blind(
    task: Annotated[list[str], typer.Option(
        help="task or domain (metaworld, toy) or Reacher-hidden-v5; repeat for several")],
    seeds: Annotated[int, typer.Option(
        min=1, help="episodes per policy, env seeds first-seed, first-seed + 1, ...")] = 20,
    first_seed: Annotated[int, typer.Option(min=0)] = 100,
    out: Annotated[Path, typer.Option(help="table to add the measured rows to (created if missing)")] = Path(
        "goal-blind.csv"),
    update_package_table: Annotated[bool, typer.Option(
        "--update-package-table", help="also rewrite the package's table (demonstrators/goal_blind.csv)")] = False,
    demonstrator: Annotated[str | None, typer.Option(
        metavar="MODULE:CALLABLE", help="your own goal-conditioned expert (called with the task name; it must have "
        "act_toward(observations, goals)), for a task of your own; default: the package's scripted expert")] = None,
    weights: Annotated[Path | None, typer.Option(
        help="a folder of trained goal-aware experts (the meta-RL tasks'), from `vintix demonstrator train`")] = None,
    blind_aim: Annotated[str, typer.Option(
        help="what the goal-blind expert aims at: mean (the mean goal) or best (the best constant goal, for tasks "
        "whose mean goal is no goal, as a direction task's)")] = "mean",
) -> None:
    """Which tasks hide information: the expert's success and return aimed at the true goal vs blind (the mean goal,
    or the best constant one), beside a random policy's return."""
    from vintix.demonstrators.goal_blind import goal_blind_baseline, goal_blind_path, write_goal_blind

    try:
        specs = resolve_tasks(task)
        command = f"vintix demonstrator goal-blind --task {{task}} --seeds {seeds} --first-seed {first_seed}"
        command += f" --demonstrator {demonstrator}" if demonstrator else ""
        command += f" --weights {weights}" if weights else ""
        command += f" --blind-aim {blind_aim}" if blind_aim != "mean" else ""
        results = [goal_blind_baseline(spec.name, seeds, first_seed, command.format(task=spec.name), demonstrator,
                                       weights, blind_aim)
                   for spec in tqdm(specs, desc="goal-blind baselines", disable=None)]
    except (VintixError, ValueError) as error:
        raise _fail(error) from None
    table = Table(title=f"success over {seeds} episodes (env seeds {first_seed}..{first_seed + seeds - 1})")
    for column in ("task", "true goal", "goal-blind", "hidden information", "return: true goal", "return: goal-blind",
                   "return: random", "hidden return"):
        table.add_column(column, justify="left" if column == "task" else "right")
    for r in sorted(results, key=lambda r: -r.hidden_information):
        table.add_row(r.task, f"{r.true_goal_success:.2f}", f"{r.goal_blind_success:.2f}",
                      f"{r.hidden_information:+.2f}", f"{r.true_goal_return:.1f}", f"{r.goal_blind_return:.1f}",
                      f"{r.random_return:.1f}", f"{r.hidden_return:+.2f}")
    console.print(table)
    console.print(f"wrote {len(results)} rows to {write_goal_blind(results, out)}")
    if update_package_table:
        console.print(f"updated the package's table {write_goal_blind(results, goal_blind_path())}")


@demonstrator_app.command("histories")
def demonstrator_histories(
    task: Annotated[str, typer.Option(help="a hidden-goal task (Meta-World, toy, Reacher-hidden-v5, meta-RL tasks), "
                                      "or your own with --demonstrator")],
    behaviour: Annotated[str, typer.Option(help="how a demonstrator that never sees the goal plays: "
                                           "posterior-sampling, probing or probe-then-sample")] = "probe-then-sample",
    seeds: Annotated[int, typer.Option(min=1, help="histories, env seeds first-seed, first-seed + 1, ...")] = 20,
    first_seed: Annotated[int, typer.Option(min=0)] = 100,
    episodes: Annotated[int, typer.Option(min=1, help="episodes per history")] = 8,
    probe_margin: Annotated[float, typer.Option(help=_doc("CollectionPlan", "probe_margin"))] = 0.0,
    aim: Annotated[str, typer.Option(help=_doc("CollectionPlan", "aim"))] = "hand",
    lapse_probability: Annotated[float, typer.Option(help=_doc("CollectionPlan", "lapse_probability"))] = 0.0,
    reward_tolerance: Annotated[float, typer.Option(min=0.0, help=_doc("CollectionPlan", "reward_tolerance"))] = 0.0,
    demonstrator_source: Annotated[str | None, typer.Option(
        "--demonstrator", metavar="MODULE:CALLABLE", help="your own reward-reading demonstrator (called with the task "
        "name, as a recipe's demonstrator: is), for a task of your own; the behaviour options are then unused")] = None,
    weights: Annotated[Path | None, typer.Option(
        help="a meta-RL task: its goal-aware expert's trained weights in this folder instead of the shipped ones")
        ] = None,
    threads: ThreadsOption = None,
) -> None:
    """How a demonstrator that infers the goal from rewards does alone, episode after episode, without noise."""
    _use_threads(threads)
    import numpy as np

    from vintix.demonstrators import BEHAVIOURS, GoalInferringDemonstrator, load_demonstrator
    from vintix.demonstrators.scores import history_outcomes

    try:
        if demonstrator_source is not None:
            behaviour = demonstrator_source
            demonstrator = load_demonstrator(task, source=demonstrator_source)
        else:
            demonstrator = load_demonstrator(task, weights, behaviour=behaviour, probe_margin=probe_margin, aim=aim,
                                             lapse_probability=lapse_probability, reward_tolerance=reward_tolerance)
        if not isinstance(demonstrator, GoalInferringDemonstrator):
            inferring = ", ".join(b for b in BEHAVIOURS if b != "expert")
            raise VintixError(f"{behaviour}: a demonstrator that does not read its rewards (it has no begin, observe "
                              f"and expert_act: docs/demonstrators.md) does not learn within a history; choose a "
                              f"behaviour among {inferring} (`vintix demonstrator eval` scores the expert)")
        outcomes = history_outcomes(task, demonstrator, range(first_seed, first_seed + seeds), episodes)
    except (VintixError, ValueError) as error:
        raise _fail(error) from None
    settings = f", probe margin {probe_margin}" if probe_margin else ""
    settings += f", aiming the {aim}" if aim != "hand" else ""
    settings += f", lapses at {lapse_probability}" if lapse_probability else ""
    settings += f", reward tolerance {reward_tolerance}" if reward_tolerance else ""
    table = Table(title=f"{task}, {behaviour}{settings}: {seeds} histories "
                        f"(env seeds {first_seed}..{first_seed + seeds - 1})")
    for column in ("episode", "success", "mean return", "median end distance to goal"):
        table.add_column(column, justify="right")
    for episode in range(episodes):
        distances = outcomes.end_distance[:, episode]
        distance = "–" if np.isnan(distances).all() else f"{np.median(distances):.3f}"
        table.add_row(str(episode + 1), f"{outcomes.success[:, episode].mean():.2f}",
                      f"{outcomes.returns[:, episode].mean():.1f}", distance)
    console.print(table)


@demonstrator_app.command("list")
def demonstrator_list() -> None:
    """Which tasks have a demonstrator, how it was made, and its recorded score."""
    from vintix.demonstrators.base import expert_name
    from vintix.demonstrators.trained import weights_paths
    from vintix.tasks.scores import read_scores

    scores = {(s.task, s.policy): s for s in read_scores()}
    result = Table(title="demonstrators (score: ours, recorded by `vintix demonstrator eval`)")
    for column in ("task", "kind", "training", "score", "paper expert"):
        result.add_column(column, justify="left" if column in ("task", "kind", "training") else "right")
    for spec in list_tasks():
        if spec.domain == "bidexhands":
            continue
        kind, training = "scripted (metaworld.policies)", ""
        if spec.domain != "metaworld":
            _, meta_path = weights_paths(expert_name(spec))
            if meta_path.is_file():
                meta = json_loads(meta_path.read_text())
                kind = f"{meta['algorithm']} (shipped)"
                training = f"{meta['timesteps']:,} steps, {meta['train_seconds'] / 60:.0f} min"
            else:
                kind = "none: `vintix demonstrator train`"
        ours = scores.get((spec.name, "demonstrator"))
        result.add_row(spec.name, kind, training, "—" if ours is None else _score(ours.mean, ours.std),
                       _paper_score(spec.paper_expert))
    console.print(result)


def _check(check: dict[str, Any]) -> str:
    """A score check of a demonstrator training run, as one phrase."""
    return f"step {check['step']:,}: {_score(check['mean'], check['std'])}, normalized {check['normalized']:.3f}"


@demonstrator_app.command("runs")
def demonstrator_runs(
    episodes: Annotated[int, typer.Option(min=0, help="also play this many deterministic episodes of each run's "
                                          "saved policy (0: none; scored as `demonstrator eval` scores)")] = 0,
) -> None:
    """Unfinished demonstrator trainings saved in the cache: how far each got, how it does, time left."""
    from vintix.demonstrators.trained import expert_task
    from vintix.demonstrators.training import best_check, evaluate_unfinished_run, training_runs_dir, unfinished_runs

    runs = unfinished_runs()
    if not runs:
        console.print(f"no unfinished demonstrator training under {training_runs_dir()}")
        return
    result = Table(title="unfinished demonstrator trainings (resume one with `vintix demonstrator train --task TASK`)")
    columns = ["group", "algorithm", "seed", "steps", "hours trained", "hours left", "recent training return"]
    for column in columns + ([f"deterministic return ({episodes} episodes)"] if episodes else []):
        result.add_column(column, justify="left" if column in ("group", "algorithm") else "right")
    for run in runs:
        recent = "—" if run.recent_return is None else f"{run.recent_return:,.1f}"
        row = [run.group, run.algorithm, str(run.seed), f"{run.steps:,} / {run.budget:,}",
               f"{run.train_seconds / 3600:.1f}", f"{run.seconds_left() / 3600:.1f}", recent]
        if episodes:
            task, returns = evaluate_unfinished_run(run, episodes)
            row.append(f"{task}: {_score(float(returns.mean()), float(returns.std()))}")
        result.add_row(*row)
    console.print(result)
    for run in runs:
        if run.score_checks:
            console.print(f"{run.group} seed {run.seed}, {len(run.score_checks)} score checks: "
                          f"last {_check(run.score_checks[-1])}; best "
                          f"{_check(max(run.score_checks, key=lambda check: check['normalized']))}")
        kept = best_check(run.folder)
        if kept is not None:
            console.print(f"{run.group} seed {run.seed}: the policy of its best check since they were kept "
                          f"({_check(kept[1])}) is in {kept[0]}; score it with `vintix demonstrator eval --task "
                          f"{expert_task(run.group).name} --weights {kept[0]}`")
    console.print(f"saved under {training_runs_dir()}; the recent return is the mean of the last 100 training "
                  "episodes, exploration included (`vintix demonstrator eval` scores a finished one)")


def registry_dims(task_name: str) -> tuple[int, int, bool] | None:
    """(obs_dim, act_dim, discrete) the registry expects for a dataset's task name; None if it is not ours."""
    spec = find_task(task_name)
    return None if spec is None else (spec.obs_dim, spec.act_dim, spec.discrete)


def registry_episode_limit(task_name: str) -> int | None:
    """The most steps an episode of a dataset's task can have; None if the registry does not know the task
    or its episodes end themselves (Bi-DexHands' episode length is a mean)."""
    spec = find_task(task_name)
    return None if spec is None else spec.episode_limit


@data_app.command("validate")
def data_validate(root: Annotated[Path, typer.Argument(help="dataset root: <root>/<domain>/<task>/")]) -> None:
    """Check a dataset's structure, dtypes, dims (vs the task registry), step numbers and values against the
    format specified in docs/data-format.md."""
    from vintix.data import task_dirs, validate_task
    from vintix.errors import DatasetError

    try:
        folders = task_dirs(root)
    except DatasetError as error:
        raise _fail(error) from None
    if not folders:
        raise _fail(DatasetError(root, "no <domain>/<task_dir>/ folders found; point to the dataset root "
                                       "(layout: docs/data-format.md)"))
    problems = [p for folder in tqdm(folders, desc="validating", disable=None)
                for p in validate_task(folder, registry_dims, registry_episode_limit)]
    for problem in problems:
        console.print(f"[red]✗[/red] {_shown(problem)}", highlight=False)
    if problems:
        console.print(f"{len(problems)} problem(s) in {root}; the format is specified in docs/data-format.md")
        raise typer.Exit(code=1)
    console.print(f"[green]✓[/green] {len(folders)} task folder(s) in {root} follow the format")


@data_app.command("stats")
def data_stats(root: Annotated[Path, typer.Argument(help="dataset root: <root>/<domain>/<task>/")]) -> None:
    """Histories, steps and episodes per task, and the mean return of each history's i-th episode."""
    from vintix.data import summarize_dataset
    from vintix.errors import DatasetError
    from vintix.evaluate import shots_to_show

    try:
        summaries = summarize_dataset(root)
    except DatasetError as error:
        raise _fail(error) from None
    table = Table(title=f"dataset {root}")
    for column in ("domain", "task", "histories", "steps", "episodes", "mean episode length"):
        table.add_column(column, justify="left" if column in ("domain", "task") else "right")
    for s in summaries:
        table.add_row(_shown(s.domain), _shown(s.task_name), str(s.histories), f"{s.steps:,}", f"{s.episodes:,}",
                      f"{s.mean_episode_length:.1f}")
    console.print(table)
    # How the histories improve, episode by episode: what a demonstrator's own check looks at first.
    longest = max((len(s.return_by_episode) for s in summaries), default=0)
    shown = shots_to_show(longest)
    returns = Table(title="mean return of each history's i-th episode (over the histories that have one)")
    returns.add_column("task")
    for index in shown:
        returns.add_column(f"ep {index}", justify="right")
    for s in summaries:
        values = s.return_by_episode
        returns.add_row(_shown(s.task_name), *(f"{values[i - 1]:.3g}" if i <= len(values) else "" for i in shown))
    console.print(returns)


OWN_EXPERT_HELP = ("scale each history by its own noise-free episodes instead of the table's expert (fair where "
                   "histories play different variants of a task, e.g. Meta-World's hidden goals)")


@data_app.command("plot")
def data_plot(
    root: Annotated[Path, typer.Argument(help="dataset root: <root>/<domain>/<task>/")],
    out: Annotated[Path, typer.Option(help="folder for the PNG figures")] = Path("figs"),
    bins: Annotated[int, typer.Option(min=1, help="bins along the history")] = 50,
    reference: Annotated[str, typer.Option(
        help="normalize by 'ours' (measured demonstrator/random returns) or 'paper'")] = "ours",
    own_expert: Annotated[bool, typer.Option(help=OWN_EXPERT_HELP)] = False,
) -> None:
    """Paper Figure 3: IQM of normalized episode return along the histories, per task and per domain."""
    from vintix.collect.calibrate import noise_free_return
    from vintix.data.plot import plot_dataset

    try:
        written, skipped = plot_dataset(root, out, bins, reference, noise_free_return if own_expert else None)
    except (VintixError, ValueError) as error:
        raise _fail(error) from None
    if skipped:
        console.print(f"skipped {len(skipped)} task(s) without a '{reference}' reference score: "
                      f"{', '.join(map(_shown, skipped))}")
    scale = (f"'{reference}' random scores and each history's noise-free return" if own_expert
             else f"'{reference}' random/expert scores")
    console.print(f"wrote {len(written)} figures under {out} (normalized by the {scale})")


@data_app.command("export-minari")
def data_export_minari(
    root: Annotated[Path, typer.Argument(help="dataset root: <root>/<domain>/<task>/")],
    dataset_id: Annotated[str, typer.Option(help="Minari dataset id, e.g. vintix/reach-v3/noise-distilled-v0")],
    task: Annotated[str | None, typer.Option(help="the task to export, where the dataset holds several")] = None,
    author: Annotated[str | None, typer.Option(help="for Minari's metadata")] = None,
    author_email: Annotated[str | None, typer.Option(help="for Minari's metadata")] = None,
    code_permalink: Annotated[str | None, typer.Option(help="for Minari's metadata: the code behind the data")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="replace a local Minari dataset of this id")] = False,
) -> None:
    """Write one task's learning histories as a local Minari dataset (one Minari episode per episode)."""
    from vintix.collect.export import export_minari

    try:
        dataset = export_minari(root, dataset_id, task, author=author, author_email=author_email,
                                code_permalink=code_permalink, overwrite=overwrite)
    except (VintixError, ValueError) as error:  # Minari raises ValueError for a bad or taken id
        raise _fail(error) from None
    console.print(f"wrote Minari dataset {dataset_id}: {dataset.total_episodes:,} episodes, {dataset.total_steps:,} "
                  f"steps, under {dataset.storage.data_path.parent}; load it with minari.load_dataset({dataset_id!r})",
                  highlight=False)


@data_app.command("smoothness")
def data_smoothness(
    root: Annotated[Path, typer.Argument(help="dataset root: <root>/<domain>/<task>/")],
    bins: Annotated[int, typer.Option(min=2, help="bins along the history")] = 10,
    reference: Annotated[str, typer.Option(
        help="normalize by 'ours' (measured demonstrator/random returns) or 'paper'")] = "ours",
    own_expert: Annotated[bool, typer.Option(help=OWN_EXPERT_HELP)] = False,
) -> None:
    """Does each task's return rise smoothly from random to demonstrator level?

    The criterion noise schedules are chosen by."""
    from vintix.collect.calibrate import noise_free_return
    from vintix.data.plot import SMOOTH_CORRELATION, SMOOTH_JUMP, SMOOTH_RISE, smoothness

    try:
        results, skipped = smoothness(root, bins, reference, noise_free_return if own_expert else None)
    except (VintixError, ValueError) as error:
        raise _fail(error) from None
    table = Table(title=f"smoothness over {bins} bins of each history (worst history per task; smooth: rank "
                        f"correlation >= {SMOOTH_CORRELATION}, largest jump <= {SMOOTH_JUMP}, last bin - first "
                        f">= {SMOOTH_RISE})")
    for column in ("task", "histories", "rank correlation", "largest jump", "first bin", "last bin", "smooth"):
        table.add_column(column, justify="left" if column == "task" else "right")
    for r in results:
        table.add_row(r.task, str(r.histories), f"{r.rank_correlation:.2f}", f"{r.largest_jump:.2f}", f"{r.start:.2f}",
                      f"{r.end:.2f}", "yes" if r.smooth() else "[red]no[/red]")
    console.print(table)
    if skipped:
        console.print(f"skipped {len(skipped)} task(s) without a '{reference}' reference score: "
                      f"{', '.join(map(_shown, skipped))}")
    console.print(f"{sum(r.smooth() for r in results)} of {len(results)} tasks rise smoothly")


@data_app.command("fit-schedule")
def data_fit_schedule(
    root: Annotated[Path, typer.Argument(help="dataset root collected by `vintix collect` (any schedule)")],
    knots: Annotated[int, typer.Option(min=2, help="knots per schedule (11: one per tenth of the history)")] = 11,
) -> None:
    """Fit each task's noise schedule to its histories so the expected return rises linearly; prints recipe lines."""
    from vintix.collect.calibrate import fit_schedules

    try:
        fitted, skipped = fit_schedules(root, knots)
    except (VintixError, ValueError) as error:
        raise _fail(error) from None
    table = Table(title="noise schedule knots: ε at evenly spaced points of the noised history, placed so the "
                        "expected return rises linearly (fitted to the episodes' returns at their mean ε)")
    for column in ("task", "episodes", "knots"):
        table.add_column(column, justify="left" if column != "episodes" else "right")
    for f in fitted:
        table.add_row(f.task, str(f.episodes), " ".join(f"{k:.3g}" for k in f.knots))
    console.print(table)
    for reason in skipped:
        console.print(f"[red]no knots[/red] for {reason}")
    if fitted:
        console.print("recipe lines (under 'tasks:'; knots replace the curvature):")
        print("\n".join(f"  {f.task}: {{knots: [{', '.join(f'{k:g}' for k in f.knots)}]}}" for f in fitted))


def _print_yaml(settings: dict[str, Any]) -> None:
    """Settings as YAML a recipe or config file could hold (plain print: no rich markup or wrapping)."""
    import yaml

    print(yaml.safe_dump(settings, sort_keys=False, width=120), end="")


@app.command("train")
def train_command(
    config: Annotated[str, typer.Option(
        help="model preset (tiny, small, paper) or a YAML file of TrainConfig fields")] = "tiny",
    data: Annotated[Path | None, typer.Option(help=_doc("TrainConfig", "data"))] = None,
    out: Annotated[Path | None, typer.Option(help=_doc("TrainConfig", "out"))] = None,
    settings: Annotated[list[str] | None, typer.Option(
        "--set", metavar="FIELD=VALUE",
        help="override one TrainConfig field (repeatable), e.g. --set max_steps=500")] = None,
    threads: Annotated[int | None, typer.Option(min=0, max=MAX_THREADS, help=_doc("TrainConfig", "threads"))] = None,
    print_config: Annotated[bool, typer.Option(
        "--print-config", help="print every TrainConfig field as this command would train with it (the config's "
        "base: resolved, then --data, --out and --set), then stop")] = False,
) -> None:
    """Train (or resume) a model by Algorithm Distillation.

    Many GPUs: torchrun --nproc-per-node N -m vintix train ... (same options)."""
    from vintix.agent import resolve_checkpoint
    from vintix.agent.pretrained import shipped_name
    from vintix.evaluate import in_context_scorer
    from vintix.train import load_config, train

    try:
        train_config = load_config(config, {"data": data and str(data), "out": out and str(out),
                                            "threads": threads}, settings)
        if print_config:
            return _print_yaml(dataclasses.asdict(train_config))
        init_name = None
        if train_config.init_from is not None:  # a shipped model's name is the agent stage's to resolve
            source = resolve_checkpoint(train_config.init_from)
            init_name = shipped_name(source)
            train_config = dataclasses.replace(train_config, init_from=str(source))
        train(train_config, scorer=in_context_scorer(train_config), init_name=init_name)
    except VintixError as error:
        raise _fail(error) from None


_OVERWRITE_HELP = ("write into --out even where it holds files (never into the command's own input, nor into another "
                   "kind of output)")
_SNAPSHOT_HELP = ("the authors' release snapshot folder (model.pth, config.json, metadata.json), fetched by you: "
                  "hf download dunnolab/Vintix --local-dir DIR")


@app.command("import-official")
def import_official_command(
    snapshot: Annotated[Path, typer.Argument(help=_SNAPSHOT_HELP)],
    out: Annotated[Path, typer.Option(
        help="folder for our checkpoint (model.safetensors, config.json, README.md)")] = Path("vintix-official"),
    overwrite: Annotated[bool, typer.Option(help=_OVERWRITE_HELP)] = False,
) -> None:
    """Import the authors' released Vintix model as one of our checkpoints (nothing is downloaded)."""
    from vintix.model.official import RELEASE_SHA256, import_official

    try:
        console.print(f"importing {snapshot}: reading and checking its weights", highlight=False)
        result = import_official(snapshot, out, overwrite)
    except (VintixError, OSError) as error:
        raise _fail(error) from None
    if result.known_release:
        console.print(f"model.pth sha256 {result.sha256}: the known release")
    else:
        console.print(f"[yellow]model.pth sha256 {result.sha256} is not the known release[/yellow] ({RELEASE_SHA256}); "
                      "imported because every key and shape matched", highlight=False)
    if result.renamed:
        console.print("release names on our envs: " + ", ".join(f"{a} -> {b}" for a, b in result.renamed.items()),
                      highlight=False)
    if result.adapted:
        console.print(f"observations mapped onto the release's layout for: {', '.join(result.adapted)}")
    if result.derived_tasks:
        console.print(f"statistics derived from the released setpoints for: {', '.join(result.derived_tasks)}")
    console.print(f"wrote a checkpoint of {result.tasks} tasks to {result.directory}; evaluate it with "
                  f"vintix eval --checkpoint {result.directory} --tasks ...", highlight=False)


@app.command("export-official")
def export_official_command(
    checkpoint: Annotated[str, typer.Argument(help="our checkpoint directory, a training run, or a shipped model")],
    out: Annotated[Path, typer.Option(help="folder for model.pth, config.json and metadata.json")] = Path(
        "vintix-release"),
    overwrite: Annotated[bool, typer.Option(help=_OVERWRITE_HELP)] = False,
) -> None:
    """Write a checkpoint in the authors' release format, loadable by their code unchanged."""
    from vintix.agent import resolve_checkpoint
    from vintix.model.official import export_official

    try:
        directory = export_official(resolve_checkpoint(checkpoint), out, overwrite)
    except (VintixError, OSError) as error:
        raise _fail(error) from None
    console.print(f"wrote model.pth, config.json and metadata.json to {directory}", highlight=False)


@bench_app.command("train")
def bench_train(
    presets: Annotated[list[str] | None, typer.Argument(
        metavar="[PRESETS]...", help="model presets (default: tiny small)")] = None,
    batch_size: Annotated[int, typer.Option(min=1, help="windows per step")] = 4,
    steps: Annotated[int, typer.Option(min=1, help="timed steps per preset (after one warm-up step)")] = 3,
    device: Annotated[str, typer.Option(help="cpu or cuda")] = "cpu",
) -> None:
    """Training tokens/s and MFU per preset, MFU against this device's matmul rate measured in the same run."""
    import os

    import torch

    from vintix.model.model import preset
    from vintix.train.bench import benchmark_training, parameter_count

    for name in presets or []:
        preset(name)  # an unknown name fails now, not after the matmul measurement
    peak, results = benchmark_training(presets or ["tiny", "small"], batch_size, steps, torch.device(device))
    table = Table(title=f"training speed on {device} ({torch.get_num_threads()} threads, load average "
                        f"{os.getloadavg()[0]:.2f}); matmul peak {peak / 1e9:,.1f} GFLOP/s")
    for column in ("preset", "parameters", "window", "batch", "tokens/s", "MFU"):
        table.add_column(column, justify="left" if column == "preset" else "right")
    for r in results:
        table.add_row(r.preset, f"{r.parameters / 1e6:.2f}M", str(r.window_len), str(r.batch_size),
                      f"{r.tokens_per_s:,.0f}", f"{r.mfu:.1%}")
    console.print(table)
    console.print("parameters: one encoder/head per group of all 102 registry tasks; paper preset "
                  f"{parameter_count('paper'):,} (paper: 332,100,768)")


DEFAULT_COLLECT_BENCH_TASKS = ["InvertedPendulum-v5", "Hopper-v5", "HalfCheetah-v5", "industrial-benchmark-40-v1"]


@bench_app.command("collect")
def bench_collect(
    task_names: Annotated[list[str] | None, typer.Argument(
        metavar="[TASKS]...", help="tasks (default: InvertedPendulum, Hopper, HalfCheetah, IB p=40)")] = None,
    steps: Annotated[int, typer.Option(min=1, help="env steps per measurement")] = 20_000,
    envs_per_batch: Annotated[int | None, typer.Option(
        min=1, help="histories stepped together (default: the collector's)")] = None,
    repeats: Annotated[int, typer.Option(min=1, help="alternating raw/collector measurements; medians kept")] = 3,
    out: Annotated[Path | None, typer.Option(help="also write the rates as a CSV table (what --plan reads)")] = None,
) -> None:
    """Collector steps/s against the raw env's, each in one process, measured side by side (tasks without
    a demonstrator: uniform-random play's rate only)."""
    import os

    import torch

    from vintix.collect.bench import benchmark_collection, write_rates
    from vintix.collect.collector import DEFAULT_ENVS_PER_BATCH

    torch.set_num_threads(1)  # one process per core, as `vintix collect --workers` runs
    batch = envs_per_batch or DEFAULT_ENVS_PER_BATCH
    try:
        specs = _runnable_tasks(task_names or DEFAULT_COLLECT_BENCH_TASKS)
        if out is not None:
            check_output_path(out)
    except VintixError as error:
        raise _fail(error) from None
    results = benchmark_collection([s.name for s in specs], steps, batch, repeats)
    load = f"load average {os.getloadavg()[0]:.2f}"  # a busy machine's rates are lower: say how busy
    table = Table(title=f"collection speed in one process, {batch} histories per batch, median of {repeats} ({load})")
    for column in ("task", "raw env steps/s", "collector steps/s", "collector / raw"):
        table.add_column(column, justify="left" if column == "task" else "right")
    for r in results:
        collected = "no demonstrator" if r.collect_steps_per_s is None else f"{r.collect_steps_per_s:,.0f}"
        table.add_row(r.task, f"{r.raw_steps_per_s:,.0f}", collected, "" if r.ratio is None else f"{r.ratio:.2f}")
    console.print(table)
    if out is not None:
        command = "vintix bench collect " + " ".join(sys.argv[3:]) + f" ({load})"
        console.print(f"added {len(results)} rows to {write_rates(results, out, command)}")


@bench_app.command("infer")
def bench_infer(
    presets: Annotated[list[str] | None, typer.Argument(
        metavar="[PRESETS]...", help="model presets (default: tiny small paper)")] = None,
    envs: Annotated[list[int] | None, typer.Option(min=1, help="batch sizes (default: 1 and 16)")] = None,
    repeats: Annotated[int, typer.Option(min=1, help="timed cached steps per measurement (median)")] = 20,
    recompute: Annotated[bool, typer.Option(
        help="also time a full-window recompute (minutes at the paper's size)")] = True,
    threads: Annotated[int | None, typer.Option(
        min=1, max=MAX_THREADS, help="torch intra-op threads (default: torch's)")] = None,
    window: Annotated[int | None, typer.Option(
        min=1, help="context length in steps instead of the preset's (a paper-size cache for 16 envs at its "
                    "8192 steps needs 20 GiB)")] = None,
) -> None:
    """Agent step latency and throughput: KV cache (first-full vs steady) vs full-window recompute."""
    import os

    import torch

    from vintix.agent.bench import literal_steady_state, memory_needed, time_inference
    from vintix.model.model import preset

    for name in presets or []:
        preset(name)  # an unknown name fails before any timing
    if threads:
        torch.set_num_threads(threads)
    memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    table = Table(title=f"agent step on cpu, fp32, window full ({torch.get_num_threads()} threads; load average at "
                        f"start {os.getloadavg()[0]:.2f}); cache states set directly, see vintix/agent/bench.py")
    for column in ("preset", "params", "window", "envs", "first-full ms", "steady ms", "steady/first",
                   "recompute ms", "cache speedup", "env-steps/s"):
        table.add_column(column, justify="left" if column == "preset" else "right")
    notes = []
    for name in presets or ["tiny", "small", "paper"]:
        for batch in envs or [1, 16]:
            cache_bytes, recompute_bytes = memory_needed(name, batch, window)
            if cache_bytes > memory / 2:
                notes.append(f"{name} × {batch} envs skipped: its KV cache needs {cache_bytes / 2**30:.1f} GiB "
                             f"of this machine's {memory / 2**30:.0f} GiB")
                continue
            timing = time_inference(name, batch, repeats if name != "paper" else max(3, repeats // 4),
                                    (1 if name == "paper" else 3) if recompute and recompute_bytes < memory / 2 else 0,
                                    window)
            speedup = timing.cache_speedup
            table.add_row(name, f"{timing.parameters / 1e6:.1f}M", str(timing.window), str(batch),
                          f"{timing.first_full_ms:.2f}", f"{timing.steady_ms:.2f}",
                          f"{timing.steady_over_first_full:.2f}",
                          "—" if timing.recompute_ms is None else f"{timing.recompute_ms:,.0f}",
                          "—" if speedup is None else f"{speedup:,.0f}×", f"{timing.env_steps_per_second:,.0f}")
    console.print(table)
    for note in notes:
        console.print(f"note: {note}")
    filling, steady = literal_steady_state("tiny")
    console.print(f"literal run check (tiny, 1 env, 4096 real steps): median step {filling:.2f} ms around the step "
                  f"that fills the window, {steady:.2f} ms over the last 1024 steps; load average now "
                  f"{os.getloadavg()[0]:.2f}")


@app.command("eval")
def eval_command(
    checkpoint: Annotated[str, typer.Option(help="a checkpoint directory (config.json + model.safetensors), a "
                                             "training run (its best checkpoint, else its newest), a shipped model "
                                             "(cpu-suite, icrl-reach, point-goal) or a release snapshot")],
    tasks: Annotated[list[str], typer.Option(help=_doc("EvalConfig", "tasks"))],
    out: Annotated[Path, typer.Option(help="folder for episodes.csv and run.json")] = Path("results"),
    shots: Annotated[int | None, typer.Option(help=_doc("EvalConfig", "shots"), show_default=False)] = None,
    seeds: Annotated[int, typer.Option(help=_doc("EvalConfig", "seeds"))] = EvalConfig.seeds,
    first_seed: Annotated[int, typer.Option(help=_doc("EvalConfig", "first_seed"))] = EvalConfig.first_seed,
    ml1: Annotated[bool, typer.Option("--ml1", help=_doc("EvalConfig", "ml1"))] = EvalConfig.ml1,
    variation: Annotated[list[str] | None, typer.Option(help=_doc("EvalConfig", "variation"))] = None,
    prompt_from: Annotated[Path | None, typer.Option(help=_doc("EvalConfig", "prompt_from"))] = None,
    prompt_steps: Annotated[int | None, typer.Option(help=_doc("EvalConfig", "prompt_steps"))] = None,
    reference: Annotated[str, typer.Option(
        help="reference table of the printed summary: ours (our measured demonstrators and random policy; every "
             "task has it) or paper (the paper's table; what comparisons with its numbers need)")] = "ours",
    label: Annotated[str | None, typer.Option(
        help="name of this model in reports (default: checkpoint folder)")] = None,
    batch_envs: Annotated[int, typer.Option(help=_doc("EvalConfig", "batch_envs"))] = EvalConfig.batch_envs,
    reward_input: Annotated[str, typer.Option(metavar="true|zero|shuffled|other-goal",
                                              help=_doc("EvalConfig", "reward_input"))] = EvalConfig.reward_input,
    greedy: Annotated[bool, typer.Option("--greedy", help=_doc("EvalConfig", "greedy"))] = EvalConfig.greedy,
    sample_noise: Annotated[str | None, typer.Option(help=_doc("EvalConfig", "sample_noise"))] = None,
    device: str = "cpu",
    threads: Annotated[int, typer.Option(min=1, max=MAX_THREADS, help="torch CPU threads; 1 suits small models, whose "
                                         "steps are many tiny ops that a second thread slows down on a busy "
                                         "machine")] = 1,
    ray: Annotated[str | None, typer.Option(help=_RAY_HELP)] = None,
    overwrite: Annotated[bool, typer.Option(
        help="write into --out even where it holds another run's results (a re-run of the same run, the same "
             "checkpoint, weights, rewards fed back and tasks, replaces its own without it)")] = False,
) -> None:
    """Many-shot in-context RL from an empty context (or a prompt); per-episode results and a summary."""
    import torch

    from vintix.agent import Agent, resolve_checkpoint
    from vintix.agent.pretrained import checkpoint_name
    from vintix.evaluate import evaluate, ml1_success, parse_variation, summarize
    from vintix.tasks.scores import check_table

    torch.set_num_threads(capped_threads(threads, _note))
    shots = shots if shots is not None else ML1_SHOTS if ml1 else EvalConfig.shots
    try:
        check_table(reference)  # summarize() would otherwise meet it only after the whole run
        config = EvalConfig(tasks=tasks, shots=shots, seeds=seeds, first_seed=first_seed,
                            variation=parse_variation(variation or []), prompt_from=prompt_from,
                            prompt_steps=prompt_steps, batch_envs=batch_envs, reward_input=reward_input,
                            ml1=ml1, greedy=greedy, sample_noise=sample_noise)
        resolved = resolve_checkpoint(checkpoint)
        agent = Agent.from_pretrained(resolved, device)
        rows, notes = evaluate(agent, config, out, checkpoint_name(checkpoint, resolved), label, True, ray,
                               overwrite)
        summary = summarize(rows, reference)
    except (VintixError, ValueError) as error:
        raise _fail(error) from None
    for note in notes:
        _note(note)
    if reward_input != "true":
        console.print(f"rewards fed back to the model: {reward_input}; scores and success from the true returns")
    written = f"{len(rows)} episodes to {out / 'episodes.csv'} and the run's settings to {out / 'run.json'}"
    if not summary:  # no reference scores to normalize by (a task of your own without them)
        console.print(f"no task has a {reference} reference score, so there is no normalized table; wrote {written} "
                      "(returns and success per episode)")
        return
    _print_task_summary(summary, reference, shots, seeds)
    _print_shot_curves(rows, reference, shots)
    if ml1:
        _print_ml1(ml1_success(rows))
    console.print(f"wrote {written}")


def _print_task_summary(summary: list[dict[str, Any]], reference: str, shots: int, seeds: int) -> None:
    """The table of `vintix eval`: per task, the normalized score at the first and last shot and its plateau, and
    the success rate where the task has a success flag."""
    plateau = f"best {PLATEAU_SHOTS}-shot plateau" if PLATEAU_SHOTS < shots else f"mean of all {shots} shots"
    with_success = any(s["success_first"] is not None for s in summary)
    table = Table(title=f"normalized score ({reference} reference), mean over {seeds} run(s) per task"
                        + ("; success rate where the task has a success flag" if with_success else ""))
    # The paper's Vintix scores are normalized by the paper's table: beside scores normalized the same way only.
    with_paper = reference == "paper"
    columns = ["variation", "shot 1", f"shot {shots}", plateau, "from shot"] + (
        ["paper's Vintix"] if with_paper else []) + (["success shot 1", f"success {plateau}"] if with_success else [])
    # A task's name is never cut ("industrial-benchmark-…"): the other columns wrap instead.
    table.add_column("task", no_wrap=True, min_width=max(len(s["task"]) for s in summary))
    for column in columns:
        table.add_column(column, justify="left" if column == "variation" else "right")
    for s in summary:
        cells = [s["task"], s["variation"] or "—", f"{s['first']:.2f}", f"{s['last']:.2f}", f"{s['plateau']:.2f}",
                 str(s["plateau_from"])]
        if with_paper:
            cells.append("—" if s["paper_vintix"] is None else f"{s['paper_vintix']:.2f}")
        if with_success:
            cells += [_rate(s["success_first"]), _rate(s["success_plateau"])]
        table.add_row(*cells)
    console.print(table)


def _print_shot_curves(rows: list[dict[str, Any]], reference: str, shots: int) -> None:
    """The in-context table of `vintix eval`: per domain, the IQM of the normalized score (and the success rate)
    at a spread of shots."""
    from vintix.evaluate import iqm, shot_curves, shots_to_show

    shown = shots_to_show(shots)
    which = "at each shot" if len(shown) == shots else f"at shots {', '.join(map(str, shown))} of {shots}"
    per_shot = Table(title=f"in context: IQM of the normalized score ({reference} reference) {which} over the "
                           "domain's runs, as `vintix report` gives it; success rate: mean over runs")
    per_shot.add_column("domain")
    for shot in shown:
        per_shot.add_column(f"shot {shot}", justify="right")
    scores, successes = shot_curves(rows, f"normalized_{reference}", iqm), shot_curves(rows, "success")
    for domain, curve in scores.items():
        per_shot.add_row(domain, *(f"{curve[shot - 1]:.2f}" if shot <= len(curve) else "" for shot in shown))
        if domain in successes:
            success = successes[domain]
            per_shot.add_row("  success rate",
                             *(_rate(success[shot - 1]) if shot <= len(success) else "" for shot in shown))
    console.print(per_shot)


def _print_ml1(summary: list[dict[str, Any]]) -> None:
    """Meta-World's ML1 score per task (`vintix.evaluate.ml1_success`)."""
    table = Table(title=f"Meta-World ML1 meta-test: success rate of the {ML1_SCORED_SHOTS} scored episodes after "
                        f"{ML1_ADAPTATION_SHOTS} adaptation episodes, mean over test goals (95 % CI)")
    for column in ("task", "test goals", "success", "adaptation ep 1", f"adaptation ep {ML1_ADAPTATION_SHOTS}"):
        table.add_column(column, justify="left" if column == "task" else "right")
    for s in summary:
        table.add_row(s["task"], str(s["goals"]), f"{s['success']:.0%} [{s['low']:.0%}, {s['high']:.0%}]",
                      _rate(s["adaptation_first"]), _rate(s["adaptation_last"]))
    console.print(table)


def _rate(rate: float | None) -> str:
    """A success rate as a percentage, or a dash for a task without a success flag."""
    return "—" if rate is None else f"{rate:.0%}"


def _shot_window(text: str | None) -> tuple[int, int] | None:
    """``"2-40"`` -> (2, 40); None stays None; anything else, an error naming the option."""
    if text is None:
        return None
    first, dash, last = text.partition("-")
    if not (dash and first.strip().isdigit() and last.strip().isdigit()):
        raise VintixError(f"--gap-shots {text!r}: give FIRST-LAST, two shot numbers, e.g. --gap-shots 2-40")
    return int(first), int(last)


@app.command("report")
def report_command(
    results: Annotated[list[Path], typer.Argument(
        help="`vintix eval` output folders (several: compared side by side)")],
    out: Annotated[Path, typer.Option(help="folder for report.md and figures/")] = Path("report"),
    reference: Annotated[str, typer.Option(
        help="reference table: ours (our measured demonstrators and random policy; every task has it) or paper "
             "(the paper's table; what comparisons with its numbers need)")] = "ours",
    plateau_shots: Annotated[int | None, typer.Option(
        min=1, help=f"k of the best-k-shot plateau (converged score); default {PLATEAU_SHOTS}, or all the shots of a "
        "shorter run")] = None,
    model_card: Annotated[bool, typer.Option(
        help="put the released model's model-card scores beside each task and domain (results of a model "
             "imported with vintix import-official; the card uses its own reference returns)")] = False,
    gap_shots: Annotated[str | None, typer.Option(
        metavar="FIRST-LAST", help="the reward-use gap over these shots (e.g. 2-40: both runs' mean over them) "
        "instead of over the true-reward run's best plateau-shots; the report prints the shots either way")] = None,
) -> None:
    """Markdown report with PNG figures: score vs shot per task and domain, converged vs the paper's."""
    from vintix.report import write_report

    try:
        path, notes, gaps = write_report(results, out, reference, plateau_shots, model_card,
                                         _shot_window(gap_shots))
    except (VintixError, ValueError) as error:
        raise _fail(error) from None
    for note in notes:
        _note(note)
    for gap in gaps:
        console.print(f"reward-use gap: {gap}", highlight=False, soft_wrap=True)
    figures = sorted((out / "figures").rglob("*.png"))
    console.print(f"wrote {path} and {len(figures)} figures under {out / 'figures'}")


if __name__ == "__main__":
    app()
