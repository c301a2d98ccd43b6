"""The authors' released Vintix checkpoint (Hugging Face ``dunnolab/Vintix``), in and out.

A release snapshot is a folder of three files: ``model.pth`` (``torch.save`` of the state dict, 870 fp32
tensors), ``config.json`` (the training config; its model fields are read, the rest kept but unused)
and ``metadata.json`` (per task: group, dims, reward scale, observation statistics). `import_official`
turns it into one of our checkpoints (``model.safetensors`` + ``config.json`` + a model card); `export_official` writes
one of ours back in the release's format, so the authors' code loads it unchanged.

What makes the imported model compute what the authors' does (docs/official-checkpoint.md):
- the architecture options of the release: LeakyReLU encoders and heads (exact GELU in the transformer
  MLP, as ours), one padding vector pair shared by all groups, observations divided by ``std + 1e-6``
  with no floor (``ModelConfig.std_floor = 0, std_epsilon = 1e-6``), qk-LayerNorm, ALiBi, no positions;
- names: Meta-World ``-v2`` tasks run on our ``-v3`` envs, MuJoCo ``-v4`` on ``-v5``, with observation
  layouts (`vintix.tasks.layouts`) where the two versions' observations differ;
- Industrial Benchmark setpoints 80-100, scored by the model card but absent from the metadata, get
  statistics derived from the released setpoints (`_derived_setpoint_norms`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from vintix.atomic import atomic_path, atomic_write_text, check_free_space, check_replaceable, folder_lock
from vintix.errors import at_file
from vintix.fields import checked_fields, read_json_object
from vintix.model.checkpoint import (
    WEIGHTS_FILE,
    CheckpointError,
    build_model,
    metadata_for,
    read_metadata,
    save_pretrained,
)
from vintix.model.model import GroupSpec, ModelConfig, TaskNorm, Vintix, preset
from vintix.tasks import find_task
from vintix.tasks.layouts import legacy_layout

WEIGHTS = "model.pth"
CONFIG = "config.json"
METADATA = "metadata.json"
RELEASE_SHA256 = "894e6ff9fed53a25d3d1f61b568f2d331195130bc85e3efbdd1f360a8b894916"
"""sha256 of ``model.pth`` in the release this importer was written against"""


class OfficialFormatError(CheckpointError):
    """A release snapshot (or a checkpoint to export) that does not fit the release's format."""


# ----------------------------------------------------------------------------------------------
# Config: the release's model fields onto ModelConfig


_SIZE_FIELDS = {  # release field -> ModelConfig field
    "observation_emb_dim": "obs_emb_dim",
    "action_emb_dim": "act_emb_dim",
    "reward_emb_dim": "rew_emb_dim",
    "transformer_depth": "n_layers",
    "transformer_heads": "n_heads",
    "intermediate_size": "mlp_dim",
    "context_len": "context_len",
}
_FIXED_FIELDS: dict[str, Any] = {  # release fields whose other values select code we do not implement
    "normalize_qk": True,
    "bias": True,
    "parallel_residual": False,
    "shared_attention_norm": False,
    "norm_class": "LayerNorm",
    "mlp_class": "GptNeoxMLP",
    "inner_ep_pos_enc": False,
    "norm_acs": False,
    "norm_obs": True,
}
_DROPOUT_FIELDS = ("attn_dropout", "residual_dropout")
MODEL_FIELDS = (*_SIZE_FIELDS, "hidden_dim", *_DROPOUT_FIELDS, *_FIXED_FIELDS)
"""The release config's fields that describe the model; the others (lr, data_dir, ...) train it."""


@dataclass
class ReleaseSizes:
    """The release config's numbers, each of the type the release writes (`config_from_official` checks them)."""

    observation_emb_dim: int
    action_emb_dim: int
    reward_emb_dim: int
    transformer_depth: int
    transformer_heads: int
    intermediate_size: int
    context_len: int
    hidden_dim: int
    attn_dropout: float
    residual_dropout: float


@dataclass
class ReleaseTask:
    """A task's entry of the release ``metadata.json``, the fields a model is built from (`_norm_from_entry`)."""

    observation_shape: dict[str, list[int]]
    group_name: str
    reward_scale: float
    obs_mean: list[float]
    obs_std: list[float]


_RELEASE_FIX = "is this a Vintix release? download the snapshot again"


def official_semantics(**sizes: Any) -> ModelConfig:
    """A ModelConfig computing what the release's model computes, at the given sizes (the `paper` preset
    holds the release's sizes and semantics)."""
    return preset("paper", **sizes)


def config_from_official(config: Mapping[str, Any], where: str = CONFIG) -> ModelConfig:
    """Our ModelConfig for a release ``config.json``; a model field we do not implement is an error."""
    missing = [name for name in MODEL_FIELDS if name not in config]
    if missing:
        raise OfficialFormatError(f"{where}: model fields {missing} are missing; is this a Vintix release config?")
    unsupported = [f"{name}={config[name]!r} (we implement {value!r})" for name, value in _FIXED_FIELDS.items()
                   if config[name] != value]
    if config["attn_dropout"] != config["residual_dropout"]:
        unsupported.append(f"attn_dropout={config['attn_dropout']} with residual_dropout="
                           f"{config['residual_dropout']} (we implement one dropout rate for both)")
    if unsupported:
        raise OfficialFormatError(f"{where}: this vintix does not implement {'; '.join(unsupported)}")
    checked_fields(dict(config), ReleaseSizes, Path(where), at_file(OfficialFormatError), _RELEASE_FIX)
    sizes = {ours: config[theirs] for theirs, ours in _SIZE_FIELDS.items()}
    try:
        model_config = official_semantics(**sizes, dropout=float(config["attn_dropout"]))
    except (TypeError, ValueError) as error:
        raise OfficialFormatError(f"{where}: model fields out of range ({error})") from error
    if config["hidden_dim"] != model_config.d_model:
        raise OfficialFormatError(f"{where}: hidden_dim {config['hidden_dim']} is not observation_emb_dim + "
                                  f"action_emb_dim + reward_emb_dim = {model_config.d_model}")
    return model_config


def config_to_official(config: ModelConfig) -> dict[str, Any]:
    """The release's model fields for `config`; a config the release's code cannot express is an error."""
    sizes = {theirs: getattr(config, ours) for theirs, ours in _SIZE_FIELDS.items()}
    expected = official_semantics(**{ours: getattr(config, ours) for ours in _SIZE_FIELDS.values()},
                                  dropout=config.dropout)
    differ = [f"{f.name}={getattr(config, f.name)!r} (the release: {getattr(expected, f.name)!r})"
              for f in dataclasses.fields(ModelConfig) if getattr(config, f.name) != getattr(expected, f.name)]
    if differ:
        raise OfficialFormatError(
            f"the release's code cannot express this model: {'; '.join(differ)}. Train at the paper preset, or set "
            "these fields to the release's values (tiny/small sizes are fine)")
    return {**sizes, "hidden_dim": config.d_model, "attn_dropout": config.dropout,
            "residual_dropout": config.dropout, **_FIXED_FIELDS}


# ----------------------------------------------------------------------------------------------
# State dict: the release's key names onto ours, one rule per module kind


_PLACEHOLDERS = {"g": r"[^.]+", "i": r"\d+", "p": r"weight|bias", "e": r"[0235]", "h": r"[0246]"}
"""{g} a group, {i} a block, {p} weight or bias, {e} an encoder's Linear/LayerNorm index, {h} a head's Linear"""
_KEY_RULES: tuple[tuple[str, str], ...] = (  # (release key, our key)
    ("encoder.obs_encoders.{g}.layers.{e}.{p}", "encoders.{g}.obs.{e}.{p}"),
    ("encoder.acs_encoders.{g}.layers.{e}.{p}", "encoders.{g}.act.{e}.{p}"),
    ("encoder.rews_encoders.{g}.layers.0.{p}", "encoders.{g}.rew.0.{p}"),
    ("encoder.prev_acs_padding", "act_pad"),
    ("encoder.prev_rew_padding", "rew_pad"),
    ("transformer.blocks.{i}.norm1.{p}", "blocks.{i}.ln_1.{p}"),
    ("transformer.blocks.{i}.norm2.{p}", "blocks.{i}.ln_2.{p}"),
    ("transformer.blocks.{i}.attention.in_proj.{p}", "blocks.{i}.attn.qkv.{p}"),
    ("transformer.blocks.{i}.attention.q_norm.{p}", "blocks.{i}.attn.q_norm.{p}"),
    ("transformer.blocks.{i}.attention.k_norm.{p}", "blocks.{i}.attn.k_norm.{p}"),
    ("transformer.blocks.{i}.attention.out_proj.{p}", "blocks.{i}.attn.proj.{p}"),
    ("transformer.blocks.{i}.mlp.fc.{p}", "blocks.{i}.mlp.fc.{p}"),
    ("transformer.blocks.{i}.mlp.proj.{p}", "blocks.{i}.mlp.proj.{p}"),
    ("transformer.ln_f.{p}", "ln_f.{p}"),
    ("head.acs_decoders.{g}.layers.{h}.{p}", "heads.{g}.{h}.{p}"),
)
_PADDINGS = {"act_pad", "rew_pad"}  # [1, d] in the release, [d] here


def _key_pattern(template: str) -> re.Pattern[str]:
    return re.compile("".join(f"(?P<{part[1]}>{_PLACEHOLDERS[part[1]]})" if part.startswith("{") else re.escape(part)
                              for part in re.split(r"(\{\w\})", template)))


def _rename(name: str, rules: list[tuple[re.Pattern[str], str]]) -> str | None:
    for pattern, template in rules:
        match = pattern.fullmatch(name)
        if match:
            return template.format(**match.groupdict())
    return None


_TO_OURS = [(_key_pattern(theirs), ours) for theirs, ours in _KEY_RULES]
_TO_THEIRS = [(_key_pattern(ours), theirs) for theirs, ours in _KEY_RULES]


def state_dict_from_official(official: Mapping[str, torch.Tensor], model: Vintix, where: str = WEIGHTS
                             ) -> dict[str, torch.Tensor]:
    """`model`'s parameters from a release state dict (meta tensors work too: nothing is copied). Every
    release tensor is consumed exactly once; a key no rule knows, a key `model` lacks, a parameter no
    release key fills or a shape that differs is an OfficialFormatError naming them."""
    expected = dict(model.named_parameters())
    ours: dict[str, torch.Tensor] = {}
    unknown, unexpected, wrong_shape = [], [], []
    for name, tensor in official.items():
        target = _rename(name, _TO_OURS)
        if target is None:
            unknown.append(name)
        elif target not in expected:
            unexpected.append(f"{name} (-> {target})")
        else:
            value = tensor.reshape(-1) if target in _PADDINGS and tensor.dim() == 2 and tensor.shape[0] == 1 else tensor
            if value.shape != expected[target].shape:
                wrong_shape.append(f"{name} {tuple(tensor.shape)}, expected {tuple(expected[target].shape)}")
            ours[target] = value
    missing = sorted(_rename(name, _TO_THEIRS) or name for name in set(expected) - set(ours))
    problems = [f"{label}: {names[:6]}{' ...' if len(names) > 6 else ''} ({len(names)})"
                for label, names in (("keys no release module has", unknown), ("keys for groups or layers the "
                                     "metadata and config do not describe", unexpected),
                                     ("missing keys", missing), ("wrong shapes", wrong_shape)) if names]
    if problems:
        raise OfficialFormatError(f"{where} does not fit the model that {CONFIG} and {METADATA} describe: "
                                  + "; ".join(problems))
    return ours


def state_dict_to_official(model: Vintix) -> dict[str, torch.Tensor]:
    """`model`'s parameters under the release's key names and shapes (buffers stay out: the release's
    normalization statistics live in ``metadata.json``)."""
    official = {}
    for name, tensor in model.named_parameters():
        theirs = _rename(name, _TO_THEIRS)
        if theirs is None:
            raise OfficialFormatError(f"parameter {name} has no place in the release's format")
        official[theirs] = tensor.detach().cpu().reshape(1, -1) if name in _PADDINGS else tensor.detach().cpu()
    return official


# ----------------------------------------------------------------------------------------------
# Metadata: tasks, groups and statistics


def _our_task_name(name: str) -> str:
    """Our registry's name for a release task (reach-v2 -> reach-v3, Ant-v4 -> Ant-v5), else the name."""
    spec = find_task(name)
    return spec.name if spec is not None else name


def _norm_from_entry(name: str, entry: Mapping[str, Any], where: str) -> TaskNorm:
    if isinstance(entry, Mapping):  # each field of the type the release writes, named where it is not
        checked_fields(dict(entry), ReleaseTask, Path(where), at_file(OfficialFormatError), _RELEASE_FIX, within=name)
    try:
        dim = int(entry["observation_shape"]["proprio"][0])
        norm = TaskNorm(_our_task_name(name), str(entry["group_name"]), [float(x) for x in entry["obs_mean"]],
                        [float(x) for x in entry["obs_std"]], float(entry["reward_scale"]))
    except (KeyError, TypeError, ValueError, IndexError) as error:
        raise OfficialFormatError(f"{where}: task {name!r} lacks or mangles a field ({error!r}); the release "
                                  "schema is {action_type, action_dim, observation_shape: {proprio: [d]}, "
                                  "group_name, reward_scale, obs_mean, obs_std, acs_mean, acs_std}") from error
    if len(norm.obs_mean) != dim or len(norm.obs_std) != dim:
        raise OfficialFormatError(f"{where}: task {name!r} has {len(norm.obs_mean)} obs_mean and "
                                  f"{len(norm.obs_std)} obs_std values for a {dim}-dim observation")
    # A damaged statistic would surface later as NaN actions, blamed on a training run that never was (a value that
    # is not finite, ReleaseTask's check refused already).
    damaged = (["obs_std below 0"] if min(norm.obs_std, default=0) < 0 else []) + (
        [f"reward_scale {norm.reward_scale}"] if norm.reward_scale <= 0 else [])
    if damaged:
        raise OfficialFormatError(f"{where}: task {name!r} has a damaged {'; '.join(damaged)} (std >= 0 and "
                                  "reward_scale > 0 expected); download the snapshot again")
    spec = find_task(norm.task)
    if spec is not None and spec.obs_dim != dim:
        # Our env's observation differs from the release's: a known older layout bridges them; otherwise
        # the agent refuses the task with both dims named (`vintix.agent.resolve_task`).
        norm = dataclasses.replace(norm, obs_layout=legacy_layout(spec.name, dim))
    return norm


DERIVED_SETPOINTS = (80, 85, 90, 95, 100)
"""Industrial Benchmark setpoints the model card scores but the metadata lacks"""


def _derived_setpoint_norms(norms: list[TaskNorm]) -> list[TaskNorm]:
    """Statistics for Industrial Benchmark setpoints 80-100 from the released 0-75.

    Channel 0 of an Industrial Benchmark observation is the setpoint, constant within a task: its mean is
    the setpoint (fitted on the released tasks, exact where they are) and its std 0, so it normalizes to 0
    as in training. The other channels, the reward scale and the group come from the highest released
    setpoint, the nearest one.
    """
    released = {}
    for norm in norms:
        spec = find_task(norm.task)
        if spec is not None and spec.domain == "industrial_benchmark":
            released[int(spec.name.split("-")[2])] = norm
    if len(released) < 2:
        return []
    points = sorted(released)
    slope, offset = np.polyfit(points, [float(released[p].obs_mean[0]) for p in points], 1)
    nearest = released[points[-1]]
    derived = []
    for setpoint in DERIVED_SETPOINTS:
        if setpoint in released or find_task(f"industrial-benchmark-{setpoint}-v1") is None:
            continue
        mean, std = list(nearest.obs_mean), list(nearest.obs_std)
        mean[0], std[0] = float(offset + slope * setpoint), 0.0
        derived.append(dataclasses.replace(nearest, task=f"industrial-benchmark-{setpoint}-v1", obs_mean=mean,
                                           obs_std=std))
    return derived


def groups_from_metadata(metadata: Mapping[str, Any], where: str = METADATA) -> list[GroupSpec]:
    """Our GroupSpecs for the release's groups, in order of first appearance; tasks of one group that
    disagree on dims are an error."""
    groups: dict[str, GroupSpec] = {}
    for name, entry in metadata.items():
        try:
            spec = GroupSpec(str(entry["group_name"]), int(entry["observation_shape"]["proprio"][0]),
                             int(entry["action_dim"]))
        except (KeyError, TypeError, ValueError, IndexError) as error:
            raise OfficialFormatError(f"{where}: task {name!r} lacks group_name, observation_shape or "
                                      f"action_dim ({error!r})") from error
        known = groups.setdefault(spec.name, spec)
        if known != spec:
            raise OfficialFormatError(f"{where}: task {name!r} gives group {spec.name!r} dims {spec.obs_dim}/"
                                      f"{spec.act_dim}, other tasks of it {known.obs_dim}/{known.act_dim}")
    return list(groups.values())


# ----------------------------------------------------------------------------------------------
# Import and export


@dataclass
class ImportResult:
    """What `import_official` wrote and what it noticed."""

    directory: Path
    sha256: str
    known_release: bool
    """model.pth is the release this importer was written against (else: every key and shape matched)"""
    tasks: int
    derived_tasks: list[str] = field(default_factory=list)
    renamed: dict[str, str] = field(default_factory=dict)
    """release name -> our name, where they differ"""
    adapted: list[str] = field(default_factory=list)
    """tasks whose env observation is mapped onto the release's layout"""


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        while chunk := stream.read(1 << 24):
            digest.update(chunk)
    return digest.hexdigest()


def is_official_snapshot(directory: str | os.PathLike[str]) -> bool:
    """A folder holding a release's three files (and none of our checkpoint's)."""
    path = Path(directory)
    return all((path / name).is_file() for name in (WEIGHTS, CONFIG, METADATA)) and not (path / WEIGHTS_FILE).exists()


def _read_json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise OfficialFormatError(f"{path.parent}: no {path.name}; a release snapshot holds {WEIGHTS}, {CONFIG} "
                                  f"and {METADATA} (hf download dunnolab/Vintix --local-dir DIR)")
    return read_json_object(path, at_file(OfficialFormatError), "download the snapshot again")


def _load_official_weights(path: Path) -> dict[str, torch.Tensor]:
    if not path.is_file():
        _read_json(path)  # the same "no such file" message
    try:
        weights = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises several kinds for truncated or foreign files
        raise OfficialFormatError(f"{path}: unreadable as a weights-only torch file ({error}); it is truncated or "
                                  "not the release's, download it again") from error
    if not isinstance(weights, dict) or not all(isinstance(k, str) and isinstance(v, torch.Tensor)
                                                for k, v in weights.items()):
        odd = next((repr(k) for k in weights if not isinstance(k, str)), None) if isinstance(weights, dict) else None
        raise OfficialFormatError(f"{path}: a state dict (name -> tensor) expected, got {type(weights).__name__}"
                                  + (f" with the key {odd}" if odd else ""))
    damaged = [name for name, tensor in weights.items() if tensor.is_floating_point() and not tensor.isfinite().all()]
    if damaged:
        raise OfficialFormatError(f"{path}: tensor(s) {damaged[:5]} hold NaN or inf; the file is damaged, download "
                                  "it again")
    return weights


def import_official(snapshot: str | os.PathLike[str], out: str | os.PathLike[str], overwrite: bool = False
                    ) -> ImportResult:
    """Our checkpoint in `out` of the release snapshot in `snapshot` (nothing is downloaded). `out` must be
    empty or new, or `overwrite` given; never the snapshot itself."""
    snapshot = Path(snapshot)
    check_replaceable(out, "checkpoint", overwrite, inputs=[snapshot])
    with folder_lock(out, "vintix import-official"):  # two imports into `out` would mix their files
        return _import_official(snapshot, out)


def _import_official(snapshot: Path, out: str | os.PathLike[str]) -> ImportResult:
    config = _read_json(snapshot / CONFIG)
    metadata = _read_json(snapshot / METADATA)
    model_config = config_from_official(config, str(snapshot / CONFIG))
    groups = groups_from_metadata(metadata, str(snapshot / METADATA))
    norms = [_norm_from_entry(name, entry, str(snapshot / METADATA)) for name, entry in metadata.items()]
    names = [n.task for n in norms]
    if len(set(names)) != len(names):
        raise OfficialFormatError(f"{snapshot / METADATA}: two release tasks map onto one of ours: "
                                  f"{sorted({n for n in names if names.count(n) > 1})}")
    derived = _derived_setpoint_norms(norms)
    weights_path = snapshot / WEIGHTS
    weights = _load_official_weights(weights_path)
    sha256 = file_sha256(weights_path)
    model = build_model(metadata_for(model_config, groups, norms + derived))
    model.load_state_dict(state_dict_from_official(weights, model, str(weights_path)), strict=False)
    renamed = {theirs: norm.task for theirs, norm in zip(metadata, norms, strict=True) if theirs != norm.task}
    extra = {"official": {
        "source": str(snapshot.resolve()), "sha256": sha256, "known_release": sha256 == RELEASE_SHA256,
        "config": config, "task_names": {norm.task: theirs for theirs, norm in zip(metadata, norms, strict=True)},
        "derived_tasks": [n.task for n in derived],
        "action_stats": {theirs: {k: entry.get(k) for k in ("action_type", "acs_mean", "acs_std")}
                         for theirs, entry in metadata.items()},
    }}
    directory = save_pretrained(model, out, extra)
    return ImportResult(directory, sha256, sha256 == RELEASE_SHA256, len(norms) + len(derived),
                        [n.task for n in derived], renamed, [n.task for n in norms if n.obs_layout is not None])


def export_official(checkpoint: str | os.PathLike[str], out: str | os.PathLike[str], overwrite: bool = False
                    ) -> Path:
    """Write the model in `checkpoint` as a release snapshot in `out` (model.pth, config.json,
    metadata.json), loadable by the authors' code; `import_official` of it gives the same model back. `out`
    must be empty or new, or `overwrite` given; never the checkpoint itself."""
    check_replaceable(out, "release", overwrite, inputs=[checkpoint])
    # Before the lock writes its file: model.pth holds the same weights as model.safetensors, and JSON beside it.
    check_free_space(out, int(1.1 * (Path(checkpoint) / "model.safetensors").stat().st_size) + 2**20,
                     "the release snapshot would", "free space, or write elsewhere (--out)")
    with folder_lock(out, "vintix export-official"):  # two exports into `out` would mix their files
        return _export_official(checkpoint, out)


def _export_official(checkpoint: str | os.PathLike[str], out: str | os.PathLike[str]) -> Path:
    from vintix.model.checkpoint import load_pretrained

    meta = read_metadata(checkpoint)
    model = load_pretrained(checkpoint)
    discrete = sorted(name for name, group in model.groups.items() if group.discrete)
    if discrete:  # the authors' code has continuous heads only: the logits of a discrete group would pass as actions
        raise OfficialFormatError(f"{checkpoint}: group(s) {discrete} act in a discrete space, which the release "
                                  "format (continuous heads only) cannot hold; keep the vintix checkpoint (vintix "
                                  "eval, Agent.from_pretrained read it)")
    model_fields = config_to_official(model.config)
    official = meta.get("extra", {}).get("official", {})
    names: dict[str, str] = official.get("task_names", {})
    action_stats: dict[str, dict[str, Any]] = official.get("action_stats", {})
    derived = set(official.get("derived_tasks", []))
    metadata = {}
    for norm in model.task_norms:
        if norm.task in derived:
            continue
        theirs = names.get(norm.task, norm.task)
        group = model.groups[norm.group]
        stats = action_stats.get(theirs, {})
        metadata[theirs] = {
            "action_type": stats.get("action_type", "continuous"), "action_dim": group.act_dim,
            "observation_shape": {"proprio": [group.obs_dim]}, "group_name": norm.group,
            "reward_scale": float(norm.reward_scale), "obs_mean": [float(x) for x in norm.obs_mean],
            "obs_std": [float(x) for x in norm.obs_std],
            # Actions are not normalized (norm_acs false); the schema still has their statistics.
            "acs_mean": stats.get("acs_mean", [0.0] * group.act_dim),
            "acs_std": stats.get("acs_std", [1.0] * group.act_dim),
        }
    directory = Path(out)
    directory.mkdir(parents=True, exist_ok=True)
    with atomic_path(directory / WEIGHTS) as temporary:
        torch.save(state_dict_to_official(model), temporary)
    atomic_write_text(directory / CONFIG, json.dumps({**official.get("config", {}), **model_fields}, indent=1) + "\n")
    atomic_write_text(directory / METADATA, json.dumps(metadata) + "\n")
    return directory


__all__ = ["ImportResult", "OfficialFormatError", "RELEASE_SHA256", "config_from_official", "config_to_official",
           "export_official", "import_official", "is_official_snapshot",
           "state_dict_from_official", "state_dict_to_official"]
