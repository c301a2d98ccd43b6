"""Trained demonstrators (MuJoCo, Industrial Benchmark): Stable-Baselines3 policies shipped as
weights only.

A demonstrator is stored per encoder group as ``weights/<group>.safetensors`` (the tensors that
`predict` uses, plus the observation-normalization statistics when the policy was trained behind
`VecNormalize`) and ``weights/<group>.json`` (algorithm, policy architecture, how it was trained and
with which command). Nothing is pickled: the SB3 policy is rebuilt from the JSON and the env's spaces,
then the tensors are loaded into it. One file per group rather than per task because one Industrial
Benchmark policy serves all 21 setpoints (the setpoint is part of its observation). The meta-RL tasks
(HalfCheetah-Vel, HalfCheetah-Dir, Ant-Dir) share their bodies' groups but each has an expert of its own, stored
under the task's name (`expert_name`): a goal-aware one, which observes the hidden parameter appended to the
observation (`vintix.tasks.meta_mujoco.with_goal_observed`) and can aim at any parameter it is given
(`act_toward`), as a goal-inferring demonstrator needs.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from importlib import resources
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load_file
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecNormalize
from stable_baselines3.sac.policies import SACPolicy

from vintix.atomic import atomic_save_tensors, atomic_write_text
from vintix.demonstrators.base import expert_name, goal_observed
from vintix.errors import VintixError, at_file
from vintix.fields import read_json_object
from vintix.tasks import TaskSpec, action_box, get_task, list_tasks, make_env
from vintix.tasks.meta_mujoco import with_goal_observed

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"PPO": PPO, "SAC": SAC}
OBS_MEAN, OBS_VAR = "obs_rms.mean", "obs_rms.var"


def expert_task(name: str) -> TaskSpec:
    """The first task whose demonstrator is `name` (`expert_name`), the one its training scores it on."""
    return next(spec for spec in list_tasks() if expert_name(spec) == name)


def expert_env(task: str, observation_dims: int = 0, **options: Any) -> gym.Env:
    """`task`'s env as its trained expert sees it: the first `observation_dims` dimensions of its observation (0:
    all), and a meta-RL task's hidden parameter after them."""
    env = first_observations(make_env(task, **options), observation_dims)
    return with_goal_observed(env) if goal_observed(get_task(task)) else env


def shipped_weights_dir() -> Path:
    """Where the package keeps its trained demonstrators."""
    return Path(str(resources.files("vintix.demonstrators").joinpath("weights")))


def weights_paths(group: str, directory: Path | None = None) -> tuple[Path, Path]:
    """(tensors, metadata) files of a group's demonstrator."""
    directory = directory or shipped_weights_dir()
    return directory / f"{group}.safetensors", directory / f"{group}.json"


def _inference_module(policy: BasePolicy) -> torch.nn.Module:
    # Off-policy algorithms act through the actor alone; their critics are training-only weight.
    actor = getattr(policy, "actor", None)
    return actor if isinstance(actor, torch.nn.Module) else policy


def save_trained_policy(model: BaseAlgorithm, vec_normalize: VecNormalize | None, group: str,
                        directory: Path, info: dict[str, Any]) -> Path:
    """Write the acting weights of `model` (and its obs statistics) as the demonstrator of `group`."""
    tensors_path, meta_path = weights_paths(group, directory)
    directory.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().cpu().contiguous() for k, v in _inference_module(model.policy).state_dict().items()}
    meta: dict[str, Any] = {"algorithm": type(model).__name__, "policy_kwargs": model.policy_kwargs, **info}
    if vec_normalize is not None:
        statistics = vec_normalize.obs_rms  # one RunningMeanStd per key for a Dict observation space
        assert isinstance(statistics, RunningMeanStd), "every vintix task observes a flat Box"
        tensors[OBS_MEAN] = torch.as_tensor(statistics.mean, dtype=torch.float64)
        tensors[OBS_VAR] = torch.as_tensor(statistics.var, dtype=torch.float64)
        meta["obs_normalization"] = {"clip": vec_normalize.clip_obs, "epsilon": vec_normalize.epsilon}
    atomic_save_tensors(tensors, tensors_path)
    atomic_write_text(meta_path, json.dumps(meta, indent=2) + "\n")
    return tensors_path


_RESAVE = "save the pair again with `vintix demonstrator train`, or point --weights at a folder of intact ones"


def _read_weights(tensors_path: Path, meta_path: Path) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """A demonstrator's metadata and tensors, or a named error for a damaged or foreign pair. Layer widths
    in the metadata are checked against the tensors before SB3 builds anything: a width that no tensor
    has cannot load, and an absurd one would exhaust memory building the policy."""
    metadata = read_json_object(meta_path, at_file(VintixError), _RESAVE)
    if not isinstance(metadata.get("policy_kwargs"), dict):
        raise VintixError(f"{meta_path}: not a demonstrator's metadata (a JSON object with 'algorithm' and "
                          f"'policy_kwargs'); {_RESAVE}")
    if metadata.get("algorithm") not in ALGORITHMS:
        raise VintixError(f"{meta_path}: algorithm {metadata.get('algorithm')!r} is not one of "
                          f"{', '.join(ALGORITHMS)}; {_RESAVE}")
    try:
        tensors = load_file(str(tensors_path))
    except (SafetensorError, OSError) as error:
        raise VintixError(f"{tensors_path}: not a readable safetensors file ({error}); {_RESAVE}") from None
    widest = max((max(t.shape, default=1) for t in tensors.values()), default=0)
    widths = _layer_widths(metadata["policy_kwargs"].get("net_arch", []))
    if any(not isinstance(w, int) or not 0 < w <= widest for w in widths):
        raise VintixError(f"{meta_path}: net_arch {metadata['policy_kwargs']['net_arch']} has layer widths that "
                          f"no tensor of {tensors_path.name} has (widest {widest}); the pair does not belong "
                          f"together; {_RESAVE}")
    return metadata, tensors


def _layer_widths(net_arch: object) -> list[object]:
    """Every layer width in an SB3 `net_arch` (a list of widths, or a dict of such lists per network)."""
    if isinstance(net_arch, dict):
        return [w for widths in net_arch.values() for w in _layer_widths(widths)]
    return list(net_arch) if isinstance(net_arch, list) else [net_arch]


class MissingDemonstratorError(VintixError):
    """A task whose group's demonstrator has not been trained (no weights where they are looked for)."""


class TrainedDemonstrator:
    """A trained SB3 policy acting deterministically on a batch of observations."""

    def __init__(self, spec: TaskSpec, directory: Path | None = None) -> None:
        tensors_path, meta_path = weights_paths(expert_name(spec), directory)
        if not tensors_path.is_file() or not meta_path.is_file():
            raise MissingDemonstratorError(
                f"no trained demonstrator for {spec.name!r} ({expert_name(spec)!r}) in {tensors_path.parent}: "
                f"train one with `vintix demonstrator train --task {spec.name}` (see demonstrators/training.py "
                "for its budget), or collect a task that has one (`vintix demonstrator list`)."
            )
        self.metadata, tensors = _read_weights(tensors_path, meta_path)
        self.observation_dims = int(self.metadata.get("observation_dims", 0))
        self.goal_observed = goal_observed(spec)
        env = expert_env(spec.name, self.observation_dims)
        observation_space, action_space = env.observation_space, env.action_space
        env.close()
        policy_class = ALGORITHMS[self.metadata["algorithm"]].policy_aliases["MlpPolicy"]
        try:  # an edited or foreign file: a keyword the policy does not take, a value of the wrong kind
            self.policy: BasePolicy = policy_class(
                observation_space, action_space, lr_schedule=lambda _: 0.0, **self.metadata["policy_kwargs"]
            )
        except (TypeError, ValueError, KeyError, AttributeError) as error:
            raise VintixError(f"{meta_path}: its policy_kwargs {self.metadata['policy_kwargs']} do not make a "
                              f"{self.metadata['algorithm']} policy ({type(error).__name__}: {error}); "
                              f"{_RESAVE}") from None
        self.obs_mean, self.obs_var = tensors.pop(OBS_MEAN, None), tensors.pop(OBS_VAR, None)
        if (self.obs_mean is None) != (self.obs_var is None):
            raise VintixError(f"{tensors_path} holds only one of {OBS_MEAN} and {OBS_VAR}, the observation "
                              f"statistics the policy was trained with; {_RESAVE}")
        try:
            _inference_module(self.policy).load_state_dict(tensors)
        except RuntimeError as error:  # missing, unexpected or misshapen tensors
            raise VintixError(f"{tensors_path} does not fit the {self.metadata['algorithm']} policy that "
                              f"{meta_path.name} describes for {spec.name!r}: {error}; {_RESAVE}") from None
        self.policy.set_training_mode(False)
        modules = deterministic_actor(self.policy)
        self._mlp = None if modules is None else NumpyMlp.from_modules(modules)

    def policy_input(self, observations: np.ndarray, goals: np.ndarray | None = None) -> np.ndarray:
        """What the policy sees of `observations`: their first `observation_dims` dimensions if it was
        trained on those only, then a goal-aware expert's `goals` [n, goal_dim], scaled as
        `VecNormalize.normalize_obs` did in training (saved statistics)."""
        if self.observation_dims:
            observations = observations[:, :self.observation_dims]
        if self.goal_observed:
            assert goals is not None, "a goal-aware expert acts on a goal"
            observations = np.concatenate([observations, goals], axis=1)
        if self.obs_mean is None or self.obs_var is None:  # both or neither (checked on loading)
            return observations
        settings = self.metadata["obs_normalization"]
        scaled = (observations - self.obs_mean.numpy()) / np.sqrt(self.obs_var.numpy() + settings["epsilon"])
        return np.clip(scaled, -settings["clip"], settings["clip"]).astype(np.float32)

    def act(self, observations: np.ndarray, envs: Sequence[gym.Env]) -> np.ndarray:
        """What ``policy.predict(..., deterministic=True)`` returns (up to float32 rounding), computed by
        `NumpyMlp` from the policy's own weights: predict re-sets the training mode of every module and
        builds a distribution object on each call, and torch's per-op dispatch alone took longer than
        the simulator's step in a collection loop. A goal-aware expert reads each env's hidden parameter."""
        goals = np.stack([env.unwrapped.true_goal for env in envs]) if self.goal_observed else None  # type: ignore[attr-defined]
        return self._act(self.policy_input(np.asarray(observations), goals))

    def act_toward(self, observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """A goal-aware expert's actions had the hidden parameter of env i been ``goals[i]`` (a goal-inferring
        demonstrator's guesses)."""
        if not self.goal_observed:
            raise VintixError(f"{self.metadata['group']!r}'s expert observes no hidden goal to aim at")
        return self._act(self.policy_input(np.asarray(observations), np.asarray(goals, dtype=np.float64)))

    def _act(self, inputs: np.ndarray) -> np.ndarray:
        if self._mlp is None:
            actions, _ = self.policy.predict(inputs, deterministic=True)
            return actions
        actions = self._mlp(np.asarray(inputs, dtype=np.float32))
        if self.policy.squash_output:  # tanh-squashed policies act in [-1, 1]
            return self.policy.unscale_action(actions)
        space = action_box(self.policy.action_space)
        return np.clip(actions, space.low, space.high)


def observation_view(space: gym.Space, dims: int) -> gym.Space:
    """The space of the first `dims` dimensions of a Box observation space (0: the whole space)."""
    if not dims:
        return space
    if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1 or not 0 < dims <= space.shape[0]:
        raise VintixError(f"cannot view the first {dims} dimensions of observation space {space}")
    return gym.spaces.Box(space.low[:dims], space.high[:dims], dtype=space.dtype)


def first_observations(env: gym.Env, dims: int) -> gym.Env:
    """`env` observed through its first `dims` observation dimensions (0: unchanged)."""
    if not dims:
        return env
    return gym.wrappers.TransformObservation(env, lambda obs: obs[:dims], observation_view(env.observation_space, dims))


def deterministic_actor(policy: BasePolicy) -> list[torch.nn.Module] | None:
    """The modules, in order, that map a (normalized, flat) observation to the policy's deterministic
    action: SAC's mean squashed by tanh, PPO's Gaussian mean; None for others."""
    if isinstance(policy, SACPolicy) and not policy.actor.use_sde:
        return [*policy.actor.latent_pi, policy.actor.mu, torch.nn.Tanh()]
    if isinstance(policy, ActorCriticPolicy) and isinstance(policy.action_dist, DiagGaussianDistribution):
        return [*policy.mlp_extractor.policy_net, policy.action_net]
    return None


class NumpyMlp:
    """A stack of Linear / Tanh / ReLU modules evaluated with numpy in float32.

    In a collection step the demonstrator runs once per batch between the envs' steps, with cold
    caches: a 2-layer MLP of 64 units took 156 µs per call through torch and 32 µs through numpy,
    HalfCheetah's 256-unit one 238 µs and 138 µs (16 observations, this 2-core CPU).
    """

    ACTIVATIONS: ClassVar[dict[type[torch.nn.Module], Callable[[np.ndarray], np.ndarray]]] = {
        torch.nn.Tanh: np.tanh, torch.nn.ReLU: lambda x: np.maximum(x, 0)}

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray] | Callable[[np.ndarray], np.ndarray]]) -> None:
        self.layers = layers

    @classmethod
    def from_modules(cls, modules: Sequence[torch.nn.Module]) -> NumpyMlp | None:
        """The same function as `modules` applied in turn; None if one is not Linear, Tanh or ReLU."""
        layers: list[tuple[np.ndarray, np.ndarray] | Callable[[np.ndarray], np.ndarray]] = []
        for module in modules:
            if isinstance(module, torch.nn.Linear) and module.bias is not None:
                layers.append((module.weight.detach().numpy().T.copy(), module.bias.detach().numpy().copy()))
            elif type(module) in cls.ACTIVATIONS:
                layers.append(cls.ACTIVATIONS[type(module)])
            else:
                return None
        return cls(layers)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        for layer in self.layers:
            x = x @ layer[0] + layer[1] if isinstance(layer, tuple) else layer(x)
        return x
