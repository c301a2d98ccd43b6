"""Many-shot in-context RL (paper §3; docs/evaluation.md): every (task, seed) run is one env, all stepped in
lockstep through one batched `Agent`, from an empty context (cold start) or after a prompt taken
from the start of a stored learning history.

Protocol: env ``i`` of a task is ``make_env(task, seed=first_seed + i)``. A Meta-World env keeps one
hidden goal for its life (drawn from its seed), so each seed is another goal to infer from reward
across shots. Envs step together; a run leaves the batch (and the agent its context) as soon as it
has played ``shots`` episodes, so 100-step Meta-World runs do not wait, stepping, for 1000-step
MuJoCo runs of the same batch.

Reward ablation (`EvalConfig.reward_input`): the rewards fed back to the model can be zeros, or the
episode's own rewards drawn out of order, to measure how much of the in-context improvement the
rewards drive. Returns, success and normalized scores always come from the env's true rewards.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import sys
import time
from collections.abc import Callable, Hashable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import torch
from tqdm import tqdm

from vintix import cluster
from vintix.agent import Agent
from vintix.atomic import atomic_write_text, check_output_kind, check_output_path, check_replaceable, folder_lock
from vintix.data.discovery import find_tasks
from vintix.data.reader import LearningHistory
from vintix.errors import OutputPathError, UnknownTaskError, VintixError, at_file
from vintix.evaluate.config import (
    ML1_ADAPTATION_SHOTS,
    ML1_SCORED_SHOTS,
    PLATEAU_SHOTS,
    EvalConfig,
    EvalConfigError,
    RunFile,
)
from vintix.evaluate.summary import best_k_plateau, estimate_with_ci
from vintix.fields import read_json_file
from vintix.model.checkpoint import weights_sha256
from vintix.model.model import Vintix
from vintix.tasks import TaskSpec, action_space_of, find_task, get_task, make_env, resolve_tasks, select_tasks
from vintix.tasks.custom import custom_specs
from vintix.tasks.metaworld import ML1_SEED, MetaWorldTaskEnv
from vintix.tasks.registry import has_hidden_goal
from vintix.tasks.scores import Reference, missing_reference_note, reference
from vintix.train.config import SELECT_METRICS, ConfigError, TrainConfig
from vintix.train.trainer import Scorer, Selection

EPISODES_FILE = "episodes.csv"
RUN_FILE = "run.json"
GOAL_PROTOCOL = "one hidden goal per env for its life, drawn from the env seed (ML45 meta-RL protocol)"
ML1_PROTOCOL = (f"Meta-World ML1 meta-test: run i plays test goal first_seed + i of metaworld.ML1(task, "
                f"seed={ML1_SEED}), {ML1_ADAPTATION_SHOTS} adaptation episodes then {ML1_SCORED_SHOTS} scored ones, "
                "success at any step")
_SHUFFLE_STREAM = 1
"""Mixed into the env seed for the shuffled-reward draws: gymnasium seeds the env's own generator with
the bare seed, and the draws should not share its stream."""


@dataclass(frozen=True)
class Episode:
    """One finished episode of one run."""

    episode_return: float
    length: int
    success: float | None
    """Meta-World's success flag (1 if reached at any step); None for envs without one"""
    last_observation: np.ndarray
    """The env's observation after the episode's last step (where it ended: Meta-World's hand at [:3])"""
    optimal: float | None = None
    """the most the episode could return under its env's goal (`optimal_return`), read as it ends, so an env that
    draws its goal at its first reset is asked after it; None for an env that does not say"""


def parse_variation(items: Sequence[str]) -> dict[str, float]:
    """``["viscosity=0.05", "gravity_scale=1.1"]`` -> ``{"viscosity": 0.05, "gravity_scale": 1.1}``."""
    variation: dict[str, float] = {}
    for item in items:
        name, _, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            raise VintixError(
                f"variation {item!r} is not NAME=NUMBER, e.g. viscosity=0.05 or gravity_scale=1.1") from None
        if name.strip() in variation:  # the last would win without a word
            raise VintixError(f"variation {name.strip()!r} is given twice ({variation[name.strip()]:g} and "
                              f"{number:g}); give each once")
        variation[name.strip()] = number
    return variation


@dataclass(frozen=True)
class Prompt:
    """The start of a stored learning history, and the env seed the history was collected on."""

    rows: dict[str, np.ndarray]
    env_seed: int | None


def load_prompt(root: Path, task: str, index: int, steps: int) -> Prompt:
    """The first `steps` rows of history `index` of `task` in the dataset at `root`.

    A Meta-World run must be evaluated on the hidden goal of the history that prompts it, so a
    Meta-World history must say its env seed (`vintix collect` records it; published files do not).
    """
    spec = get_task(task)
    matches = [t for t in find_tasks(root) if _canonical(t.task_name) == spec.name]
    if not matches or not matches[0].history_paths:
        raise VintixError(
            f"{root} has no learning history of {spec.name}: cannot prompt it; collect some or drop --prompt-from")
    paths = matches[0].history_paths
    if index >= len(paths):
        raise VintixError(f"{matches[0].task_dir} has {len(paths)} histories, but prompting run {index + 1} needs "
                          f"history {index + 1}: use --seeds {len(paths)} or fewer, or collect more histories")
    with LearningHistory(paths[index]) as history:
        if history.num_steps < steps:
            raise VintixError(f"{history.path} has {history.num_steps} steps, fewer than the prompt's {steps}")
        if spec.domain == "metaworld" and history.env_seed is None:
            raise VintixError(f"{history.path} does not record the env seed it was collected on, so its hidden goal is "
                              "unknown and a run prompted with it would chase another goal; prompt Meta-World with "
                              "histories from `vintix collect`")
        return Prompt(history.read(0, steps), history.env_seed)


def _canonical(task: str) -> str | None:
    try:
        return get_task(task).name
    except UnknownTaskError:
        return None


class RewardFeed:
    """The rewards one env's run feeds back to the model (`EvalConfig.reward_input`): the env's own,
    zeros, (shuffled) at each step one drawn uniformly from the rewards the current episode has
    returned so far, this step's included: the episode's own values, their link to the states and
    actions that earned them broken, or (other-goal) what each step would have earned under another run's
    hidden goal (`other_goal_reward`, which an other-goal feed is given): rewards as consistent as the true ones,
    pointing elsewhere. The shuffled draws come from a generator seeded by `seed` (the env seed), so a shuffled
    run is reproducible."""

    def __init__(self, reward_input: str, seed: int, other_goal: Callable[[Any], float] | None = None) -> None:
        if (reward_input == "other-goal") != (other_goal is not None):
            raise ValueError("an other-goal feed, and only it, takes the other goal's reward (other_goal_reward)")
        self.reward_input = reward_input
        self._episode: list[float] = []
        self._rng = np.random.default_rng((_SHUFFLE_STREAM, seed))
        self._other_goal = other_goal

    def __call__(self, reward: float, action: Any = None) -> float:
        """What the model is told the last action earned, given the env's `reward` for it (and, for an
        other-goal feed, the `action`, priced before the env resets)."""
        if self.reward_input == "zero":
            return 0.0
        if self.reward_input == "shuffled":
            self._episode.append(float(reward))
            return self._episode[int(self._rng.integers(len(self._episode)))]
        if self._other_goal is not None:
            return self._other_goal(action)
        return float(reward)

    def new_episode(self) -> None:
        """Forget the finished episode's rewards."""
        self._episode.clear()


OTHER_GOAL_SEEDS = 100
"""How many env seeds after a run's `other_goal` looks through for a goal unlike its own."""


def other_goal(task: str, seed: int, env: Any) -> np.ndarray:
    """The hidden goal of the first env seed after `seed` whose goal differs from `env`'s own (on a direction
    task, the other direction): what an other-goal feed prices each step under. `env` must be able to price a
    step under another goal (`rewards_under_goals`, as the hidden-goal tasks whose demonstrators infer it)."""
    inner = env.unwrapped
    if not hasattr(inner, "rewards_under_goals") or not hasattr(inner, "true_goal"):
        raise VintixError(f"{task}: reward_input 'other-goal' feeds the rewards of another hidden goal, and this "
                          "task's env cannot price a step under another goal (rewards_under_goals); use 'zero' or "
                          "'shuffled'")
    own = inner.true_goal
    for other_seed in range(seed + 1, seed + 1 + OTHER_GOAL_SEEDS):
        other: Any = make_env(task, seed=other_seed)  # a hidden-goal env says its true_goal
        try:
            goal = np.asarray(other.unwrapped.true_goal, dtype=np.float64)
        finally:
            other.close()
        if not np.allclose(goal, own):
            return goal
    raise VintixError(f"{task}: env seeds {seed + 1}-{seed + OTHER_GOAL_SEEDS} all draw the goal of seed {seed}, so "
                      "there is no other goal to feed; use 'zero' or 'shuffled'")


def other_goal_reward(task: str, seed: int, env: Any) -> Callable[[Any], float]:
    """What an action `env` just took would have earned under `other_goal`'s goal: an other-goal feed's rewards."""
    goal, inner = other_goal(task, seed, env)[None], env.unwrapped
    return lambda action: float(inner.rewards_under_goals(goal, action)[0])


def play_shots(agent: Agent, envs: Sequence[Any], feeds: Sequence[RewardFeed], shots: int,
               progress: bool = False, first_rewards: np.ndarray | None = None,
               greedy: bool = False) -> list[list[Episode]]:
    """Step `envs` (the agent already reset for them) until each has finished `shots` episodes; an
    env that has is dropped from the agent's batch (`Agent.keep`). `feeds[i]` turns env i's rewards
    into the ones the agent is fed; episode returns and success are the env's own. `first_rewards`: the
    reward of the step before the first (a prompt's last; zeros for a cold start). `greedy`: act on the
    argmax of a discrete group's logits (a gaussian policy's mean), not a draw."""
    n = len(envs)
    observations = [env.reset()[0] for env in envs]
    rewards = np.zeros(n) if first_rewards is None else np.asarray(first_rewards, np.float64).copy()
    starts = np.ones(n, dtype=bool)
    returns, lengths = np.zeros(n), np.zeros(n, dtype=int)
    success: list[float | None] = [None] * n
    episodes: list[list[Episode]] = [[] for _ in envs]
    bar = tqdm(total=n * shots, desc="episodes", disable=None if progress else True, leave=False)
    active = list(range(n))  # the envs still playing, in the agent's batch order
    while active:
        actions = agent.act([observations[i] for i in active], rewards[active], starts[active], deterministic=greedy)
        for i, action in zip(active, actions, strict=True):
            observation, reward, terminated, truncated, info = envs[i].step(action)
            fed = feeds[i](reward, action)  # before a reset: an other-goal feed prices this step's state
            returns[i] += reward
            lengths[i] += 1
            if "success" in info:
                success[i] = max(success[i] or 0.0, float(info["success"]))
            if terminated or truncated:
                episodes[i].append(Episode(float(returns[i]), int(lengths[i]), success[i], observation,
                                           optimal_return(envs[i])))
                bar.update(1)
                observation, _ = envs[i].reset()
                rewards[i], starts[i] = fed, True  # the last reward (`ModelConfig.last_reward`)
                feeds[i].new_episode()
                returns[i], lengths[i], success[i] = 0.0, 0, None
            else:
                rewards[i], starts[i] = fed, False
            observations[i] = observation
        playing = [j for j, i in enumerate(active) if len(episodes[i]) < shots]
        if len(playing) < len(active):
            active = [active[j] for j in playing]
            if active:
                agent.keep(playing)
    bar.close()
    return episodes


def run_episodes(
    agent: Agent, config: EvalConfig, specs: Sequence[TaskSpec], progress: bool = False,
    ray: str | None = None, checkpoint: str = "",
) -> list[dict[str, Any]]:
    """Every (task, seed) run of `config` for `specs`: one result row per episode. Runs go in batches of
    `config.batch_envs`, one after another through `agent`, or, given a Ray address `ray`, one Ray task
    per batch, each loading the model from `checkpoint` itself; rows come back in the same order."""
    runs = [(spec, config.first_seed + i) for spec in specs for i in range(config.seeds)]
    prompt_steps = agent.model.config.context_len // 2 if config.prompt_steps is None else config.prompt_steps
    batches = [runs[start : start + config.batch_envs] for start in range(0, len(runs), config.batch_envs)]
    if ray is None:
        done = log_lines_off_terminal((run_batch(agent, config, batch, prompt_steps, progress) for batch in batches),
                                      len(batches), "batches of runs", progress)
        return [row for rows in done for row in rows]
    if not checkpoint or agent.device.type != "cpu":
        raise VintixError("evaluating on Ray needs the model's checkpoint folder (each worker loads the model itself) "
                          f"and the cpu device (a worker has one CPU and no GPU); got {checkpoint!r} on {agent.device}")
    cluster.connect(ray)
    # Workers may run in another folder: paths that exist here go absolute (a shipped model's name stays
    # a name), and each uses the driver's thread count, so that a batch computes exactly what it would here.
    source = str(Path(checkpoint).absolute()) if Path(checkpoint).exists() else checkpoint
    config = replace(config, prompt_from=config.prompt_from and config.prompt_from.absolute())
    calls = [(source, torch.get_num_threads(), config, batch, prompt_steps) for batch in batches]
    by_batch = dict(log_lines_off_terminal(cluster.map_tasks(_run_batch_in_worker, calls, "evaluation batches",
                                                             progress), len(batches), "batches of runs", progress))
    return [row for index in range(len(batches)) for row in by_batch[index]]


_Item = TypeVar("_Item")


def log_lines_off_terminal(items: Iterable[_Item], total: int, what: str, progress: bool) -> Iterator[_Item]:
    """`items`, passed through; with `progress` off a terminal (a log file, where tqdm's bars are off), a line as
    each arrives: how many of `total` `what` are done and the minutes so far, so a long evaluation's log shows it
    is alive."""
    lines, started = progress and not sys.stderr.isatty(), time.perf_counter()
    for done, item in enumerate(items, 1):
        if lines:
            print(f"{done}/{total} {what} done, {(time.perf_counter() - started) / 60:.1f} min", flush=True)
        yield item


def _run_batch_in_worker(checkpoint: str, threads: int, config: EvalConfig, batch: list[tuple[TaskSpec, int]],
                         prompt_steps: int) -> list[dict[str, Any]]:
    """One batch of runs in a Ray worker, with a model loaded there (a model object would travel
    pickled with every task; the checkpoint folder is a path)."""
    torch.set_num_threads(threads)
    return run_batch(Agent.from_pretrained(checkpoint), config, batch, prompt_steps)


def run_batch(agent: Agent, config: EvalConfig, batch: list[tuple[TaskSpec, int]], prompt_steps: int,
              progress: bool = False) -> list[dict[str, Any]]:
    """The (task, seed) runs of `batch`, stepped together through `agent`: one result row per episode."""
    variation = ",".join(f"{k}={v:g}" for k, v in sorted(config.variation.items()))
    prompts = None
    if config.prompt_from is not None:
        prompts = [load_prompt(config.prompt_from, spec.name, seed - config.first_seed, prompt_steps)
                   for spec, seed in batch]
        batch = [(spec, seed if p.env_seed is None else p.env_seed)
                 for (spec, seed), p in zip(batch, prompts, strict=True)]
    envs = [make_env(spec.name, seed=seed, **config.variation) for spec, seed in batch]
    try:
        if config.ml1:
            for env, (_, seed) in zip(envs, batch, strict=True):
                assert isinstance(env.unwrapped, MetaWorldTaskEnv)  # `_evaluate` refuses other tasks
                env.unwrapped.use_ml1_test_goal(seed)  # run i: ML1's test goal first_seed + i
        agent.sample_noise = config.sample_noise or agent.model.config.sample_noise
        # Each batch is a new run; each env draws from its env seed's own stream: a run does not depend on its batch.
        agent.reset([spec.name for spec, _ in batch], [action_space_of(env.action_space) for env in envs],
                    seeds=[seed for _, seed in batch], discard_context=True)
        tasks = list(agent.tasks)  # the agent's batch shrinks as runs finish
        if prompts is not None:
            agent.prompt(*([p.rows[key] for p in prompts] for key in ("observation", "action", "reward", "step_num")))
        feeds = [RewardFeed(config.reward_input, seed, other_goal_reward(spec.name, seed, env)
                            if config.reward_input == "other-goal" else None)
                 for (spec, seed), env in zip(batch, envs, strict=True)]
        last_prompt_rewards = None if prompts is None else np.array([p.rows["reward"][-1] for p in prompts])
        results = play_shots(agent, envs, feeds, config.shots, progress, last_prompt_rewards, config.greedy)
    finally:
        for env in envs:
            env.close()
    return [
        {"task": spec.name, "domain": spec.domain, "split": spec.split, "group": spec.group, "seed": seed,
         "variation": variation, "prompt_steps": prompt_steps if config.prompt_from else 0,
         "reward_input": config.reward_input,
         "norm_source": task.norm_source, "shot": shot + 1, "return": e.episode_return, "length": e.length,
         "success": "" if e.success is None else e.success, "optimal": "" if e.optimal is None else e.optimal}
        for (spec, seed), task, episodes in zip(batch, tasks, results, strict=True)
        for shot, e in enumerate(episodes)
    ]


def optimal_return(env: Any) -> float | None:
    """The most an episode of `env` can return under its own hidden goal (the discrete benchmarks, whose scores
    are fractions of it), or None for an env that does not say."""
    optimal = getattr(env.unwrapped, "optimal_return", None)
    return None if optimal is None else float(optimal())


def references(tasks: Sequence[str], rows: Sequence[dict[str, Any]] = ()) -> dict[str, dict[str, Reference | None]]:
    """Both tables' references of `tasks` (checked before any env runs: expert ≤ random raises); given the `rows` of
    their runs, a task whose every row carries its env's optimum may score by it (`reference`'s env_optimum)."""
    optimum = {task: bool(rows) and all(r["optimal"] != "" for r in rows if r["task"] == task) for task in tasks}
    return {table: {task: reference(task, table, optimum[task]) for task in tasks} for table in ("paper", "ours")}


def missing_reference_notes(refs: dict[str, dict[str, Reference | None]]) -> list[str]:
    """A note for each table that lacks some of the tasks."""
    missing = {table: [task for task, ref in by_task.items() if ref is None] for table, by_task in refs.items()}
    return [missing_reference_note(tasks, table) for table, tasks in missing.items() if tasks]


def add_normalized_scores(rows: list[dict[str, Any]], refs: dict[str, dict[str, Reference | None]]) -> None:
    """Add `normalized_<table>` to every row (empty where the table lacks the task)."""
    for row in rows:
        for table, by_task in refs.items():
            ref = by_task[row["task"]]
            optimal = row.get("optimal") if row.get("optimal") != "" else None
            row[f"normalized_{table}"] = "" if ref is None else float(ref.normalize(row["return"], optimal))


def write_results(out: Path, rows: list[dict[str, Any]], run: dict[str, Any]) -> tuple[Path, Path]:
    """`episodes.csv` (one row per episode) and `run.json` (how it was run) under `out`, atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    episodes = buffer.getvalue()
    # The reader checks that the two files belong together: a folder mixing two runs' files is refused.
    run = {**run, "episodes_sha256": hashlib.sha256(episodes.encode()).hexdigest()}
    atomic_write_text(out / EPISODES_FILE, episodes)
    atomic_write_text(out / RUN_FILE, json.dumps(run, indent=1, default=str) + "\n")
    return out / EPISODES_FILE, out / RUN_FILE


def run_identity(checkpoint: str, weights_sha256: str, config: EvalConfig) -> dict[str, Any]:
    """What makes results one run's: the checkpoint (its name, and the sha256 of its weights, since two models may
    share a name), the rewards fed back and the tasks. A results folder holds one run (`check_results_folder`)."""
    return {"checkpoint": checkpoint, "weights_sha256": weights_sha256, "reward_input": config.reward_input,
            "tasks": list(config.tasks)}


def _identity_of(run: dict[str, Any]) -> dict[str, Any]:
    config = run.get("config")
    config = config if isinstance(config, dict) else {}
    return {"checkpoint": run.get("checkpoint"), "weights_sha256": run.get("weights_sha256"),
            "reward_input": config.get("reward_input"), "tasks": config.get("tasks")}


def describe_run(identity: dict[str, Any]) -> str:
    """A run's identity in words, for the message that refuses to mix two runs."""
    sha = identity.get("weights_sha256")
    tasks = identity.get("tasks")
    named = ", ".join(map(str, tasks)) if isinstance(tasks, list) else "?"
    return (f"{identity.get('checkpoint')!r} (weights sha256 {str(sha)[:12] if sha else 'not recorded'}, "
            f"{identity.get('reward_input')} rewards, tasks {named})")


def check_results_folder(out: Path, identity: dict[str, Any], overwrite: bool) -> None:
    """OutputPathError where `out` holds results of another run than `identity` (`run_identity`), naming both: a
    re-run of the same run may replace its own results, anything else needs `overwrite`. Called with `out`
    locked, whose entries the lock checked (no FIFO or link is read)."""
    try:
        run: dict[str, Any] | None = asdict(read_json_file(out / RUN_FILE, RunFile, at_file(VintixError), ""))
    except (OSError, VintixError):  # none, or not one vintix could have written: the general rule below
        run = None
    if run is not None and _identity_of(run) == identity:
        return
    if run is not None and not overwrite and (out / EPISODES_FILE).exists():
        raise OutputPathError(f"{out} holds the results of {describe_run(_identity_of(run))}; this run is "
                              f"{describe_run(identity)}: write them to another --out, or pass --overwrite to "
                              "replace them")
    check_replaceable(out, "results", overwrite)


def default_label(checkpoint: str, reward_input: str = "true") -> str:
    """A short name for a checkpoint in reports: its folder, or 'run/step-N' for a training checkpoint,
    and the rewards it was fed when not the true ones, e.g. 'ckpt (zero rewards)'."""
    path = Path(checkpoint)
    name = f"{path.parent.parent.name}/{path.name}" if path.parent.name == "checkpoints" else path.name or "model"
    return name if reward_input == "true" else f"{name} ({reward_input} rewards)"


def evaluate(
    agent: Agent, config: EvalConfig, out: Path | None = None, checkpoint: str = "", label: str | None = None,
    progress: bool = False, ray: str | None = None, overwrite: bool = False,
) -> tuple[list[dict[str, Any]], list[str]]:
    """Run `config` with `agent` (on the Ray cluster at address `ray` if given, where workers load
    `checkpoint`: see `run_episodes`); write the results under `out` if given: a folder that is empty, or holds
    this checkpoint's earlier results, or any with `overwrite`. Returns the episode rows and notes (skipped
    tasks, missing references) for the user."""
    if out is None:
        return _evaluate(agent, config, None, checkpoint, label, progress, ray)
    check_output_path(out / EPISODES_FILE)  # fail now, not after the whole run
    check_output_kind(out, "results")  # by the names in it alone, before the lock leaves its file there
    identity = run_identity(checkpoint, weights_sha256(agent.model), config)
    # The lock first: it refuses a folder holding a FIFO or a link before anything in it is read.
    with folder_lock(out, "vintix eval"):  # a second eval into `out` is refused, not mixed with this one
        check_results_folder(out, identity, overwrite)
        return _evaluate(agent, config, out, checkpoint, label, progress, ray, identity["weights_sha256"])


def _evaluate(agent: Agent, config: EvalConfig, out: Path | None, checkpoint: str, label: str | None,
              progress: bool, ray: str | None, weights: str = "") -> tuple[list[dict[str, Any]], list[str]]:
    specs, notes = select_tasks(config.tasks, list(agent.model.groups), [t.task for t in agent.model.task_norms])
    if config.ml1 and (others := [spec.name for spec in specs if spec.domain != "metaworld"]):
        raise EvalConfigError(f"ml1: Meta-World's ML1 protocol is for Meta-World tasks, not {', '.join(others)}; "
                              "evaluate those without --ml1")
    references([s.name for s in specs])  # a reference that cannot normalize fails before any env runs
    started = time.time()
    rows = run_episodes(agent, config, specs, progress, ray, checkpoint)
    refs = references([s.name for s in specs], rows)
    add_normalized_scores(rows, refs)
    if out is not None:
        model = agent.model
        write_results(out, rows, {
            "label": label or default_label(checkpoint, config.reward_input),
            "checkpoint": checkpoint,
            "weights_sha256": weights,
            "model_config": asdict(model.config),
            "config": asdict(config),
            "references": {table: {task: None if ref is None else asdict(ref) for task, ref in by_task.items()}
                           for table, by_task in refs.items()},
            "seconds": round(time.time() - started, 1),
            "torch": torch.__version__,
        } | ({"goal_protocol": ML1_PROTOCOL if config.ml1 else GOAL_PROTOCOL} if any(map(has_hidden_goal, specs))
             else {})
          | ({"custom_tasks": custom} if (custom := custom_specs([s.name for s in specs])) else {}))
    return rows, notes + missing_reference_notes(refs) + no_success_notes(rows)


def no_success_notes(rows: Sequence[dict[str, Any]]) -> list[str]:
    """A note for each task of your own whose env never reported ``info["success"]``, so that its missing success
    columns are said, not silent (the package's tasks without a flag, MuJoCo's and the bandit's, are documented)."""
    custom = custom_specs(sorted({row["task"] for row in rows}))
    flagged = {row["task"] for row in rows if row["success"] != ""}
    return [f"{task}: its env's step never put 'success' in info, so no success rate is reported; a task with one "
            "counts an episode a success when info['success'] is true at any of its steps" for task in custom
            if task not in flagged]


def summarize(rows: Sequence[dict[str, Any]], table: str = "paper",
              plateau_shots: int = PLATEAU_SHOTS) -> list[dict[str, Any]]:
    """Per task and variation: mean normalized score at the first and last shot and its best
    `plateau_shots`-shot plateau (means over seeds), beside the paper's Vintix score; for tasks with a
    success flag (Meta-World) also the success rate at the first shot and its best plateau (else None).
    The paper's Vintix score is None for a task that is not the paper's."""
    scores = _by_shot(rows, f"normalized_{table}", _task_variant)
    successes = _by_shot(rows, "success", _task_variant)
    summary = []
    for (task, variation), shots in sorted(scores.items()):
        curve = _curve(shots)
        plateau, at = best_k_plateau(curve, plateau_shots)
        success = _curve(successes[task, variation]) if (task, variation) in successes else None
        paper = get_task(task).paper_vintix_normalized
        summary.append({"task": task, "variation": variation, "runs": len(shots[min(shots)]), "first": curve[0],
                        "last": curve[-1], "plateau": plateau, "plateau_from": at + 1,
                        "paper_vintix": None if paper is None else paper.mean,
                        "success_first": None if success is None else float(success[0]),
                        "success_plateau": None if success is None else best_k_plateau(success, plateau_shots)[0]})
    return summary


def ml1_success(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per task, Meta-World's ML1 score of an ``ml1`` evaluation: the success rate of each run's scored episodes
    (the 3 after its 10 adaptation episodes), its mean over the runs (test goals) with a 95 % bootstrap interval,
    beside the success rate of the first and the last adaptation episode."""
    scored = range(ML1_ADAPTATION_SHOTS + 1, ML1_ADAPTATION_SHOTS + ML1_SCORED_SHOTS + 1)
    by_run: dict[str, dict[int, dict[int, float]]] = {}
    for row in rows:
        by_run.setdefault(row["task"], {}).setdefault(int(row["seed"]), {})[int(row["shot"])] = float(row["success"])
    summary = []
    for task, runs in sorted(by_run.items()):
        success, low, high = estimate_with_ci(np.array([np.mean([run[s] for s in scored]) for run in runs.values()]),
                                              np.mean)
        summary.append({"task": task, "goals": len(runs), "success": success, "low": low, "high": high,
                        "adaptation_first": float(np.mean([run[1] for run in runs.values()])),
                        "adaptation_last": float(np.mean([run[ML1_ADAPTATION_SHOTS] for run in runs.values()]))})
    return summary


@dataclass(frozen=True)
class ShotResults:
    """One task's cold-start runs as `vintix eval` measures them: row i is env seed ``seeds[i]``, column j shot j+1."""

    task: str
    seeds: list[int]
    returns: np.ndarray
    """[seeds, shots] episode returns"""
    success: np.ndarray
    """[seeds, shots] 0/1 success flags (NaN for a task without one)"""
    scores: np.ndarray
    """[seeds, shots] normalized scores against our measured demonstrators (NaN without a reference)"""

    def per_shot(self, what: str = "success") -> np.ndarray:
        """The mean over seeds of `what` (returns, success or scores) at each shot."""
        values: np.ndarray = getattr(self, what)
        return values.mean(axis=0)


def evaluate_shots(agent: Agent, task: str, shots: int = 10, seeds: int = 5, first_seed: int = 100,
                   reward_input: str = "true", greedy: bool = False, **settings: Any) -> ShotResults:
    """Play `shots` episodes from an empty context on each of `seeds` envs of `task` (seeds `first_seed`, ...) and
    return every episode's return, success and score: Stable-Baselines3's ``evaluate_policy`` habit, for in-context
    runs, with the numbers `vintix eval` prints (it is the same run). `settings`: any other `EvalConfig` field.
    `task` is one task's name: its rows are one task's, so a domain, a split or a list is refused."""
    if not isinstance(task, str):
        raise EvalConfigError(f"evaluate_shots plays one task: give one task's name, e.g. 'reach-v3', not {task!r}")
    if find_task(task) is None:
        if "," in task:
            raise EvalConfigError(f"evaluate_shots plays one task: give one task's name, not the list {task!r}")
        matches = [spec.name for spec in resolve_tasks([task])]  # a name of nothing: UnknownTaskError
        raise EvalConfigError(f"evaluate_shots plays one task, and {task!r} is {len(matches)} tasks "
                              f"({', '.join(matches[:4])}{', ...' if len(matches) > 4 else ''}): give one of them")
    config = EvalConfig(tasks=[task], shots=shots, seeds=seeds, first_seed=first_seed, reward_input=reward_input,
                        greedy=greedy, **settings)
    rows, _ = evaluate(agent, config)
    if not rows:
        raise UnknownTaskError(f"{task!r}: the model plays none of it (its groups: {', '.join(agent.model.groups)})")
    order = sorted({int(r["seed"]) for r in rows})

    def grid(column: str) -> np.ndarray:
        values = np.full((len(order), shots), np.nan)
        for r in rows:
            if r[column] != "":
                values[order.index(int(r["seed"])), int(r["shot"]) - 1] = float(r[column])
        return values

    return ShotResults(rows[0]["task"], order, grid("return"), grid("success"), grid("normalized_ours"))


def shot_curves(rows: Sequence[dict[str, Any]], column: str = "normalized_paper",
                statistic: Callable[[np.ndarray], Any] = np.mean) -> dict[str, np.ndarray]:
    """Per domain (with split and variation, e.g. 'industrial_benchmark test'): `statistic` (the mean, or
    `iqm` as `vintix report` aggregates a domain's scores) of `column` (a normalized score, or 'success') at
    each shot over all its tasks and runs that have it, shots as far as every run went."""
    return {name: _curve(shots, statistic) for name, shots in sorted(_by_shot(rows, column, _domain_name).items())}


def _task_variant(row: dict[str, Any]) -> tuple[str, str]:
    return row["task"], row["variation"]


def _domain_name(row: dict[str, Any]) -> str:
    return " ".join(part for part in (row["domain"], row["split"], row["variation"]) if part)


_Key = TypeVar("_Key", bound=Hashable)


def _by_shot(rows: Sequence[dict[str, Any]], column: str, key: Callable[[dict[str, Any]], _Key]
             ) -> dict[_Key, dict[int, list[float]]]:
    """The values of `column` per `key(row)` and shot, over the rows that have one (not empty)."""
    grouped: dict[_Key, dict[int, list[float]]] = {}
    for row in rows:
        if row[column] != "":
            grouped.setdefault(key(row), {}).setdefault(int(row["shot"]), []).append(float(row[column]))
    return grouped


def _curve(shots: dict[int, list[float]], statistic: Callable[[np.ndarray], Any] = np.mean) -> np.ndarray:
    return np.array([statistic(np.asarray(shots[s])) for s in sorted(shots)])


def shots_to_show(shots: int, columns: int = 12) -> list[int]:
    """Every shot when they fit in `columns`, else the first three and then a spread up to the last."""
    if shots <= columns:
        return list(range(1, shots + 1))
    spread = np.unique(np.geomspace(4, shots, columns - 3).round().astype(int))
    return [1, 2, 3, *spread.tolist()]


def in_context_score(model: Vintix, tasks: Sequence[str], shots: int = TrainConfig.select_shots,
                     seeds: int = TrainConfig.select_seeds, first_seed: int = TrainConfig.select_first_seed,
                     table: str = TrainConfig.select_reference, metric: str = TrainConfig.select_metric,
                     reward_input: str = EvalConfig.reward_input) -> float:
    """The converged in-context score: the mean over the last half of `shots` cold-start shots on
    `tasks`, `seeds` runs each, of the normalized score (`table` reference) or, with `metric`
    'success', of the success flag (over the tasks that have one), with `reward_input` rewards fed
    back (`EvalConfig.reward_input`). Use goals/seeds no training history used (a high
    `first_seed`), so that the best checkpoint is the best *in context*, not the best at recalling
    its training goals."""
    if metric not in SELECT_METRICS:
        raise ConfigError(f"select_metric must be one of {', '.join(map(repr, SELECT_METRICS))}, got {metric!r}")
    was_training = model.training
    model.eval()
    try:
        config = EvalConfig(tasks=list(tasks), shots=shots, seeds=seeds, first_seed=first_seed,
                            reward_input=reward_input)
        rows, _ = evaluate(Agent(model), config)
    finally:
        model.train(was_training)
    column = "success" if metric == "success" else f"normalized_{table}"
    late = [float(r[column]) for r in rows if r["shot"] > shots // 2 and r[column] != ""]
    if not late and metric == "success":
        raise ConfigError(f"none of {list(tasks)} has a success flag (Meta-World tasks have one), "
                          "so there is no success rate to select by; use select_metric 'score', or select_tasks "
                          "with a success flag")
    if not late:
        raise VintixError(f"no '{table}' reference score for any of {list(tasks)}: the in-context score cannot be "
                          f"normalized; choose select_reference 'paper' or select_tasks with scores")
    return float(np.mean(late))


def in_context_scorer(config: TrainConfig) -> Scorer | None:
    """The trainer's checkpoint-selection scorer for `config` (None when it selects no checkpoints): the
    `in_context_score` with true rewards fed back and, with `config.select_reward_gap`, its gap to the
    same runs with zero rewards fed back."""
    if not config.select_every:
        return None

    def select(model: Vintix, tasks: Sequence[str]) -> Selection:
        def score(reward_input: str) -> float:
            return in_context_score(model, tasks, config.select_shots, config.select_seeds, config.select_first_seed,
                                    config.select_reference, config.select_metric, reward_input)

        true = score("true")
        return Selection(true, true - score("zero") if config.select_reward_gap else math.nan)

    return select
