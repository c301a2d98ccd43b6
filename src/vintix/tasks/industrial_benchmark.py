"""Industrial Benchmark (Hein et al., 2017) as a gymnasium env, around the `IDS` simulator of
`industrial-benchmark-python`.

Why not the package's own `IBGym`: it is written for the old `gym` API, which we do not install.
Two more things need care, and one fix serves both: the `IDS` module gets a NumPy namespace of its
own (a copy of NumPy's attributes) instead of the real module.
- `IDS` calls `np.float`, which NumPy 2 removed: the namespace keeps the alias, without patching
  NumPy for the whole process.
- `IDS` draws every random number from NumPy's *global* RNG (`np.random.*`). Each env points the
  namespace's `random` at its own `RandomState` before running the simulator, so envs stepped
  alternately in one process give the same trajectories as each run alone, and the process's
  global RNG is never touched. (Swapping the global state in and out instead costs ~2x the step.)
"""

from __future__ import annotations

import types
from functools import cache
from typing import Any, Literal

import gymnasium as gym
import numpy as np

from vintix.errors import MissingDependencyError

EPISODE_LENGTH = 250  # the paper's episode length for this domain
REWARD_DIVISOR = 100.0  # the paper down-scales the classic reward by 100
INSTALL_HINT = "pip install --no-deps industrial-benchmark-python==2.0"


@cache
def _ids_module() -> types.ModuleType:
    """The simulator's module, running on a NumPy namespace of its own (see the module docstring)."""
    try:
        from industrial_benchmark_python import IDS as ids_module
    except ImportError as error:
        raise MissingDependencyError(
            f"Industrial Benchmark tasks need the package industrial-benchmark-python: run `{INSTALL_HINT}` "
            "(--no-deps: its metadata asks for the old `gym`, which the simulator never uses)."
        ) from error
    namespace = types.ModuleType("numpy")
    namespace.__dict__.update(vars(np))
    namespace.float = float  # type: ignore[attr-defined]
    ids_module.np = namespace
    return ids_module


class IndustrialBenchmarkEnv(gym.Env):
    """Observation: setpoint, velocity, gain, shift, fatigue, consumption. Action: changes of
    velocity, gain and shift in [-1, 1]. Reward: -(3·fatigue + consumption) / 100 ("classic"), or
    its change since the previous step ("delta", what the paper's PPO demonstrators train on). The
    classic reward is always in `info["classic_reward"]`."""

    metadata = {"render_modes": []}

    def __init__(self, setpoint: float, reward_type: Literal["classic", "delta"] = "classic") -> None:
        if not 0 <= setpoint <= 100:
            raise ValueError(f"Industrial Benchmark setpoint must lie in [0, 100], got {setpoint}")
        if reward_type not in ("classic", "delta"):
            raise ValueError(f"reward_type must be 'classic' or 'delta', got {reward_type!r}")
        self._simulator = _ids_module()
        self.setpoint = float(setpoint)
        self.reward_type = reward_type
        high = np.array([100, 100, 100, 100, np.inf, np.inf], dtype=np.float32)
        self.observation_space = gym.spaces.Box(np.zeros(6, dtype=np.float32), high, dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        self._simulator_rng = np.random.RandomState(0)
        self._ids: Any = None
        self._last_classic_reward = 0.0

    def _use_own_rng(self) -> None:
        """Point the simulator's `np.random` at this env's RNG; call before every simulator call."""
        self._simulator.np.random = self._simulator_rng

    def _observation(self) -> np.ndarray:
        return self._ids.visibleState()[:6].astype(np.float32)  # drop the trailing cost and reward

    def _classic_reward(self) -> float:
        return float(-self._ids.state["cost"] / REWARD_DIVISOR)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        simulator_seed = int(self.np_random.integers(2**31 - 1))
        self._use_own_rng()
        self._ids = self._simulator.IDS(self.setpoint, inital_seed=simulator_seed)
        self._last_classic_reward = self._classic_reward()
        return self._observation(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self._ids is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        self._use_own_rng()
        self._ids.step(np.asarray(action, dtype=np.float64))
        classic = self._classic_reward()
        reward = classic if self.reward_type == "classic" else classic - self._last_classic_reward
        self._last_classic_reward = classic
        return self._observation(), reward, False, False, {"classic_reward": classic}
