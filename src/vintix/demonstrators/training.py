"""Training demonstrators with Stable-Baselines3, one recipe per encoder group.

The paper imitated JAT's MuJoCo experts and trained PPO for Industrial Benchmark; no registry serves
JAT's agents, so MuJoCo demonstrators are trained here from scratch. Each recipe picks what reaches a
good score fastest on a CPU: PPO for the pendulum and Swimmer (cheap env steps, on-policy is fine),
SAC for the small MuJoCo bodies and Humanoid (sample-efficient where gradient steps are affordable), and
Sample Factory's PPO, the recipe of JAT's own experts, for Ant and HumanoidStandup (millions of cheap steps
beat SAC's costly ones there). Hyperparameters follow the RL Baselines3 Zoo where it has tuned ones;
budgets are set for a laptop and recorded beside each shipped policy.

Industrial Benchmark follows the paper (PPO, advantage normalization, target KL 0.2, batch 50,
gamma 0.97, 1M steps, trained on the delta reward and scored on the classic one) with one change: a
single policy is trained on all 21 setpoints at once, one env each (the setpoint is its first
observation), with 250 steps per env per rollout (5,250 per update, the paper's 2,500 per task).

A recipe can give a target score (`stop_at_score`): the slowest runs then stop once their policy,
scored as it would ship, reaches it, rather than spending CPU-hours past the bar.

Training resumes: every few minutes (less often when saving is slow), and on Ctrl-C or SIGTERM, the
run saves the SB3 model, its replay buffer and its VecNormalize statistics (SB3's own save functions)
under ``~/.cache/vintix/demonstrator-training``; re-running the same command continues from there.
The episodes in progress restart and the RNG streams differ, so a resumed run is not bit-identical to
an uninterrupted one. These are local, pickled working files; only the final weights ship, as
safetensors. Unpickling runs whatever code a file holds, so a saved state is loaded only when its
folder and files belong to the user and nobody else can write them (`refuse_untrusted_state`).
"""

from __future__ import annotations

import json
import random
import shutil
import stat
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import MISSING, asdict, dataclass, field, fields, replace
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize

from vintix.atomic import atomic_write_text
from vintix.demonstrators.base import refuse_untrusted
from vintix.demonstrators.scores import episode_returns
from vintix.demonstrators.trained import (
    ALGORITHMS,
    TrainedDemonstrator,
    expert_env,
    expert_name,
    expert_task,
    save_trained_policy,
)
from vintix.errors import VintixError, json_loads
from vintix.interrupt import Interrupted, sigterm_as_ctrl_c
from vintix.tasks import get_task, list_tasks
from vintix.tasks.scores import reference
from vintix.userdirs import user_cache_dir


@dataclass(frozen=True)
class DemonstratorRecipe:
    """How to train the demonstrator of one encoder group."""

    algorithm: str
    """'PPO' or 'SAC' (Stable-Baselines3)."""
    timesteps: int
    """Env steps to train for, over all envs together."""
    hyperparameters: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments of the SB3 algorithm (gamma, batch_size, ...)."""
    train_tasks: tuple[str, ...] = ()
    """Tasks trained on, one env each; empty: the group's single task."""
    normalize_observations: bool = False
    """Train behind VecNormalize (its statistics ship with the weights)."""
    normalize_rewards: bool = False
    """Also scale rewards by VecNormalize's running return std while training (scores use raw rewards)."""
    n_envs: int = 1
    """Copies of each train task's env, stepped together (a PPO rollout takes `n_steps` from each)."""
    learning_rate_decay: bool = False
    """Decay the learning rate linearly from `hyperparameters['learning_rate']` to 0 over `timesteps`; the
    budget then shapes what the run learns, so a saved run resumes only under the same budget."""
    env_options: dict[str, Any] = field(default_factory=dict)
    """Options for `make_env` during training only (evaluation uses the task as registered)."""
    observation_dims: int = 0
    """Train (and act) on the first N observation dimensions only; 0: all of them."""
    stop_at_score: float | None = None
    """Stop before the budget once the policy, scored as it would ship, reaches this score normalized by
    the paper's random and expert returns (checked every `SCORE_EVERY` of `timesteps`, whatever budget a
    run is given); None: never."""


SCORE_EVERY = 0.025
"""Share of a recipe's `timesteps` between two checks of `DemonstratorRecipe.stop_at_score`: a quick run
(`--timesteps 5000`) of a long recipe is not slowed by checks every few steps."""
SCORE_EPISODES, SCORE_SEED = 20, 1_000
"""Deterministic episodes of a check, as many as `vintix demonstrator eval` reports, on env seeds
`SCORE_SEED + i`: none of them is one of the seeds eval reports, so a run that stops on a lucky check is
not also scored on it. 10 were too few: HumanoidStandup's PPO stopped on a check of 0.87 and scored 0.76
over eval's 20 (a few episodes never stand up)."""
# Fields that decide when a run stops, not what it learns, so a saved run resumes whatever they say:
# a budget is read by SB3 only for learning-rate and clip-range schedules, and a recipe's hyperparameters
# (JSON) hold no schedules, only constants; `learning_rate_decay` makes the budget a training field again.
_STOPPING_FIELDS = ("timesteps", "stop_at_score")


_IB_SETPOINTS = tuple(t.name for t in list_tasks(domain="industrial_benchmark"))

# Sample Factory's MuJoCo PPO (sf_examples/mujoco), which trained JAT's experts, those the paper normalizes by
# (294k-319k on HumanoidStandup): 64 envs x 64-step rollouts, 2 epochs of 4 minibatches, learning rate 0.00295
# decaying linearly over 10M steps, observations and returns normalized. SB3 has no KL penalty (Sample
# Factory's kl_loss_coeff 0.1) and does not share the actor's and critic's layers. SB3 runs it at 1.9k
# (HumanoidStandup) to 3.7k (Ant) steps/s on one core, SAC at under 30 on Humanoid. The whole schedule is
# trained: stopped at 0.85 mid-schedule (4M steps, a 10-episode check of 0.87), HumanoidStandup's policy
# scored 0.76 over eval's 20 episodes, as a few never stood up. The checks stay, as the run's learning curve;
# 1.0 stops only at the expert's own level. Ant reached it (1.01) at 8.75M steps; HumanoidStandup, after the
# whole 10M, scored 0.78 over eval's 20 episodes and 0.87 over 100: an episode stands up or not (docs/demonstrators.md).
_SAMPLE_FACTORY_PPO = DemonstratorRecipe(
    "PPO", 10_000_000,
    {"n_steps": 64, "batch_size": 1024, "n_epochs": 2, "learning_rate": 0.00295, "max_grad_norm": 3.5,
     "vf_coef": 1.3, "ent_coef": 0.0, "gamma": 0.99, "gae_lambda": 0.95, "clip_range": 0.2},
    normalize_observations=True, normalize_rewards=True, n_envs=64, learning_rate_decay=True, stop_at_score=1.0,
)

_EVERY_EPISODE = {"resample_goal_each_episode": True}
"""A meta-RL task's hidden parameter drawn anew every episode, as its goal-aware expert trains."""

RECIPES: dict[str, DemonstratorRecipe] = {
    "mujoco-invertedpendulum": DemonstratorRecipe("PPO", 50_000),
    "mujoco-inverteddoublependulum": DemonstratorRecipe("SAC", 50_000),
    "mujoco-reacher": DemonstratorRecipe("SAC", 30_000),
    "mujoco-swimmer": DemonstratorRecipe("PPO", 300_000, {"gamma": 0.9999}, normalize_observations=True),
    "mujoco-pusher": DemonstratorRecipe("SAC", 60_000),
    "mujoco-hopper": DemonstratorRecipe("SAC", 300_000),
    # 10k random steps first, as the RL Zoo does: SAC from 100 steps settled on a 1.6k-return gait at 300k.
    "mujoco-halfcheetah": DemonstratorRecipe("SAC", 300_000, {"learning_starts": 10_000}),
    "mujoco-walker2d": DemonstratorRecipe("SAC", 500_000),
    # Humanoid's run stops once a check scores 0.85 of the paper's expert: the bar is 0.8, and hours of CPU
    # past it buy nothing the dataset needs; the margin covers a lucky check. Its budget is a ceiling, twice
    # the RL Zoo's: the Zoo trains SAC on Humanoid for 2M steps after 10k random ones (6232 in its
    # benchmark, 0.82 of the paper's expert; the bar is 6045).
    "mujoco-humanoid": DemonstratorRecipe("SAC", 4_000_000, {"learning_starts": 10_000}, stop_at_score=0.85),
    # On Ant-v5's 78 contact forces, TD3 with the RL Zoo's settings learned 2-3x slower than on its 27 joint
    # positions and velocities alone (seed 1, mean training return at 100k / 174k steps: 228 / about 420
    # against 600 / 1,232), then settled at 0.45-0.50 of the paper's expert from 350k to 560k steps (3.2
    # CPU-hours). Sample Factory's PPO on the 27 does better (docs/demonstrators.md).
    "mujoco-ant": replace(_SAMPLE_FACTORY_PPO, observation_dims=27),
    "mujoco-humanoidstandup": _SAMPLE_FACTORY_PPO,
    # The meta-RL tasks' goal-aware experts (`expert_name`): the parameter in their observation, redrawn every
    # episode in training, so one policy runs at any target velocity or in either direction. Their bodies'
    # recipes; no target score (the paper has no reference for these tasks).
    "halfcheetah-vel": DemonstratorRecipe("SAC", 200_000, {"learning_starts": 10_000}, env_options=_EVERY_EPISODE),
    "halfcheetah-dir": DemonstratorRecipe("SAC", 300_000, {"learning_starts": 10_000}, env_options=_EVERY_EPISODE),
    "ant-dir": replace(_SAMPLE_FACTORY_PPO, observation_dims=27, env_options=_EVERY_EPISODE, stop_at_score=None),
    "industrial_benchmark": DemonstratorRecipe(
        "PPO", 1_000_000,
        {"gamma": 0.97, "n_steps": 250, "batch_size": 50, "target_kl": 0.2, "normalize_advantage": True},
        train_tasks=_IB_SETPOINTS, normalize_observations=True, env_options={"reward_type": "delta"},
    ),
}


def recipe_for(task: str) -> DemonstratorRecipe:
    """The training recipe of a task's demonstrator (`expert_name`); Meta-World and Bi-DexHands have none."""
    spec = get_task(task)
    if expert_name(spec) not in RECIPES:
        reason = ("its demonstrators are metaworld's scripted policies, nothing to train"
                  if spec.domain == "metaworld" else "no recipe for this domain")
        raise VintixError(f"cannot train a demonstrator for {spec.name!r}: {reason}")
    return RECIPES[expert_name(spec)]


def _monitored_env(task: str, options: dict[str, Any], observation_dims: int) -> gym.Env:
    return Monitor(expert_env(task, observation_dims, **options))


def training_runs_dir() -> Path:
    """Where unfinished training runs are saved, one folder per group and seed."""
    return user_cache_dir("demonstrator-training")


def default_state_dir(group: str, seed: int) -> Path:
    """Where an unfinished training run of `group` with `seed` keeps what it needs to resume."""
    return training_runs_dir() / f"{group}-seed{seed}"


def _training_fields(recipe: dict[str, Any]) -> dict[str, Any]:
    """A recipe's fields (as a dict) less `_STOPPING_FIELDS`: what a saved run must match."""
    return {name: value for name, value in recipe.items() if name not in _STOPPING_FIELDS}


def _plan(group: str, budget: int, seed: int, recipe: DemonstratorRecipe) -> dict[str, Any]:
    """What a run records of itself (group, budget, seed, the recipe's training fields); a saved state
    must match all of it to be resumed (`latest_training_state`), the budget only if it sets a schedule."""
    plan = {"group": group, "timesteps": budget, "seed": seed, "recipe": _training_fields(asdict(recipe))}
    return dict(json.loads(json.dumps(plan)))  # tuples as lists, as they come back from state.json


# Fields `DemonstratorRecipe` no longer has, with the value that left them unused: a run saved with that
# value trained as a recipe without the field does (TD3's action noise, 0 for SAC and PPO).
_REMOVED_FIELDS: dict[str, Any] = {"action_noise_std": 0.0}


def _saved_plan(info: dict[str, Any]) -> dict[str, Any]:
    """The plan a state was saved with, recipe fields added to `DemonstratorRecipe` since then at their
    defaults and fields removed since then dropped where unused: a run saved by an older vintix stays
    resumable."""
    defaults: dict[str, Any] = {}
    for f in fields(DemonstratorRecipe):
        if f.name in _STOPPING_FIELDS:
            continue
        if f.default is not MISSING:
            defaults[f.name] = f.default
        elif f.default_factory is not MISSING:
            defaults[f.name] = f.default_factory()
    plan = info["plan"]
    saved = {name: value for name, value in _training_fields(plan["recipe"]).items()
             if name not in _REMOVED_FIELDS or value != _REMOVED_FIELDS[name]}
    return {**plan, "recipe": {**json.loads(json.dumps(defaults)), **saved}}


STATE_FILE = "state.json"  # written last: a state folder without it is incomplete
STATE_PREFIX = "steps-"  # + step: a saved state to resume from; only the newest is kept
BEST_CHECK_PREFIX = "best-at-"  # + step: the best score check's policy, kept beside the newest state


def _delete_folders(directory: Path, prefix: str, but: Path | None = None) -> None:
    """Delete the folders of `directory` whose names start with `prefix`, all `but` one."""
    for other in directory.glob(f"{prefix}*"):
        if other != but:
            shutil.rmtree(other, ignore_errors=True)


def save_training_state(model: BaseAlgorithm, vec_normalize: VecNormalize | None, directory: Path,
                        plan: dict[str, Any], train_seconds: float,
                        score_checks: Sequence[dict[str, Any]] = ()) -> Path:
    """Save what resuming needs into ``directory/steps-N/``, then delete older (or incomplete) states;
    `score_checks` (those of `DemonstratorRecipe.stop_at_score` so far) are kept with it."""
    state = directory / f"{STATE_PREFIX}{model.num_timesteps:012d}"
    shutil.rmtree(state, ignore_errors=True)
    state.mkdir(parents=True, mode=0o700)
    model.save(state / "model.zip")
    if isinstance(model, OffPolicyAlgorithm):
        model.save_replay_buffer(state / "replay_buffer.pkl")
    if vec_normalize is not None:
        vec_normalize.save(str(state / "vecnormalize.pkl"))
    for path in [state, *state.iterdir()]:  # whatever the umask: only the user may write what gets unpickled
        path.chmod(path.stat().st_mode & ~(stat.S_IWGRP | stat.S_IWOTH))
    returns = [episode["r"] for episode in model.ep_info_buffer or ()]
    info = {"plan": plan, "num_timesteps": model.num_timesteps, "train_seconds": round(train_seconds, 1),
            "recent_return": round(float(np.mean(returns)), 1) if returns else None,
            "score_checks": list(score_checks)}
    atomic_write_text(state / STATE_FILE, json.dumps(info, indent=1) + "\n")
    _delete_folders(directory, STATE_PREFIX, but=state)
    return state


def _newest_state(directory: Path) -> tuple[Path, dict[str, Any]] | None:
    """The newest complete state in `directory` and its info, if any."""
    complete = sorted(p.parent for p in directory.glob(f"{STATE_PREFIX}*/{STATE_FILE}"))
    return (complete[-1], json_loads((complete[-1] / STATE_FILE).read_text())) if complete else None


def keep_best_check(model: BaseAlgorithm, vec_normalize: VecNormalize | None, group: str, observation_dims: int,
                    directory: Path, check: dict[str, Any]) -> Path:
    """Write the policy of score check `check` as shipped weights into ``directory/best-at-N/``, then
    delete the one kept before: a policy that scores well at one check can fall at the next (Humanoid's SAC:
    0.71 at 900k steps, 0.33 at 1.1M), and the run's newest state keeps only the latest."""
    kept = directory / f"{BEST_CHECK_PREFIX}{check['step']:012d}"
    shutil.rmtree(kept, ignore_errors=True)
    save_trained_policy(model, vec_normalize, group, kept, {"observation_dims": observation_dims,
                                                            "score_check": check})
    _delete_folders(directory, BEST_CHECK_PREFIX, but=kept)
    return kept


def best_check(directory: Path) -> tuple[Path, dict[str, Any]] | None:
    """The folder of the best score check's policy kept in `directory` (`keep_best_check`) and that check."""
    complete = sorted(meta.parent for meta in directory.glob(f"{BEST_CHECK_PREFIX}*/*.json"))
    if not complete:
        return None
    [meta] = complete[-1].glob("*.json")
    return complete[-1], json_loads(meta.read_text())["score_check"]


def latest_training_state(directory: Path, plan: dict[str, Any]) -> tuple[Path, dict[str, Any]] | None:
    """The newest complete state in `directory` and its info; an unfinished run with another plan
    is an error (resuming it under new settings would train neither), one with another budget is not
    (a budget only says where to stop), unless its learning rate decays over that budget."""
    found = _newest_state(directory)
    if found is None:
        return None
    state, info = found
    saved = _saved_plan(info)
    if not saved["recipe"]["learning_rate_decay"]:
        saved["timesteps"] = plan["timesteps"]
    if saved != plan:
        raise VintixError(
            f"{directory} holds an unfinished run with other settings ({info['plan']}); re-run with those "
            f"settings to finish it, or delete the folder to start this one ({plan})"
        )
    return state, info


@dataclass(frozen=True)
class UnfinishedRun:
    """A demonstrator training run saved before its end, as its newest state records it."""

    folder: Path
    group: str
    algorithm: str
    seed: int
    steps: int
    """Env steps done."""
    budget: int
    """Env steps the run trains for."""
    train_seconds: float
    """Time spent training, over all the sessions it was resumed in (its saves included)."""
    recent_return: float | None
    """Mean return of its last (up to 100) training episodes before the save, exploration included;
    None when no episode had ended since the run was last started."""
    observation_dims: int = 0
    """The observation dimensions its policy sees (`DemonstratorRecipe.observation_dims`; 0: all)."""
    score_checks: tuple[dict[str, Any], ...] = ()
    """Its score checks so far (`DemonstratorRecipe.stop_at_score`), oldest first: step, mean, std, normalized."""

    def seconds_left(self) -> float:
        """Training time still needed at the pace so far."""
        return (self.budget - self.steps) * self.train_seconds / max(self.steps, 1)


def unfinished_runs(root: Path | None = None) -> list[UnfinishedRun]:
    """Every run saved under `root` (default: `training_runs_dir`) that has not finished."""
    root = root or training_runs_dir()
    runs = []
    for folder in sorted(p for p in root.glob("*") if p.is_dir()):
        found = _newest_state(folder)
        if found is not None:
            info = found[1]
            plan = _saved_plan(info)
            runs.append(UnfinishedRun(folder, plan["group"], plan["recipe"]["algorithm"], plan["seed"],
                                      info["num_timesteps"], plan["timesteps"], info["train_seconds"],
                                      info.get("recent_return"), plan["recipe"]["observation_dims"],
                                      tuple(info.get("score_checks", ()))))
    return runs


def score_as_shipped(model: BaseAlgorithm, vec_normalize: VecNormalize | None, group: str, observation_dims: int,
                     episodes: int, seed: int = 0) -> tuple[str, np.ndarray]:
    """(task, returns) of `episodes` deterministic episodes of `model` on the first task of `group`: its
    acting weights are exported as they would ship, then scored as `vintix demonstrator eval` scores a
    shipped demonstrator."""
    spec = expert_task(group)
    with tempfile.TemporaryDirectory() as exported:
        save_trained_policy(model, vec_normalize, group, Path(exported), {"observation_dims": observation_dims})
        demonstrator = TrainedDemonstrator(spec, Path(exported))
    return spec.name, episode_returns(spec.name, demonstrator, episodes, seed)


PICKLED_FILES = ("model.zip", "vecnormalize.pkl", "replay_buffer.pkl")
"""The files of a saved state that SB3 unpickles when it loads them."""


def refuse_untrusted_state(state: Path) -> None:
    """Raise unless `state` and its pickled files are owned by this user and writable by nobody else:
    another user who could write them (a cache on shared storage) could make loading run their code."""
    for path in [state, *(state / name for name in PICKLED_FILES if (state / name).exists())]:
        try:
            refuse_untrusted(path)
        except VintixError as error:
            raise VintixError(f"{error}. A saved training state: `chmod -R go-w {state}` if you wrote it, otherwise "
                              f"delete {state.parent} and train from the start") from None


def evaluate_unfinished_run(run: UnfinishedRun, episodes: int, seed: int = 0) -> tuple[str, np.ndarray]:
    """(task, returns) of `episodes` deterministic episodes of the policy in `run`'s newest save, scored
    as it would ship (`score_as_shipped`; training returns include exploration)."""
    found = _newest_state(run.folder)
    if found is None:
        raise VintixError(f"{run.folder} holds no complete saved state to evaluate")
    state = found[0]
    refuse_untrusted_state(state)
    model = ALGORITHMS[run.algorithm].load(state / "model.zip", device="cpu")
    vec_normalize = None
    if (state / "vecnormalize.pkl").is_file():
        spec = expert_task(run.group)
        venv = DummyVecEnv([partial(_monitored_env, spec.name, {}, run.observation_dims)])
        vec_normalize = VecNormalize.load(str(state / "vecnormalize.pkl"), venv)
        venv.close()
    return score_as_shipped(model, vec_normalize, run.group, run.observation_dims, episodes, seed)


@contextmanager
def _global_rngs_kept() -> Iterator[None]:
    """Restore Python's, numpy's and torch's global RNGs on leaving: SB3 samples its replay batches and
    actions from them, and building a policy to score draws its initial weights from them, so a score
    check inside training would otherwise change what the run learns."""
    python_state, numpy_state = random.getstate(), np.random.get_state()
    with torch.random.fork_rng(devices=[]):
        yield
    random.setstate(python_state)
    np.random.set_state(numpy_state)


class _StopAtScore(BaseCallback):
    """Scores the policy as it would ship each time training passes a multiple of `every` env steps, and
    stops training once the normalized mean reaches `target`; `report` gets each check as a line, and
    `checks` (those of the sessions before, when resumed) gains each as a dict: the run's learning curve.
    `keep` gets each check that beats `best` (the best normalized score kept so far), to keep its policy."""

    def __init__(self, score: Callable[[], tuple[str, np.ndarray]], every: int, target: float,
                 report: Callable[[str], object] | None, checks: list[dict[str, Any]],
                 keep: Callable[[dict[str, Any]], object], best: float):
        super().__init__()
        self.score, self.every, self.target, self.report, self.checks = score, every, target, report, checks
        self.keep, self.best = keep, best
        self.reached: dict[str, Any] | None = None

    def _on_training_start(self) -> None:
        self.checked = self.model.num_timesteps // self.every

    def _on_step(self) -> bool:
        if self.num_timesteps // self.every == self.checked:
            return True
        self.checked = self.num_timesteps // self.every
        with _global_rngs_kept():
            task, returns = self.score()
        paper = reference(task, "paper")
        if paper is None:
            raise VintixError(f"{task} has no published scores, so stop_at_score (a fraction of the paper's expert) "
                              "cannot be checked: train it with a recipe without stop_at_score")
        score = float(paper.normalize(returns.mean()))
        check = {"step": self.num_timesteps, "mean": round(float(returns.mean()), 1),
                 "std": round(float(returns.std()), 1), "normalized": round(score, 4)}
        self.checks.append(check)
        if check["normalized"] > self.best:
            self.best = check["normalized"]
            self.keep(check)
        if self.report:
            self.report(f"step {self.num_timesteps:,}: {task} {returns.mean():,.1f} ± {returns.std():,.1f} over "
                        f"{len(returns)} deterministic episodes, normalized {score:.3f} (stops at {self.target})")
        if score < self.target:
            return True
        self.reached = {"step": self.num_timesteps, "normalized_score": round(float(score), 4),
                        "target": self.target, "episodes": len(returns), "seed": SCORE_SEED}
        return False


class _SaveEvery(BaseCallback):
    """Calls `save` whenever `seconds` of training have passed since the last call, or longer when saving
    is slow, so that saves take at most `max_share` of the time: Humanoid's 5.6 GB replay buffer takes
    21 s to write, 7 % of a 5-minute interval. Stopping (Ctrl-C, SIGTERM) saves anyway."""

    def __init__(self, save: Callable[[], object], seconds: float, max_share: float = 0.02):
        super().__init__()
        self.save, self.seconds, self.max_share = save, seconds, max_share
        self.wait, self.last = seconds, time.perf_counter()

    def _on_step(self) -> bool:
        if time.perf_counter() - self.last >= self.wait:
            began = time.perf_counter()
            self.save()
            self.last = time.perf_counter()
            self.wait = max(self.seconds, (self.last - began) / self.max_share)
        return True


def _new_or_resumed(recipe: DemonstratorRecipe, venv: VecEnv, seed: int, resume: Path | None
                    ) -> tuple[BaseAlgorithm, VecNormalize | None]:
    """The SB3 model (and its VecNormalize wrapper, if the recipe has one): fresh, or loaded from `resume`."""
    vec_normalize = None
    if resume is not None:
        refuse_untrusted_state(resume)
    if recipe.normalize_observations:
        if resume is not None:
            vec_normalize = VecNormalize.load(str(resume / "vecnormalize.pkl"), venv)
        else:
            gamma = recipe.hyperparameters.get("gamma", 0.99)
            vec_normalize = VecNormalize(venv, norm_obs=True, norm_reward=recipe.normalize_rewards, gamma=gamma)
        venv = vec_normalize
    algorithm = ALGORITHMS[recipe.algorithm]
    if resume is None:
        extra: dict[str, Any] = {}
        if recipe.learning_rate_decay:  # SB3 calls it with the share of the budget left, 1 -> 0
            extra["learning_rate"] = LinearSchedule(recipe.hyperparameters["learning_rate"], 0.0, 1.0)
        model = algorithm("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **{**recipe.hyperparameters, **extra})
    else:
        model = algorithm.load(resume / "model.zip", env=venv, device="cpu")
        if isinstance(model, OffPolicyAlgorithm):
            model.load_replay_buffer(resume / "replay_buffer.pkl")
    # A logger without outputs: SB3's default one makes an empty SB3-<time> folder in /tmp every run.
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model, vec_normalize


def trained_weights_dir() -> Path:
    """Where `train_demonstrator` puts weights unless told otherwise: the user's folder, not the installed
    package (which may be read-only, and whose weights every collection uses). Collect with them through
    a recipe's ``demonstrator: weights:DIR``; score them with ``vintix demonstrator eval --weights DIR``."""
    return user_cache_dir("demonstrators")


def train_demonstrator(task: str, timesteps: int | None = None, seed: int = 0, out: Path | None = None,
                       progress_bar: bool = True, recipe: DemonstratorRecipe | None = None,
                       state_dir: Path | None = None, save_minutes: float = 5.0,
                       callback: BaseCallback | None = None, report: Callable[[str], object] | None = None) -> Path:
    """Train the demonstrator of `task`'s group and save it into `out` (default: `trained_weights_dir`, the
    user's folder; the package's shipped weights change only when `out` is `shipped_weights_dir()`).

    Returns the weights file. `timesteps` overrides the budget (e.g. for a quick check); `recipe`
    replaces the group's recipe (to try other hyperparameters). The resumable state is saved every
    `save_minutes` (less often when a save takes over 2 % of that) and on Ctrl-C or SIGTERM under
    `state_dir` (default: `default_state_dir`); a run finds and continues it, and deletes it once the
    weights are written, unless the recipe's `stop_at_score` was not reached: then the state stays, so a
    larger budget can continue the run. Each score check that beats the run's best so far keeps its policy
    beside the state (`keep_best_check`), as a policy can fall between checks. `callback`: one more SB3
    callback (several: a CallbackList); `report`: gets a line per score check of a recipe with `stop_at_score`.
    """
    spec = get_task(task)
    recipe = recipe or recipe_for(task)
    budget = timesteps or recipe.timesteps
    tasks = recipe.train_tasks or (spec.name,)
    expert = expert_name(spec)
    plan = _plan(expert, budget, seed, recipe)
    state_dir = state_dir or default_state_dir(expert, seed)
    found = latest_training_state(state_dir, plan)
    venv = DummyVecEnv([partial(_monitored_env, name, recipe.env_options, recipe.observation_dims)
                        for name in tasks for _ in range(recipe.n_envs)])
    model, vec_normalize = _new_or_resumed(recipe, venv, seed, found[0] if found else None)
    seconds_before = found[1]["train_seconds"] if found else 0.0
    start = time.perf_counter()

    score_checks: list[dict[str, Any]] = found[1].get("score_checks", []) if found else []

    def save_state() -> Path:
        return save_training_state(model, vec_normalize, state_dir, plan,
                                   seconds_before + time.perf_counter() - start, score_checks)

    callbacks: list[BaseCallback] = [_SaveEvery(save_state, save_minutes * 60.0)]
    stop = None
    if recipe.stop_at_score is not None:
        score = partial(score_as_shipped, model, vec_normalize, expert, recipe.observation_dims,
                        SCORE_EPISODES, SCORE_SEED)
        if found is None:  # a fresh run: a policy kept by an earlier one in this folder is not its own
            _delete_folders(state_dir, BEST_CHECK_PREFIX)
        kept = best_check(state_dir)
        keep = partial(keep_best_check, model, vec_normalize, expert, recipe.observation_dims, state_dir)
        stop = _StopAtScore(score, max(1, round(recipe.timesteps * SCORE_EVERY)), recipe.stop_at_score, report,
                            score_checks, keep, kept[1]["normalized"] if kept else -np.inf)
        callbacks.append(stop)
    if callback is not None:
        callbacks.append(callback)
    try:
        with sigterm_as_ctrl_c():
            model.learn(total_timesteps=budget - model.num_timesteps, callback=callbacks,
                        reset_num_timesteps=found is None, progress_bar=progress_bar)
    except KeyboardInterrupt:
        save_state()
        raise Interrupted(
            f"interrupted at step {model.num_timesteps:,}; the run is saved under {state_dir}: "
            "re-run the same command to resume"
        ) from None
    finally:
        venv.close()
    seconds = seconds_before + time.perf_counter() - start
    command = f"vintix demonstrator train --task {spec.name} --seed {seed}"
    if timesteps:
        command += f" --timesteps {timesteps}"
    info = {"group": expert, "train_tasks": list(tasks), "timesteps": model.num_timesteps, "seed": seed,
            "train_seconds": round(seconds, 1), "hyperparameters": recipe.hyperparameters,
            "env_options": recipe.env_options, "command": command}
    for name in ("observation_dims", "n_envs", "normalize_rewards", "learning_rate_decay"):  # those a recipe changed
        if getattr(recipe, name) != DemonstratorRecipe.__dataclass_fields__[name].default:
            info[name] = getattr(recipe, name)
    if found:
        info["resumed_at"] = found[1]["num_timesteps"]
    short_of_target = stop is not None and stop.reached is None
    goes_on = short_of_target and not recipe.learning_rate_decay  # a larger budget would change a schedule
    if stop is not None and stop.reached:
        info["stopped_at_score"] = {**stop.reached, "budget": budget}
    if score_checks:
        info["score_checks"] = score_checks
    if short_of_target:
        kept = best_check(state_dir) if goes_on else None
        info["short_of_target"] = {"target": recipe.stop_at_score, "budget": budget,
                                   **({"state": str(state_dir)} if goes_on else {}),
                                   **({"best_check": {"folder": str(kept[0]), **kept[1]}} if kept else {})}
    path = save_trained_policy(model, vec_normalize, expert, out or trained_weights_dir(), info)
    if goes_on:
        save_state()  # a larger budget (`--timesteps`) goes on from here rather than from scratch
    else:
        shutil.rmtree(state_dir, ignore_errors=True)
    return path
