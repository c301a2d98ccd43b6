"""The model shipped in the package: loads by name, small, says how it was made, acts in every domain."""

from __future__ import annotations

import re

import numpy as np
import pytest

from inference_model import one_torch_thread  # noqa: F401  (autouse fixture)
from vintix.agent import Agent, resolve_checkpoint, shipped_models
from vintix.collect.recipe import load_recipe
from vintix.errors import ShadowedNameError
from vintix.model.checkpoint import WEIGHTS_FILE, CheckpointError, read_metadata
from vintix.tasks import get_task, make_env


# point-goal: no checkpoint selection
@pytest.mark.parametrize("name", ["cpu-suite", "icrl-reach", "icrl-suite", "vintix-cpu", "vintix-cpu-meta"])
def test_a_shipped_model_is_small_trained_on_its_recipe_and_records_how_it_was_made(name):
    assert name in shipped_models()
    folder = resolve_checkpoint(name)
    assert (folder / WEIGHTS_FILE).stat().st_size <= 25 * 2**20
    extra = read_metadata(folder)["extra"]
    suite = {plan.task for plan in load_recipe(name) if get_task(plan.task).split == "train"}
    assert set(extra["trained_tasks"]) == suite  # trained on its recipe's train split, nothing held out
    assert np.isfinite(extra["in_context_score"]) and extra["select_reference"] == "ours"
    assert "vintix train" in (folder / "TRAINING.md").read_text()


def test_no_shipped_file_names_a_folder_of_the_machine_that_trained_it():
    root = resolve_checkpoint("vintix-cpu").parent
    texts = [path for path in root.rglob("*") if path.suffix in (".json", ".md")]
    assert len(texts) >= 3 * len(shipped_models())
    # Two or more path components after a slash that starts a word: /work/cells/x, not a URL's //host/x or 1/2.
    absolute = re.compile(r"(?<![\w.~)\]>/:-])/[A-Za-z_][\w.-]*/[\w.-]+")
    found = [f"{path.relative_to(root)}: {match.group(0)}" for path in texts
             for match in absolute.finditer(path.read_text())]
    assert found == []


def test_a_name_means_one_thing_and_unknown_names_list_the_shipped_ones(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cpu-suite").mkdir()
    with pytest.raises(ShadowedNameError, match="write ./cpu-suite for yours"):
        resolve_checkpoint("cpu-suite")  # the shipped model, or the empty folder here? Neither, silently
    with pytest.raises(CheckpointError, match="neither a model checkpoint"):
        resolve_checkpoint("./cpu-suite")  # the empty folder here
    with pytest.raises(CheckpointError, match="shipped: .*cpu-suite"):
        resolve_checkpoint("no-such-model")


def test_the_shipped_model_acts_within_bounds_in_all_three_domains_and_on_held_out_tasks():
    agent = Agent.from_pretrained("cpu-suite")
    tasks = ["door-open-v3", "industrial-benchmark-30-v1", "Reacher-v5", "door-lock-v3", "industrial-benchmark-90-v1"]
    envs = [make_env(task, seed=100) for task in tasks]
    agent.reset(tasks, [env.action_space for env in envs])
    # Held-out tasks have their own statistics in the checkpoint (collected, never trained on).
    assert [t.norm_source for t in agent.tasks] == ["task"] * len(tasks)
    observations = [env.reset()[0] for env in envs]
    rewards, starts = np.zeros(len(envs)), np.ones(len(envs), dtype=bool)
    for _ in range(3):
        actions = agent.act(observations, rewards, starts)
        for i, (env, action) in enumerate(zip(envs, actions, strict=True)):
            assert env.action_space.contains(action.astype(env.action_space.dtype))
            observations[i], rewards[i], *_ = env.step(action)
        starts[:] = False
    for env in envs:
        env.close()


def test_results_name_a_shipped_model_by_its_name_and_a_local_checkpoint_relative_to_the_working_directory(
        tmp_path, monkeypatch):
    import json
    import shutil

    from typer.testing import CliRunner

    from vintix.agent.pretrained import resolve_checkpoint
    from vintix.cli import app

    monkeypatch.chdir(tmp_path)
    shutil.copytree(resolve_checkpoint("point-goal"), tmp_path / "models" / "mine")
    for run, (given, name) in enumerate((("point-goal", "point-goal"), ("models/mine", "models/mine"),
                                         (str(tmp_path / "models" / "mine"), "models/mine"))):
        result = CliRunner().invoke(app, ["eval", "--checkpoint", given, "--tasks", "point-goal-v1", "--shots", "1",
                                          "--seeds", "1", "--out", f"results-{run}"])
        assert result.exit_code == 0, result.output
        assert json.loads((tmp_path / f"results-{run}" / "run.json").read_text())["checkpoint"] == name


# Sum of |action| over 12 greedy steps of each shipped model on its first task (random observations, rewards and
# episode starts from numpy's seed 0), measured with the code before action heads became one interface: the
# refactor changed no weight name and no head's arithmetic. (A discrete model's draws did change, once, when each env
# got a stream of its own.)
PLAYED_BEFORE_THE_HEAD_INTERFACE = {
    "bandit": 0.0, "cpu-suite": 15.197059579193592, "darkroom": 13.0, "icrl-reach": 15.793161699548364,
    "icrl-suite": 15.273853041231632, "keytodoor": 30.0, "point-goal": 9.18310959637165,
    "vintix-cpu": 29.401571810245514, "vintix-cpu-meta": 34.37126350402832}


@pytest.mark.parametrize("name", sorted(PLAYED_BEFORE_THE_HEAD_INTERFACE))
def test_every_shipped_model_loads_and_plays_as_it_did(name):
    agent = Agent.from_pretrained(name, threads=1)
    agent.reset([agent.model.task_norms[0].task])
    dim = agent.tasks[0].env_obs_dim(agent.model)
    rng = np.random.default_rng(0)
    played = 0.0
    for t in range(12):
        action = agent.act([rng.normal(size=dim).astype(np.float32)], [float(rng.uniform())], [t % 5 == 0],
                           deterministic=True)[0]
        played += float(np.abs(np.asarray(action, dtype=np.float64)).sum())
    assert played == pytest.approx(PLAYED_BEFORE_THE_HEAD_INTERFACE[name], rel=1e-4)
