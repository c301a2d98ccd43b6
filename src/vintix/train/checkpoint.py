"""Training checkpoints: the model checkpoint (`save_pretrained`) plus what exact resume needs.

``<out>/checkpoints/step-00000200/`` holds ``model.safetensors`` + ``config.json`` (so
``load_pretrained`` works on it with no dataset), ``optimizer.safetensors`` (AdamW moments keyed
``<parameter name>/<state key>``: tensors are never pickled), ``rng.safetensors`` (every rank's
torch RNG state) and ``trainer.json`` (step, tokens seen, optimizer hyperparameters, the config).
The directory is assembled under ``step-N.partial`` and renamed when complete, so a checkpoint
directory without ``.partial`` is always whole when written; a file damaged later (a full disk, a
copy cut short) is caught on resume, which goes on from the newest checkpoint whose files all read
(`resumable_checkpoint`).

``<out>/checkpoints/best/`` (a model checkpoint only) holds the model with the best in-context score
so far when training selects checkpoints (``select_every``); its ``config.json`` ``extra`` says the
step and score. Pruning never touches it, and a run folder loads as it when it exists.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file

from vintix.atomic import PARTIAL_SUFFIX, atomic_directory, atomic_save_tensors, atomic_write_text, not_a_file
from vintix.errors import json_loads
from vintix.model.checkpoint import (
    CONFIG_FILE,
    WEIGHTS_FILE,
    CheckpointError,
    is_checkpoint,
    load_pretrained,
    read_metadata,
    save_pretrained,
)
from vintix.model.model import GroupSpec, ModelConfig, Vintix

CHECKPOINTS = "checkpoints"
STATE_FILE = "trainer.json"
OPTIMIZER_FILE = "optimizer.safetensors"
RNG_FILE = "rng.safetensors"
BEST = "best"
_STEP_DIR = re.compile(r"step-(\d+)")


def checkpoint_dir(out: str | os.PathLike[str], step: int) -> Path:
    """Where the checkpoint of optimizer step ``step`` lives."""
    return Path(out) / CHECKPOINTS / f"step-{step:08d}"


def list_checkpoints(out: str | os.PathLike[str]) -> list[Path]:
    """Complete checkpoints of a run, oldest first."""
    folder = Path(out) / CHECKPOINTS
    if not folder.is_dir():
        return []
    found = [p for p in folder.iterdir() if _STEP_DIR.fullmatch(p.name) and (p / STATE_FILE).is_file()]
    return sorted(found, key=lambda p: int(p.name.split("-")[1]))


def latest_checkpoint(out: str | os.PathLike[str]) -> Path | None:
    """The newest complete checkpoint of a run, if any."""
    found = list_checkpoints(out)
    return found[-1] if found else None


def _state_problem(directory: Path) -> str | None:
    """What is wrong with a checkpoint's ``trainer.json`` (None: it has what resuming reads)."""
    try:
        state = json_loads((directory / STATE_FILE).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        return f"{STATE_FILE} is not readable JSON ({error})"
    counts = ("step", "tokens", "world_size")
    if not isinstance(state, dict) or not all(type(state.get(key)) is int and state[key] >= 0 for key in counts):
        return f"{STATE_FILE} lacks the non-negative integers {list(counts)}"
    if state["step"] != int(directory.name.split("-")[1]):
        return f"{STATE_FILE} says step {state['step']}, its folder step {int(directory.name.split('-')[1])}"
    groups = state.get("optimizer_param_groups")
    if not (isinstance(groups, list) and groups and all(isinstance(g, dict) and isinstance(g.get("params"), list)
                                                         and isinstance(g.get("betas"), list) and len(g["betas"]) == 2
                                                         for g in groups)):
        return f"{STATE_FILE} lacks the optimizer's parameter groups"
    return None


def checkpoint_problem(directory: Path) -> str | None:
    """Why resuming from a training checkpoint would fail (None: every file reads and fits).

    Reads every file whole, as resuming does: a truncated ``.safetensors`` or garbage JSON shows.
    """
    try:
        load_pretrained(directory)  # config.json + weights: readable, fitting, finite
    except CheckpointError as error:
        return str(error)
    for name in (OPTIMIZER_FILE, RNG_FILE):
        try:
            load_file(str(directory / name))
        except Exception as error:  # safetensors raises its own SafetensorError (and OSError when missing)
            return f"{directory / name}: unreadable ({error})"
    problem = _state_problem(directory)
    return None if problem is None else f"{directory / STATE_FILE}: {problem}"


def resumable_checkpoint(out: str | os.PathLike[str], note: Callable[[str], object] | None = print) -> Path | None:
    """The checkpoint a run resumes from: the newest one whose files all read (`checkpoint_problem`).

    Newer damaged checkpoints are passed over with a `note` saying so: training repeats their steps
    (exactly, as resume is deterministic) and `prune_checkpoints` deletes them once it is past them,
    as they are no longer the run's. None when the run has no checkpoint; CheckpointError naming the
    folder to delete when it has checkpoints but not one intact (starting over silently could cost
    days of training that a repaired file would save).
    """
    damaged: list[tuple[Path, str]] = []
    for directory in reversed(list_checkpoints(out)):
        problem = checkpoint_problem(directory)
        if problem is None:
            for bad, why in damaged:
                if note is not None:
                    note(f"note: checkpoint {bad} is damaged ({why}); resuming from {directory}, the newest intact "
                         "one: its later steps are trained again and the damaged folder is replaced")
            return directory
        damaged.append((directory, problem))
    if damaged:
        raise CheckpointError(
            f"no intact checkpoint to resume from in {Path(out) / CHECKPOINTS}: "
            + "; ".join(f"{bad.name}: {why}" for bad, why in damaged)
            + f". Delete {Path(out) / CHECKPOINTS} to train this run from scratch, or train into a new --out"
        )
    return None


def intact_alternative_hint(directory: Path) -> str:
    """For an error about a model in a training run: which of the run's other checkpoints load, and
    what to delete so that the run folder means one of them (empty when `directory` is no run's)."""
    if directory.parent.name != CHECKPOINTS:
        return ""
    run = directory.parent.parent
    for other in reversed(list_checkpoints(run)):
        if other != directory:
            try:
                load_pretrained(other)
            except CheckpointError:
                continue
            return (f". The run's newest intact checkpoint is {other}: pass it with --checkpoint, or delete the "
                    f"damaged {directory} so that {run} means it")
    return f". The run {run} has no other intact checkpoint: re-train, or restore {directory} from a backup"


def best_checkpoint_dir(out: str | os.PathLike[str]) -> Path:
    """Where a run keeps its model with the best in-context score."""
    return Path(out) / CHECKPOINTS / BEST


def best_score(out: str | os.PathLike[str]) -> float | None:
    """The in-context score of a run's best checkpoint, None before it has one."""
    directory = best_checkpoint_dir(out)
    if not is_checkpoint(directory):
        return None
    return float(read_metadata(directory)["extra"]["in_context_score"])


def save_best_checkpoint(out: str | os.PathLike[str], model: Vintix, extra: dict[str, Any]) -> Path:
    """Replace the run's best checkpoint with `model` (assembled aside, then renamed into place)."""
    directory = best_checkpoint_dir(out)
    with atomic_directory(directory) as partial:
        save_pretrained(model, partial, extra=extra)
    return directory


def model_directory(path: str | os.PathLike[str]) -> Path:
    """What `load_pretrained` should read for `path`: `path` itself when it holds a model, else the
    training run at `path`'s best checkpoint (`best_checkpoint_dir`) if it selected one, else its
    newest (so `runs/x` means the model that run recommends)."""
    path = Path(path)
    if is_checkpoint(path):
        return path
    if is_checkpoint(best_checkpoint_dir(path)):
        return best_checkpoint_dir(path)
    latest = latest_checkpoint(path)
    if latest is None and (why := not_a_file(path / CONFIG_FILE)):
        raise CheckpointError(why)
    if latest is None:
        raise CheckpointError(
            f"{path}: neither a model checkpoint ({CONFIG_FILE} + {WEIGHTS_FILE}) nor a training run with "
            f"{CHECKPOINTS}/step-N/ inside; point to a `vintix train --out` folder or one of its checkpoints"
        )
    return latest


def _optimizer_tensors(optimizer: torch.optim.Optimizer,
                       names: list[str]) -> tuple[dict[str, torch.Tensor], list[dict]]:
    """AdamW state as flat named tensors, and its param groups with parameter names instead of indices."""
    state = optimizer.state_dict()
    tensors = {f"{names[i]}/{key}": value.detach().cpu().contiguous()
               for i, per_param in state["state"].items() for key, value in per_param.items()}
    groups = [{**g, "params": [names[i] for i in g["params"]]} for g in state["param_groups"]]
    return tensors, groups


def load_optimizer(optimizer: torch.optim.Optimizer, names: list[str], directory: Path) -> None:
    """Restore optimizer state saved by `save_training_checkpoint` (names must match the model's)."""
    tensors = load_file(str(directory / OPTIMIZER_FILE))
    groups = json_loads((directory / STATE_FILE).read_text())["optimizer_param_groups"]
    index = {name: i for i, name in enumerate(names)}
    in_groups, in_tensors = {n for g in groups for n in g["params"]}, {k.rsplit("/", 1)[0] for k in tensors}
    missing = sorted((in_groups ^ set(names)) | (in_tensors - set(names)))
    if missing:
        raise CheckpointError(f"{directory}: optimizer state does not match the model's parameters ({missing[:5]})")
    state: dict[int, dict[str, torch.Tensor]] = {}
    for key, value in tensors.items():
        name, field = key.rsplit("/", 1)
        state.setdefault(index[name], {})[field] = value
    param_groups = [{**g, "betas": tuple(g["betas"]), "params": [index[n] for n in g["params"]]} for g in groups]
    optimizer.load_state_dict({"state": state, "param_groups": param_groups})


def save_training_checkpoint(
    directory: Path, model: Vintix, optimizer: torch.optim.Optimizer, param_names: list[str],
    rng: dict[str, torch.Tensor], state: dict[str, Any], extra: dict[str, Any],
) -> Path:
    """Write a whole checkpoint directory atomically (see the module docstring)."""
    with atomic_directory(directory) as partial:
        save_pretrained(model, partial, extra=extra)
        tensors, groups = _optimizer_tensors(optimizer, param_names)
        atomic_save_tensors(tensors, partial / OPTIMIZER_FILE)
        atomic_save_tensors({k: v.contiguous() for k, v in rng.items()}, partial / RNG_FILE)
        atomic_write_text(partial / STATE_FILE,
                          json.dumps({**state, "optimizer_param_groups": groups}, indent=1) + "\n")
    return directory


def read_training_state(directory: Path) -> dict[str, Any]:
    """``trainer.json`` of a checkpoint."""
    return json_loads((directory / STATE_FILE).read_text())


def read_rng(directory: Path) -> dict[str, torch.Tensor]:
    """Saved RNG states: ``cpu`` (and ``cuda``) as ``[world_size, n]`` byte tensors."""
    return load_file(str(directory / RNG_FILE))


def check_resumable(directory: Path, config: ModelConfig, groups: list[GroupSpec], task_names: list[str]
                    ) -> dict[str, Any]:
    """Refuse to resume a run whose checkpoint was made for another model or another task set; return the
    checkpoint's metadata (for `resume_changes`)."""
    meta = read_metadata(directory)
    problems = []
    # A field the checkpoint lacks was added to ModelConfig after it was written: it has the field's default,
    # as loading it gives it (`load_pretrained`).
    defaults = {f.name: f.default for f in dataclasses.fields(ModelConfig)}
    saved_config, wanted_config = {**defaults, **meta["config"]}, dataclasses.asdict(config)
    changed = sorted(k for k in set(saved_config) | set(wanted_config) if saved_config.get(k) != wanted_config.get(k))
    if changed:
        problems.append("model config differs in " + ", ".join(
            f"{k} (checkpoint {saved_config.get(k)!r}, now {wanted_config.get(k)!r})" for k in changed))
    saved_groups = [(g["name"], g["obs_dim"], g["act_dim"]) for g in meta["groups"]]
    wanted_groups = [(g.name, g.obs_dim, g.act_dim) for g in groups]
    if saved_groups != wanted_groups:
        problems.append(f"groups differ (checkpoint {saved_groups}, now {wanted_groups})")
    saved_tasks = [t["task"] for t in meta["task_norms"]]
    if saved_tasks != task_names:
        problems.append(f"tasks differ (checkpoint {saved_tasks}, now {task_names})")
    if problems:
        raise CheckpointError(
            f"cannot resume from {directory}: " + "; ".join(problems)
            + ". Train into a new --out directory, or re-run with the config and data of the original run"
        )
    return meta


def run_relative(path: str | os.PathLike[str], out: str | os.PathLike[str]) -> str:
    """`path` as seen from the run folder `out`."""
    return os.path.relpath(os.path.abspath(path), os.path.abspath(out))


RUN_PATH_FIELDS = ("data", "stats_cache_dir", "init_from")
"""TrainConfig fields that name a file or folder"""


def portable_record(extra: dict[str, Any], init_name: str | None = None) -> dict[str, Any]:
    """What a saved model records about its training (``extra``, holding ``dataset`` and ``train_config``) with every
    path relative to the run folder (``out`` itself becomes "."), and ``init_from`` the shipped model's name where
    `init_name` gives it: a model that is shared or shipped names no folder of the machine that trained it, and
    a run moved with its data still points at it. A record already relative is returned as it is."""
    config = extra.get("train_config")
    if not isinstance(config, dict) or config.get("out") in (None, "."):
        return extra
    out = config["out"]
    recorded = {field: run_relative(config[field], out) for field in RUN_PATH_FIELDS if config.get(field) is not None}
    if init_name is not None:
        recorded["init_from"] = init_name
    portable = dict(extra, train_config={**config, **recorded, "out": "."})
    if extra.get("dataset") is not None:
        portable["dataset"] = run_relative(extra["dataset"], out)
    return portable


def resume_changes(meta: dict[str, Any], config: dict[str, Any], dataset_fingerprint: str,
                   free: Iterable[str]) -> list[str]:
    """How a run resumed with `config` (a TrainConfig as a dict) on data of `dataset_fingerprint` differs
    from the run that wrote the checkpoint whose metadata is `meta`, ignoring the `free` fields."""
    extra = meta.get("extra", {})
    saved = extra.get("train_config", {})
    changes = [f"{key} (checkpoint {saved[key]!r}, now {value!r})" for key, value in config.items()
               if key not in free and key in saved and saved[key] != value]
    if extra.get("dataset_fingerprint") not in (None, dataset_fingerprint):
        changes.append(f"the data's histories (checkpoint trained on {extra.get('dataset')}; the files were changed, "
                       "added, removed or copied since: the same key as the statistics cache's)")
    return changes


def prune_checkpoints(out: str | os.PathLike[str], keep: int, step: int | None = None) -> None:
    """Delete all but the ``keep`` newest checkpoints, and leftovers of interrupted saves. With the
    run's current ``step``, checkpoints past it go too: they are damaged ones that resume passed over
    (`resumable_checkpoint`), and left there they would count as the newest and push good ones out."""
    found = list_checkpoints(out)
    if step is not None:
        for stale in [c for c in found if int(c.name.split("-")[1]) > step]:
            shutil.rmtree(stale)
            found.remove(stale)
    for old in found[:-keep]:
        shutil.rmtree(old)
    for partial in (Path(out) / CHECKPOINTS).glob(f"step-*{PARTIAL_SUFFIX}"):
        shutil.rmtree(partial, ignore_errors=True)
