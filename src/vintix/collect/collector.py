"""Collect noise-distilled learning histories into the official dataset layout.

Each history is reproducible from (seed, task, history index) alone: its env seed and its noise
RNG derive from those, never from which other histories share its process. Histories are collected
in fixed batches (indices 0..k-1, k..2k-1, ...) whose envs step in lockstep so the demonstrator
runs batched; a batch is re-collected whole unless all its files exist. Files appear only when
complete, so re-running an interrupted collection finishes exactly what is missing, and gives the
same bytes as an uninterrupted run even if the demonstrator's batched numerics depend on the batch.

Each history records the settings it was made with (root attributes: env seed, base seed, steps,
noise schedule, with the knots its pilot fitted if it had one, and the demonstrator's behaviour when
it is not the expert's) and, per step, the demonstrator's action before noise
(``demonstrator_action``). A demonstrator that infers the hidden goal from rewards
(``behaviour:`` other than ``expert``, `vintix.demonstrators.posterior`) plays the history, and the
goal-aware expert's action is what ``demonstrator_action`` records: the action a model can only
predict by reading the context's rewards (``probe-then-sample`` records its probe in the first episode).
Re-running into a folder whose histories were made with other settings is refused
(`CollectionSettingsError`): skipping them as "already done" would silently keep the wrong data.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from vintix import cluster
from vintix.atomic import check_free_space, check_output_kind, folder_lock, remove_leftovers
from vintix.collect.calibrate import pilot_knots
from vintix.collect.noise import NoiseSchedule, epsilon_greedy, mix_action
from vintix.data import LearningHistory, LearningHistoryWriter, task_directory, write_task_metadata
from vintix.data.layout import HISTORY_END, TERMINATED, TRUNCATED, history_bytes
from vintix.data.writer import UNFINISHED_FILES
from vintix.demonstrators import BEHAVIOURS, Demonstrator, GoalInferringDemonstrator, load_demonstrator
from vintix.errors import DiskSpaceError, VintixError, call_plugin
from vintix.fields import check_field_types
from vintix.interrupt import sigterm_as_ctrl_c
from vintix.memory import ensure_fits
from vintix.tasks import TaskSpec, action_space_of, get_task, make_env
from vintix.tasks.custom import custom_specs

DEFAULT_ENVS_PER_BATCH = 16
"""`CollectionPlan.envs_per_batch` unless given."""


class CollectionError(VintixError, ValueError):
    """A collection plan that cannot run (a setting out of range)."""


class CollectionSettingsError(CollectionError):
    """The output folder already holds histories made with other settings."""


@dataclass(frozen=True)
class CollectionPlan:
    """What to collect for one task."""

    task: str
    histories: int
    """Number of learning histories."""
    steps: int
    """Steps per history (N of the noise schedule)."""
    schedule: NoiseSchedule = NoiseSchedule()
    seed: int = 0
    """Base seed; history i of task t is seeded from (seed, t, i)."""
    envs_per_batch: int = DEFAULT_ENVS_PER_BATCH
    """Histories stepped in lockstep in one process (one batched demonstrator call per step; more
    histories per call leave more of the process's time to the simulator, `vintix bench collect`)."""
    behaviour: str = "expert"
    """How the demonstrator plays: 'expert' (sees the hidden goal), or 'posterior-sampling' / 'probing' /
    'probe-then-sample' (infers it from the rewards it earns; Meta-World, toy and Reacher-hidden-v5 tasks;
    `vintix.demonstrators.posterior`)."""
    probe_margin: float = 0.0
    """With behaviour 'probing' or 'probe-then-sample': how far outside the goal box (in the goal's units)
    the corners its first episode probes lie (`PosteriorSettings.probe_margin`)."""
    lapse_probability: float = 0.0
    """With behaviour 'probe-then-sample': the chance that an episode after the first aimed one is a lapse, a clean
    failure (aimed at a goal drawn from the prior, or its object mishandled) followed by aimed episodes again
    (`PosteriorSettings.lapse_probability`)."""
    reward_tolerance: float = 0.0
    """With a behaviour that infers the goal: the std of its reward likelihood (`PosteriorSettings.reward_tolerance`),
    how far its aimed episodes miss while they close in on the goal; 0: the behaviour's default for the task."""
    aim: str = "hand"
    """What a scripted reach expert puts on the goal: 'hand' (Meta-World's policy) or 'gripper-centre' (what
    reach's success measures; `vintix.demonstrators.base.AIMS`)."""
    target: str = "expert"
    """What a demonstrator that reads its rewards records as each row's demonstrator_action, the target of
    `expert_distillation` training: 'expert', the goal-aware expert's action (a model matches it only by reading
    its rewards), or 'proposal', its own action before the noise (with noise in the history, a model then learns
    to act as the demonstrator would from the states noise put it in, and to recover from its own slips: DART)."""
    demonstrator: str | None = None
    """A demonstrator from outside the package: ``module:callable`` (called with the task name, returns a
    Demonstrator), ``sb3:ALGO:PATH`` / ``sbx:ALGO:PATH`` (a trained model file, unpickled: yours only) or
    ``weights:DIR`` (weights `vintix demonstrator train` wrote); None: the package's own
    (`vintix.demonstrators.base.external_demonstrator`). ``rollouts:CHECKPOINT`` records histories a model played
    (`vintix.agent.rollouts`), which `collect` is handed as its demonstrator."""
    first_history: int = 0
    """index of the plan's first history (its files, its seeds): a later collection into the same folder, such as a
    round of the model's own rollouts beside the histories it was trained on (DAgger), takes the next indices"""

    def __post_init__(self) -> None:
        check_field_types(self, CollectionError)
        bad = [f"{k}={v}" for k, v in (("histories", self.histories), ("steps", self.steps),
                                       ("envs_per_batch", self.envs_per_batch)) if v < 1]
        bad += [f"first_history={self.first_history}"] if self.first_history < 0 else []
        # numpy seed sequences are unsigned; histories record the seed as an HDF5 64-bit integer.
        bad += [f"seed={self.seed}"] if not 0 <= self.seed < 2**63 else []
        if bad:
            raise CollectionError(f"{self.task}: {', '.join(bad)}; histories, steps and envs_per_batch must be >= 1, "
                                  "first_history >= 0, 0 <= seed < 2**63")
        if self.schedule.pilot_steps and self.schedule.knots:
            raise CollectionError(
                f"{self.task}: give knots or pilot_steps, not both (a pilot fits each history's knots)")
        if self.behaviour not in BEHAVIOURS:
            raise CollectionError(
                f"{self.task}: unknown behaviour {self.behaviour!r}; choose one of {', '.join(BEHAVIOURS)}")
        if self.target not in TARGETS:
            raise CollectionError(f"{self.task}: target {self.target!r} is unknown; choose one of {', '.join(TARGETS)}")
        if self.behaviour != "expert" and self.schedule.pilot_steps:
            raise CollectionError(f"{self.task}: pilot_steps fit knots to the expert's answer to noise; a "
                                  f"{self.behaviour} history has no such answer: drop pilot_steps")

    @property
    def indices(self) -> range:
        """The indices of the plan's histories."""
        return range(self.first_history, self.first_history + self.histories)

    def recorded_settings(self, index: int) -> dict[str, Any]:
        """What history `index` of this plan records about how it was made (its file's root attributes)."""
        env_seed = history_seeds(get_task(self.task).name, index, self.seed).env_seed
        # Only settings other than the defaults are recorded, so histories made with the defaults keep their bytes.
        behaviour = {name: getattr(self, name) for name, default in DEMONSTRATOR_SETTING_DEFAULTS.items()
                     if getattr(self, name) != default}
        return {"task": get_task(self.task).name, "env_seed": env_seed, "collection_seed": self.seed,
                "steps": self.steps, **self.schedule.recorded(), **behaviour}

    def load_demonstrator(self) -> Demonstrator:
        """The demonstrator this plan's histories are played by."""
        return load_demonstrator(get_task(self.task).name, behaviour=self.behaviour, source=self.demonstrator,
                                 probe_margin=self.probe_margin, aim=self.aim,
                                 lapse_probability=self.lapse_probability, reward_tolerance=self.reward_tolerance)


TARGETS = ("expert", "proposal")
"""What a reward-reading demonstrator's rows may record as their target (`CollectionPlan.target`)."""

DEMONSTRATOR_SETTING_DEFAULTS: dict[str, Any] = {
    field.name: field.default for field in fields(CollectionPlan)
    if field.name in ("behaviour", "probe_margin", "lapse_probability", "reward_tolerance", "aim", "target",
                      "demonstrator")}
"""The `CollectionPlan` fields that say how the demonstrator plays, with their defaults: each is recorded in a
history where it is not the default (in the fields' order, the order of a file's attributes), so a history that
does not record one was made with its default."""


@dataclass(frozen=True)
class HistorySummary:
    """What a finished history looks like, for the end-of-run report."""

    path: Path
    task: str
    steps: int
    episode_returns: np.ndarray
    """the return of each complete episode: an episode the history's end cut short is left out"""
    collected_now: bool
    """False when the file was already there from an earlier (interrupted) run."""

    def mean_return(self, first: bool, fraction: float = 0.1) -> float:
        """Mean return of the first (or last) `fraction` of the history's complete episodes (NaN: none)."""
        if not len(self.episode_returns):
            return float("nan")
        n = max(1, int(len(self.episode_returns) * fraction))
        chosen = self.episode_returns[:n] if first else self.episode_returns[-n:]
        return float(np.mean(chosen))


def history_path(root: Path, spec: TaskSpec, index: int) -> Path:
    return task_directory(root, spec.domain, spec.name) / f"history-{index:04d}.h5"


class HistorySeeds(NamedTuple):
    """What one history is seeded with."""

    env_seed: int
    noise: np.random.Generator
    """The uniform noise mixed into the history's actions."""
    pilot_noise: np.random.Generator
    """The noise of its pilot run (`NoiseSchedule.pilot_steps`), a stream of its own so that histories
    without a pilot are the same as before pilots existed."""
    demonstrator: np.random.Generator
    """The draws of a demonstrator that learns within the history (its goal guesses); a stream of its own."""


def history_seeds(task: str, index: int, seed: int) -> HistorySeeds:
    """The seeds of one history; crc32 because Python's str hash changes per process."""
    sequence = np.random.SeedSequence([seed, zlib.crc32(task.encode()), index])
    # Children are numbered: a fourth stream leaves the first three (and older histories) unchanged.
    env_sequence, noise_sequence, pilot_sequence, demonstrator_sequence = sequence.spawn(4)
    return HistorySeeds(int(env_sequence.generate_state(1)[0]), np.random.default_rng(noise_sequence),
                        np.random.default_rng(pilot_sequence), np.random.default_rng(demonstrator_sequence))


def batches(plan: CollectionPlan) -> list[list[int]]:
    k = plan.envs_per_batch
    return [list(plan.indices[start:start + k]) for start in range(0, plan.histories, k)]


BLOCK_STEPS = 1_000
"""Steps buffered per batch before each history's rows go to its writer in one append: appending
(and checking) one row at a time cost more than stepping InvertedPendulum."""


@dataclass
class _Block:
    """The rows of the last few steps of a batch of histories, [step, history, ...], and their noise."""

    observation: np.ndarray
    action: np.ndarray
    demonstrator_action: np.ndarray
    reward: np.ndarray
    step_num: np.ndarray
    noise: np.ndarray
    """Uniform noise of each history for these steps, drawn from its own RNG in one call per block (a discrete
    task's: two uniform [0, 1) draws per step, `epsilon_greedy`'s coin and random action)."""
    episode_end: np.ndarray
    """0, or how the episode ended at this step (`vintix.data.layout.TERMINATED`, ...)"""
    final_observation: np.ndarray
    """the observation the env returned after an episode's last step (meaningful where `episode_end`)"""

    @classmethod
    def empty(cls, steps: int, histories: int, obs_dim: int, act_dim: int, discrete: bool = False) -> _Block:
        # A discrete task's actions are one index per step.
        action_shape, action_dtype = ((), np.int64) if discrete else ((act_dim,), np.float32)
        return cls(np.empty((steps, histories, obs_dim), np.float32),
                   np.empty((steps, histories, *action_shape), action_dtype),
                   np.empty((steps, histories, *action_shape), action_dtype), np.empty((steps, histories), np.float32),
                   np.empty((steps, histories), np.int64), np.empty((steps, histories, 2 if discrete else act_dim)),
                   np.zeros((steps, histories), np.int8), np.zeros((steps, histories, obs_dim), np.float32))

    def write(self, steps: int, writers: Sequence[LearningHistoryWriter]) -> None:
        """Append the first `steps` rows of each history to its writer."""
        for i, writer in enumerate(writers):
            writer.append(self.observation[:steps, i], self.action[:steps, i], self.reward[:steps, i],
                          self.step_num[:steps, i], demonstrator_action=self.demonstrator_action[:steps, i],
                          episode_end=self.episode_end[:steps, i], final_observation=self.final_observation[:steps, i])


def collect_batch(plan: CollectionPlan, indices: Sequence[int], root: Path,
                  demonstrator: Demonstrator | None = None, progress_position: int = 0) -> list[Path]:
    """Collect histories `indices` of `plan.task` together, writing one file each (after each one's
    pilot run, if the schedule has one)."""
    spec = get_task(plan.task)
    demonstrator = demonstrator or plan.load_demonstrator()
    seeds = [history_seeds(spec.name, i, plan.seed) for i in indices]
    envs = [make_env(spec.name, seed=s.env_seed) for s in seeds]
    label = f"{spec.name} histories {indices[0]}-{indices[-1]}"
    writers: list[LearningHistoryWriter] = []
    try:
        schedules = _history_schedules(plan, envs, demonstrator, [s.pilot_noise for s in seeds],
                                       f"{label} pilot", progress_position)
        writers = [LearningHistoryWriter(history_path(root, spec, i), spec.obs_dim, spec.act_dim,
                                         demonstrator_actions=True, episode_ends=True, discrete=spec.discrete,
                                         attrs=plan.recorded_settings(i) | schedule.recorded())
                   for i, schedule in zip(indices, schedules, strict=True)]
        # One column per history only when pilots gave them schedules of their own: a 1M-step batch of 16
        # would otherwise hold 16 copies of the same 8 MB column.
        distinct = schedules if plan.schedule.pilot_steps else schedules[:1]
        ensure_fits(8 * plan.steps * len(distinct), f"the noise levels of {len(distinct)} {plan.steps:,}-step "
                    "history(ies)", "Collect shorter histories (steps)")
        epsilons = np.stack([schedule.epsilon(np.arange(plan.steps), plan.steps) for schedule in distinct], axis=1)
        _play(envs, demonstrator, epsilons, [s.noise for s in seeds], label, progress_position,
              lambda block, start, rows: block.write(rows, writers), [s.demonstrator for s in seeds],
              record_proposal=plan.target == "proposal")
        return [writer.close() for writer in writers]
    except BaseException:
        for writer in writers:
            writer.abort()
        raise
    finally:
        for env in envs:
            env.close()


def _history_schedules(plan: CollectionPlan, envs: Sequence[gym.Env], demonstrator: Demonstrator,
                       rngs: Sequence[np.random.Generator], label: str, progress_position: int) -> list[NoiseSchedule]:
    """The schedule of each history of a batch: the plan's, or, with a pilot, knots fitted to a run of
    `pilot_steps` under linear decay on the history's own env (on Meta-World, its goal)."""
    steps = plan.schedule.pilot_steps
    if not steps:
        return [plan.schedule] * len(envs)
    epsilon = NoiseSchedule().epsilon(np.arange(steps), steps)
    reward, step_num = np.empty((steps, len(envs)), np.float32), np.empty((steps, len(envs)), np.int64)

    def keep(block: _Block, start: int, rows: int) -> None:
        reward[start:start + rows], step_num[start:start + rows] = block.reward[:rows], block.step_num[:rows]

    _play(envs, demonstrator, epsilon[:, None], rngs, label, progress_position, keep)
    try:
        return [replace(plan.schedule, knots=pilot_knots(epsilon, reward[:, i], step_num[:, i]))
                for i in range(len(envs))]
    except ValueError as error:
        raise CollectionError(f"{plan.task}: {error}") from error


def _play(envs: Sequence[gym.Env], demonstrator: Demonstrator, epsilons: np.ndarray,
          rngs: Sequence[np.random.Generator], label: str, progress_position: int,
          on_block: Callable[[_Block, int, int], None],
          demonstrator_rngs: Sequence[np.random.Generator] = (), record_proposal: bool = False) -> None:
    """Play `envs` from a reset for ``len(epsilons)`` steps, env i at noise ``epsilons[t, i]`` (or all at
    ``epsilons[t, 0]`` when it has one column), handing each full block of rows to
    ``on_block(block, first step, rows)``.

    The envs step in lockstep: one batched demonstrator call per step, the noise mixed in for all
    histories at once, rows buffered for `BLOCK_STEPS` steps. Each history's noise still comes from
    its own RNG, drawn in the order a step-by-step loop would draw it, so the data do not depend on
    the block size. A demonstrator that learns within the history (`GoalInferringDemonstrator`) starts
    afresh with `demonstrator_rngs`, is told what every step earned, and its goal-aware expert's action
    is the row's demonstrator action (with `record_proposal`, its own action before the noise instead).
    """
    learner = demonstrator if isinstance(demonstrator, GoalInferringDemonstrator) else None
    if learner is not None:
        learner.begin(envs, demonstrator_rngs)
    total = len(epsilons)
    space = action_space_of(envs[0].action_space)
    discrete = isinstance(space, gym.spaces.Discrete)
    # A discrete task's "bounds" are its first and last action, and its noise two uniform draws (`epsilon_greedy`).
    low: np.ndarray
    high: np.ndarray
    if isinstance(space, gym.spaces.Discrete):
        low, high = np.zeros(1), np.full(1, int(space.n) - 1)
    else:
        low, high = space.low, space.high
    observations = np.stack([env.reset()[0] for env in envs])
    block = _Block.empty(min(BLOCK_STEPS, total), len(envs), observations.shape[1], len(low), discrete)
    step_nums = np.zeros(len(envs), dtype=np.int64)
    for t in tqdm(range(total), desc=label, position=progress_position, leave=False, mininterval=1.0, disable=None):
        k = t % len(block.step_num)
        if k == 0:
            size = min(len(block.step_num), total - t)
            for i, rng in enumerate(rngs):
                block.noise[:size, i] = (rng.random(size=(size, 2)) if discrete
                                         else rng.uniform(low, high, size=(size, len(low))))
        # What the demonstrator proposes, inside the action bounds: the action it would execute at ε = 0.
        proposal = _within(call_plugin(f"{label}: the demonstrator's act", "Fix the demonstrator",
                                       demonstrator.act, observations, envs), low, high, discrete, label)
        target = proposal if learner is None or record_proposal else _within(
            learner.expert_act(observations, envs), low, high, discrete, label)
        if discrete:
            actions = epsilon_greedy(proposal, epsilons[t], block.noise[k], int(high[0]) + 1)
        else:  # float32 before stepping, so the action stored is exactly the action executed.
            actions = mix_action(proposal, epsilons[t][:, None], block.noise[k]).astype(np.float32)
        block.observation[k], block.action[k], block.demonstrator_action[k] = observations, actions, target
        block.step_num[k] = step_nums
        for i, env in enumerate(envs):
            next_obs, reward, terminated, truncated, _ = env.step(actions[i])
            block.reward[k, i] = reward
            if learner is not None:
                learner.observe(i, env, actions[i], float(reward), terminated or truncated)
            # Terminated wins over truncated when both hold (gymnasium's convention for what ended it).
            ended = TERMINATED if terminated else TRUNCATED if truncated else HISTORY_END if t == total - 1 else 0
            block.episode_end[k, i] = ended
            if ended:
                block.final_observation[k, i] = next_obs
            if terminated or truncated:
                next_obs, _ = env.reset()
                step_nums[i] = 0
            else:
                step_nums[i] += 1
            observations[i] = next_obs
        if k == len(block.step_num) - 1 or t == total - 1:
            on_block(block, t - k, k + 1)


def _within(actions: np.ndarray, low: np.ndarray, high: np.ndarray, discrete: bool, label: str) -> np.ndarray:
    """A demonstrator's actions inside the action bounds: a Box's clipped; a Discrete's must be its indices, since
    rounding an action that is not one would record a choice the demonstrator never made."""
    if not discrete:
        return np.clip(actions, low, high)
    indices = np.asarray(actions).reshape(-1)
    if indices.dtype.kind not in "iu" or indices.min() < 0 or indices.max() > high[0]:
        raise CollectionError(f"{label}: the demonstrator's actions {indices[:8].tolist()} are not indices 0-"
                              f"{int(high[0])} of the task's Discrete({int(high[0]) + 1}) space; fix the demonstrator")
    return indices.astype(np.int64)


def settings_differences(path: Path, plan: CollectionPlan, index: int) -> list[str]:
    """How an existing history `index` differs from what `plan` would make: ``"steps 1000 (now 500)"``.
    Files without recorded settings (older or published ones) are compared on their length alone."""
    with LearningHistory(path) as history:
        found = {**history.attrs, "steps": history.num_steps}
        differences = [] if history.has_demonstrator_action else ["no demonstrator actions (now stored)"]
    recorded = plan.recorded_settings(index)
    if "curvature" in found:  # a file of ours, its schedule read as the schedule reads it (no knots: the power law)
        schedule = NoiseSchedule.from_recorded(found)
        found |= {"knots": list(schedule.knots), "pilot_steps": schedule.pilot_steps, "level": schedule.level}
        recorded.setdefault("pilot_steps", 0)
        recorded.setdefault("level", None)
        for key, default in DEMONSTRATOR_SETTING_DEFAULTS.items():  # recorded only when not the default
            found.setdefault(key, default)
            recorded.setdefault(key, default)
        if not plan.schedule.pilot_steps:  # with a pilot, each history fitted its own knots: nothing to compare
            recorded.setdefault("knots", [])
    return differences + [f"{key} {found[key]!r} (now {value!r})" for key, value in recorded.items()
                          if key in found and found[key] != value]


def _check_existing_histories(plan: CollectionPlan, root: Path) -> None:
    spec = get_task(plan.task)
    for index in plan.indices:
        path = history_path(root, spec, index)
        differences = settings_differences(path, plan, index) if path.exists() else []
        if differences:
            raise CollectionSettingsError(
                f"{path.parent} holds histories made with other settings ({path.name}: {', '.join(differences)}), "
                "so there is nothing to resume; collect into another --out, re-run with the folder's settings, or "
                f"delete {path.parent} to collect it anew"
            )


def _collect_batch_in_worker(args: tuple[CollectionPlan, list[int], Path, Demonstrator | None, int]) -> list[Path]:
    plan, indices, root, demonstrator, position = args
    return collect_batch(plan, indices, root, demonstrator, progress_position=position)


def _start_worker(parent: int) -> None:
    import torch

    torch.set_num_threads(1)  # one process per core: threads inside would only contend
    # The parent owns its workers: Ctrl-C reaches it (and the whole process group), and it ends every
    # worker with SIGTERM, on which a worker deletes its unfinished files and exits.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _exit_quietly)
    if sys.platform == "linux":
        # A parent that cannot end its workers (kill -9) would leave them blocked forever on a queue it no
        # longer feeds: Linux sends them SIGTERM when it dies (prctl PR_SET_PDEATHSIG).
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:  # the parent died before the line above could ask for the signal
        os._exit(1)


_PR_SET_PDEATHSIG = 1
"""linux/prctl.h"""


def _exit_quietly(signum: int, frame: object) -> None:
    # Deleting the unfinished histories and leaving at once, rather than raising: an exception raised
    # wherever the signal lands (a destructor, say) would be printed, not unwound.
    for path in list(UNFINISHED_FILES):
        path.unlink(missing_ok=True)
    os._exit(128 + signum)


def collect(plans: CollectionPlan | Sequence[CollectionPlan], root: str | Path, workers: int = 1,
            demonstrator: Demonstrator | None = None, ray: str | None = None) -> list[HistorySummary]:
    """Collect every missing history of `plans` under `root`, spreading batches of all tasks over
    `workers` processes, or over the Ray cluster at address `ray` ("auto": see `vintix.cluster.connect`);
    returns a summary of every history of the plans. `demonstrator` (one task only) defaults to the
    project's demonstrator of each task."""
    plans = [plans] if isinstance(plans, CollectionPlan) else list(plans)
    root = Path(root)
    if workers < 1:
        raise CollectionError(f"workers must be >= 1, got {workers}")
    # Fail before writing anything: a missing Ray or an unreachable cluster, a task without a demonstrator.
    if ray is not None:
        cluster.connect(ray)
    if demonstrator is None:
        check_demonstrators(plans)
    check_output_kind(root, "dataset")
    check_disk_space(plans, root)
    # `kill` ends a collection as Ctrl-C does: its unfinished files removed, its workers ended.
    with folder_lock(root, "vintix collect"), sigterm_as_ctrl_c():
        return _collect(plans, root, workers, demonstrator, ray)


def check_demonstrators(plans: Sequence[CollectionPlan], untrained_ok: bool = False) -> list[str]:
    """Load each plan's demonstrator once, so that a setting it refuses (a behaviour the task has no demonstrator
    for, a probe margin without a probe, a demonstrator that cannot be loaded) fails now: `collect` and
    `collect --plan` check the same. With `untrained_ok` (a plan for a machine that may have them), a demonstrator
    whose weights are not trained yet is returned as a note instead."""
    from vintix.demonstrators.trained import MissingDemonstratorError

    notes = []
    for plan in plans:
        try:
            plan.load_demonstrator()
        except MissingDemonstratorError as error:
            if not untrained_ok:
                raise
            notes.append(str(error))
    return notes


def check_disk_space(plans: Sequence[CollectionPlan], root: Path) -> None:
    """A CollectionError now, not a full disk hours from now, when the histories still to collect need more
    space than the folder's file system has free (`history_bytes`)."""
    missing = sum(history_bytes(get_task(plan.task), plan.steps) for plan in plans for i in plan.indices
                  if not history_path(root, get_task(plan.task), i).exists())
    try:
        check_free_space(root, missing, "the histories still to collect", "free space, collect fewer or shorter "
                         "histories, or write elsewhere (--out)")
    except DiskSpaceError as error:
        raise CollectionError(str(error)) from None


def _collect(plans: list[CollectionPlan], root: Path, workers: int, demonstrator: Demonstrator | None,
             ray: str | None) -> list[HistorySummary]:
    jobs = []
    for plan in plans:
        spec = get_task(plan.task)
        _check_existing_histories(plan, root)
        # The noise-free tail fraction tells expert distillation (a training ablation) which rows to keep.
        # A task of your own travels with its data, so training and `vintix data` need no registration.
        custom = custom_specs([spec.name])
        write_task_metadata(task_directory(root, spec.domain, spec.name), spec.name, spec.obs_dim, spec.act_dim,
                            discrete=spec.discrete, domain=spec.domain, group=spec.group,
                            reward_scale=spec.reward_scale,
                            noise_free_fraction=plan.schedule.noise_free_fraction,
                            **({"custom_task": custom[spec.name]} if custom else {}))
        jobs += [(plan, indices, root, demonstrator) for indices in batches(plan)
                 if not all(history_path(root, spec, i).exists() for i in indices)]
    for plan, indices, *_ in jobs:  # what a killed collection left of the histories it was writing
        for index in indices:
            remove_leftovers(history_path(root, get_task(plan.task), index))
    if ray is not None:
        _collect_on_ray(jobs, root)
    elif workers > 1 and len(jobs) > 1:
        # Leaving the pool's block for any reason (a worker's error, Ctrl-C, or `kill`, which collect()
        # turns into Ctrl-C) terminates the workers and waits for them: they are never orphaned, blocked
        # on a queue nobody feeds, and they remove their unfinished files.
        with multiprocessing.Pool(workers, initializer=_start_worker, initargs=(os.getpid(),)) as pool:
            pool.map(_collect_batch_in_worker, [(*job, n % workers) for n, job in enumerate(jobs)], chunksize=1)
            # The normal end lets each worker take its sentinel and exit. Only an abnormal one goes through the
            # block's terminate(), which races the idle workers for the task queue's lock (they hold it while
            # waiting for work) and signals them mid-wait: the suspect in a collection that wrote every history
            # and then did not exit (seen once, under load; not reproduced).
            pool.close()
            pool.join()
    else:
        for job in jobs:
            collect_batch(*job)
    fresh = {history_path(root, get_task(plan.task), i) for plan, indices, *_ in jobs for i in indices}
    paths = [history_path(root, get_task(plan.task), i) for plan in plans for i in plan.indices]
    return [summarize_history(path, collected_now=path in fresh) for path in paths]


def _collect_on_ray(jobs: list[tuple[CollectionPlan, list[int], Path, Demonstrator | None]], root: Path) -> None:
    """One Ray task per batch, each writing its files under `root` as a local worker would. Workers on
    other machines write to their own disks unless `root` is a shared filesystem: said here, not left
    to a missing-file error in the summary."""
    calls = [((plan, indices, root.absolute(), demonstrator, 0),) for plan, indices, _, demonstrator in jobs]
    for _ in cluster.map_tasks(_collect_batch_in_worker, calls, "history batches"):
        pass
    missing = [path for plan, indices, *_ in jobs
               for path in (history_path(root, get_task(plan.task), i) for i in indices) if not path.exists()]
    if missing:
        raise CollectionError(f"Ray workers wrote {len(missing)} histories that this machine cannot see under {root} "
                              f"(e.g. {missing[0]}): --out must be a folder every node of the cluster shares")


def summarize_history(path: Path, collected_now: bool) -> HistorySummary:
    with LearningHistory(path) as history:
        returns, ends = history.episode_returns(), history.episode_ends()
        # The last episode is cut short where the history's end came first (recorded as such; a file that
        # records no episode ends: unless its last step is an episode's last, which it cannot tell, so it goes).
        cut = ends is None or ends[1][-1] == HISTORY_END
        complete = returns[:-1] if cut and len(returns) > 1 else returns
        return HistorySummary(path, str(history.attrs.get("task", path.parent.name)), history.num_steps, complete,
                              collected_now)
