"""Our own reference scores: each demonstrator's and a uniform-random policy's return, measured here.

The paper's published scores come from other env versions (MuJoCo v4, Meta-World v2) and other
demonstrators, so normalizing by our demonstrators' measured scores is the fair yardstick for data
we collect; `scores.csv` beside this file keeps them, one row per (task, policy), each with how it
was measured (episodes, seed, env and package versions, date, command). That table normalizes every
result, so it is reference data, read-only at run time: `vintix demonstrator eval` writes what it
measures to a table in the user's folder, and rewrites the package's only when asked to
(``--update-package-table``).
"""

from __future__ import annotations

import csv
import datetime
import io
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from importlib import metadata, resources
from pathlib import Path

import gymnasium as gym
import numpy as np

from vintix.atomic import atomic_write_text
from vintix.demonstrators.base import Demonstrator
from vintix.tasks import ReferenceScore, TaskSpec, get_task, make_env

POLICIES = ("demonstrator", "random")
_DOMAIN_PACKAGES = {"mujoco": "mujoco", "metaworld": "metaworld", "industrial_benchmark": "industrial-benchmark-python"}


def scores_path() -> Path:
    """The package's score table."""
    return Path(str(resources.files("vintix.demonstrators").joinpath("scores.csv")))


@dataclass(frozen=True)
class MeasuredScore:
    """One row of the score table: a policy's episode returns on one task, and how they were measured."""

    task: str
    policy: str
    """'demonstrator' or 'random'."""
    mean: float
    std: float
    episodes: int
    seed: int
    env_version: str
    """gymnasium id and the simulator package's version: returns drift across versions."""
    measured_on: str
    command: str

    def reference(self) -> ReferenceScore:
        return ReferenceScore(self.mean, self.std, f"ours: {self.policy}, {self.episodes} episodes, seed "
                              f"{self.seed}, {self.env_version}, {self.measured_on}")


class UniformRandomPolicy:
    """Uniform-random actions from each env's own (seeded) action space."""

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        return np.stack([env.action_space.sample() for env in envs])


def env_version(spec: TaskSpec) -> str:
    package = _DOMAIN_PACKAGES.get(spec.domain)
    return f"{spec.name}, {package} {metadata.version(package)}" if package else spec.name


def episode_returns(task: str, policy: Demonstrator, episodes: int, seed: int = 0) -> np.ndarray:
    """One episode in each of `episodes` envs (env i seeded `seed + i`: for Meta-World, its own hidden
    goal), stepped in lockstep so the policy acts on a batch; returns their undiscounted returns."""
    return episode_outcomes(task, policy, episodes, seed)[0]


def episode_outcomes(task: str, policy: Demonstrator, episodes: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """`episode_returns`, and each episode's success (1 if the env flagged success at any step, else 0)."""
    envs = [make_env(task, seed=seed + i) for i in range(episodes)]
    observations = np.stack([env.reset()[0] for env in envs])
    returns, success = np.zeros(episodes), np.zeros(episodes)
    running = np.ones(episodes, dtype=bool)
    while running.any():
        active = np.flatnonzero(running)
        actions = policy.act(observations[active], [envs[i] for i in active])
        for i, action in zip(active, actions):
            observations[i], reward, terminated, truncated, info = envs[i].step(action)
            returns[i] += float(reward)
            success[i] = max(success[i], float(info.get("success", 0.0)))
            running[i] = not (terminated or truncated)
    for env in envs:
        env.close()
    return returns, success


def measure(task: str, policy_name: str, policy: Demonstrator, episodes: int, seed: int, command: str) -> MeasuredScore:
    """Run `policy` and describe its returns as a score-table row."""
    spec = get_task(task)
    returns = episode_returns(spec.name, policy, episodes, seed)
    return MeasuredScore(spec.name, policy_name, round(float(returns.mean()), 3), round(float(returns.std()), 3),
                         episodes, seed, env_version(spec), datetime.date.today().isoformat(), command)


def read_scores(path: Path | None = None) -> list[MeasuredScore]:
    """Every row of the score table (none if it does not exist yet)."""
    path = path or scores_path()
    if not path.is_file():
        return []
    rows = csv.DictReader(path.read_text().splitlines())
    return [MeasuredScore(**{**row, "mean": float(row["mean"]), "std": float(row["std"]),
                             "episodes": int(row["episodes"]), "seed": int(row["seed"])}) for row in rows]


def record_scores(new: Sequence[MeasuredScore], path: Path) -> Path:
    """Add rows to the score table at `path`, replacing any earlier row of the same (task, policy).

    `path` has no default: rewriting the package's reference table (`scores_path()`) has to be asked for.
    """
    replaced = {(s.task, s.policy) for s in new}
    rows = [s for s in read_scores(path) if (s.task, s.policy) not in replaced] + list(new)
    rows.sort(key=lambda s: (s.task, POLICIES.index(s.policy)))
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=[f.name for f in fields(MeasuredScore)], lineterminator="\n")
    writer.writeheader()
    writer.writerows(asdict(s) for s in rows)
    atomic_write_text(path, buffer.getvalue())
    return path


def our_reference_scores(task: str, path: Path | None = None) -> tuple[ReferenceScore, ReferenceScore] | None:
    """(random, expert) as measured here for `task`, or None if either was never measured."""
    name = get_task(task).name
    found = {s.policy: s.reference() for s in read_scores(path) if s.task == name}
    if not set(POLICIES) <= set(found):
        return None
    return found["random"], found["demonstrator"]
