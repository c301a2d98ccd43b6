"""The in-context agent: a Vintix model stepping a batch of envs, one token per env step.

Cold start (paper §2.3.3): the context starts empty; each step appends the token
``[o_t | a_{t-1} | r_{t-1}]`` of every env and reads off ``a_t``. The previous action is the agent's
own last action (as clipped and sent to the env). Task names serve only to pick each env's group
(its encoder and head) and its observation normalization; the model never receives a task id.

Tasks without statistics in the checkpoint (held-out tasks: ML45 test tasks, Industrial Benchmark
setpoints ≥ 80) use their group's pooled statistics: the mixture of the group's per-task
normalizations, each task weighted equally. `AgentTask.norm_source` says which one an env got.
"""

from __future__ import annotations

import functools
import os
import threading
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar, cast

import gymnasium as gym
import numpy as np
import torch

from vintix.agent.cache import KVCache, cached_backbone
from vintix.agent.pretrained import resolve_checkpoint
from vintix.errors import UnknownTaskError, VintixError
from vintix.fields import check_threads
from vintix.model.checkpoint import CheckpointError, load_pretrained
from vintix.model.model import Vintix, episode_returns_so_far, normalize_inputs
from vintix.tasks import ActionSpaceError, action_space_of, find_task, get_task, task_action_space
from vintix.tasks.layouts import ObsLayout
from vintix.train.checkpoint import intact_alternative_hint


class AgentInputError(VintixError, ValueError):
    """An observation, reward or prompt the agent cannot take (wrong shape, NaN or inf)."""


class AgentStateError(VintixError, RuntimeError):
    """An agent used out of order (acting, prompting or keeping envs before `Agent.reset`)."""


class AgentOutputError(VintixError, ArithmeticError):
    """The model computed a NaN or inf action (damaged weights, or a numerical overflow): the agent
    raises instead of sending it, as clipping cannot make NaN an action within the env's bounds."""


@dataclass(frozen=True)
class AgentTask:
    """How the agent treats one env: group, normalization, action bounds."""

    task: str
    group: str
    obs_mean: torch.Tensor
    obs_std: torch.Tensor
    reward_scale: float
    norm_source: str
    """'task' (the checkpoint's statistics of this task) or 'group-pooled' (held-out task)"""
    action_low: np.ndarray
    """a Box task's bounds (a discrete task's: 0 and its last action)"""
    action_high: np.ndarray
    obs_layout: ObsLayout | None = None
    """how the env's observation becomes the group's (`vintix.tasks.layouts`); None: as it is"""

    def env_obs_dim(self, model: Vintix) -> int:
        """Dimension of the observations the env gives (and `Agent.act` takes)."""
        return self.obs_layout.env_dim if self.obs_layout is not None else model.groups[self.group].obs_dim


def _checkpoint_task_index(model: Vintix, task: str) -> int | None:
    """Index of `task` in the checkpoint's norms, matching the name or any registry alias."""
    try:
        return model.task_index(task)
    except UnknownTaskError:
        pass
    try:
        canonical = get_task(task).name
    except UnknownTaskError:
        return None
    for index, norm in enumerate(model.task_norms):
        try:
            if get_task(norm.task).name == canonical:
                return index
        except UnknownTaskError:
            continue
    return None


def _pooled_reward_scale(model: Vintix, members: list[int], registry_scale: float) -> float:
    """The reward scale of a task the checkpoint has no statistics of: where training put every task's rewards at
    unit scale (`TrainConfig.normalize_rewards`, each task's own 1 / std), the mean of its group's scales, which is
    what the model learned to read; else the registry's, which training used too."""
    normalized = model.checkpoint_extra.get("train_config", {}).get("normalize_rewards", False)
    return float(model.reward_scale[members].mean()) if normalized else registry_scale


def resolve_task(model: Vintix, task: str, action_space: gym.spaces.Box | gym.spaces.Discrete | None = None
                 ) -> AgentTask:
    """Group and normalization of `task` for `model`; an unknown task or group, or an action space of another kind
    or size than the group's, is a clear error."""
    index = _checkpoint_task_index(model, task)
    if index is not None:
        group = model.task_norms[index].group
        dim = model.groups[group].obs_dim
        mean, std = model.obs_mean[index, :dim], model.obs_std[index, :dim]
        reward_scale, source = float(model.reward_scale[index]), "task"
        layout = model.task_norms[index].obs_layout
    else:
        spec = get_task(task)  # raises UnknownTaskError naming close matches
        group = spec.group
        if group not in model.groups:
            raise UnknownTaskError(
                f"task {task!r} belongs to group {group!r}, which this checkpoint has no encoder for; its "
                f"groups are {sorted(model.groups)}. Evaluate tasks of those groups or train on {group!r}."
            )
        dim = model.groups[group].obs_dim
        members = [i for i, norm in enumerate(model.task_norms) if norm.group == group]
        means, stds = model.obs_mean[members, :dim], model.obs_std[members, :dim]
        divisor_floor = model.config.std_floor + model.config.std_epsilon  # as the model's own divisors
        mean = means.mean(0)
        std = ((stds**2 + means**2).mean(0) - mean**2).clamp_min(0).sqrt().clamp_min(divisor_floor)
        reward_scale, source, layout = _pooled_reward_scale(model, members, spec.reward_scale), "group-pooled", None
    known = find_task(task)
    env_dim = layout.env_dim if layout is not None else model.groups[group].obs_dim
    if known is not None and known.obs_dim != env_dim:
        raise AgentInputError(
            f"task {task!r} has {known.obs_dim}-dim observations but the checkpoint's group {group!r} expects "
            f"{env_dim}; the checkpoint was trained on another version of this env"
        )
    group_spec = model.groups[group]
    try:
        space = action_space_of(action_space if action_space is not None else task_action_space(task))
    except ActionSpaceError as error:
        raise AgentInputError(f"task {task!r}: {error}") from error
    if isinstance(space, gym.spaces.Discrete) != group_spec.discrete:
        kind, other = ("discrete", "continuous (Box)") if group_spec.discrete else ("continuous", "discrete")
        raise AgentInputError(
            f"task {task!r} acts in {space}, but the checkpoint's group {group!r} is {kind}: a {kind} model cannot "
            f"play a {other} task. Evaluate it on tasks of its own kind, or train a model on {task!r}'s data")
    if isinstance(space, gym.spaces.Discrete):
        if int(space.n) != group_spec.act_dim:
            raise AgentInputError(f"task {task!r}: action space {space} has {int(space.n)} actions, group {group!r} "
                                  f"chooses among {group_spec.act_dim}")
        low, high = np.zeros(1, np.float32), np.full(1, group_spec.act_dim - 1, np.float32)
    else:
        low, high = np.asarray(space.low, np.float32), np.asarray(space.high, np.float32)
        if low.shape != (group_spec.act_dim,):
            raise AgentInputError(
                f"task {task!r}: action space has shape {low.shape}, group {group!r} acts in {group_spec.act_dim} dims"
            )
    return AgentTask(task, group, mean, std, reward_scale, source, low, high, layout)


def _one_per_env(what: str, values: np.ndarray, n: int) -> np.ndarray:
    """`values` as one entry per env of `n`; any other count (one value for several envs included: it would
    be spread over all of them) is an AgentInputError naming `what`."""
    flat = values.reshape(-1)
    if len(flat) != n:
        raise AgentInputError(f"{what} has {len(flat)} value(s) for {n} env(s); give one per env, in the order of "
                              "agent.reset's tasks")
    return flat


def _numbers(what: str, values: object, dtype: type) -> np.ndarray:
    """`values` as an array of `dtype`; text (even "1.5"), complex numbers, None or ragged lists are an
    AgentInputError naming `what`, and so are flags other than 0/1 where `dtype` is bool."""
    try:
        array = np.asarray(values)
    except (TypeError, ValueError) as error:
        raise AgentInputError(f"{what} must be numbers: {error}") from error
    kinds = "biu" if dtype is bool else "biuf"  # numpy's bool, int, unsigned, float kinds
    if array.dtype.kind not in kinds:
        wanted = "booleans (or 0/1)" if dtype is bool else "real numbers"
        raise AgentInputError(f"{what} must be {wanted}, got {array.dtype} values: {values!r}"[:300])
    if dtype is bool and not np.isin(array, (0, 1)).all():
        raise AgentInputError(f"{what} must be booleans (or 0/1), got {values!r}"[:300])
    return array.astype(dtype)


@dataclass(frozen=True)
class _GroupBatch:
    """The envs of one group within the batch, with their per-env constants stacked once at reset."""

    envs: torch.Tensor
    obs_mean: torch.Tensor
    obs_std: torch.Tensor
    reward_scale: torch.Tensor
    action_low: torch.Tensor
    action_high: torch.Tensor

    @classmethod
    def of(cls, tasks: list[AgentTask], group: str, device: torch.device) -> _GroupBatch:
        envs = [i for i, t in enumerate(tasks) if t.group == group]
        members = [tasks[i] for i in envs]

        def stack(values: list[np.ndarray]) -> torch.Tensor:
            return torch.as_tensor(np.stack(values), dtype=torch.float32, device=device)

        return cls(
            envs=torch.tensor(envs, device=device),
            obs_mean=torch.stack([t.obs_mean for t in members]).to(device),
            obs_std=torch.stack([t.obs_std for t in members]).to(device),
            reward_scale=torch.tensor([t.reward_scale for t in members], device=device),
            action_low=stack([t.action_low for t in members]),
            action_high=stack([t.action_high for t in members]),
        )


def _autoreset_mode(mode: str | gym.vector.AutoresetMode) -> str:
    """'same-step' or 'next-step' from either spelling; a vector env that does not reset itself
    (``AutoresetMode.DISABLED``) is reset by the caller, which is same-step for the agent."""
    modes = {"same-step": "same-step", "next-step": "next-step", gym.vector.AutoresetMode.SAME_STEP: "same-step",
             gym.vector.AutoresetMode.NEXT_STEP: "next-step", gym.vector.AutoresetMode.DISABLED: "same-step"}
    if mode not in modes:
        raise AgentInputError(f"autoreset must be 'same-step', 'next-step' or a gymnasium AutoresetMode, got {mode!r}")
    return modes[mode]


class ContextDiscardedWarning(UserWarning):
    """`Agent.reset` threw away a context: everything the agent had learned in it."""


_AgentMethod = TypeVar("_AgentMethod", bound=Callable[..., Any])


def _one_call_at_a_time(method: _AgentMethod) -> _AgentMethod:
    """Run `method` holding the agent's lock: its context is one sequence, and two threads stepping it at
    once would interleave their tokens (or fail mid-write) instead of raising a clear error."""

    @functools.wraps(method)
    def guarded(self: Agent, *args: Any, **kwargs: Any) -> Any:
        if not self._busy.acquire(blocking=False):
            raise AgentStateError(f"agent.{method.__name__} while another thread is inside this agent; an Agent "
                                  "holds one context: give each thread its own Agent (they can share the model)")
        try:
            return method(self, *args, **kwargs)
        finally:
            self._busy.release()

    return cast(_AgentMethod, guarded)


class Agent:
    """A stateful policy over a batch of envs, with a sliding-window KV cache (`KVCache`).

    ``agent.reset(tasks)``, then each step ``actions = agent.act(obs, prev_rewards, episode_starts)``.
    Envs of a batch may belong to different groups; they share one backbone forward per step.
    """

    def __init__(self, model: Vintix, seed: int = 0, threads: int | None = None) -> None:
        """`seed`: the draws of a sampling head's actions (categorical, gaussian, flow: `vintix.model.ActionHead`),
        restarted at every `reset`, so a run is reproducible; a deterministic model draws nothing. `threads`:
        torch's CPU threads for this process (`torch.set_num_threads`), None to leave them as they are. One thread
        suits a small model stepping a few envs: its step is too short to share, and with torch's default (one
        thread per core) a core another job holds stalls every step (a shipped model's step on a 2-core CPU with a
        training on it: 20.7 ms mean with 2 threads, 1.3 ms with 1)."""
        if threads is not None:
            try:
                torch.set_num_threads(check_threads(threads))
            except ValueError as error:
                raise AgentInputError(f"{error} (or None for torch's setting)") from None
        self.model = model
        self.seed = seed
        self.sample_noise = model.config.sample_noise
        """how often a sampling head draws its noise: 'step' or 'episode' (`ModelConfig.sample_noise`, the model's
        own by default; no weight depends on it)"""
        self._streams: list[torch.Generator] = []
        """each env's own stream of draws (`reset`'s seeds)"""
        self.tasks: list[AgentTask] = []
        self.cache: KVCache | None = None
        self._groups: dict[str, _GroupBatch] = {}
        self._prev_action: dict[str, torch.Tensor] = {}
        self._held_noise: dict[str, torch.Tensor] = {}
        """per group, each env's noise of its last draw (`_noise`)"""
        self._busy = threading.Lock()
        self._awaiting_start = np.zeros(0, dtype=bool)
        self._last_rewards = np.zeros(0)
        """per env, sat out the last step under next-step autoreset: its next observation starts an episode"""
        self._episode_returns = np.zeros(0)
        """per env, what its episode had earned before the last token fed (`ModelConfig.episode_return`)"""

    @classmethod
    def from_pretrained(cls, directory: str | os.PathLike[str], device: str | torch.device = "cpu",
                        threads: int | None = None, trust_code: bool = False) -> Agent:
        """An agent around the model saved in `directory`: a checkpoint (see `vintix.model.save_pretrained`),
        a training run's folder (its best checkpoint, else its newest), or a shipped model's name
        (`vintix.agent.shipped_models`, e.g. ``"cpu-suite"``). A damaged checkpoint of a training run
        raises CheckpointError naming the run's newest intact one: evaluating another step than the
        one asked for is the user's choice, never a silent fallback. `threads`: as `Agent`'s (1 for a few
        envs on a CPU). `trust_code`: run the code its custom tasks name (`vintix.model.load_pretrained`)."""
        resolved = resolve_checkpoint(directory)
        try:
            return cls(load_pretrained(resolved, device, trust_code), threads=threads)
        except CheckpointError as error:
            raise CheckpointError(f"{error}{intact_alternative_hint(resolved)}") from error

    @property
    def device(self) -> torch.device:
        return self.model.ln_f.weight.device

    @property
    def steps(self) -> int:
        """Tokens fed since the last reset (prompt included)."""
        return 0 if self.cache is None else self.cache.length

    @_one_call_at_a_time
    def reset(self, tasks: Sequence[str], action_spaces: Sequence[gym.spaces.Box | gym.spaces.Discrete] | None = None,
              *, seeds: Sequence[int] | None = None, discard_context: bool = False) -> None:
        """Start a cold (empty-context) run on one env per task name. Actions are clipped to
        `action_spaces` (default: each task's registry env's action space); a Discrete space's actions are the
        indices 0 to n - 1 of a discrete group's logits.

        `seeds`: one per env, the seed of the env's own stream of draws (with the agent's `seed`): `vintix eval`
        gives each env its env seed, so a run plays the same alone, in any batch, or through `predict` after
        ``reset([task], seeds=[env_seed])``. Default: the envs' indices in the batch, 0, 1, ...

        This clears the context, which is where in-context learning lives: a new *episode* is an
        ``episode_start`` flag to `act` / `predict`, never a reset. Clearing a context that holds steps
        warns (`ContextDiscardedWarning`) unless `discard_context` says it is meant (a new run)."""
        if self.cache is not None and self.cache.length and not discard_context:
            warnings.warn(
                f"agent.reset cleared a context of {self.cache.length} steps, and with it what the agent learned "
                "in context. For a new episode pass episode_start=True to act/predict instead; to start a new run, "
                "reset(..., discard_context=True)", ContextDiscardedWarning, stacklevel=3)
        if isinstance(tasks, str) or not tasks:
            raise AgentInputError("reset needs at least one task: a list of task names, one per env (e.g. "
                                  f"['reach-v3']), got {tasks!r}")
        wrong = [task for task in tasks if not isinstance(task, str) or not task]
        if wrong:
            raise AgentInputError(f"reset's tasks must be task names (strings), got {wrong[0]!r} among them")
        if action_spaces is not None and len(action_spaces) != len(tasks):
            raise AgentInputError(f"{len(tasks)} tasks but {len(action_spaces)} action spaces; give one per task")
        streams = self._new_streams(range(len(tasks)) if seeds is None else seeds, len(tasks))
        spaces = action_spaces if action_spaces is not None else [None] * len(tasks)
        self.tasks = [resolve_task(self.model, task, space) for task, space in zip(tasks, spaces, strict=True)]
        self._regroup()
        self._prev_action = {g: self._no_actions(g, len(b.envs)) for g, b in self._groups.items()}
        self._held_noise = {g: torch.zeros(len(b.envs), self.model.action_head(g).noise_dim, device=self.device)
                            for g, b in self._groups.items()}
        self.cache = KVCache.for_model(self.model, len(self.tasks))
        self._awaiting_start = np.zeros(len(self.tasks), dtype=bool)
        self._last_rewards = np.zeros(len(self.tasks))  # next-step autoreset: the reward that came with the flag
        self._episode_returns = np.zeros(len(self.tasks))
        self._streams = streams

    def _new_streams(self, seeds: Sequence[int], envs: int) -> list[torch.Generator]:
        """Each of `envs` envs' stream of draws, seeded from the agent's seed and the env's."""
        whole = all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) and s >= 0 for s in seeds)
        if isinstance(seeds, str) or len(seeds) != envs or not whole:
            raise AgentInputError(f"reset's seeds must be one whole number >= 0 per env ({envs}), got "
                                  f"{list(seeds)[:8]}")
        states = [np.random.SeedSequence([self.seed, int(s)]).generate_state(2, np.uint32) for s in seeds]
        return [torch.Generator(self.device).manual_seed(int(a) << 32 | int(b)) for a, b in states]

    def _no_actions(self, group: str, envs: int) -> torch.Tensor:
        """The previous actions of `envs` envs of `group` before their first: zeros (an episode start's padding
        replaces them, or a `ModelConfig.last_action` model reads them, as it was trained on a history's first row);
        a discrete group's are indices."""
        spec = self.model.groups[group]
        if spec.discrete:
            return torch.zeros(envs, dtype=torch.long, device=self.device)
        return torch.zeros(envs, spec.act_dim, device=self.device)

    def _regroup(self) -> None:
        """Per-group views of the batch (`self.tasks`), built once per reset or keep, not per step."""
        self._groups = {g: _GroupBatch.of(self.tasks, g, self.device) for g in sorted({t.group for t in self.tasks})}

    @_one_call_at_a_time
    def keep(self, envs: Sequence[int]) -> None:
        """Go on with only the envs at batch indices `envs` (they become envs 0, 1, ... in that
        order); the others are dropped with their context. The kept envs act exactly as they would
        have: this lets a batch shrink as its envs finish, instead of stepping them to no purpose."""
        envs = list(envs)
        if self.cache is None:
            raise AgentStateError("call agent.reset(tasks) before agent.keep(...)")
        if any(isinstance(i, (bool, np.bool_)) for i in envs):
            raise AgentInputError(f"keep takes env indices, not a mask, got {envs}"[:200] + "; for a mask, "
                                  "keep(np.flatnonzero(mask))")
        if not envs or not all(isinstance(i, (int, np.integer)) and 0 <= i < len(self.tasks) for i in envs):
            raise AgentInputError(f"keep needs indices in 0..{len(self.tasks) - 1}, got {envs}")
        if len(set(envs)) != len(envs):
            raise AgentInputError(f"keep got an index twice ({envs}); each env's context can be kept once")
        old_groups = self._groups
        self.tasks = [self.tasks[i] for i in envs]
        self._awaiting_start = self._awaiting_start[envs]
        self._last_rewards = self._last_rewards[envs]
        self._episode_returns = self._episode_returns[envs]
        self._regroup()
        self._streams = [self._streams[i] for i in envs]
        self._prev_action = self._kept_rows(self._prev_action, old_groups, envs)
        self._held_noise = self._kept_rows(self._held_noise, old_groups, envs)
        self.cache.keep(torch.tensor(envs, device=self.device))

    def _kept_rows(self, rows: dict[str, torch.Tensor], old_groups: dict[str, _GroupBatch],
                   envs: list[int]) -> dict[str, torch.Tensor]:
        """Per-group rows of each env (its previous action, its held noise) after `keep(envs)`, gathered by the
        envs' old batch indices."""
        by_env: dict[int, torch.Tensor] = {}
        for group, batch in old_groups.items():
            by_env.update(zip(batch.envs.tolist(), rows[group], strict=True))
        return {g: torch.stack([by_env[envs[j]] for j in b.envs.tolist()]) for g, b in self._groups.items()}

    def _check(self, what: str, env: int, values: np.ndarray, shape: tuple[int, ...]) -> None:
        task = self.tasks[env]
        if values.shape != shape:
            raise AgentInputError(
                f"env {env} ({task.task}, group {task.group!r}): {what} has shape {values.shape}, the group "
                f"expects {shape}; is this env the task the agent was reset with?"
            )
        if not np.isfinite(values).all():
            raise AgentInputError(
                f"env {env} ({task.task}): {what} contains NaN or inf; the env diverged (check its physics "
                "variation) or returned an invalid value; the agent does not sanitize inputs"
            )

    def _previous_actions(self) -> list[np.ndarray]:
        """Each env's last action (zeros before its first), in batch order."""
        actions: list[np.ndarray] = [np.empty(0)] * len(self.tasks)
        for group, members in self._groups.items():
            for i, a in zip(members.envs.tolist(), self._prev_action[group].cpu().numpy(), strict=True):
                actions[i] = a
        return actions

    def _model_obs(self, env: int, obs: np.ndarray) -> np.ndarray:
        """Env `env`'s observation(s) in its group's channel layout."""
        layout = self.tasks[env].obs_layout
        return np.asarray(obs) if layout is None else layout.apply(np.asarray(obs))

    def _tokens(
        self, obs: Sequence[np.ndarray], prev_actions: dict[str, torch.Tensor], prev_rewards: np.ndarray,
        episode_starts: np.ndarray,
    ) -> tuple[torch.Tensor, np.ndarray]:
        """Tokens ``[B, T, d_model]`` from per-env obs ``[T, obs_dim]``, rewards/starts ``[B, T]``, and what each
        token's episode had earned before it ``[B, T]``, which an `ModelConfig.episode_return` model reads and the
        caller keeps for the tokens it feeds."""
        steps = prev_rewards.shape[1]
        returns = episode_returns_so_far(prev_rewards, episode_starts, self._episode_returns + prev_rewards[:, 0])
        with_returns = self.model.config.episode_return
        tokens = torch.empty(len(self.tasks), steps, self.model.config.d_model, device=self.device)
        for group, batch in self._groups.items():
            envs = batch.envs.tolist()
            o = torch.as_tensor(np.stack([self._model_obs(i, obs[i]) for i in envs]), dtype=torch.float32,
                                device=self.device)
            raw = np.stack([prev_rewards[envs], returns[envs]], -1) if with_returns else prev_rewards[envs]
            reward = torch.as_tensor(raw, dtype=torch.float32, device=self.device)
            o, reward = normalize_inputs(o, reward, batch.obs_mean, batch.obs_std, batch.reward_scale)
            start = torch.as_tensor(episode_starts[envs], device=self.device)
            tokens[batch.envs] = self.model.encode(group, o, prev_actions[group], reward, start)
        return tokens, returns

    @_one_call_at_a_time
    @torch.inference_mode()
    def act(
        self, obs: Sequence[np.ndarray], prev_rewards: Sequence[float] | np.ndarray,
        episode_starts: Sequence[bool] | np.ndarray, deterministic: bool = False,
    ) -> list[np.ndarray]:
        """One step of every env: actions (clipped to each env's bounds), one array per env; a discrete env's is
        an integer index (a 0-d array), drawn from the model's logits, or their argmax when `deterministic` (a
        gaussian head's: its mean; a flow head's: where zero noise flows). AD and DPT sample: a greedy policy on a
        flat distribution never explores.

        ``obs[i]`` is env ``i``'s raw observation and ``prev_rewards[i]`` the raw reward it returned for the
        agent's previous action; where ``episode_starts[i]`` (the first observation of an episode) that is the
        previous episode's last reward, which only a `ModelConfig.last_reward` model reads. The model normalizes
        both (per-task observation statistics, per-task reward scale). A NaN/inf action from the model raises
        `AgentOutputError`: every action returned is finite and within bounds.
        """
        return self._act(obs, prev_rewards, episode_starts, sample=not deterministic)

    def _act(
        self, obs: Sequence[np.ndarray], prev_rewards: Sequence[float] | np.ndarray,
        episode_starts: Sequence[bool] | np.ndarray, skip: np.ndarray | None = None, sample: bool = True,
    ) -> list[np.ndarray]:
        """`act`, where envs in `skip` sit the step out (`KVCache.advance`): their token goes nowhere, their
        previous action stays, and it is what they get back (the env ignores it)."""
        if self.cache is None:
            raise AgentStateError("call agent.reset(tasks) before agent.act(...)")
        batch = len(self.tasks)
        if len(obs) != batch:
            raise AgentInputError(f"the agent was reset with {batch} envs; got {len(obs)} observations")
        starts = _one_per_env("episode_starts", _numbers("episode_starts", episode_starts, bool), batch)
        rewards = _one_per_env("prev_rewards", _numbers("prev_rewards", prev_rewards, np.float64), batch)
        # An episode start's reward is the previous episode's last, which only a last_reward model reads; a
        # run's first step has none.
        if not self.model.config.last_reward or self.cache.length == 0:
            rewards = np.where(starts, 0.0, rewards)
        observations = [_numbers(f"observation of env {i}", o, np.float32) for i, o in enumerate(obs)]
        for i, task in enumerate(self.tasks):
            self._check("observation", i, observations[i], (task.env_obs_dim(self.model),))
            self._check("previous reward", i, rewards[i : i + 1], (1,))
        if self.cache.length == 0 and not starts.all():
            raise AgentInputError(
                f"env(s) {np.flatnonzero(~starts).tolist()}: the first step of an empty context must be an episode "
                "start (episode_starts True): there is no previous action or reward to feed. To go on from stored "
                "steps, agent.prompt(...) them first"
            )
        sitting_out = None if skip is None or not skip.any() else torch.as_tensor(skip, device=self.device)
        prev_actions = {g: a.unsqueeze(1) for g, a in self._prev_action.items()}
        tokens, returns = self._tokens([o[None] for o in observations], prev_actions, rewards[:, None],
                                       starts[:, None])
        hidden = cached_backbone(self.model, tokens, self.cache, sitting_out)[:, -1]
        self._episode_returns = returns[:, 0] if skip is None else np.where(skip, self._episode_returns, returns[:, 0])
        actions: list[np.ndarray] = [np.empty(0)] * batch
        for group, members in self._groups.items():
            head = self.model.action_head(group)
            noise = self._noise(group, members, starts, sample) if head.noise_dim else None
            action, finite = head.act(hidden[members.envs], noise)
            if not finite.all():
                env = int(members.envs[~finite][0])
                raise AgentOutputError(
                    f"env {env} ({self.tasks[env].task}): the model's action is NaN/inf for finite inputs; its "
                    "weights are damaged or it overflowed. Load another checkpoint (an earlier one of the run)"
                )
            discrete = self.model.groups[group].discrete
            if not discrete:
                action = torch.clamp(action, members.action_low, members.action_high)
            if sitting_out is not None:
                out = sitting_out[members.envs]
                action = torch.where(out if discrete else out.unsqueeze(1), self._prev_action[group], action)
            self._prev_action[group] = action
            for i, a in zip(members.envs.tolist(), action.cpu().numpy(), strict=True):
                actions[i] = np.asarray(a, dtype=np.int64) if discrete else a
        return actions

    def _noise(self, group: str, members: _GroupBatch, starts: np.ndarray, sample: bool) -> torch.Tensor | None:
        """The draws a sampling head acts on for `group`'s envs this step (None when not `sample`: its greedy
        action), each env's from its own stream: a fresh draw every step, or under `ModelConfig.sample_noise`
        'episode' the draw of each env's episode start, held to its end (one posterior sample an episode)."""
        if not sample:
            return None
        head, held = self.model.action_head(group), self._held_noise[group]
        envs = members.envs.tolist()
        fresh = torch.stack([head.draw_noise(self._streams[i]) for i in envs]).to(held.device)
        if self.sample_noise == "episode":
            fresh = torch.where(torch.as_tensor(starts[envs], device=held.device).unsqueeze(1), fresh, held)
        self._held_noise[group] = fresh
        return fresh

    @_one_call_at_a_time
    @torch.inference_mode()
    def predict(
        self, observation: np.ndarray | Sequence[float], reward: float | Sequence[float] | np.ndarray | None = None,
        episode_start: bool | Sequence[bool] | np.ndarray | None = None, deterministic: bool = False,
        autoreset: str | gym.vector.AutoresetMode = "same-step",
    ) -> tuple[np.ndarray, None]:
        """The agent as a policy, in Stable-Baselines3's shape: ``action, _ = agent.predict(obs, reward,
        episode_start)`` after ``agent.reset(tasks)``.

        One env (``reset`` with one task): `observation` ``[obs_dim]``, `reward` and `episode_start`
        scalars, the action ``[act_dim]``. Several (a Gymnasium vector env): ``[n_envs, obs_dim]`` in, ``[n_envs,
        act_dim]`` out. Observations and rewards are the env's raw ones; the model normalizes them.
        `reward`: what the env returned for the previous action, one per env; at an episode start the previous
        episode's last reward, read by a `ModelConfig.last_reward` model and ignored (None allowed) by others.
        None where the model reads a reward is an error, never a silent zero; on the first call it may be None.
        `episode_start`: this observation begins an episode, i.e. the previous step ended one (SB3's
        convention); default: True on the first call after `reset`, False after. A new episode is a
        flag, never a `reset`: the context (what the agent has learned in context) carries over.

        `autoreset`: how the env starts the next episode. ``"same-step"`` (a plain loop that resets the env
        itself, SB3's VecEnv, Gymnasium's ``AutoresetMode.SAME_STEP``): the observation after an episode's
        last step is the next episode's first. ``"next-step"`` (Gymnasium vector envs' default,
        ``AutoresetMode.NEXT_STEP``): it is the finished episode's last observation, and the env's next
        step ignores the action and returns the new episode's first; pass ``episode_start`` as the previous
        step's ``terminated | truncated`` in both modes, and the agent sits that step out (no token for the
        stale observation; it returns the env's previous action) and takes the next observation as a start.
        `deterministic`: a sampling head acts greedily rather than on a draw (`act`; a deterministic model
        always does). Returns ``(action, None)``: no recurrent state, the context lives in the agent.
        """
        if self.cache is None:
            raise AgentStateError("call agent.reset(tasks) before agent.predict(...): it names each env's task")
        mode = _autoreset_mode(autoreset)
        n = len(self.tasks)
        single = n == 1 and np.ndim(observation) == 1
        observations = [np.asarray(observation)] if single else [np.asarray(o) for o in observation]
        if len(observations) != n:
            raise AgentInputError(f"the agent was reset with {n} env(s); got observations of shape "
                                  f"{np.shape(observation)} (one env: [obs_dim]; several: [n_envs, obs_dim])")
        first = self.cache.length == 0
        default_start = np.full(n, first)
        starts = default_start if episode_start is None else _one_per_env(
            "episode_start", _numbers("episode_start", episode_start, bool), n)
        rewards = np.zeros(n) if reward is None else _one_per_env("reward", _numbers("reward", reward, np.float64), n)
        last_reward = self.model.config.last_reward
        skip = None
        if mode == "next-step" and not first:
            # An env flagged now ended its episode on the last step: this observation is that episode's last,
            # which the model never sees as a token. An env that sat out the last step starts one now, with the
            # last reward that came with the flag.
            skip = starts & ~self._awaiting_start
            starts = self._awaiting_start.copy()
            self._awaiting_start = skip
            rewards = np.where(starts, self._last_rewards, rewards)
            self._last_rewards = np.where(skip, rewards, 0.0)
        # No reward where one is read would feed zeros: the zero-reward ablation, which must never happen unasked.
        # A last_reward model also reads, at an episode start, the previous episode's last reward.
        if skip is None:
            reading = np.full(n, not first) if last_reward else ~starts
        else:
            reading = (skip & last_reward) | ~(starts | skip)
        if reward is None and reading.any():
            where = ("mid-episode or at an episode start (there this model reads the previous episode's last reward), "
                     "where the model reads the") if last_reward else "mid-episode, where the model reads the"
            raise AgentInputError(
                f"reward is None, but env(s) {np.flatnonzero(reading).tolist()[:10]} are {where} reward the env "
                "returned for the previous action: pass it (None is for the first step after reset; to feed zeros on "
                "purpose, pass 0.0)")
        if skip is not None and skip.all():
            actions = self._previous_actions()
        else:
            actions = self._act(observations, rewards, starts, skip, sample=not deterministic)
        stacked = np.stack(actions)
        return (stacked[0] if single else stacked), None
    @_one_call_at_a_time
    @torch.inference_mode()
    def prompt(
        self, observations: Sequence[np.ndarray], actions: Sequence[np.ndarray], rewards: Sequence[np.ndarray],
        step_nums: Sequence[np.ndarray],
    ) -> None:
        """Feed stored steps (rows of a learning history, one array ``[T, ...]`` per env, the same T
        for every env and at most the window) as context before acting: a prompted, not cold, start."""
        if self.cache is None:
            raise AgentStateError("call agent.reset(tasks) before agent.prompt(...)")
        steps = len(step_nums[0])
        if any(len(s) != steps for s in step_nums):
            raise AgentInputError("every env's prompt must have the same number of steps")
        if self.cache.length + steps > self.cache.window:  # one chunk must not wrap around the sliding window
            raise AgentInputError(
                f"a prompt of {steps} steps after {self.cache.length} does not fit the model's "
                f"{self.cache.window}-step window; prompt with at most the window "
                "(vintix eval: a smaller --prompt-steps)"
            )
        for i, task in enumerate(self.tasks):
            spec = self.model.groups[task.group]
            self._check("prompt observations", i, _numbers("prompt observations", observations[i], np.float64),
                        (steps, task.env_obs_dim(self.model)))
            shape = (steps,) if spec.discrete else (steps, spec.act_dim)
            self._check("prompt actions", i, _numbers("prompt actions", actions[i], np.float64), shape)
            if spec.discrete and not np.isin(actions[i], np.arange(spec.act_dim)).all():
                raise AgentInputError(f"env {i} ({task.task}): prompt actions must be the indices 0-{spec.act_dim - 1} "
                                      f"of group {task.group!r}'s actions")
            self._check("prompt rewards", i, _numbers("prompt rewards", rewards[i], np.float64), (steps,))
        # Row t of a history: o_t, a_t taken at o_t, r_t after it; token t carries a_{t-1}, r_{t-1}.
        def dtype(group: str) -> torch.dtype:
            return torch.long if self.model.groups[group].discrete else torch.float32

        shifted = {
            g: torch.as_tensor(
                np.stack([np.concatenate([np.zeros_like(actions[i][:1]), actions[i][:-1]]) for i in b.envs.tolist()]),
                dtype=dtype(g), device=self.device,
            )
            for g, b in self._groups.items()
        }
        prev_rewards = np.stack([np.concatenate([[0.0], np.asarray(r[:-1], np.float64)]) for r in rewards])
        starts = np.stack([np.asarray(s) == 0 for s in step_nums])
        starts[:, 0] = True  # a prompt's first step has nothing before it
        tokens, returns = self._tokens(observations, shifted, prev_rewards, starts)
        cached_backbone(self.model, tokens, self.cache)
        self._episode_returns = returns[:, -1]
        for g, b in self._groups.items():
            self._prev_action[g] = torch.as_tensor(
                np.stack([actions[i][-1] for i in b.envs.tolist()]), dtype=dtype(g), device=self.device
            )
