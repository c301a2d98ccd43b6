"""Model checkpoints, in the Hugging Face Hub's layout: ``model.safetensors`` (weights), ``config.json``
(config, groups, task norms) and ``README.md`` (a model card), written by huggingface_hub's mixin
(`Vintix.save_pretrained`), so a folder can be pushed to the Hub as it is (``model.push_to_hub``).

A checkpoint directory is self-contained: it loads on a machine that has neither the dataset nor
the training code's state, which is what inference and evaluation need. Weights are never pickled.
The weights are written atomically, then ``config.json``, atomically too, so a directory with a
``config.json`` has the weights that go with it. Training writes a whole checkpoint directory aside
and renames it into place. ``extra`` carries whatever the
writer wants to keep beside the model (training step, dataset fingerprint, ...) and comes back
unchanged. Folders written before this layout hold ``model.json`` instead of ``config.json``; they load
the same way.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file

from vintix.atomic import atomic_save_tensors, atomic_write_text, not_a_file
from vintix.errors import DeviceError, VintixError, at_file
from vintix.fields import checked_fields, read_json_file
from vintix.memory import build_within_memory
from vintix.model.model import GroupSpec, ModelConfig, TaskNorm, Vintix, count_parameters, estimated_parameters
from vintix.tasks import list_tasks
from vintix.tasks.custom import custom_specs, register_specs
from vintix.tasks.layouts import ObsLayout

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
LEGACY_CONFIG_FILE = "model.json"
"""What `CONFIG_FILE` was called before checkpoints took the Hub's layout; still read."""
MODEL_CARD_FILE = "README.md"
FORMAT_VERSION = 1


class CheckpointError(VintixError, ValueError):
    """A checkpoint directory that is missing, incomplete, or made for another model."""


def model_metadata(model: Vintix, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Everything besides the weights that rebuilds `model`, as JSON-ready data."""
    return metadata_for(model.config, list(model.groups.values()), model.task_norms, extra)


def metadata_for(config: ModelConfig, groups: Sequence[GroupSpec], norms: Sequence[TaskNorm],
                 extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """The JSON half of a checkpoint of a model with this config, groups and normalization (`build_model`
    builds it before any weights exist)."""
    metadata = {
        "format_version": FORMAT_VERSION,
        "config": dataclasses.asdict(config),
        "groups": [dataclasses.asdict(g) for g in groups],
        "task_norms": [task_norm_json(t) for t in norms],
        "extra": extra or {},
    }
    # Tasks registered from outside the package travel with the model, so loading it needs no registration: its
    # tasks' and every other task of its groups' (a held-out split of your own that no history was collected on).
    group_names = {g.name for g in groups}
    same_groups = [t.name for t in list_tasks() if t.domain == "custom" and t.group in group_names]
    custom = custom_specs([t.task for t in norms] + same_groups)
    return metadata | ({"custom_tasks": custom} if custom else {})


def task_norm_json(norm: TaskNorm) -> dict[str, Any]:
    """A task's normalization as JSON-ready data (`task_norm_from_json` reads it back)."""
    data: dict[str, Any] = {
        "task": norm.task, "group": norm.group, "obs_mean": [float(x) for x in norm.obs_mean],
        "obs_std": [float(x) for x in norm.obs_std], "reward_scale": float(norm.reward_scale)}
    if norm.obs_layout is not None:  # absent rather than null, so older checkpoints' files stay as they were
        data["obs_layout"] = {"env_dim": norm.obs_layout.env_dim, "channels": list(norm.obs_layout.channels)}
    return data


def task_norm_from_json(data: dict[str, Any]) -> TaskNorm:
    layout = data.get("obs_layout")
    return TaskNorm(**{**data, "obs_layout": None if layout is None else
                       ObsLayout(int(layout["env_dim"]), tuple(int(c) for c in layout["channels"]))})


def save_pretrained(model: Vintix, directory: str | os.PathLike[str], extra: dict[str, Any] | None = None,
                    details: str = "", name: str = "A Vintix model") -> Path:
    """Write `model` to `directory` (created if needed) through huggingface_hub's mixin: weights,
    ``config.json`` with `extra`, and a model card titled `name` that shows the training facts in `extra`
    and `details` (markdown, e.g. how a shipped model was made). Returns the directory."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    for stale in (MODEL_CARD_FILE, LEGACY_CONFIG_FILE):  # the mixin keeps an existing card; rewrite it
        (directory / stale).unlink(missing_ok=True)
    model.checkpoint_extra = dict(extra or {})
    model.save_pretrained(directory, model_card_kwargs=model_card_fields(model, model.checkpoint_extra, details, name))
    return directory


def weights_sha256(model: Vintix) -> str:
    """sha256 of the model's parameters and buffers (names, dtypes, shapes and bytes, in name order): which weights
    they are, wherever they were loaded from, so that two models of one name are told apart."""
    digest = hashlib.sha256()
    for name, tensor in sorted(model.state_dict().items()):
        value = tensor.detach().cpu().contiguous()
        digest.update(f"{name}:{value.dtype}:{tuple(value.shape)};".encode())
        digest.update(value.view(torch.uint8).numpy().tobytes() if value.numel() else b"")
    return digest.hexdigest()


def write_checkpoint(model: Vintix, directory: Path) -> None:
    """`model`'s weights, then its ``config.json`` (with ``model.checkpoint_extra``), each atomically, so a
    folder whose config.json is there has the weights that go with it (`Vintix._save_pretrained`)."""
    directory = Path(directory)
    # safetensors refuses tensors that share memory or are not contiguous; a state_dict has neither.
    weights = {name: tensor.detach().cpu().contiguous() for name, tensor in model.state_dict().items()}
    atomic_save_tensors(weights, directory / WEIGHTS_FILE, metadata={"format": "pt"})
    metadata = model_metadata(model, model.checkpoint_extra)
    atomic_write_text(directory / CONFIG_FILE, json.dumps(metadata, indent=1) + "\n")


def model_card_fields(model: Vintix, extra: dict[str, Any], details: str, name: str) -> dict[str, Any]:
    """What `vintix.model.model.MODEL_CARD` shows: the model's size and tasks, and how it was trained."""
    lines = []
    if "step" in extra:
        lines.append(f"Training: step {extra['step']:,}, {extra.get('tokens', 0):,} tokens on "
                     f"{', '.join(extra.get('trained_tasks', [])) or 'its dataset'} (dataset fingerprint "
                     f"{extra.get('dataset_fingerprint', 'unknown')}).")
    if extra.get("in_context_score") is not None:
        # No gap where the selection measured none (a run of visible-goal tasks only): said, not printed as None.
        gap = extra.get("reward_use_gap")
        lines.append(f"Kept as the run's best in context: {extra.get('select_metric', 'score')} "
                     f"{extra['in_context_score']:.3f} on unseen seeds of {', '.join(extra.get('select_tasks', []))} "
                     + (f"(reward-use gap {gap:+.3f})." if gap is not None and math.isfinite(gap)
                        else "(no reward-use gap measured)."))
    if "official" in extra:
        lines.append(f"Imported from the authors' release (model.pth sha256 {extra['official'].get('sha256')}).")
    if "train_config" in extra:
        config = json.dumps(extra["train_config"], indent=1, default=str)
        lines.append(f"The training config (`vintix train --config FILE` with these fields):\n\n```json\n{config}\n```")
    return {"name": name, "parameters": f"{count_parameters(model):,}", "context_len": model.config.context_len,
            "n_groups": len(model.groups), "n_tasks": len(model.task_norms),
            "training": "## Training\n\n" + "\n\n".join(lines) if lines else "", "details": details}


def checkpoint_config_path(directory: str | os.PathLike[str]) -> Path | None:
    """The JSON half of the checkpoint in `directory`, in either layout; None if it holds no checkpoint."""
    directory = Path(directory)
    current, legacy = directory / CONFIG_FILE, directory / LEGACY_CONFIG_FILE
    # An official release snapshot holds a config.json too (its training config), beside its model.pth.
    if current.is_file() and not (directory / "model.pth").exists():
        return current
    return legacy if legacy.is_file() else None


def is_checkpoint(directory: str | os.PathLike[str]) -> bool:
    """Whether `directory` holds one of our checkpoints (its JSON half, in either layout)."""
    return checkpoint_config_path(directory) is not None


@dataclass
class CheckpointFile:
    """The JSON half of a checkpoint (``config.json``), as `read_metadata` checks it."""

    format_version: int
    """`FORMAT_VERSION` of the vintix that wrote it"""
    config: dict[str, Any]
    """the ModelConfig's fields"""
    groups: list[dict[str, Any]]
    """each GroupSpec's fields"""
    task_norms: list[dict[str, Any]]
    """each task's normalization statistics (`task_norm_from_json`)"""
    extra: dict[str, Any] = field(default_factory=dict)
    """what the model records about its training (`Vintix.checkpoint_extra`)"""
    custom_tasks: dict[str, dict[str, Any]] = field(default_factory=dict)
    """the specs of the tasks of your own it was trained on (`vintix.tasks.custom`)"""


@dataclass
class TrainingRecord:
    """The fields of a checkpoint's ``extra`` that vintix reads back (the model card shows them, resume and the
    agent read some), each checked like `CheckpointFile`'s; ``extra`` may hold more."""

    step: int = 0
    """the optimizer steps it was trained for"""
    tokens: int = 0
    """the training tokens it saw"""
    trained_tasks: list[str] = field(default_factory=list)
    """the tasks of its dataset"""
    dataset: str | None = None
    """its dataset's folder, relative to the run folder"""
    dataset_fingerprint: str | None = None
    """the content key of its dataset's histories (`vintix.train.data.content_fingerprint`)"""
    in_context_score: float | None = None
    """the selection's in-context score, where this is a run's best checkpoint"""
    reward_use_gap: float | None = None
    """the selection's reward-use gap, where it measured one"""
    select_metric: str = "score"
    """what the selection ranked by"""
    select_tasks: list[str] = field(default_factory=list)
    """the tasks the selection played"""
    train_config: dict[str, Any] = field(default_factory=dict)
    """the TrainConfig's fields"""
    init_from_sha256: str | None = None
    """the weights it was fine-tuned from (`weights_sha256`)"""
    official: dict[str, Any] = field(default_factory=dict)
    """where it was imported from the authors' release: the file's sha256 and the metadata's"""


def read_metadata(directory: str | os.PathLike[str]) -> dict[str, Any]:
    """The JSON half of a checkpoint, each field of the type `CheckpointFile` gives it, each group's of `GroupSpec`'s,
    and its ``extra`` checked against `TrainingRecord`."""
    found = checkpoint_config_path(directory)
    if found is None:
        raise CheckpointError(f"{directory}: no {CONFIG_FILE}; is this a checkpoint directory written by vintix?")
    damaged = at_file(CheckpointError)
    fix = "the checkpoint is damaged or not vintix's: re-save it, or use another"
    meta = read_json_file(found, CheckpointFile, damaged, fix)
    for index, group in enumerate(meta.groups):  # each group's fields too: a text obs_dim was a message naming none
        checked_fields(group, GroupSpec, found, damaged, fix, within=f"groups[{index}]")
    record = dataclasses.asdict(checked_fields(meta.extra, TrainingRecord, found, damaged, fix, within="extra"))
    meta.extra.update({key: record[key] for key in meta.extra if key in record})  # as converted; no key added
    if meta.format_version != FORMAT_VERSION:
        raise CheckpointError(
            f"{found}: checkpoint format {meta.format_version}, this vintix reads format {FORMAT_VERSION}"
        )
    return dataclasses.asdict(meta)


def build_model(meta: dict[str, Any]) -> Vintix:
    """An untrained model with the architecture, groups and normalization a checkpoint describes."""
    known = {f.name for f in dataclasses.fields(ModelConfig)}
    unknown = sorted(set(meta["config"]) - known)
    if unknown:
        raise CheckpointError(f"checkpoint config has fields {unknown} that this vintix's ModelConfig lacks")
    try:
        config = ModelConfig(**meta["config"])
        groups, norms = [GroupSpec(**g) for g in meta["groups"]], [task_norm_from_json(t) for t in meta["task_norms"]]
        # Twice the model: it and the weights read into it.
        return build_within_memory(lambda: Vintix(config, groups, norms), 2, "the model this checkpoint describes",
                                   "Its config is damaged, or it needs a machine with more memory",
                                   estimated_parameters(config, groups))
    except (TypeError, ValueError, KeyError, AttributeError) as error:  # a hand-edited or damaged config.json
        raise CheckpointError(f"does not describe a model this vintix can build ({error}); the checkpoint is "
                              "damaged or not vintix's") from error


def torch_device(name: str | torch.device) -> torch.device:
    """`name` as a torch device this machine has; a DeviceError says what to use instead."""
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError) as error:
        raise DeviceError(f"unknown device {name!r}; use cpu or cuda") from error
    if device.type == "cuda" and not torch.cuda.is_available():
        raise DeviceError(f"device {name!r} requested but torch sees no GPU; use cpu")
    if device.type not in ("cpu", "cuda"):
        raise DeviceError(f"device {name!r} is not supported; use cpu or cuda")
    return device


def load_pretrained(directory: str | os.PathLike[str], device: str | torch.device = "cpu",
                    trust_code: bool = False) -> Vintix:
    """The model saved in `directory`, in eval mode, on `device`. The custom tasks its config keeps are
    registered; the code they name (env factories) runs only with `trust_code` or ``VINTIX_TRUST_CODE=1``,
    unless you registered the same tasks yourself (`vintix.tasks.custom`)."""
    directory = Path(directory)
    device = torch_device(device)  # before reading gigabytes of weights
    meta = read_metadata(directory)
    register_specs(meta.get("custom_tasks", {}), str(directory / CONFIG_FILE), trust_code)
    try:
        model = build_model(meta)
    except CheckpointError as error:  # build_model cannot name the file it was read from
        raise CheckpointError(f"{directory / CONFIG_FILE}: {error}") from error
    weights_path = directory / WEIGHTS_FILE
    if why := not_a_file(weights_path):
        raise CheckpointError(why)
    if not weights_path.is_file():
        raise CheckpointError(f"{directory}: {CONFIG_FILE} is there but {WEIGHTS_FILE} is not; re-save it")
    try:
        weights = load_file(str(weights_path))
    except Exception as error:  # safetensors raises its own SafetensorError on truncated files
        raise CheckpointError(f"{weights_path}: unreadable ({error}); the file is truncated or damaged") from error
    expected = model.state_dict()
    missing, unexpected = sorted(set(expected) - set(weights)), sorted(set(weights) - set(expected))
    wrong_shape = [k for k in set(expected) & set(weights) if expected[k].shape != weights[k].shape]
    if missing or unexpected or wrong_shape:
        raise CheckpointError(
            f"{weights_path} does not fit the model in {CONFIG_FILE}: missing {missing[:5]}, unexpected "
            f"{unexpected[:5]}, wrong shape {sorted(wrong_shape)[:5]}"
        )
    # A diverged run's weights are NaN: refuse them here rather than let a model act with NaN.
    non_finite = sorted(k for k, v in weights.items() if v.is_floating_point() and not torch.isfinite(v).all())
    if non_finite:
        raise CheckpointError(
            f"{weights_path}: {len(non_finite)} of {len(weights)} tensors hold NaN/inf (e.g. {non_finite[:3]}); the "
            "training run diverged before this checkpoint: use an earlier one"
        )
    model.load_state_dict(weights)
    model.checkpoint_extra = dict(meta.get("extra") or {})
    return model.to(device).eval()
