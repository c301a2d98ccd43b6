"""The training configuration: one dataclass, every field documented (CleanRL style).

``--config`` takes a model preset name (``tiny``, ``small``, ``paper``: the defaults below with that
model) or a YAML file of TrainConfig fields, which may build on another (``base:``, `vintix.configfiles`);
``--set field=value`` overrides single fields.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from vintix.atomic import not_a_file
from vintix.configfiles import read_layered
from vintix.errors import VintixError, local_or_shipped
from vintix.fields import MAX_THREADS, check_field_types
from vintix.model.model import PRESETS, ModelConfig, preset


class ConfigError(VintixError, ValueError):
    """A training config that cannot be read or has unknown/invalid fields."""


SELECT_METRICS = ("score", "success")
"""What checkpoint selection may average over the last selection shots (`TrainConfig.select_metric`)."""


@dataclass
class TrainConfig:
    """Everything a training run depends on; saved in every checkpoint."""

    data: str = "data"
    """dataset root (<root>/<domain>/<task>/*.h5)"""
    out: str = "runs/default"
    """run directory: checkpoints/, log.csv, tensorboard/; re-running with the same out resumes"""
    model: str = "tiny"
    """model preset: tiny, small or paper"""
    model_overrides: dict[str, Any] = field(default_factory=dict)
    """ModelConfig fields to override, e.g. {mask_reward: true} for the AD-without-rewards ablation"""
    init_from: str | None = None
    """fine-tune: start from this model's weights (a checkpoint or a training run; `vintix train` also takes a shipped
    model's name), loaded wherever a parameter has the same name and shape, so task groups it lacks start fresh; its
    model settings must be this run's. A resumed run takes its weights from its own checkpoint instead"""
    tasks: list[str] = field(default_factory=lambda: ["train"])
    """train on these task names / domains / splits of the dataset (default: the train split, so held-out
    tasks in the folder never leak into training; [] for every task). The dataset's other tasks of the
    same groups get observation statistics only, for held-out evaluation"""
    window_len: int | None = None
    """steps per training window L (default: the model's context_len); also the saved model's context_len,
    the window the agent attends over"""
    batch_size: int = 8
    """windows per micro-batch per process"""
    grad_accum: int = 1
    """micro-batches per optimizer step (equal weights)"""
    max_steps: int = 2000
    """optimizer steps in the whole run (the cosine schedule ends here)"""
    lr: float = 3e-4
    """peak learning rate (paper: 3e-4)"""
    min_lr_fraction: float = 0.1
    """the cosine decays to lr * min_lr_fraction at max_steps"""
    warmup_steps: int = 100
    """linear warm-up, in optimizer steps"""
    beta1: float = 0.9
    """AdamW beta1 (paper: 0.9)"""
    beta2: float = 0.99
    """AdamW beta2 (paper: 0.99)"""
    weight_decay: float = 0.1
    """AdamW weight decay, applied to matrices only (not biases, norms, padding vectors)"""
    grad_clip: float = 1.0
    """clip the global gradient norm to this (0: no clipping)"""
    episode_sparsity: int = 1
    """keep every k-th episode of a history in a window (1: all episodes)"""
    stochastic_sparsity: bool = False
    """draw the sparsity of each window uniformly from 1..episode_sparsity"""
    task_sampling: str = "uniform"
    """'uniform' over tasks (the paper) or 'volume' (proportional to a task's steps)"""
    expert_distillation: bool = False
    """learn the demonstrator's actions instead of the history's: the paper's ED ablation on expert histories, or
    the recorded target (the demonstrator_action column) of in-context RL histories; see expert_rows"""
    expert_rows: str = "auto"
    """expert distillation on 'auto': every row, target = the stored demonstrator action, for tasks whose histories
    all store it (else 'tail'); 'tail': the noise-free tail only (paper)"""
    normalize_rewards: bool = False
    """scale each task's rewards to unit std over its data (stored in the checkpoint as the task's reward
    scale) instead of the registry's fixed scale: a reward encoder then sees every task's rewards at one scale"""
    expert_tail_fraction: float | None = None
    """tail fraction for expert_distillation (default: each task JSON's noise_free_fraction)"""
    seed: int = 0
    """seed of the model initialization and of the window sampler"""
    threads: int = 0
    """torch CPU threads of each training process (0: auto, the cores the load average leaves idle, at least one:
    on a 2-core machine running another training, 2 threads ran 3.2x slower than 1); `vintix train --threads`"""
    num_workers: int = 0
    """DataLoader worker processes per training process (0: load in the training process)"""
    device: str = "auto"
    """'auto' (CUDA if available), 'cpu' or 'cuda'; under torchrun each rank takes cuda:LOCAL_RANK"""
    checkpoint_every: int = 200
    """optimizer steps between checkpoints (the last step is always saved)"""
    keep_checkpoints: int = 3
    """most recent checkpoints kept on disk (older ones are deleted)"""
    log_every: int = 10
    """optimizer steps between log lines (CSV, TensorBoard, progress bar)"""
    tensorboard: bool = True
    """also write TensorBoard event files under <out>/tensorboard"""
    select_every: int = 0
    """optimizer steps between cold-start in-context evaluations that keep the best model in
    <out>/checkpoints/best (0: never); a multiple of log_every, so the score lands in the log"""
    select_tasks: list[str] = field(default_factory=list)
    """tasks of that evaluation (empty: the tasks trained on), run on env seeds no history was collected
    on: for Meta-World, hidden goals training never saw"""
    select_shots: int = 8
    """episodes per selection run; the score is the mean select_metric of the last half of them"""
    select_seeds: int = 3
    """selection runs per task (env seeds select_first_seed, select_first_seed + 1, ...)"""
    select_first_seed: int = 1000
    """env seed of the first selection run (collection seeds are 32-bit hashes, so these are unseen)"""
    select_reference: str = "ours"
    """reference table of the selection score: 'ours' (our measured demonstrators) or 'paper'"""
    select_metric: str = "score"
    """what selection averages: 'score' (normalized score) or 'success' (success rate, over the select_tasks
    that have a success flag, e.g. Meta-World; an error at the first selection if none has)"""
    select_reward_gap: bool = True
    """at each selection also run the same shots with zero rewards fed back, and log reward_use_gap (the
    metric with true rewards minus with zeros: how much the rewards drive it); doubles selection time"""
    stats_cache_dir: str | None = None
    """where normalization statistics are cached (default: ~/.cache/vintix/norm-stats)"""
    allow_resume_changes: bool = False
    """resume a run even though its data or a setting that shapes training (lr, batch size, seed, ...)
    differs from what its checkpoint recorded; by default such a resume is refused, naming each change"""

    def __post_init__(self) -> None:
        # Values from YAML and --set arrive untyped: "abc" must not reach a comparison as max_steps.
        check_field_types(self, ConfigError)
        if self.model not in PRESETS:
            raise ConfigError(f"model preset {self.model!r} is unknown; choose one of {sorted(PRESETS)}")
        # An empty path is the working folder to Path(""): never what a config that names one means.
        empty = [name for name in ("data", "out", "init_from", "stats_cache_dir") if getattr(self, name) == ""]
        if empty:
            raise ConfigError(f"{', '.join(empty)} given as an empty text; give a path, or null for none")
        positive = {"batch_size": self.batch_size, "grad_accum": self.grad_accum, "max_steps": self.max_steps,
                    "episode_sparsity": self.episode_sparsity, "checkpoint_every": self.checkpoint_every,
                    "keep_checkpoints": self.keep_checkpoints, "log_every": self.log_every,
                    "select_shots": self.select_shots, "select_seeds": self.select_seeds,
                    "window_len": 1 if self.window_len is None else self.window_len}
        bad = [f"{k}={v}" for k, v in positive.items() if v < 1]
        if bad:
            raise ConfigError(f"these fields must be >= 1: {', '.join(bad)}")
        non_negative = {"warmup_steps": self.warmup_steps, "weight_decay": self.weight_decay,
                        "grad_clip": self.grad_clip, "num_workers": self.num_workers, "seed": self.seed,
                        "threads": self.threads,
                        "select_first_seed": self.select_first_seed}
        bad = [f"{k}={v}" for k, v in non_negative.items() if v < 0]
        if bad:
            raise ConfigError(f"these fields must be >= 0: {', '.join(bad)}")
        ranges = {"lr": (self.lr, 0 < self.lr),
                  "min_lr_fraction": (self.min_lr_fraction, 0 <= self.min_lr_fraction <= 1),
                  "beta1": (self.beta1, 0 <= self.beta1 < 1), "beta2": (self.beta2, 0 <= self.beta2 < 1),
                  "expert_tail_fraction": (self.expert_tail_fraction,
                                           self.expert_tail_fraction is None or 0 < self.expert_tail_fraction <= 1)}
        bad = [f"{k}={v}" for k, (v, ok) in ranges.items() if not ok]
        if bad:
            raise ConfigError(f"out of range: {', '.join(bad)} (lr > 0; min_lr_fraction in [0, 1]; betas in [0, 1); "
                              "expert_tail_fraction in (0, 1])")
        if self.threads > MAX_THREADS:
            raise ConfigError(f"threads must be 0 (auto) or a number of CPU threads up to {MAX_THREADS}, got "
                              f"{self.threads}")
        if self.task_sampling not in ("uniform", "volume"):
            raise ConfigError(f"task_sampling must be 'uniform' or 'volume', got {self.task_sampling!r}")
        if self.expert_rows not in ("auto", "tail"):
            raise ConfigError(f"expert_rows must be 'auto' or 'tail', got {self.expert_rows!r}")
        if self.select_every < 0 or self.select_every % self.log_every:
            raise ConfigError(f"select_every must be 0 or a positive multiple of log_every ({self.log_every}), "
                              f"got {self.select_every}")
        if self.select_reference not in ("ours", "paper"):
            raise ConfigError(f"select_reference must be 'ours' or 'paper', got {self.select_reference!r}")
        if self.select_metric not in SELECT_METRICS:
            raise ConfigError(f"select_metric must be one of {', '.join(map(repr, SELECT_METRICS))}, "
                              f"got {self.select_metric!r}")
        if self.device not in ("auto", "cpu", "cuda"):
            raise ConfigError(f"device must be 'auto', 'cpu' or 'cuda', got {self.device!r}")
        context_len = self._preset_config().context_len  # also checks model_overrides
        if self.window_len is not None and self.window_len > context_len:
            raise ConfigError(
                f"window_len {self.window_len} exceeds the model's context_len {context_len}; "
                "lower window_len or raise model_overrides.context_len"
            )

    def model_config(self) -> ModelConfig:
        """The model to train: the preset with ``model_overrides`` applied, its context_len cut to
        ``window_len`` when that is given. The saved model then attends, when it acts, over the window it
        was trained on: positions beyond it were never seen in training."""
        config = self._preset_config()
        return dataclasses.replace(config, context_len=self.window_len) if self.window_len is not None else config

    def _preset_config(self) -> ModelConfig:
        known = {f.name for f in dataclasses.fields(ModelConfig)}
        unknown = sorted(set(self.model_overrides) - known)
        if unknown:
            raise ConfigError(f"model_overrides has unknown ModelConfig fields {unknown}; known: {sorted(known)}")
        try:
            return preset(self.model, **self.model_overrides)
        except ValueError as error:
            raise ConfigError(f"model_overrides: {error}") from error

    @property
    def window(self) -> int:
        """The window length actually used (the trained model's context_len)."""
        return self.model_config().context_len


_SET_HINT = ("(--set values are read as YAML: --set max_steps=500, --set 'tasks=[reach-v3, push-v3]', "
             "--set model_overrides={mask_reward: true}, or one model field on top of the config's: "
             "--set model_overrides.policy=flow)")


FREE_ON_RESUME = frozenset({
    "data", "out", "max_steps", "device", "threads", "num_workers", "checkpoint_every", "keep_checkpoints", "log_every",
    "tensorboard", "select_every", "select_shots", "select_seeds", "select_first_seed", "select_reward_gap",
    "stats_cache_dir", "allow_resume_changes", "model", "model_overrides", "init_from",
})
"""TrainConfig fields a resumed run may change: where things are, how long it runs, how often it logs,
saves and scores; how the model is spelled (preset and overrides), as long as the model they make is the
checkpoint's (`check_resumable` compares the two); and where its first weights came from (`init_from`: a resumed
run's weights are its checkpoint's, and `vintix train` spells a shipped model's name as its folder). Every other
field shapes the weights or what "best" means, so a resumed run that changes one is a different run
(`TrainConfig.allow_resume_changes`)."""


def _parse_override(item: str) -> tuple[str, Any]:
    if "=" not in item:
        raise ConfigError(f"--set expects field=value, got {item!r}")
    key, value = item.split("=", 1)
    if not value.strip():
        raise ConfigError(f"--set {item!r} gives {key.strip()} no value; write {key.strip()}=null for none, or leave "
                          "the --set out for the config's value")
    try:
        return key.strip(), yaml.safe_load(value)
    except yaml.YAMLError as error:  # a tag such as !!python/object, or broken YAML
        problem = " ".join(str(error).split())
        raise ConfigError(f"--set {item!r}: the value is not plain YAML ({problem}) {_SET_HINT}") from None


def shipped_configs() -> list[str]:
    """Names of the training configs the package ships (`src/vintix/train/configs/`)."""
    return sorted(p.name.removesuffix(".yaml") for p in resources.files("vintix.train").joinpath("configs").iterdir()
                  if p.name.endswith(".yaml"))


def shipped_config(name: str) -> Path | None:
    """The file of the training config the package ships as `name`, or None."""
    shipped = resources.files("vintix.train").joinpath("configs").joinpath(f"{name}.yaml")
    return Path(str(shipped)) if shipped.is_file() else None


def load_config(config: str, overrides: dict[str, Any] | None = None, settings: list[str] | None = None) -> TrainConfig:
    """A TrainConfig from a preset name, a shipped config's name or a YAML file, then ``overrides`` (e.g.
    --data/--out), then ``settings`` (``"field=value"`` strings, values parsed as YAML)."""
    if config in PRESETS:
        fields: dict[str, Any] = {"model": config}
    else:
        path = Path(config)
        shipped = shipped_config(config)
        if shipped is not None and not local_or_shipped(config, True, "training config", a_file=True):
            path = shipped
        elif why := not_a_file(path):
            raise ConfigError(f"--config {why}")
        elif not path.is_file():
            raise ConfigError(f"--config {config!r} is neither a model preset ({', '.join(PRESETS)}), a shipped config "
                              f"({', '.join(shipped_configs())}) nor a YAML file")
        fields = read_layered(path, shipped_config, ConfigError, "training config")
    given = {k: v for k, v in (overrides or {}).items() if v is not None}
    fields.update(given)
    parsed = [_parse_override(item) for item in settings or []]
    repeated = sorted({key for key, _ in parsed if [k for k, _ in parsed].count(key) > 1})
    if repeated:
        raise ConfigError(f"--set {', '.join(repeated)} given more than once; give each field once")
    settings_given = dict(parsed)
    clashes = [f"--{k} {given[k]} but --set {k}={v}" for k, v in settings_given.items() if k in given and v != given[k]]
    if clashes:
        raise ConfigError(f"{'; '.join(clashes)}: give each value once")
    for key in [k for k in settings_given if k.startswith("model_overrides.")]:
        # One model field on top of the config's overrides, where --set model_overrides={...} replaces them all.
        fields["model_overrides"] = {**(fields.get("model_overrides") or {}),
                                     key.removeprefix("model_overrides."): settings_given.pop(key)}
    fields.update(settings_given)
    known = {f.name for f in dataclasses.fields(TrainConfig)}
    unknown = sorted(set(fields) - known)
    if unknown:
        raise ConfigError(f"unknown TrainConfig fields {unknown}; known: {sorted(known)}")
    try:
        return TrainConfig(**fields)
    except ConfigError as error:
        if not settings:
            raise
        raise ConfigError(f"{error} {_SET_HINT}") from error
