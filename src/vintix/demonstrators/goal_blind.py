"""The goal-blind baseline: how well a hidden-goal task goes for an expert that does not know the goal.

The scripted expert aimed at the task's mean goal (the average of the hidden goals its envs draw)
plays one episode per seed; beside it, the same expert aimed at the true goal. A task whose
goal-blind success is near the true-goal success does not need its hidden goal (Meta-World's
button-press: the goal follows from the button's observed position), so improvement over shots there
cannot show that a model reads rewards; a task whose goal-blind success is low can. The table
`goal_blind.csv` beside the reference scores holds every Meta-World task, measured by `vintix
demonstrator goal-blind`.

A low goal-blind success is not enough for the rewards to be the only way to the goal: where the goal
is a body (plate-slide's net, assembly's peg), an agent that touches it sees it in its observations.
`observation_spread_across_goals` checks that: envs that differ only in their hidden goal, the same
actions on all of them.

The mean goal is a fair blind aim where goals fill a region around it (Meta-World's boxes). It is not where
they do not: a direction task's goals are +1 and -1, and an expert aimed at their mean, 0, is asked for what
it never trained on. There the blind aim is the best constant one (`blind_aim="best"`): of the mean goal and
`AIM_CANDIDATES` drawn goals, the one whose return over `AIM_SCOUT_EPISODES` scouting seeds is highest, the
most a goal-blind expert of this family earns. Tasks without a success flag (the meta-RL MuJoCo tasks) read
their hidden information by return, normalized between a random policy's and the true goal's
(`GoalBlindResult.hidden_return`).
"""

from __future__ import annotations

import csv
import datetime
import io
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, fields
from importlib import resources
from pathlib import Path

import gymnasium as gym
import numpy as np

from vintix.atomic import atomic_write_text
from vintix.demonstrators.base import load_demonstrator
from vintix.demonstrators.posterior import GoalConditionedExpert
from vintix.demonstrators.scores import episode_outcomes
from vintix.errors import VintixError
from vintix.tasks import action_box, get_task, make_env
from vintix.tasks.check import random_policy_returns

MEAN_GOAL_DRAWS = 50
MEAN_GOAL_FIRST_SEED = 1_000_000
"""Seeds of the envs whose goals are averaged into the mean goal: far from any evaluation seed."""
BLIND_AIMS = ("mean", "best")
"""What a goal-blind expert aims at: the mean goal, or the best constant goal (`best_blind_aim`)."""
AIM_CANDIDATES = 8
AIM_SCOUT_EPISODES = 10
AIM_SCOUT_FIRST_SEED = 2_000_000
"""Seeds on which `best_blind_aim` scores its candidates: neither an evaluation seed nor a mean-goal draw."""


@dataclass(frozen=True)
class GoalBlindResult:
    """One task's success and return with the true goal and with the mean goal, one episode per seed."""

    task: str
    seeds: int
    first_seed: int
    true_goal_success: float
    goal_blind_success: float
    true_goal_return: float
    goal_blind_return: float
    measured_on: str
    command: str
    blind_aim: str = "mean"
    """what the goal-blind expert aimed at (`BLIND_AIMS`); rows measured before this column: the mean goal"""
    random_return: float = float("nan")
    """a uniform-random policy's mean return on the same seeds (NaN in rows measured before this column)"""

    @property
    def hidden_information(self) -> float:
        """How much success the hidden goal decides: true-goal success minus goal-blind success."""
        return self.true_goal_success - self.goal_blind_success

    @property
    def hidden_return(self) -> float:
        """How much return the hidden goal decides, as a share of the true goal's over a random policy's:
        ``(true - blind) / (true - random)``, 1 where a blind expert does no better than random."""
        return (self.true_goal_return - self.goal_blind_return) / (self.true_goal_return - self.random_return)


def goal_blind_path() -> Path:
    """The package's goal-blind table."""
    return Path(str(resources.files("vintix.demonstrators").joinpath("goal_blind.csv")))


def goals_of_seeds(task: str, seeds: Iterable[int]) -> list[np.ndarray]:
    """The hidden goal that a new env of `task` with each of `seeds` draws."""
    env = make_env(task)
    goals = []
    for seed in seeds:
        env.reset(seed=seed)  # draws the goal a new env with this seed would
        goals.append(env.unwrapped.true_goal)  # type: ignore[attr-defined]
    env.close()
    return goals


def goal_draws(task: str) -> list[np.ndarray]:
    """The hidden goals of `task`'s envs on `MEAN_GOAL_DRAWS` seeds no evaluation uses."""
    return goals_of_seeds(task, range(MEAN_GOAL_FIRST_SEED, MEAN_GOAL_FIRST_SEED + MEAN_GOAL_DRAWS))


def mean_goal(task: str, draws: list[np.ndarray] | None = None) -> np.ndarray:
    """The average of `task`'s `goal_draws` (drawn here unless given)."""
    return np.mean(goal_draws(task) if draws is None else draws, axis=0)


class AimedExpert:
    """A goal-conditioned expert aimed at `goal` in every env, or at each env's true goal when None."""

    def __init__(self, expert: GoalConditionedExpert, goal: np.ndarray | None) -> None:
        self.expert, self.goal = expert, goal

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        goals = np.stack([env.unwrapped.true_goal if self.goal is None else self.goal for env in envs])  # type: ignore[attr-defined]
        space = action_box(envs[0].action_space)
        return np.clip(self.expert.act_toward(observations, goals), space.low, space.high)


def best_blind_aim(task: str, expert: GoalConditionedExpert) -> np.ndarray:
    """The goal that, aimed at in every env, earns `expert` the most mean return on the scouting seeds: of the
    mean goal and the goals of `AIM_CANDIDATES` draws."""
    draws = goal_draws(task)  # drawn once: the mean's draws, the first of them the candidates
    candidates = [mean_goal(task, draws), *draws[:AIM_CANDIDATES]]
    scouted = [episode_outcomes(task, AimedExpert(expert, goal), AIM_SCOUT_EPISODES,
                                AIM_SCOUT_FIRST_SEED)[0].mean() for goal in candidates]
    return candidates[int(np.argmax(scouted))]


def goal_blind_baseline(task: str, seeds: int = 20, first_seed: int = 100, command: str = "",
                        source: str | None = None, weights: Path | None = None,
                        blind_aim: str = "mean") -> GoalBlindResult:
    """Measure `task`'s goal-blind baseline on env seeds ``first_seed ..``, beside the true goal's and a random
    policy's: the package's expert (trained ones from `weights`, a folder, if given), or the goal-conditioned
    expert `source` (``module:callable``, as a recipe names one), aimed blind at `blind_aim` (`BLIND_AIMS`)."""
    spec = get_task(task)
    if blind_aim not in BLIND_AIMS:
        raise VintixError(f"unknown blind aim {blind_aim!r}; choose one of {', '.join(BLIND_AIMS)}")
    expert = load_demonstrator(spec.name, weights=weights, source=source)
    if not hasattr(expert, "act_toward"):
        whose = f"the demonstrator {source!r}" if source else "the package's"
        raise VintixError(f"{spec.name!r}: {whose} expert has no act_toward(observations, goals), so it cannot be "
                          "aimed at a goal it is given (the scripted experts of Meta-World, toy and Reacher-hidden-v5 "
                          "tasks can; for your own task, give --demonstrator MODULE:CALLABLE returning one that can)")
    aim = mean_goal(spec.name) if blind_aim == "mean" else best_blind_aim(spec.name, expert)  # type: ignore[arg-type]
    true_returns, true_success = episode_outcomes(spec.name, AimedExpert(expert, None), seeds, first_seed)  # type: ignore[arg-type]
    blind_returns, blind_success = episode_outcomes(spec.name, AimedExpert(expert, aim), seeds, first_seed)  # type: ignore[arg-type]
    random_return = float(np.mean([random_policy_returns(spec.name, 1, first_seed + i).returns[0]
                                   for i in range(seeds)]))
    return GoalBlindResult(spec.name, seeds, first_seed, float(true_success.mean()), float(blind_success.mean()),
                           round(float(true_returns.mean()), 3), round(float(blind_returns.mean()), 3),
                           datetime.date.today().isoformat(), command, blind_aim, round(random_return, 3))


def read_goal_blind(path: Path | None = None) -> dict[str, GoalBlindResult]:
    """The goal-blind table by task (empty if it does not exist)."""
    path = path or goal_blind_path()
    if not path.is_file():
        return {}
    types = {f.name: f.type for f in fields(GoalBlindResult)}  # a column the file lacks takes its default
    cast = {"int": int, "float": float, "str": str}
    return {row["task"]: GoalBlindResult(**{k: cast[str(types[k])](v) for k, v in row.items()})
            for row in csv.DictReader(path.read_text().splitlines())}


def write_goal_blind(results: list[GoalBlindResult], path: Path) -> Path:
    """Add `results` to the table at `path` (replacing rows of the same tasks), atomically."""
    rows = read_goal_blind(path) | {r.task: r for r in results}
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=[f.name for f in fields(GoalBlindResult)], lineterminator="\n")
    writer.writeheader()
    writer.writerows(asdict(rows[task]) for task in sorted(rows))
    atomic_write_text(path, buffer.getvalue())
    return path


def observation_spread_across_goals(task: str, goal_seeds: Sequence[int] = (100, 101, 102, 103)) -> tuple[float, ...]:
    """How far apart the same actions leave envs of Meta-World `task` that differ only in their hidden goal.

    Every env starts as env seed ``goal_seeds[0]`` (the same object start) with the goal of one of
    `goal_seeds`. Three episodes play the same actions on all of them: the probe of behaviour
    'probe-then-sample', uniform-random actions, and the scripted expert aimed at the second env's goal.
    Returns, per episode, the largest spread (max - min over envs) of any observation entry: all zeros when
    only the rewards tell the goals apart, as on reach, where the goal is a marker with no body."""
    goals = goals_of_seeds(task, goal_seeds)
    envs = [make_env(task, seed=goal_seeds[0]) for _ in goals]
    for env, goal in zip(envs, goals, strict=True):
        env.reset()  # the first reset draws the seed's goal, which place_goal then replaces
        env.unwrapped.place_goal(goal)  # type: ignore[attr-defined]
    probe = load_demonstrator(task, behaviour="probe-then-sample")
    probe.begin(envs, [np.random.default_rng(0) for _ in envs])  # type: ignore[attr-defined]
    rng, spreads = np.random.default_rng(0), []
    for episode in ("probe", "random", "expert"):
        obs = np.stack([env.reset()[0] for env in envs])
        spread, truncated = 0.0, False
        while not truncated:
            if episode == "probe":
                action = probe.act(obs, envs)[0]
            elif episode == "random":
                action = rng.uniform(-1, 1, size=envs[0].action_space.shape)
            else:
                action = probe.expert.act_toward(obs[:1], goals[1][None])[0]  # type: ignore[attr-defined]
            for i, env in enumerate(envs):
                obs[i], reward, terminated, truncated, _ = env.step(action)
                if episode == "probe":
                    probe.observe(i, env, action, float(reward), terminated or truncated)  # type: ignore[attr-defined]
            spread = max(spread, float(np.ptp(obs, axis=0).max()))
        spreads.append(spread)
    for env in envs:
        env.close()
    return tuple(spreads)
