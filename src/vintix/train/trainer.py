"""Algorithm Distillation training: next-action MSE over multi-episode windows (paper §2.3; docs/training.md).

One loop serves one CPU, one GPU and ``torchrun`` DDP (gloo on CPU, nccl on GPU; rank 0 is global
``RANK`` 0). Steps, the warm-up and the cosine all count *optimizer* steps; gradient accumulation
weights every micro-batch equally. Re-running with the same ``out`` resumes from the newest
checkpoint, and an interrupted-then-resumed run reproduces the uninterrupted one (the window
sampler is a function of the window index, and model, optimizer, step and RNG are restored).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import math
import os
import shutil
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, TypeVar

import numpy as np
import torch
import torch.distributed as dist
from torch import nn
from tqdm import tqdm

from vintix.atomic import atomic_write_text, check_output_kind, folder_lock
from vintix.errors import DeviceError, VintixError
from vintix.fields import available_cores, capped_threads
from vintix.interrupt import Interrupted, StopRequest, stop_requests
from vintix.memory import build_within_memory
from vintix.model.checkpoint import WEIGHTS_FILE, CheckpointError, load_pretrained
from vintix.model.model import Vintix, count_parameters, estimated_parameters
from vintix.model.official import file_sha256
from vintix.tasks import select_tasks
from vintix.train.checkpoint import (
    best_checkpoint_dir,
    best_score,
    check_resumable,
    checkpoint_dir,
    latest_checkpoint,
    load_optimizer,
    model_directory,
    portable_record,
    prune_checkpoints,
    read_rng,
    read_training_state,
    resumable_checkpoint,
    resume_changes,
    save_best_checkpoint,
    save_training_checkpoint,
)
from vintix.train.config import FREE_ON_RESUME, ConfigError, TrainConfig
from vintix.train.data import Batch, TrainingData, WindowBatches, WindowDataset, collate_windows, load_training_data

_Result = TypeVar("_Result")
Callback = Callable[[Vintix, int], None]
"""Called on rank 0 as ``callback(model, step)`` after an optimizer step."""


@dataclass(frozen=True)
class Selection:
    """What one in-context checkpoint selection measured."""

    score: float
    """the selection metric with the true rewards fed back (higher is better): it chooses the best checkpoint"""
    reward_use_gap: float = math.nan
    """the score minus the same run's with zero rewards fed back: how much of it the rewards earn (in-context
    RL's signature; near 0, the model improves over shots without reading rewards); NaN when not measured"""


Scorer = Callable[[Vintix, Sequence[str]], Selection]
"""``scorer(model, tasks)``: the model's cold-start in-context `Selection` on ``tasks``, whose score chooses
the best checkpoint; `vintix.evaluate.in_context_scorer` makes one from a TrainConfig. It lives above
training (it runs envs and the agent), so the trainer takes it as an argument."""


class NonFiniteLossError(VintixError, RuntimeError):
    """Training met a NaN/inf loss or gradient and stopped before it reached the weights (the message
    names the step and the last good checkpoint)."""


# ----------------------------------------------------------------------------------------------
# The pieces the loop (and the benchmark) are made of


class WindowLoss(nn.Module):
    """Per-window loss of a micro-batch that may mix groups: each group's head's own (`ActionHead.loss`: MSE, a
    gaussian's negative log-likelihood, a discrete group's cross-entropy, a flow's velocity error).

    Each group's windows go through their own encoder, all windows through one backbone call, then
    each group's head. Wrapping this (not the model) in DDP makes the whole mixed-group pass one
    DDP forward. A window's loss is the mean over its positions and action channels.
    """

    def __init__(self, model: Vintix) -> None:
        super().__init__()
        self.model = model

    def forward(self, batch: Batch) -> torch.Tensor:
        return self.per_position(batch).mean(dim=1)

    def per_position(self, batch: Batch) -> torch.Tensor:
        """Each window's loss at each of its positions, ``[windows, positions]`` (`scripts/window_loss.py` shows it
        along the window)."""
        groups = list(batch)
        tokens = [self.model.embed(g, b["task_idx"], b["obs"], b["prev_action"], b["prev_reward"], b["step_num"],
                                   b.get("prev_return")) for g, b in batch.items()]
        hidden = self.model.backbone(torch.cat(tokens))
        return torch.cat([self.model.action_head(group).loss(part, batch[group]["action"])
                          for group, part in zip(groups, hidden.split([t.shape[0] for t in tokens]), strict=True)])


def window_sizing_notes(data: TrainingData, window_len: int, keep_first_steps: int,
                        eval_shots: int | None) -> list[str]:
    """Where training windows will not look like what an evaluation of `eval_shots` episodes (the in-context
    selection's; None: not known) shows the agent: its context starts at a run's first step while it fits the window,
    and a history longer than the window gives mostly windows that start mid-history (docs/training.md#sizing)."""
    notes = []
    for task in data.tasks:
        longest = max((h.steps for h in task.histories), default=0)
        lengths = [np.diff(h.bounds) for h in task.histories]
        episode = int(np.median(np.concatenate(lengths))) if any(len(x) for x in lengths) else 1
        fits = window_len // max(episode, 1)
        # A context of constant noise (DPT's random contexts, `NoiseSchedule.level`) looks alike wherever it starts.
        constant = all("level" in h.history.attrs for h in task.histories)
        starts_at_a_run = eval_shots is None or eval_shots <= fits
        if longest > window_len and not keep_first_steps and not constant and starts_at_a_run:
            shown = f"an evaluation of up to {fits} episodes" if eval_shots is None else \
                f"the selection's {eval_shots}-episode runs"
            notes.append(f"{task.name}: its histories ({longest:,} steps) are longer than the {window_len:,}-step "
                         f"window, so most training windows start mid-history, while {shown} show the model a "
                         "context that starts at the run's first episode; for those, make histories as long as the "
                         "window, or keep their start (keep_first_steps) (docs/training.md#sizing-histories-and-"
                         "windows)")
    return notes


def build_optimizer(model: nn.Module, config: TrainConfig) -> tuple[torch.optim.AdamW, list[str]]:
    """AdamW with weight decay on matrices only; also the parameter names in the optimizer's order."""
    named = [(n, p) for n, p in model.named_parameters() if p.requires_grad]
    decay = [(n, p) for n, p in named if p.ndim >= 2]
    no_decay = [(n, p) for n, p in named if p.ndim < 2]
    optimizer = torch.optim.AdamW(
        [{"params": [p for _, p in decay], "weight_decay": config.weight_decay},
         {"params": [p for _, p in no_decay], "weight_decay": 0.0}],
        lr=config.lr, betas=(config.beta1, config.beta2),
    )
    return optimizer, [n for n, _ in decay + no_decay]


def learning_rate(step: int, config: TrainConfig) -> float:
    """Linear warm-up to ``lr`` over ``warmup_steps``, then cosine to ``lr * min_lr_fraction`` at ``max_steps``."""
    if step < config.warmup_steps:
        return config.lr * (step + 1) / config.warmup_steps
    progress = min(1.0, (step - config.warmup_steps) / max(1, config.max_steps - config.warmup_steps))
    floor = config.lr * config.min_lr_fraction
    return floor + (config.lr - floor) * 0.5 * (1.0 + math.cos(math.pi * progress))


def flops_per_token(model: Vintix, group: str, window_len: int) -> float:
    """Training FLOPs per token (forward + backward) for a window of ``window_len`` steps of ``group``.

    PaLM's count: 6 per parameter the token passes through (backbone, the group's encoder and
    head), plus 12 · layers · width · T for attention scores and values. The full T×T attention is
    counted, as the additive-bias kernel computes it all.
    """
    used = (count_parameters(model.blocks) + count_parameters(model.ln_f)
            + count_parameters(model.encoders[group]) + count_parameters(model.heads[group]))
    config = model.config
    return 6.0 * used + 12.0 * config.n_layers * config.d_model * window_len


def measure_matmul_flops(device: torch.device, dtype: torch.dtype = torch.float32, size: int = 1024,
                         repeats: int = 5) -> float:
    """This device's dense matmul rate (FLOP/s, best of ``repeats``): the peak that MFU is relative to."""
    a = torch.randn(size, size, device=device, dtype=dtype)
    b = torch.randn(size, size, device=device, dtype=dtype)
    best = math.inf
    for _ in range(repeats + 1):  # the first call warms up the kernels
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        start = time.perf_counter()
        a @ b
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        best = min(best, time.perf_counter() - start)
    return 2.0 * size**3 / best


def batch_to(batch: Batch, device: torch.device) -> Batch:
    """Move a collated micro-batch to ``device``."""
    return {g: {k: v.to(device, non_blocking=True) for k, v in b.items()} for g, b in batch.items()}


def precision_context(device: torch.device) -> contextlib.AbstractContextManager:
    """bf16 autocast on CUDA; plain fp32 on CPU, where bf16 matmuls are 10-100x slower."""
    if device.type == "cuda":
        return torch.autocast("cuda", dtype=torch.bfloat16)
    return contextlib.nullcontext()


# ----------------------------------------------------------------------------------------------
# Processes


@dataclass(frozen=True)
class Distributed:
    """This process's place in a ``torchrun`` job (a single process is rank 0 of 1)."""

    rank: int
    local_rank: int
    world_size: int

    @property
    def is_main(self) -> bool:
        """Global rank 0 writes checkpoints and logs (never LOCAL_RANK 0 of every node)."""
        return self.rank == 0

    def barrier(self) -> None:
        """Wait for every rank (nothing to wait for alone)."""
        if self.world_size > 1:
            dist.barrier()


def resolve_device(name: str, local_rank: int) -> torch.device:
    """'auto' picks CUDA when available; a torchrun rank takes its LOCAL_RANK's GPU."""
    use_cuda = name == "cuda" or (name == "auto" and torch.cuda.is_available())
    if use_cuda and not torch.cuda.is_available():
        raise DeviceError("device 'cuda' requested but torch sees no GPU; use device=cpu or auto")
    return torch.device("cuda", local_rank) if use_cuda else torch.device("cpu")


def busy_cores(samples: int = 10, interval: float = 0.02) -> float | None:
    """How many cores other work keeps busy now: the runnable threads /proc/loadavg counts, less the one reading
    it, averaged over `samples` reads `interval` seconds apart; None without /proc/loadavg (not Linux). The
    1-minute load average would instead still count a job that ended seconds ago, such as the collection a
    script runs just before training."""
    path = Path("/proc/loadavg")
    if not path.is_file():
        return None
    counts = []
    for i in range(samples):
        if i:
            time.sleep(interval)
        counts.append(int(path.read_text().split()[3].split("/")[0]) - 1)  # "running/total"
    return sum(counts) / samples


def training_threads(requested: int, world_size: int) -> int:
    """torch CPU threads for one of `world_size` training processes: `requested`, or (0) the cores that other work
    leaves idle now (`busy_cores`; without /proc, by the 1-minute load average), shared among the processes, at
    least one. A second thread on a core another job keeps busy slows the many small ops of a small model down
    instead of speeding them up."""
    if requested:
        return capped_threads(requested, print)
    cores = available_cores()
    busy = busy_cores()
    if busy is None:
        busy = os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
    return max(1, min(cores, cores - round(busy)) // world_size)


INFERENCE_ONLY_SETTINGS = ("keep_first_steps", "sample_noise", "flow_steps", "context_len")
"""Model settings no weight depends on (training windows never slide; ALiBi has no weight per position, so a window
of another length reads the same weights): a fine-tune may change them"""


def start_from_pretrained(model: Vintix, name_or_path: str) -> list[str]:
    """Copy into `model` the weights of the model in `name_or_path` (a checkpoint or a run folder: `model_directory`;
    `vintix train` resolves a shipped model's name to its folder first) wherever a parameter
    has the same name and shape, for fine-tuning; return the groups whose encoder or head keeps its fresh
    initialization, the ones that model lacks. Parameters only: buffers (the tasks' normalization statistics) stay
    this run's data's. Both must share their model settings, but the inference-only ones: a shared trunk's weights
    mean nothing in another architecture."""
    source = load_pretrained(model_directory(name_or_path))
    differ = [f"{name} {value} here, {getattr(source.config, name)} there"
              for name, value in dataclasses.asdict(model.config).items()
              if name not in INFERENCE_ONLY_SETTINGS and getattr(source.config, name) != value]
    if differ:
        raise ConfigError(f"init_from {name_or_path}: its model settings are not this run's ({'; '.join(differ)}); "
                          "train with its preset and model_overrides, or from scratch")
    target = dict(model.named_parameters())
    with torch.no_grad():
        for name, value in source.named_parameters():
            if name in target and target[name].shape == value.shape:
                target.pop(name).copy_(value)
    return sorted({name.split(".")[1] for name in target})  # encoders.<group>.… and heads.<group>.…


def init_distributed(device_name: str) -> tuple[Distributed, torch.device]:
    """Join the ``torchrun`` process group if there is one (its env vars say so)."""
    world_size = int(os.environ.get("WORLD_SIZE", "1"))
    rank, local_rank = int(os.environ.get("RANK", "0")), int(os.environ.get("LOCAL_RANK", "0"))
    device = resolve_device(device_name, local_rank)
    if world_size > 1 and not dist.is_initialized():
        if device.type == "cuda":
            torch.cuda.set_device(device)
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    return Distributed(rank, local_rank, world_size), device


# ----------------------------------------------------------------------------------------------
# Logs


_TENSORBOARD_TAGS = {"in_context_score": "in_context/score", "reward_use_gap": "in_context/reward_use_gap"}


def _duration(seconds: float) -> str:
    minutes = round(seconds / 60)
    return f"{minutes // 60} h {minutes % 60:02d} min" if minutes >= 60 else f"{max(minutes, 1)} min"


class ProgressReport:
    """Lines a person reads while a run trains: after its first logged steps, how long the run will take on this
    machine; then, off a terminal (a log file, where tqdm's bar is off), a line a minute and one at every
    in-context selection: step, loss, steps/s, time left, and the selection's score. Steps per second count
    the run's selections and checkpoints too, so the time left is wall time."""

    EVERY_S = 60.0

    def __init__(self, step: int, stop: int, metric: str, on_terminal: bool, selects: bool) -> None:
        self.first_step, self.stop, self.metric, self.on_terminal = step, stop, metric, on_terminal
        self.selects = selects
        self.started = self.last_line = time.perf_counter()
        self.estimated = False

    def log_step(self, step: int, loss: float, selection: Selection) -> None:
        now = time.perf_counter()
        per_s = (step - self.first_step) / max(now - self.started, 1e-9)
        left = _duration((self.stop - step) / per_s) if per_s > 0 else "unknown"
        if not self.estimated:
            self.estimated = True
            print(f"{per_s:.2f} steps/s on this machine: steps {step:,} to {self.stop:,} take about {left} more"
                  + (", plus the in-context selections" if self.selects else ""), flush=True)
            return
        selected = math.isfinite(selection.score)
        if self.on_terminal or not (selected or now - self.last_line >= self.EVERY_S or step == self.stop):
            return
        self.last_line = now
        scored = f"; in context: {self.metric} {selection.score:.3f}" if selected else ""
        if selected and math.isfinite(selection.reward_use_gap):
            scored += f", reward-use gap {selection.reward_use_gap:+.3f}"
        # The loss in scientific notation: a model of small action ranges trains to losses that .4f shows as 0.0000.
        remaining = f", {left} left" if step < self.stop else ""
        print(f"step {step:,}/{self.stop:,} ({step / self.stop:.0%}): loss {loss:.3e}, {per_s:.2f} steps/s"
              f"{remaining}{scored}", flush=True)


class MetricsLog:
    """One CSV row per log step (and TensorBoard scalars); a resumed run first drops rows past its step."""

    def __init__(self, out: Path, groups: Sequence[str], resume_step: int, tensorboard: bool) -> None:
        # A log.csv from before a column existed is rewritten with it, empty in its old rows.
        self.columns = ["step", "tokens", "loss", "lr", "grad_norm", "tokens_per_s", "mfu", "in_context_score",
                        "reward_use_gap", *[f"loss_{g}" for g in groups]]
        self.path = out / "log.csv"
        kept = self._rows_up_to(resume_step) if resume_step and self.path.is_file() else []
        # One writer for the rows a resume keeps and the new ones, so the file has one quoting and one line ending;
        # a kept row's columns this run no longer logs are dropped, the new ones left empty.
        rewritten = io.StringIO()
        writer = self._rows_writer(rewritten)
        writer.writeheader()
        writer.writerows(kept)
        atomic_write_text(self.path, rewritten.getvalue())
        self._file = self.path.open("a", newline="")
        self._csv = self._rows_writer(self._file)
        self.tensorboard = None
        if tensorboard:
            from torch.utils.tensorboard import SummaryWriter  # imports the tensorboard package

            # purge_step hides events a killed run wrote after its last checkpoint.
            self.tensorboard = SummaryWriter(str(out / "tensorboard"), purge_step=resume_step or None)

    def _rows_writer(self, file: IO[str]) -> csv.DictWriter:
        """The log's CSV writer on `file`."""
        return csv.DictWriter(file, self.columns, lineterminator="\n", extrasaction="ignore")

    def _rows_up_to(self, step: int) -> list[dict[str, str]]:
        """The log's rows up to `step`, those that read; a log with rows that do not (damaged on disk, edited) is
        copied aside first, and said so: the run goes on, its metrics are not silently dropped."""
        rows, damaged = [], False
        try:
            with self.path.open(newline="") as file:
                for row in csv.DictReader(file):
                    logged = str(row.get("step") or "")
                    if not logged.isdigit():
                        damaged = True
                    elif int(logged) <= step:
                        rows.append(row)
        except (UnicodeDecodeError, csv.Error):
            rows, damaged = [], True
        if damaged:
            aside = self.path.with_name(self.path.name + ".damaged")
            shutil.copyfile(self.path, aside)
            print(f"note: {self.path} has rows that do not read as a log; the whole file is kept as {aside}, and the "
                  f"log goes on with the {len(rows)} rows that read", flush=True)
        return rows

    def write(self, row: dict[str, float]) -> None:
        """Append one row; every key but step/tokens also goes to TensorBoard."""
        self._csv.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
        self._file.flush()
        if self.tensorboard is not None:
            for key, value in row.items():
                if key not in ("step", "tokens") and math.isfinite(value):
                    tag = _TENSORBOARD_TAGS.get(key, key.replace("loss_", "loss/"))
                    self.tensorboard.add_scalar(tag, value, int(row["step"]))

    def close(self) -> None:
        """Flush and close the files."""
        self._file.close()
        if self.tensorboard is not None:
            self.tensorboard.close()


# ----------------------------------------------------------------------------------------------
# The trainer


class Trainer:
    """Builds data, model and optimizer from a `TrainConfig` (resuming if ``out`` has a checkpoint).

    ``callbacks`` are ``(every, fn)`` pairs: ``fn(model, step)`` runs on rank 0 after every
    ``every``-th optimizer step with the model in eval mode, inside a forked RNG so it cannot
    change the rest of the run. ``scorer`` runs the same way every ``config.select_every`` steps on
    the selection tasks; a score above the best so far replaces ``checkpoints/best`` (training
    loss does not tell when a model has in-context skill), and the score and its reward-use
    gap go to the log.
    """

    def __init__(self, config: TrainConfig, callbacks: Sequence[tuple[int, Callback]] = (),
                 scorer: Scorer | None = None, init_name: str | None = None) -> None:
        if config.select_every and scorer is None:
            raise ConfigError("select_every needs an in-context scorer: train with `vintix train`, or pass "
                              "scorer=vintix.evaluate.in_context_scorer(config)")
        self.config = config
        self.callbacks = list(callbacks)
        self.scorer = scorer
        self.init_name = init_name
        """the shipped model's name that `config.init_from` (its folder) was given as, which saved models record"""
        self.init_sha256: str | None = None
        """the sha256 of the weights it started from: a path alone says nothing once they change"""
        self.out = Path(config.out)
        self.dist, self.device = init_distributed(config.device)
        torch.set_num_threads(training_threads(config.threads, self.dist.world_size))
        self.data = self._load_data()
        self.window_len = config.window
        torch.manual_seed(config.seed)
        # Weights, gradients and Adam's two moments: four copies before a single activation.
        model_config = config.model_config()
        self.model = build_within_memory(lambda: Vintix(model_config, self.data.groups, self.data.task_norms), 4,
                                         f"training the {config.model} preset with model_overrides "
                                         f"{config.model_overrides}", "Choose a smaller preset or model_overrides",
                                         estimated_parameters(model_config, self.data.groups))
        self.step, self.tokens = 0, 0
        resume = resumable_checkpoint(self.out, note=print if self.dist.is_main else None)
        if resume is not None:
            meta = check_resumable(resume, self.model.config, self.data.groups,
                                   [n.task for n in self.data.task_norms])
            changes = resume_changes(meta, dataclasses.asdict(config), self.data.fingerprint, FREE_ON_RESUME)
            if changes and not config.allow_resume_changes:
                raise CheckpointError(
                    f"cannot resume from {resume}: this run differs from the one that wrote it in " + "; ".join(changes)
                    + ". Re-run with the original data and settings, train into a new --out, or accept the changes "
                    "with --set allow_resume_changes=true"
                )
            self._check_max_steps(meta.get("extra", {}), resume)
            self.init_sha256 = meta.get("extra", {}).get("init_from_sha256")
            # The checkpoint's normalization statistics, not today's, are the ones the weights learned with.
            self.model = load_pretrained(resume)
        elif config.init_from is not None:
            fresh = start_from_pretrained(self.model, config.init_from)
            self.init_sha256 = file_sha256(model_directory(config.init_from) / WEIGHTS_FILE)
            if self.dist.is_main:
                print(f"starting from {config.init_from}'s weights; fresh: "
                      + (", ".join(f"group {name}" for name in fresh) or "nothing"))
        self.model.to(self.device).train()
        self.optimizer, self.param_names = build_optimizer(self.model, config)
        self.loss_module: nn.Module = WindowLoss(self.model)
        if self.dist.world_size > 1:
            # A micro-batch may lack some group, leaving its encoder and head without gradients.
            self.loss_module = nn.parallel.DistributedDataParallel(
                self.loss_module, device_ids=[self.device.index] if self.device.type == "cuda" else None,
                find_unused_parameters=len(self.data.groups) > 1,
            )
        torch.manual_seed(config.seed + 1 + self.dist.rank)  # dropout differs between ranks
        if resume is not None:
            self._restore(resume)
        self.flops = {g.name: flops_per_token(self.model, g.name, self.window_len) for g in self.data.groups}
        self.resumed_from = resume
        self.select_tasks = config.select_tasks or [t.name for t in self.data.tasks]
        if scorer is not None and config.select_tasks:  # a bad selection task fails now, not at the first selection
            select_tasks(config.select_tasks, [group.name for group in self.data.groups])
        self.best_score = best_score(self.out)

    def _check_max_steps(self, extra: dict[str, Any], resume: Path) -> None:
        """A resume below the checkpoint's step is refused, and one that moves max_steps says what that does: the
        cosine schedule ends at max_steps, so the learning rate from here on follows the new end."""
        step = int(extra.get("step", 0))
        before = (extra.get("train_config") or {}).get("max_steps")
        if step > self.config.max_steps:
            raise ConfigError(f"{resume} is at step {step:,}, past max_steps={self.config.max_steps:,}: a resumed run "
                              f"cannot go back. Train into a new --out, or --set max_steps={step:,} or more")
        if before not in (None, self.config.max_steps) and self.dist.is_main:
            print(f"note: max_steps {before:,} -> {self.config.max_steps:,}: the learning rate from step {step:,} on "
                  "follows a cosine that ends at the new max_steps")

    def _load_data(self) -> TrainingData:
        # Rank 0 computes (and caches) the normalization statistics; the others then read the cache.
        if not self.dist.is_main:
            self.dist.barrier()
        data = load_training_data(self.config.data, self.config.tasks, self.config.expert_distillation,
                                  self.config.expert_tail_fraction, self.config.stats_cache_dir,
                                  self.config.expert_rows, self.config.normalize_rewards)
        if self.dist.is_main:
            self.dist.barrier()
        return data

    def _restore(self, directory: Path) -> None:
        state = read_training_state(directory)
        self.step, self.tokens = state["step"], state["tokens"]
        load_optimizer(self.optimizer, self.param_names, directory)
        rng = read_rng(directory)
        if state["world_size"] == self.dist.world_size:
            torch.set_rng_state(rng["cpu"][self.dist.rank].clone())
            if "cuda" in rng and self.device.type == "cuda":
                torch.cuda.set_rng_state(rng["cuda"][self.dist.rank].clone(), self.device)

    def _gathered_rng(self) -> dict[str, torch.Tensor]:
        states = {"cpu": torch.get_rng_state()}
        if self.device.type == "cuda":
            states["cuda"] = torch.cuda.get_rng_state(self.device)
        if self.dist.world_size == 1:
            return {k: v.unsqueeze(0) for k, v in states.items()}
        gathered = {}
        for key, state in states.items():
            local = state.to(self.device) if dist.get_backend() == "nccl" else state
            parts = [torch.empty_like(local) for _ in range(self.dist.world_size)]
            dist.all_gather(parts, local)
            gathered[key] = torch.stack([p.cpu() for p in parts])
        return gathered

    def _replica_checksums(self) -> list[list[float]]:
        """(sum, sum of squares) of all parameters, per rank: DDP replicas must agree exactly."""
        flat = torch.cat([p.detach().double().flatten() for p in self.model.parameters()])
        local = torch.stack([flat.sum(), (flat * flat).sum()])
        if self.dist.world_size == 1:
            return [local.tolist()]
        parts = [torch.empty_like(local) for _ in range(self.dist.world_size)]
        dist.all_gather(parts, local)
        return [p.tolist() for p in parts]

    def save(self) -> Path:
        """Checkpoint the current step (every rank must call this; rank 0 writes).

        Also records every rank's parameter checksum and refuses to save diverged DDP replicas.
        """
        rng = self._gathered_rng()
        checksums = self._replica_checksums()
        if not all(math.isfinite(x) for c in checksums for x in c):  # every rank sees the same gathered sums
            raise NonFiniteLossError(f"step {self.step}: the model's parameters hold NaN/inf, so no checkpoint was "
                                     f"written; {self._last_good()}")
        if any(c != checksums[0] for c in checksums):
            raise RuntimeError(f"DDP replicas diverged at step {self.step}: parameter checksums {checksums}")
        directory = checkpoint_dir(self.out, self.step)
        if self.dist.is_main:
            state = {"step": self.step, "tokens": self.tokens, "world_size": self.dist.world_size,
                     "replica_checksums": checksums, "train_config": dataclasses.asdict(self.config)}
            save_training_checkpoint(directory, self.model, self.optimizer, self.param_names, rng, state,
                                     self._model_extra())
            prune_checkpoints(self.out, self.config.keep_checkpoints, self.step)
        self.dist.barrier()
        return directory

    def _last_good(self) -> str:
        """Where the run can go on from, for the errors that stop it."""
        last = latest_checkpoint(self.out)
        where = f"the last good checkpoint is {last}" if last is not None else "no checkpoint was written yet"
        return (f"{where}. Re-running the same command repeats the same steps, so first lower lr (now "
                f"{self.config.lr:g}), e.g. --set lr={self.config.lr / 3:.2g}, or lengthen warmup_steps")

    def _model_extra(self) -> dict[str, object]:
        """What a saved model records about its training."""
        extra: dict[str, object] = {
            "step": self.step, "tokens": self.tokens, "dataset": str(self.data.root),
            "dataset_fingerprint": self.data.fingerprint, "trained_tasks": [t.name for t in self.data.tasks],
            "train_config": dataclasses.asdict(self.config)}
        if self.init_sha256 is not None:
            extra["init_from_sha256"] = self.init_sha256
        return portable_record(extra, self.init_name)

    def _select(self) -> Selection:
        """Score the model in context (rank 0 only); keep it as ``checkpoints/best`` if its score beats the best."""
        selection = self._in_eval_mode_with_forked_rng(lambda: self.scorer(self.model, self.select_tasks))  # type: ignore[misc]
        if self.best_score is None or selection.score > self.best_score:
            self.best_score = selection.score
            gap = selection.reward_use_gap
            save_best_checkpoint(self.out, self.model, {
                **self._model_extra(), "in_context_score": selection.score,
                "reward_use_gap": gap if math.isfinite(gap) else None, "select_tasks": self.select_tasks,
                "select_reference": self.config.select_reference, "select_metric": self.config.select_metric})
        return selection

    def _loader(self) -> torch.utils.data.DataLoader:
        cfg = self.config
        dataset = WindowDataset(self.data, self.window_len, cfg.episode_sparsity, cfg.stochastic_sparsity,
                                cfg.task_sampling, cfg.seed,  # type: ignore[arg-type]
                                episode_returns=self.model.config.episode_return)
        sampler = WindowBatches(cfg.batch_size, self.step * cfg.grad_accum, self.dist.rank, self.dist.world_size)
        return torch.utils.data.DataLoader(
            dataset, batch_sampler=sampler, collate_fn=collate_windows, num_workers=cfg.num_workers,
            pin_memory=self.device.type == "cuda",
        )

    def run(self, until_step: int | None = None) -> Path:
        """Train to ``max_steps`` (or stop early at ``until_step``, checkpointing there); returns the
        last checkpoint directory."""
        cfg = self.config
        stop = min(until_step if until_step is not None else cfg.max_steps, cfg.max_steps)
        groups = [g.name for g in self.data.groups]
        group_index = {g: i for i, g in enumerate(groups)}
        # The data's windows are checked (a window longer than every history) before the log is created.
        batches = iter(self._loader())
        log = MetricsLog(self.out, groups, self.step, cfg.tensorboard) if self.dist.is_main else None
        peak = torch.tensor(measure_matmul_flops(self.device), dtype=torch.float64, device=self.device)
        if self.dist.world_size > 1:
            dist.all_reduce(peak)  # every rank's share of the machine, measured at the same time
        if self.dist.is_main:
            self._announce(groups)
        # Per group: summed window loss, windows, training FLOPs since the last log line.
        sums = torch.zeros(len(groups), 3, dtype=torch.float64, device=self.device)
        # disable=None: quiet when not on a terminal, where each redraw would be a line of the log
        progress = tqdm(total=cfg.max_steps, initial=self.step, desc="train",
                        disable=None if self.dist.is_main else True, dynamic_ncols=True)
        last_time, last_tokens, last_dir = time.perf_counter(), self.tokens, None
        report = ProgressReport(self.step, stop, cfg.select_metric, on_terminal=not progress.disable,
                                selects=bool(cfg.select_every))
        # However the loop ends (an error, a full disk, Ctrl-C), the log and TensorBoard files are closed. Ctrl-C or
        # SIGTERM stops a single-process run after its current step, saved (under torchrun, torchrun ends the ranks).
        stopping = stop_requests() if self.dist.world_size == 1 else contextlib.nullcontext(StopRequest())
        signals = contextlib.ExitStack()
        try:
            stop_request = signals.enter_context(stopping)
            while self.step < stop:
                lr, grad_norm = self._optimizer_step(batches, group_index, sums)
                progress.update(1)
                selection = Selection(math.nan)
                if cfg.select_every and self.step % cfg.select_every == 0 and self.dist.is_main:
                    started = time.perf_counter()
                    selection = self._select()
                    last_time += time.perf_counter() - started  # evaluation time is not training time
                if self.step % cfg.log_every == 0 or self.step == stop:
                    if self.dist.world_size > 1:
                        dist.all_reduce(sums)
                    now = time.perf_counter()
                    elapsed = now - last_time
                    per_group = (sums[:, 0] / sums[:, 1].clamp(min=1)).tolist()
                    row = {"step": self.step, "tokens": self.tokens,
                           "loss": float(sums[:, 0].sum() / sums[:, 1].sum()), "lr": lr, "grad_norm": float(grad_norm),
                           "tokens_per_s": (self.tokens - last_tokens) / elapsed,
                           "mfu": float(sums[:, 2].sum() / elapsed / peak), "in_context_score": selection.score,
                           "reward_use_gap": selection.reward_use_gap,
                           **{f"loss_{g}": (per_group[i] if sums[i, 1] else math.nan) for i, g in enumerate(groups)}}
                    if log is not None:
                        log.write(row)
                        shown_best = {"best": f"{self.best_score:.3f}"} if self.best_score is not None else {}
                        progress.set_postfix(loss=f"{row['loss']:.3e}", tok_s=f"{row['tokens_per_s']:,.0f}",
                                             mfu=f"{row['mfu']:.0%}", **shown_best)
                        report.log_step(self.step, row["loss"], selection)
                    sums.zero_()
                    last_time, last_tokens = time.perf_counter(), self.tokens
                self._run_callbacks()
                if self.step % cfg.checkpoint_every == 0 or self.step == stop or stop_request:
                    last_dir = self.save()
                    last_time = time.perf_counter()  # checkpoint time is not training time
                if stop_request:
                    raise Interrupted(f"stopped by {stop_request.signal} at step {self.step:,} and saved it in "
                                      f"{last_dir}; re-run the same command to resume from there")
        finally:
            signals.close()
            progress.close()
            del batches  # shuts DataLoader workers down
            if log is not None:
                log.close()
        if log is not None:
            best = (f", best in-context score {self.best_score:.3f} in {best_checkpoint_dir(self.out)}"
                    if self.best_score is not None else "")
            print(f"step {self.step}: checkpoints under {self.out / 'checkpoints'}, log {log.path}"
                  + (f", TensorBoard {self.out / 'tensorboard'}" if cfg.tensorboard else "") + best)
        return last_dir if last_dir is not None else checkpoint_dir(self.out, self.step)

    def _announce(self, groups: list[str]) -> None:
        """What the run trains, on what, where, from which step; which rows are targets; sizing notes."""
        cfg = self.config
        n_params = count_parameters(self.model)
        where = f"resuming from {self.resumed_from}" if self.resumed_from else "starting fresh"
        print(f"training {cfg.model} ({n_params / 1e6:.2f}M parameters) on {len(self.data.tasks)} tasks / "
              f"{len(groups)} groups, {self.dist.world_size} process(es) on {self.device} "
              f"({torch.get_num_threads()} CPU thread(s) each{'' if cfg.threads else ': --threads to choose'}); "
              f"{where} at step {self.step}")
        if cfg.expert_distillation:  # the ED ablation, or (on every row) the recorded-target objective
            print("demonstrator-action targets: " + "; ".join(f"{t.name}: {t.rows}" for t in self.data.tasks))
        for note in window_sizing_notes(self.data, self.window_len, self.model.config.keep_first_steps,
                                        cfg.select_shots if cfg.select_every else None):
            print(f"note: {note}")

    def _optimizer_step(self, batches: Iterator[Batch], group_index: dict[str, int],
                        sums: torch.Tensor) -> tuple[float, torch.Tensor]:
        """One optimizer step over `grad_accum` micro-batches, adding each group's loss, windows and FLOPs to `sums`;
        returns the learning rate and the gradient norm. A non-finite gradient stops the run before the step."""
        cfg = self.config
        lr = learning_rate(self.step, cfg)
        for param_group in self.optimizer.param_groups:
            param_group["lr"] = lr
        for micro in range(cfg.grad_accum):
            batch = batch_to(next(batches), self.device)
            # DDP all-reduces the gradients of the last micro-batch only.
            unsynced = (self.loss_module.no_sync()
                        if isinstance(self.loss_module, nn.parallel.DistributedDataParallel)
                        and micro < cfg.grad_accum - 1 else contextlib.nullcontext())
            with unsynced, precision_context(self.device):
                losses = self.loss_module(batch)
            (losses.mean() / cfg.grad_accum).backward()
            start = 0
            for group, part in batch.items():
                n = part["obs"].shape[0]
                totals = sums[group_index[group]]
                totals[0] += losses[start : start + n].detach().double().sum()
                totals[1] += n
                totals[2] += n * self.window_len * self.flops[group]
                start += n
        grad_norm = torch.nn.utils.clip_grad_norm_(self.model.parameters(), cfg.grad_clip or math.inf)
        # One NaN gradient would turn every weight NaN at this step; the norm is the same on every rank.
        if not torch.isfinite(grad_norm):
            raise NonFiniteLossError(
                f"step {self.step + 1}: the loss or its gradient is not finite (last micro-batch loss "
                f"{float(losses.detach().mean()):.4g}, gradient norm {float(grad_norm):.4g}); training stopped "
                f"before the optimizer step, so no NaN reached the weights; {self._last_good()}")
        self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
        self.step += 1
        self.tokens += cfg.grad_accum * cfg.batch_size * self.window_len * self.dist.world_size
        return lr, grad_norm

    def _run_callbacks(self) -> None:
        due = [fn for every, fn in self.callbacks if self.step % every == 0]
        if due and self.dist.is_main:
            self._in_eval_mode_with_forked_rng(lambda: [fn(self.model, self.step) for fn in due])

    def _in_eval_mode_with_forked_rng(self, work: Callable[[], _Result]) -> _Result:
        """Run `work` with the model in eval mode inside a forked RNG, so it cannot change the run."""
        self.model.eval()
        try:
            with torch.random.fork_rng(devices=[self.device] if self.device.type == "cuda" else []):
                return work()
        finally:
            self.model.train()


def train(config: TrainConfig, callbacks: Sequence[tuple[int, Callback]] = (), scorer: Scorer | None = None,
          init_name: str | None = None) -> Path:
    """Run (or resume) a whole training run; under ``torchrun`` every rank calls this (rank 0 holds the
    run folder, so a second training into it fails at once). `init_name`: the shipped model's name where
    ``config.init_from`` is its folder (`Trainer`)."""
    main_rank = int(os.environ.get("RANK", "0")) == 0
    check_output_kind(config.out, "run")
    try:
        with folder_lock(config.out, "vintix train") if main_rank else contextlib.nullcontext():
            return Trainer(config, callbacks, scorer, init_name).run()
    finally:
        if dist.is_initialized():
            dist.destroy_process_group()
