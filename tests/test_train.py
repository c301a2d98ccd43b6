"""The trainer on real collected Meta-World histories: loss falls, exact resume, accumulation, errors."""

from __future__ import annotations

import csv
import dataclasses
import errno
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from safetensors.torch import load_file
from typer.testing import CliRunner

from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    DAMAGE_NAMES,
    DATA,
    QUICK_TRAIN,
    RUNS,
    api_error,
    bad_input_test,
    clean_data,
    cli_error,
    damaged_release,
    documented,
    empty_dir,
    file_at,
    ib7_data,
    invoke,
    missing,
    no_fraction_data,
    not_written,
    pusher_v4_data,
    quick_train,
    straight_and_killed_runs,
    trained_run,
    unknown_task_data,
    work,
    workspace,
)
from conftest import fill_up
from vintix.agent import Agent
from vintix.atomic import folder_lock
from vintix.cli import app
from vintix.collect import CollectionPlan, NoiseSchedule, collect
from vintix.errors import DatasetError, UnknownTaskError
from vintix.interrupt import Interrupted
from vintix.model import CheckpointError, load_pretrained
from vintix.model.checkpoint import WEIGHTS_FILE, read_metadata
from vintix.model.official import file_sha256
from vintix.train import (
    ConfigError,
    NonFiniteLossError,
    TrainConfig,
    Trainer,
    WindowDataset,
    WindowLoss,
    build_optimizer,
    collate_windows,
    learning_rate,
    load_config,
    load_training_data,
    trainer,
)
from vintix.train.checkpoint import (
    best_checkpoint_dir,
    latest_checkpoint,
    list_checkpoints,
    model_directory,
    prune_checkpoints,
    read_training_state,
)
from vintix.train.trainer import Selection, busy_cores, training_threads

# A model small enough for a few dozen CPU steps in seconds; 128-step windows hold 1-2 episodes.
TEST_MODEL = dict(n_layers=2, n_heads=2, obs_emb_dim=15, act_emb_dim=15, rew_emb_dim=2, mlp_dim=64,
                  head_layers=1, context_len=128)


@pytest.fixture(scope="module")
def metaworld_data(tmp_path_factory):
    """Two tasks x two real noise-distilled histories of 600 steps (scripted experts, one group).

    The noise decays fast (p = 0.5) and the last half is noise-free, so most actions are predictable
    and a falling loss is visible within a few dozen steps.
    """
    root = tmp_path_factory.mktemp("data")
    schedule = NoiseSchedule(curvature=0.5, noise_free_fraction=0.5)
    collect([CollectionPlan(task, histories=2, steps=600, schedule=schedule, envs_per_batch=2)
             for task in ("reach-v3", "push-v3")], root)
    return root


def make_config(data, out, **overrides) -> TrainConfig:
    fields = dict(data=str(data), out=str(out), model="tiny", model_overrides=TEST_MODEL, batch_size=4,
                  max_steps=8, warmup_steps=2, log_every=1, checkpoint_every=100, tensorboard=False,
                  stats_cache_dir=str(out.parent / "stats-cache"))
    return TrainConfig(**{**fields, **overrides})


def logged(out, column="loss"):
    with (out / "log.csv").open() as f:
        return [float(row[column]) for row in csv.DictReader(f)]


def test_a_history_moved_into_another_tasks_folder_is_refused(metaworld_data, tmp_path):
    data = tmp_path / "data"
    shutil.copytree(metaworld_data, data)
    reach, push = data / "metaworld" / "reach-v3", data / "metaworld" / "push-v3"
    with h5py.File(next(reach.glob("*.h5"))) as file:
        assert file.attrs["task"] == "reach-v3"  # the collector records the task of every history
    shutil.copy(next(push.glob("*.h5")), reach / "history-0009.h5")  # same dims: only the record tells
    with pytest.raises(DatasetError, match="collected on task 'push-v3' but sits in the folder of task 'reach-v3'"):
        load_training_data(data, ["reach-v3"])


def test_loss_falls_on_real_histories(metaworld_data, tmp_path):
    out = tmp_path / "run"
    trainer = Trainer(make_config(metaworld_data, out, max_steps=40, lr=1e-3, warmup_steps=5))
    # The same 16 windows before and after (a seed the training sampler does not use).
    held = collate_windows([WindowDataset(trainer.data, 128, seed=99)[i] for i in range(16)])

    def held_loss() -> float:
        with torch.no_grad():
            return float(WindowLoss(trainer.model.eval())(held).mean())

    before = held_loss()
    trainer.model.train()
    trainer.run()
    after = held_loss()
    assert after < 0.75 * before, f"held-out windows: loss {before:.4f} -> {after:.4f}"
    losses = logged(out)
    assert len(losses) == 40 and sum(losses[-10:]) < sum(losses[:10])
    assert logged(out, "loss_metaworld") == losses  # one group: the per-group loss is the loss


def test_interrupted_and_resumed_run_equals_the_straight_run(metaworld_data, tmp_path):
    straight, resumed = tmp_path / "straight", tmp_path / "resumed"
    def config(out):
        # One thread for both: the default picks the cores the machine's load leaves free, and float sums over
        # another thread count differ in their last bits (a loaded CI machine gave the two runs different counts).
        return make_config(metaworld_data, out, max_steps=6, checkpoint_every=3, grad_accum=2, threads=1)

    Trainer(config(straight)).run()
    Trainer(config(resumed)).run(until_step=3)
    assert read_training_state(latest_checkpoint(resumed))["step"] == 3
    trainer = Trainer(config(resumed))
    assert trainer.step == 3
    trainer.run()
    a, b = latest_checkpoint(straight), latest_checkpoint(resumed)
    assert a.name == b.name == "step-00000006"
    for name in ("model.safetensors", "optimizer.safetensors"):
        wa, wb = load_file(str(a / name)), load_file(str(b / name))
        assert wa.keys() == wb.keys() and all(torch.equal(wa[k], wb[k]) for k in wa), name
    assert logged(straight) == logged(resumed)


def test_resume_with_other_settings_or_data_is_refused_unless_accepted(metaworld_data, tmp_path):
    out = tmp_path / "run"
    Trainer(make_config(metaworld_data, out, max_steps=1, checkpoint_every=1)).run()
    with pytest.raises(CheckpointError,
                       match=r"differs from the one that wrote it in batch_size \(checkpoint 4, now 2\); "
                             r"lr \(checkpoint 0.0003, now 0.002\).*allow_resume_changes=true"):
        Trainer(make_config(metaworld_data, out, max_steps=2, lr=2e-3, batch_size=2))
    other_data = tmp_path / "data"
    shutil.copytree(metaworld_data, other_data)
    (other_data / "metaworld" / "push-v3" / "history-0001.h5").unlink()
    with pytest.raises(CheckpointError, match="in the data's histories"):
        Trainer(make_config(other_data, out, max_steps=2))
    assert Trainer(make_config(metaworld_data, out, max_steps=2, log_every=2)).step == 1  # longer, logged less: free
    accepted = Trainer(make_config(metaworld_data, out, max_steps=2, lr=2e-3, allow_resume_changes=True))
    assert accepted.step == 1


def test_training_notes_histories_longer_than_a_window_that_an_evaluation_starts_at_a_runs_first_step(
        metaworld_data, tmp_path):
    """600-step histories of 100-step episodes in a 128-step window: an evaluation of one episode shows the model a
    context from the run's start, and most training windows start elsewhere."""
    from vintix.train.trainer import window_sizing_notes

    data = load_training_data(metaworld_data, ["reach-v3"], stats_cache_dir=tmp_path)
    [note] = window_sizing_notes(data, 128, keep_first_steps=0, eval_shots=1)
    assert "reach-v3: its histories (600 steps) are longer than the 128-step window" in note
    assert "the selection's 1-episode runs" in note and "keep_first_steps" in note
    assert window_sizing_notes(data, 128, keep_first_steps=0, eval_shots=8) == []  # the run outgrows the window
    assert window_sizing_notes(data, 128, keep_first_steps=100, eval_shots=1) == []  # its start is kept
    assert window_sizing_notes(data, 600, keep_first_steps=0, eval_shots=None) == []  # history = window
    random_contexts = tmp_path / "dpt"  # DPT's contexts of constant noise look alike wherever a window starts
    collect(CollectionPlan("point-goal-v1", histories=2, steps=60, schedule=NoiseSchedule(level=1.0,
                                                                                          noise_free_fraction=0.0)),
            random_contexts)
    dpt = load_training_data(random_contexts, ["point-goal-v1"], stats_cache_dir=tmp_path)
    assert window_sizing_notes(dpt, 20, keep_first_steps=0, eval_shots=1) == []


def test_resume_below_the_checkpoints_step_is_refused_and_a_moved_max_steps_is_said(metaworld_data, tmp_path, capsys):
    out = tmp_path / "run"
    Trainer(make_config(metaworld_data, out, max_steps=3, checkpoint_every=3)).run()
    with pytest.raises(ConfigError, match=r"is at step 3, past max_steps=2: a resumed run cannot go back"):
        Trainer(make_config(metaworld_data, out, max_steps=2))
    capsys.readouterr()
    assert Trainer(make_config(metaworld_data, out, max_steps=5)).step == 3
    assert "note: max_steps 3 -> 5: the learning rate from step 3 on follows" in capsys.readouterr().out


def test_resume_into_a_different_model_config_is_refused(metaworld_data, tmp_path):
    out = tmp_path / "run"
    Trainer(make_config(metaworld_data, out, max_steps=1)).run()
    with pytest.raises(CheckpointError, match=r"model config differs in mlp_dim \(checkpoint 64, now 32\)"):
        Trainer(make_config(metaworld_data, out, model_overrides={**TEST_MODEL, "mlp_dim": 32}))
    with pytest.raises(CheckpointError, match="tasks differ"):
        Trainer(make_config(metaworld_data, out, tasks=["reach-v3"]))


def test_fine_tuning_starts_from_a_models_weights_with_fresh_groups_for_tasks_it_never_had(metaworld_data, tmp_path,
                                                                                           capsys):
    source = tmp_path / "source"
    Trainer(make_config(metaworld_data, source, max_steps=2)).run()
    data = tmp_path / "data"  # the same Meta-World histories, and a MuJoCo task of a group the source lacks
    shutil.copytree(metaworld_data, data)
    collect([CollectionPlan("Reacher-v5", histories=1, steps=150, envs_per_batch=1)], data)
    tuned = Trainer(make_config(data, tmp_path / "tuned", tasks=[], init_from=str(source), max_steps=1))
    assert "fresh: group mujoco-reacher" in capsys.readouterr().out
    start, trained = load_pretrained(model_directory(source)), dict(tuned.model.named_parameters())
    for name, value in start.named_parameters():
        assert torch.equal(trained[name], value), name  # the trunk and the Meta-World encoder and head
    assert tuned.model.obs_mean.shape[0] == 3  # statistics of this run's three tasks, not the source's two
    untrained = Trainer(make_config(data, tmp_path / "scratch", tasks=[]))
    assert not torch.equal(untrained.model.blocks[0].mlp.fc.weight, trained["blocks.0.mlp.fc.weight"])
    with pytest.raises(ConfigError, match=r"init_from .*source: its model settings are not this run's \(mlp_dim 32 "
                                          r"here, 64 there\)"):
        Trainer(make_config(data, tmp_path / "other", model_overrides={**TEST_MODEL, "mlp_dim": 32},
                            init_from=str(source)))
    kept = Trainer(make_config(data, tmp_path / "kept", tasks=[], init_from=str(source), max_steps=1,
                               model_overrides={**TEST_MODEL, "keep_first_steps": 8}))  # inference-only: free
    assert kept.model.config.keep_first_steps == 8
    # ...and so is the window: no weight is a position's (the shipped point-goal, context 1024, with its own config's
    # 100-step window was refused: issue 71's red team)
    shorter = Trainer(make_config(data, tmp_path / "shorter", tasks=[], init_from=str(source), max_steps=1,
                                  window_len=start.config.context_len // 2))
    assert shorter.model.config.context_len == start.config.context_len // 2
    tuned.run()  # a resumed run's weights are its checkpoint's, however init_from is spelled now
    resumed = Trainer(make_config(data, tmp_path / "tuned", tasks=[], init_from=str(source / "checkpoints"),
                                  max_steps=2))
    assert resumed.step == 1
    # What the tuned model records names no folder of this machine, and says which weights it started from.
    extra = read_metadata(latest_checkpoint(tmp_path / "tuned"))["extra"]
    assert extra["dataset"] == "../data" and extra["train_config"]["data"] == "../data"
    assert extra["train_config"]["out"] == "." and extra["train_config"]["init_from"] == "../source"
    assert extra["init_from_sha256"] == file_sha256(model_directory(source) / WEIGHTS_FILE)
    assert str(tmp_path) not in (latest_checkpoint(tmp_path / "tuned") / "README.md").read_text()


def test_a_checkpoint_from_before_a_model_field_existed_resumes_with_that_fields_default(metaworld_data, tmp_path):
    out, paper_layout = tmp_path / "run", {**TEST_MODEL, "last_reward": False}
    Trainer(make_config(metaworld_data, out, max_steps=1, model_overrides=paper_layout)).run()
    checkpoint = latest_checkpoint(out)
    written = json.loads((checkpoint / "config.json").read_text())
    del written["config"]["last_reward"]  # as a checkpoint written before the field was added
    (checkpoint / "config.json").write_text(json.dumps(written))
    with pytest.raises(CheckpointError, match=r"last_reward \(checkpoint False, now True\)"):
        Trainer(make_config(metaworld_data, out, max_steps=2))  # the tiny preset reads the last reward
    resumed = Trainer(make_config(metaworld_data, out, max_steps=2, model_overrides=paper_layout))
    assert resumed.step == 1 and not resumed.model.config.last_reward


def test_gradient_accumulation_weights_micro_batches_equally(metaworld_data, tmp_path):
    # Two micro-batches of 2 windows = one batch of the same 4 windows (the sampler numbers windows
    # across micro-batches), so one optimizer step must land on the same weights.
    weights = []
    for name, batch, accum in (("accum", 2, 2), ("whole", 4, 1)):
        trainer = Trainer(make_config(metaworld_data, tmp_path / name, batch_size=batch, grad_accum=accum,
                                      max_steps=1, grad_clip=0.0))
        trainer.run()
        weights.append(trainer.model.state_dict())
    assert all(torch.allclose(weights[0][k], weights[1][k], atol=1e-6, rtol=0) for k in weights[0])


def test_schedule_and_weight_decay_follow_the_paper_recipe(tmp_path):
    config = TrainConfig(max_steps=110, warmup_steps=10, lr=3e-4, min_lr_fraction=0.1)
    assert learning_rate(0, config) == pytest.approx(3e-5)
    assert learning_rate(9, config) == pytest.approx(3e-4)
    assert learning_rate(60, config) == pytest.approx(3e-5 + (3e-4 - 3e-5) / 2)
    assert learning_rate(110, config) == pytest.approx(3e-5)
    model = torch.nn.Sequential(torch.nn.Linear(3, 4), torch.nn.LayerNorm(4))
    optimizer, names = build_optimizer(model, config)
    decay, no_decay = optimizer.param_groups
    assert (decay["weight_decay"], no_decay["weight_decay"]) == (0.1, 0.0)
    assert [p.ndim for p in decay["params"]] == [2] and len(no_decay["params"]) == 3
    assert names == ["0.weight", "0.bias", "1.weight", "1.bias"]
    assert optimizer.defaults["betas"] == (0.9, 0.99)


def test_checkpoint_loads_without_the_dataset_and_callbacks_see_the_model(metaworld_data, tmp_path):
    data = tmp_path / "data"
    shutil.copytree(metaworld_data, data)
    seen = []
    config = make_config(data, tmp_path / "run", max_steps=4, model_overrides={**TEST_MODEL, "mask_reward": True})
    trainer = Trainer(config, callbacks=[(2, lambda model, step: seen.append((step, model.training)))])
    checkpoint = trainer.run()
    assert seen == [(2, False), (4, False)]
    shutil.rmtree(data)
    model = load_pretrained(checkpoint)
    assert model.config.mask_reward and [t.task for t in model.task_norms] == ["push-v3", "reach-v3"]
    assert torch.equal(model.obs_mean, trainer.model.obs_mean.cpu())
    state = read_training_state(checkpoint)
    assert state["step"] == 4 and state["train_config"] == dataclasses.asdict(config)
    assert model_directory(tmp_path / "run") == checkpoint  # a run folder means its newest model
    with pytest.raises(CheckpointError, match="neither a model checkpoint"):
        model_directory(tmp_path)


def test_vintix_train_command_trains_and_resumes(metaworld_data, tmp_path):
    yaml_config = tmp_path / "train.yaml"
    yaml_config.write_text("model: tiny\nmodel_overrides: {n_layers: 1, n_heads: 2, obs_emb_dim: 15, act_emb_dim: 15, "
                           "rew_emb_dim: 2, mlp_dim: 32, context_len: 64}\nbatch_size: 2\nwarmup_steps: 1\n"
                           f"tensorboard: true\nstats_cache_dir: {tmp_path / 'cache'}\n")
    command = ["train", "--config", str(yaml_config), "--data", str(metaworld_data), "--out", str(tmp_path / "run")]
    first = CliRunner().invoke(app, [*command, "--set", "max_steps=2"])
    assert first.exit_code == 0, first.output
    second = CliRunner().invoke(app, [*command, "--set", "max_steps=3"])
    assert second.exit_code == 0, second.output
    assert "resuming from" in second.output and "step-00000002" in second.output
    assert any((tmp_path / "run" / "tensorboard").iterdir())
    bad = CliRunner().invoke(app, [*command, "--set", "window_len=4096"])
    assert bad.exit_code == 2 and "exceeds the model's context_len" in bad.output


def test_in_context_selection_keeps_the_best_model_beside_the_latest_and_across_resume(metaworld_data, tmp_path):
    out = tmp_path / "run"
    scores = iter([0.2, 0.7, 0.4, 0.5, 0.9])  # what the scorer says at steps 2, 4, 6, 8, 10
    seen = []

    def scorer(model, tasks):
        seen.append((tasks, model.training))
        score = next(scores)
        return Selection(score, reward_use_gap=score / 2)

    config = make_config(metaworld_data, out, max_steps=6, select_every=2, log_every=2, checkpoint_every=2)
    Trainer(config, scorer=scorer).run()
    assert seen == [(["push-v3", "reach-v3"], False)] * 3  # default selection tasks: the ones trained on
    best = load_pretrained(best_checkpoint_dir(out))
    assert best.task_norms and read_metadata(best_checkpoint_dir(out))["extra"]["step"] == 4
    assert logged(out, "in_context_score") == [0.2, 0.7, 0.4]
    assert logged(out, "reward_use_gap") == [0.1, 0.35, 0.2]
    assert model_directory(out) == best_checkpoint_dir(out)  # a run folder means the model it recommends
    assert latest_checkpoint(out).name == "step-00000006"  # resume still starts from the newest step

    # A log written before reward_use_gap existed: resuming keeps its rows, the new column empty in them.
    with (out / "log.csv").open() as f:
        old = [{k: v for k, v in row.items() if k != "reward_use_gap"} for row in csv.DictReader(f)]
    with (out / "log.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, list(old[0]))
        writer.writeheader()
        writer.writerows(old)
    Trainer(dataclasses.replace(config, max_steps=10), scorer=scorer).run()  # resumed: 0.5 < 0.7 stays out
    extra = read_metadata(best_checkpoint_dir(out))["extra"]
    assert extra["step"] == 10 and extra["in_context_score"] == 0.9 and extra["reward_use_gap"] == 0.45
    assert logged(out, "in_context_score") == [0.2, 0.7, 0.4, 0.5, 0.9]
    with (out / "log.csv").open() as f:
        assert [row["reward_use_gap"] for row in csv.DictReader(f)] == ["", "", "", "0.25", "0.45"]
    assert b"\r" not in (out / "log.csv").read_bytes()  # kept and new rows end their lines alike


@pytest.mark.parametrize(("setting", "message"), [
    ("max_steps=abc", "TrainConfig.max_steps must be int, got 'abc'"),
    ("lr=-1", "out of range: lr=-1.0"),
    ("lr=.nan", "TrainConfig.lr must be float, got nan"),
    ("tasks=reach-v3", r"TrainConfig.tasks must be list\[str\], got 'reach-v3'"),
    ("num_workers=-1", "must be >= 0: num_workers=-1"),
    ("window_len=0", "must be >= 1: window_len=0"),
    ("model_overrides={n_heads: 0}", "model_overrides: sizes must be >= 1 .*n_heads=0"),
    ("model_overrides={mlp_dim: big}", "ModelConfig.mlp_dim must be int, got 'big'"),
    ("select_metric=wins", "select_metric must be one of 'score', 'success', got 'wins'"),
    ("lr=!!python/object/apply:os.system [echo]", "--set 'lr=!!python/object.*': the value is not plain YAML"),
    ("tasks=[reach-v3", "--set 'tasks=\\[reach-v3': the value is not plain YAML"),
])
def test_a_setting_of_the_wrong_type_or_range_is_named_before_anything_runs(tmp_path, setting, message):
    result = CliRunner().invoke(app, ["train", "--data", str(tmp_path), "--out", str(tmp_path / "run"),
                                      "--set", setting])
    assert result.exit_code == 2 and not isinstance(result.exception, Exception), result.output  # no traceback
    output = " ".join(result.output.split())
    assert re.search(message, output) and "--set values are read as YAML" in output, output
    assert not (tmp_path / "run").exists()


def test_a_model_trained_on_shorter_windows_attends_over_them_when_it_acts(metaworld_data, tmp_path):
    out = tmp_path / "run"
    Trainer(make_config(metaworld_data, out, max_steps=1, checkpoint_every=1, window_len=48)).run()
    model = load_pretrained(latest_checkpoint(out))
    assert model.config.context_len == 48  # not the preset's 1024: positions past 48 were never trained
    agent = Agent(model)
    agent.reset(["reach-v3"])
    assert agent.cache.window == 48


def test_an_option_and_a_setting_that_disagree_are_refused(tmp_path):
    result = CliRunner().invoke(app, ["train", "--data", str(tmp_path), "--out", str(tmp_path / "a"),
                                      "--set", f"out={tmp_path / 'b'}"])
    output = " ".join(result.output.split())
    assert result.exit_code == 2
    assert f"--out {tmp_path / 'a'} but --set out={tmp_path / 'b'}: give each value once" in output
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_a_model_too_large_for_the_machine_is_refused_before_allocating(metaworld_data, tmp_path):
    result = CliRunner().invoke(app, ["train", "--data", str(metaworld_data), "--out", str(tmp_path / "run"),
                                      "--set", "model_overrides={mlp_dim: 1000000000}", "--set", "tensorboard=false"])
    output = " ".join(result.output.split())
    assert result.exit_code == 2 and re.search("training the tiny preset .* needs [0-9,.]+ GiB", output), output


def test_a_second_training_into_a_run_folder_in_use_is_refused_at_once(tmp_path):
    with folder_lock(tmp_path / "run", "vintix train"):
        result = CliRunner().invoke(app, ["train", "--data", str(tmp_path), "--out", str(tmp_path / "run")])
    assert result.exit_code == 2, result.output
    assert "run is in use by vintix train (pid" in " ".join(result.output.split()), result.output


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_training_on_cuda_without_a_gpu_is_a_named_error(tmp_path):
    result = CliRunner().invoke(app, ["train", "--data", str(tmp_path), "--out", str(tmp_path / "run"),
                                      "--set", "device=cuda"])
    assert result.exit_code == 2 and "torch sees no GPU" in result.output, result.output


def test_selection_needs_a_scorer_and_a_logged_step(metaworld_data, tmp_path):
    with pytest.raises(ConfigError, match="multiple of log_every"):
        make_config(metaworld_data, tmp_path / "run", select_every=3, log_every=2)
    with pytest.raises(ConfigError, match="needs an in-context scorer"):
        Trainer(make_config(metaworld_data, tmp_path / "run", select_every=2))
    with pytest.raises(ConfigError, match="expert_rows must be 'auto' or 'tail', got 'all'"):
        make_config(metaworld_data, tmp_path / "run", expert_rows="all")
    # A selection task that is unknown, or outside the data's groups, fails before the first step, not at the first
    # selection after minutes of training.
    never = lambda model, tasks: pytest.fail("no selection should run")  # noqa: E731
    with pytest.raises(UnknownTaskError, match="unknown task 'NoSuch-v0'"):
        Trainer(make_config(metaworld_data, tmp_path / "run", select_every=2, log_every=2, select_tasks=["NoSuch-v0"]),
                scorer=never)
    with pytest.raises(UnknownTaskError, match="group 'mujoco-hopper', which the model has no encoder for"):
        Trainer(make_config(metaworld_data, tmp_path / "run", select_every=2, log_every=2, select_tasks=["Hopper-v5"]),
                scorer=never)
    assert not (tmp_path / "run" / "checkpoints").exists()


def test_off_a_terminal_training_says_how_long_it_will_take_and_reports_each_selection(metaworld_data, tmp_path,
                                                                                         capsys):
    """A run logged to a file shows its progress: the time it will take after its first logged steps, then a line
    at each in-context selection (and a minute) with the step, loss, speed, time left and score."""
    config = make_config(metaworld_data, tmp_path / "run", max_steps=6, select_every=2, log_every=2)
    Trainer(config, scorer=lambda model, tasks: Selection(0.25, reward_use_gap=0.125)).run()
    lines = capsys.readouterr().out.splitlines()
    estimate = next(line for line in lines if "steps/s on this machine" in line)
    assert "steps 2 to 6 take about" in estimate and estimate.endswith("plus the in-context selections")
    reports = [line for line in lines if line.startswith("step 4/6") or line.startswith("step 6/6")]
    assert len(reports) == 2 and all("loss" in r and "success" not in r for r in reports)
    assert re.search(r"loss \d\.\d{3}e[+-]\d\d, ", reports[0]), "scientific notation: a small loss is not 0.0000"
    assert reports[0].endswith("left; in context: score 0.250, reward-use gap +0.125")
    assert "left" not in reports[1], "nothing is left at 100 %"


@pytest.mark.parametrize("signal_number", [signal.SIGTERM, signal.SIGINT])
def test_a_stop_signal_saves_the_step_it_ends_and_says_how_to_resume(metaworld_data, tmp_path, signal_number):
    """SIGTERM (a scheduler, `kill`) or Ctrl-C during training: the run stops after its current step, saved, and the
    same command resumes it; a run signalled nowhere near a checkpoint step loses nothing."""
    config = make_config(metaworld_data, tmp_path / "run", max_steps=8, checkpoint_every=5)
    handlers = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]
    with pytest.raises(Interrupted, match=rf"stopped by {signal_number.name} at step 3 and saved it in .*step-00000003;"
                                          " re-run the same command to resume"):
        Trainer(config, callbacks=[(3, lambda model, step: os.kill(os.getpid(), signal_number))]).run()
    assert read_training_state(latest_checkpoint(tmp_path / "run"))["step"] == 3
    assert [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)] == handlers  # restored after the run
    resumed = Trainer(config)
    assert resumed.step == 3 and read_training_state(resumed.run())["step"] == 8


def test_training_threads_are_the_ones_asked_for_or_the_cores_idle_now(monkeypatch):
    assert training_threads(1, world_size=1) == 1
    assert training_threads(4096, world_size=1) == len(os.sched_getaffinity(0))  # no more threads than cores
    cores = len(os.sched_getaffinity(0))
    # Another process busy now (runnable, whether or not it has a core): one core fewer, at least one.
    busy = subprocess.Popen([sys.executable, "-c", "print('spinning', flush=True)\nwhile True: pass"],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert busy.stdout is not None and busy.stdout.readline() == "spinning\n"
        assert busy_cores() >= 0.5
        assert training_threads(0, world_size=1) <= max(1, cores - 1)
    finally:
        busy.kill()
        busy.wait()
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    monkeypatch.setattr(trainer, "busy_cores", lambda: 1.2)
    assert training_threads(0, world_size=1) == 3  # one core busy elsewhere: the other three
    assert training_threads(0, world_size=2) == 1  # shared between two ranks
    monkeypatch.setattr(trainer, "busy_cores", lambda: 9.0)
    assert training_threads(0, world_size=1) == 1  # an overloaded machine: never 0 or fewer
    # Without /proc: the 1-minute load average.
    monkeypatch.setattr(trainer, "busy_cores", lambda: None)
    monkeypatch.setattr(os, "getloadavg", lambda: (2.2, 0.0, 0.0))
    assert training_threads(0, world_size=1) == 2


def test_a_run_without_selections_promises_none(metaworld_data, tmp_path, capsys):
    Trainer(make_config(metaworld_data, tmp_path / "run", max_steps=4, log_every=2)).run()
    estimate = next(line for line in capsys.readouterr().out.splitlines() if "steps/s on this machine" in line)
    assert "selection" not in estimate


def test_vintix_train_selects_by_real_cold_start_shots(metaworld_data, tmp_path):
    """The CLI wires the real scorer: cold-start shots on seeds no history used, score in the log."""
    out = tmp_path / "run"
    result = CliRunner().invoke(app, [
        "train", "--data", str(metaworld_data), "--out", str(out), "--set", f"model_overrides={TEST_MODEL}",
        "--set", "max_steps=2", "--set", "batch_size=2", "--set", "warmup_steps=1", "--set", "log_every=2",
        "--set", "select_every=2", "--set", "select_shots=2", "--set", "select_seeds=1",
        "--set", "select_tasks=[reach-v3]", "--set", "tensorboard=false", "--set", f"stats_cache_dir={tmp_path / 'c'}",
        "--threads", "1"])
    assert result.exit_code == 0, result.output
    assert "best in-context score" in result.output and "(1 CPU thread(s) each)" in result.output
    score = logged(out, "in_context_score")[0]
    assert score == pytest.approx(read_metadata(best_checkpoint_dir(out))["extra"]["in_context_score"], abs=1e-6)
    assert -2.0 < score < 2.0
    # The same shots with zero rewards fed back ran too (select_reward_gap is on by default).
    gap = logged(out, "reward_use_gap")[0]
    recorded = read_metadata(best_checkpoint_dir(out))["extra"]["reward_use_gap"]
    assert math.isfinite(gap) and gap == pytest.approx(recorded, abs=1e-6)


def diverge(model, step):
    """What a numerical blow-up leaves behind: one NaN weight (a callback runs right after a step)."""
    with torch.no_grad():
        model.ln_f.weight[0] = float("nan")


def test_a_non_finite_loss_stops_training_with_the_last_good_checkpoint_intact(metaworld_data, tmp_path):
    out = tmp_path / "run"
    # Checkpoints at steps 2 and 4; the weights turn NaN after step 3, so step 4's loss is NaN.
    config = make_config(metaworld_data, out, max_steps=6, checkpoint_every=2)
    with pytest.raises(NonFiniteLossError, match=r"step 4: the loss or its gradient is not finite.*last good "
                                                 r"checkpoint is .*step-00000002.*lower lr"):
        Trainer(config, callbacks=[(3, diverge)]).run()
    assert [p.name for p in list_checkpoints(out)] == ["step-00000002"]
    load_pretrained(latest_checkpoint(out))  # finite: it loads
    assert len(logged(out)) == 3


def test_parameters_that_turned_nan_are_never_checkpointed(metaworld_data, tmp_path):
    out = tmp_path / "run"
    config = make_config(metaworld_data, out, max_steps=4, checkpoint_every=2)
    with pytest.raises(NonFiniteLossError, match="step 2: the model's parameters hold NaN/inf, so no checkpoint"):
        Trainer(config, callbacks=[(2, diverge)]).run()
    assert list_checkpoints(out) == []


def test_vintix_train_on_data_with_nan_rewards_refuses_to_start(metaworld_data, tmp_path):
    data = tmp_path / "data"
    shutil.copytree(metaworld_data, data)
    path = data / "metaworld" / "push-v3" / "history-0001.h5"
    with h5py.File(path, "r+") as f:
        f["0-599/reward"][17] = float("nan")
    result = CliRunner().invoke(app, ["train", "--data", str(data), "--out", str(tmp_path / "run"),
                                      "--set", f"model_overrides={TEST_MODEL}", "--set", "max_steps=2",
                                      "--set", f"stats_cache_dir={tmp_path / 'c'}"])
    assert result.exit_code == 2, result.output
    output = " ".join(result.output.split())
    assert "history-0001.h5: NaN/inf in reward at row 17" in output and "vintix data validate" in output
    assert not (tmp_path / "run" / "checkpoints").exists()


def truncate(path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


DAMAGE = {
    "truncated optimizer": lambda c: truncate(c / "optimizer.safetensors"),
    "truncated rng": lambda c: truncate(c / "rng.safetensors"),
    "truncated weights": lambda c: truncate(c / "model.safetensors"),
    "garbage trainer.json": lambda c: (c / "trainer.json").write_text("{\"step\": 4, garbage"),
    "trainer.json of another shape": lambda c: (c / "trainer.json").write_text("{\"step\": \"4\"}"),
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_resume_passes_over_a_damaged_newest_checkpoint_and_still_equals_the_straight_run(
        metaworld_data, tmp_path, capsys, damage):
    straight, resumed = tmp_path / "straight", tmp_path / "resumed"

    def config(out):
        return make_config(metaworld_data, out, max_steps=6, checkpoint_every=2)

    Trainer(config(straight)).run()
    Trainer(config(resumed)).run(until_step=4)
    DAMAGE[damage](resumed / "checkpoints" / "step-00000004")
    capsys.readouterr()
    trainer = Trainer(config(resumed))
    note = " ".join(capsys.readouterr().out.split())
    assert "step-00000004 is damaged" in note and "resuming from" in note and trainer.step == 2
    trainer.run()
    for name in ("model.safetensors", "optimizer.safetensors"):
        a = load_file(str(latest_checkpoint(straight) / name))
        b = load_file(str(latest_checkpoint(resumed) / name))
        assert all(torch.equal(a[k], b[k]) for k in a), name
    assert [p.name for p in list_checkpoints(resumed)] == ["step-00000002", "step-00000004", "step-00000006"]


def test_a_run_without_one_intact_checkpoint_names_the_folder_to_delete(metaworld_data, tmp_path):
    out = tmp_path / "run"
    config = make_config(metaworld_data, out, max_steps=2, checkpoint_every=2)
    Trainer(config).run()
    truncate(out / "checkpoints" / "step-00000002" / "optimizer.safetensors")
    with pytest.raises(CheckpointError, match=r"no intact checkpoint to resume from .*step-00000002: .*"
                                              r"optimizer.safetensors: unreadable.*Delete .*checkpoints to train"):
        Trainer(config)


def test_evaluating_a_run_whose_newest_checkpoint_is_damaged_names_the_intact_one(metaworld_data, tmp_path):
    from vintix.agent import Agent

    out = tmp_path / "run"
    Trainer(make_config(metaworld_data, out, max_steps=4, checkpoint_every=2)).run()
    truncate(out / "checkpoints" / "step-00000004" / "model.safetensors")
    with pytest.raises(CheckpointError, match=r"step-00000004/model.safetensors: unreadable.*newest intact checkpoint "
                                              r"is .*step-00000002: pass it with --checkpoint, or delete"):
        Agent.from_pretrained(out)
    assert Agent.from_pretrained(out / "checkpoints" / "step-00000002").model.task_norms


def test_pruning_drops_checkpoints_past_the_current_step(tmp_path):
    for step in (1, 2, 3, 9):  # 9: a damaged checkpoint that resume passed over at step 3
        directory = tmp_path / "checkpoints" / f"step-{step:08d}"
        directory.mkdir(parents=True)
        (directory / "trainer.json").write_text("{}")
    prune_checkpoints(tmp_path, keep=2, step=3)
    assert [p.name for p in list_checkpoints(tmp_path)] == ["step-00000002", "step-00000003"]


def test_normalized_rewards_reach_the_model_at_unit_scale_and_a_gaussian_policy_trains(metaworld_data, tmp_path):
    out = tmp_path / "run"
    trainer = Trainer(make_config(metaworld_data, out, max_steps=30, lr=1e-3, warmup_steps=5, normalize_rewards=True,
                                  model_overrides={**TEST_MODEL, "policy": "gaussian", "reward_encoder": "mlp"}))
    rewards = np.concatenate([h.history.read(0, h.history.num_steps)["reward"]
                              for task in trainer.data.tasks for h in task.histories if task.name == "reach-v3"])
    scale = float(trainer.model.reward_scale[trainer.model.task_index("reach-v3")])
    assert scale == pytest.approx(1 / rewards.std(), rel=1e-4)  # the checkpoint carries it to the agent
    trainer.run()
    losses = logged(out)
    assert sum(losses[-5:]) < sum(losses[:5])  # a likelihood: it may go below 0


def test_shipped_training_configs_load_by_name_and_an_unknown_one_lists_them():
    config = load_config("point-goal", {"data": "d", "out": "o"})
    assert config.normalize_rewards and config.model_config().reward_encoder == "mlp" and config.out == "o"
    assert load_config("icrl-suite").expert_distillation  # the goal-aware expert's action as the target
    with pytest.raises(ConfigError, match="icrl-suite"):
        load_config("no-such-config")


def test_a_disk_that_fills_up_mid_training_ends_it_with_the_last_checkpoint_intact_and_no_partial_one(
        metaworld_data, tmp_path, small_disk):
    """Another program fills the disk after step 3 (a callback writes the ballast): step 4's checkpoint
    cannot be written. The error is the disk's (ENOSPC, naming the file), the half-written checkpoint is
    removed, step 2's stays whole, and once there is room the run resumes from it and finishes."""
    out = small_disk / "run"
    config = make_config(metaworld_data, out, max_steps=6, checkpoint_every=2)
    ballast: list[Path] = []
    with pytest.raises(OSError, match=r"No space left on device: '.*step-00000004\.\w+\.partial") as error:
        Trainer(config, callbacks=[(3, lambda model, step: ballast.append(fill_up(small_disk)))]).run()
    assert error.value.errno == errno.ENOSPC
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["step-00000002"]
    ballast[0].unlink()
    Trainer(config).run()
    assert [p.name for p in list_checkpoints(out)] == ["step-00000002", "step-00000004", "step-00000006"]


# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

for setting, needle in [("max_steps=abc", "max_steps must be int"), ("lr=-1", "lr=-1"), ("lr=.nan", "lr must be float"),
                        ("nosuchfield=1", "unknown TrainConfig fields"), ("max_steps", "expects field=value"),
                        ("tasks=reach-v3", "tasks must be list"), ("model=huge", "model preset 'huge'"),
                        ("device=tpu", "device must be"), ("window_len=100000", "exceeds the model's context_len"),
                        ("select_every=3", "multiple of log_every"), ("batch_size=0", "batch_size=0"),
                        ("beta2=1.5", "beta2=1.5"), ("model_overrides={n_heads: 0}", "n_heads=0"),
                        ("model_overrides={widht: 3}", "unknown ModelConfig fields"),
                        ("tasks=[reech-v3]", "Did you mean"), ("expert_tail_fraction=2", "expert_tail_fraction=2.0")]:
    cli_error("train", f"--set {setting}", lambda s=setting: ["train", "--data", clean_data(),
                                                            "--out", work() / "t-set", "--set", s], needle,
              after=not_written(lambda: work() / "t-set"))
cli_error("train", "--config missing file", lambda: ["train", "--config", missing("c.yaml"), "--data", clean_data()],
          "neither a model preset")
cli_error("train", "--config invalid YAML", lambda: ["train", "--config", file_at("bad-config.yaml", "a: [")(),
                                                     "--data", clean_data()], "not valid YAML")
cli_error("train", "--config YAML list", lambda: ["train", "--config", file_at("list-config.yaml", "- 1\n- 2\n")(),
                                                  "--data", clean_data()], "expected a mapping")
cli_error("train", "--data missing", lambda: ["train", "--data", missing("d"), "--out", work() / "t1", *QUICK_TRAIN],
          "not a directory")
cli_error("train", "--data empty", lambda: ["train", "--data", empty_dir("empty2")(), "--out", work() / "t2",
                                            *QUICK_TRAIN],
          "no task folder")
cli_error("train", "--out is a file", lambda: ["train", "--data", clean_data(), "--out", file_at("run-file", "x")(),
                                               *QUICK_TRAIN], "not a directory")
cli_error("train", "--set device=cuda without a GPU", lambda: ["train", "--data", clean_data(), "--out", work() / "t3",
                                                               *QUICK_TRAIN, "--set", "device=cuda"], "no GPU")
for damage, (_, needle) in DAMAGE_NAMES.items():
    if needle is None:
        continue
    cli_error("train", f"data: {damage}", lambda d=damage: ["train", "--data", DATA[d](), "--out", work() / f"t-{d}",
                                                           *QUICK_TRAIN], needle,
              after=not_written(lambda d=damage: work() / f"t-{d}" / "checkpoints"))
cli_error("train", "data: IB folder with 7 obs dims in JSON and data", lambda: [
    "train", "--data", ib7_data(), "--out", work() / "t-ib7", *QUICK_TRAIN, "--set", "tasks=[industrial_benchmark]"],
    "registry's industrial-benchmark-10-v1")
cli_error("train", "data: task not in the registry", lambda: [
    "train", "--data", unknown_task_data(), "--out", work() / "t-unknown", *QUICK_TRAIN], "not in the task registry")
cli_error("train", "data: expert distillation without noise_free_fraction", lambda: [
    "train", "--data", no_fraction_data(), "--out", work() / "t-ed", *QUICK_TRAIN, "--set", "expert_distillation=true"],
    "noise_free_fraction")
cli_error("train", "data: window longer than every history", lambda: [
    "train", "--data", clean_data(), "--out", work() / "t-window", *quick_train(
        model_overrides="{n_layers: 1, n_heads: 2, obs_emb_dim: 15, act_emb_dim: 15, rew_emb_dim: 2, mlp_dim: 32, "
                        "context_len: 1024}"), "--set", "window_len=1000"], "no history holds a window",
    after=not_written(lambda: work() / "t-window"))


def trains_anyway(data: str, expect: str) -> Callable[[], str | None]:
    def check() -> str | None:
        code, output = invoke("train", "--data", DATA[data](), "--out", work() / f"t-ok-{data}", *QUICK_TRAIN)
        return None if code == 0 and expect in output else f"exit {code}: {output[-300:]}"

    return check


documented("train", "data: a history without checksums (published layout) trains", trains_anyway(
    "published-layout", "1 tasks"))
documented("train", "data: a .partial leftover is not a history: training ignores it", trains_anyway(
    "partial-leftover", "1 tasks"))
documented("train", "data: a task folder without histories gets no windows", trains_anyway("json-only-task", "1 tasks"))
cli_error("train", "--set stats_cache_dir under a file", lambda: [
    "train", "--data", clean_data(), "--out", work() / "t-cache", *QUICK_TRAIN, "--set",
    f"stats_cache_dir={file_at('cache-file', 'x')() / 'stats'}"], "is a file, not a directory")


def corrupted_stats_cache_is_recomputed() -> str | None:
    cache = work() / "stats-cache"
    args = ["train", "--data", clean_data(), *QUICK_TRAIN, "--set", f"stats_cache_dir={cache}"]
    code, output = invoke(*args, "--out", work() / "t-cache1")
    for entry in cache.glob("*.json"):
        entry.write_text("{ damaged")
    code, output = invoke(*args, "--out", work() / "t-cache2")
    return None if code == 0 and all(json.loads(e.read_text())["validated"] for e in cache.glob("*.json")) else output


documented("train", "a damaged statistics cache entry is recomputed", corrupted_stats_cache_is_recomputed)


def stats_follow_an_in_place_change() -> str | None:
    """Issue 55, class 4: a history rewritten in place, same size, its mtime set back, gets new statistics."""
    from vintix.data import find_tasks
    from vintix.train.data import cached_obs_stats

    data = work() / "data-in-place"
    if not data.exists():
        shutil.copytree(clean_data(), data)
    task = find_tasks(data)[0]
    cache = work() / "stats-cache-in-place"

    def stats() -> list[float]:
        histories = [__import__("vintix.data").data.LearningHistory(p) for p in task.history_paths]
        return cached_obs_stats(task, histories, cache)[1]

    before = stats()
    path = task.history_paths[0]
    times = (path.stat().st_atime_ns, path.stat().st_mtime_ns)
    with h5py.File(path, "r+") as file:  # the same bytes' worth of rows, other values
        group = file[sorted(file.keys(), key=lambda k: int(k.split("-")[0]) if "-" in k else -1)[-1]]
        observations = group["proprio_observation"]
        observations[...] = observations[...] * 3.0 + 1.0
    os.utime(path, ns=times)
    return None if stats() != before else "the cached statistics of the old rows were reused"


documented("train", "statistics follow a history changed in place (same size, mtime set back)",
           stats_follow_an_in_place_change)


def resume_after_an_in_place_change() -> list[object]:
    """Issue 71, class 3: a run's data changed in place (same size, mtime set back) before it resumes; resume
    compares the data by the statistics cache's key, so it notices."""
    data, out = work() / "data-resume-in-place", work() / "t-resume-in-place"
    shutil.copytree(clean_data(), data)
    code, output = invoke("train", "--data", data, "--out", out, *QUICK_TRAIN)
    assert code == 0, output
    path = sorted((data / "metaworld" / "reach-v3").glob("*.h5"))[0]
    times = (path.stat().st_atime_ns, path.stat().st_mtime_ns)
    with h5py.File(path, "r+") as file:
        file[next(iter(file.keys()))]["reward"][0] += 1.0
    os.utime(path, ns=times)
    return ["train", "--data", data, "--out", out, *quick_train(max_steps=3)]


cli_error("train", "resume on data changed in place (same size, mtime set back)", resume_after_an_in_place_change,
          "the files were changed")


cli_error("sizes", "train a model of 25,000 layers (it fit memory and built for minutes in silence)", lambda: [
    "train", "--data", clean_data(), "--out", work() / "t-deep", "--set", "model_overrides={n_layers: 25000}"],
    "at most 256")


def damaged_log_on_resume() -> str | None:
    """Issue 55, class 6: a run whose log.csv was damaged resumes, keeping the damaged file aside and saying so."""
    run = work() / "run-damaged-log"
    if not run.exists():
        shutil.copytree(trained_run(), run)
    (run / "log.csv").write_bytes(b"step,loss\n\xff\xfe garbage,1\nnot-a-step,2\n")
    code, output = invoke("train", "--data", clean_data(), "--out", run, *quick_train(max_steps=3),
                          "--set", "allow_resume_changes=true")
    if code != 0:
        return f"exit {code}: {output[-300:]}"
    return None if "kept as" in output and (run / "log.csv.damaged").is_file() else f"not said: {output[-300:]}"


documented("train", "resume with a damaged log.csv: the run goes on, the damaged log kept aside", damaged_log_on_resume)


def resume_falls_back(run: str) -> Callable[[], str | None]:
    def check() -> str | None:
        out = RUNS[run]()
        code, output = invoke("train", "--data", clean_data(), "--out", out, *quick_train(max_steps=3))
        ok = code == 0 and "step-00000002 is damaged" in output and "resuming from" in output
        return None if ok else f"exit {code}: {output[-300:]}"

    return check


for run in ("truncated-optimizer", "truncated-rng", "garbage-trainer-json", "trainer-json-wrong-step",
            "truncated-weights", "garbage-model-json"):
    documented("train", f"resume: newest checkpoint has a {run}: falls back with a note", resume_falls_back(run))
cli_error("train", "resume: no intact checkpoint", lambda: [
    "train", "--data", clean_data(), "--out", RUNS["all-damaged"](), *quick_train(max_steps=3)],
          "no intact checkpoint to resume from")
cli_error("train", "resume into another model config", lambda: [
    "train", "--data", clean_data(), "--out", trained_run(), *quick_train(
        model_overrides="{n_layers: 2, n_heads: 2, obs_emb_dim: 15, act_emb_dim: 15, rew_emb_dim: 2, mlp_dim: 32, "
                        "head_layers: 1, context_len: 64}", max_steps=3)], "cannot resume")


def partial_checkpoint_ignored() -> str | None:
    out = RUNS["partial-leftover"]()
    code, output = invoke("train", "--data", clean_data(), "--out", out, *quick_train(max_steps=3))
    left = sorted(p.name for p in (out / "checkpoints").iterdir())
    ok = code == 0 and "resuming from" in output and left == ["step-00000001", "step-00000002", "step-00000003"]
    return None if ok else f"exit {code}, checkpoints {left}: {output[-200:]}"


documented("train", "resume: a step-N.partial left by kill -9 is ignored, then removed", partial_checkpoint_ignored)


def pusher_v4_trains() -> str | None:
    code, output = invoke("train", "--data", pusher_v4_data(), "--out", work() / "t-pusher", *QUICK_TRAIN,
                          "--set", "tasks=[Pusher-v4]")
    return None if code == 0 and "1 tasks" in output else f"exit {code}: {output[-300:]}"


documented("train", "the published dataset's Pusher-v4 folder trains (alias of v5)", pusher_v4_trains)


def killed_training_resumes_identically() -> str | None:
    """kill -9 a real `python -m vintix train` after its first checkpoint; the resumed run equals a straight one."""
    from safetensors.torch import load_file

    # One thread in both runs: the default follows the load average, and another thread count rounds differently.
    args = ["train", "--data", str(clean_data()), *quick_train(max_steps=40, checkpoint_every=5, log_every=5),
            "--threads", "1"]
    straight, killed, code, _ = straight_and_killed_runs(args, "train", "checkpoints/step-00000005")
    a, b = (load_file(str(run / "checkpoints" / "step-00000040" / "model.safetensors")) for run in (straight, killed))
    same = all(torch.equal(a[k], b[k]) for k in a)
    return None if code == 0 and same else f"exit {code}, identical weights: {same}"


documented("train", "kill -9 mid-training, then re-run: identical weights", killed_training_resumes_identically)


def config_call(**fields: object) -> Callable[[], object]:
    from vintix.train import TrainConfig

    return lambda: TrainConfig(**fields)


api_error("train", "TrainConfig(max_steps='abc')", config_call(max_steps="abc"), "max_steps must be int")
api_error("train", "TrainConfig(warmup_steps=-1)", config_call(warmup_steps=-1), "warmup_steps=-1")
api_error("train", "TrainConfig(min_lr_fraction=3)", config_call(min_lr_fraction=3), "min_lr_fraction=3")


def nan_loss_stops() -> object:
    from vintix.train import Trainer, load_config

    config = load_config("tiny", {"data": str(clean_data()), "out": str(work() / "t-nan-loss")},
                         [s for s in quick_train(max_steps=4, checkpoint_every=2) if s != "--set"])

    def diverge(model: object, step: int) -> None:
        with torch.no_grad():
            model.ln_f.weight[0] = float("nan")  # type: ignore[attr-defined]

    return Trainer(config, callbacks=[(3, diverge)]).run()


api_error("train", "a NaN loss mid-run (weights diverged after step 3)", nan_loss_stops,
          "step 4: the loss or its gradient")
api_error("train", "TrainConfig(threads=5000)", lambda: __import__("vintix.train").train.TrainConfig(threads=5000),
          "threads must be 0 (auto) or a number of CPU threads up to 1024")
cli_error("train", "vintix train --threads -1", ["train", "--threads", "-1"], "--threads")


def deep_release(folder: Path) -> None:
    config = json.loads((folder / "config.json").read_text())
    (folder / "config.json").write_text(json.dumps({**config, "transformer_depth": 10**9}))


# Sizes (issue 47, class 3): from the config's arithmetic, before a layer is built (10^9 of them never end).
cli_error("sizes", "import-official of a release of 10^9 layers", damaged_release("deep", deep_release), "at most 256")


test_bad_input_ends_as_expected = bad_input_test("train", "sizes")
