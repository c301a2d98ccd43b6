"""Demonstrators: training with SB3, weights-only save/load, shipped experts' scores, the score table."""

import json
import os
import shutil
import signal
import stat
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import spearmanr
from stable_baselines3.common.callbacks import BaseCallback
from typer.testing import CliRunner

from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    bad_input_test,
    cli_error,
    documented,
    empty_dir,
    file_at,
    invoke,
    not_written,
    once,
    work,
    workspace,
)
from vintix.cli import app
from vintix.collect import CollectionPlan, NoiseSchedule, collect
from vintix.data import LearningHistory
from vintix.demonstrators import TrainedDemonstrator, load_demonstrator, training
from vintix.demonstrators.base import expert_name
from vintix.demonstrators.scores import UniformRandomPolicy, episode_returns, measure
from vintix.demonstrators.trained import shipped_weights_dir
from vintix.demonstrators.training import (
    SCORE_EPISODES,
    SCORE_SEED,
    DemonstratorRecipe,
    best_check,
    default_state_dir,
    evaluate_unfinished_run,
    recipe_for,
    train_demonstrator,
    unfinished_runs,
)
from vintix.errors import VintixError
from vintix.tasks import get_task, make_env
from vintix.tasks.scores import our_reference_scores, read_scores, record_scores


def normalized(task: str, mean_return: float) -> float:
    spec = get_task(task)
    return (mean_return - spec.paper_random.mean) / (spec.paper_expert.mean - spec.paper_random.mean)


def small_recipe(task: str) -> DemonstratorRecipe:
    """The task's recipe with rollouts and updates small enough for a test."""
    recipe = recipe_for(task)
    if recipe.algorithm != "PPO":
        return replace(recipe, hyperparameters={**recipe.hyperparameters, "learning_starts": 100})
    return replace(recipe, train_tasks=recipe.train_tasks[:2], n_envs=min(recipe.n_envs, 2),
                   hyperparameters={**recipe.hyperparameters, "n_steps": 64, "batch_size": 32, "n_epochs": 1})


# SAC; Sample Factory's PPO; PPO + VecNormalize
@pytest.mark.parametrize("task", ["Reacher-v5", "Ant-v5", "industrial-benchmark-35-v1"])
def test_trained_policy_round_trips_through_weights_only_files(tmp_path, task):
    path = train_demonstrator(task, timesteps=120, out=tmp_path, progress_bar=False, recipe=small_recipe(task))
    assert path.suffix == ".safetensors" and path.with_suffix(".json").is_file()
    demonstrator = TrainedDemonstrator(get_task(task), tmp_path)
    assert demonstrator.metadata["algorithm"] == recipe_for(task).algorithm and demonstrator._mlp is not None
    env = make_env(task, seed=0)
    observations = np.stack([env.reset()[0], np.clip(env.observation_space.sample(), -5, 5)])
    actions = demonstrator.act(observations, [env, env])
    assert actions.shape == (2, get_task(task).act_dim)
    assert np.all(actions >= env.action_space.low) and np.all(actions <= env.action_space.high)
    np.testing.assert_array_equal(actions, demonstrator.act(observations, [env, env]))  # deterministic
    expected, _ = demonstrator.policy.predict(demonstrator.policy_input(observations), deterministic=True)
    np.testing.assert_allclose(actions, expected, rtol=1e-5, atol=1e-5)  # the numpy forward is SB3's policy


def test_a_policy_trained_on_the_first_observations_acts_on_them_alone(tmp_path):
    recipe = replace(small_recipe("Ant-v5"), observation_dims=27)  # joint positions and velocities, no contact forces
    train_demonstrator("Ant-v5", timesteps=120, out=tmp_path, progress_bar=False, recipe=recipe)
    demonstrator = TrainedDemonstrator(get_task("Ant-v5"), tmp_path)
    assert demonstrator.metadata["observation_dims"] == 27 and demonstrator.policy.observation_space.shape == (27,)
    env = make_env("Ant-v5", seed=0)
    observations = np.stack([env.reset()[0]] * 2)
    observations[1, 27:] = 0.5  # other contact forces, same joints
    actions = demonstrator.act(observations, [env, env])
    assert actions.shape == (2, 8)
    np.testing.assert_array_equal(actions[0], actions[1])


class InterruptAt(BaseCallback):
    """Ctrl-C at env step `step`, or a SIGTERM sent to this process (what `kill` sends)."""

    def __init__(self, step: int, how: str):
        super().__init__()
        self.step, self.how = step, how

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.step:
            if self.how == "sigterm":
                os.kill(os.getpid(), signal.SIGTERM)
            else:
                raise KeyboardInterrupt
        return True


class RecordStart(BaseCallback):
    """Where training starts: env steps done, transitions in the replay buffer."""

    def _on_training_start(self) -> None:
        self.start = (self.model.num_timesteps, self.model.replay_buffer.size())

    def _on_step(self) -> bool:
        return True


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm"])
def test_interrupted_training_resumes_where_it_stopped(tmp_path, how):
    task = "InvertedPendulum-v5"
    recipe = DemonstratorRecipe("SAC", 120, {"learning_starts": 20, "batch_size": 16, "buffer_size": 1000},
                                normalize_observations=True)
    run = dict(out=tmp_path, progress_bar=False, recipe=recipe)
    handler = signal.getsignal(signal.SIGTERM)
    with pytest.raises(KeyboardInterrupt):
        train_demonstrator(task, callback=InterruptAt(70, how), **run)
    assert signal.getsignal(signal.SIGTERM) is handler  # SIGTERM interrupts only while training runs
    state = default_state_dir(get_task(task).group, seed=0)
    saved = json.loads(next(state.glob("steps-*/state.json")).read_text())
    assert saved["num_timesteps"] == 70 and not (tmp_path / "mujoco-invertedpendulum.json").exists()
    [unfinished] = unfinished_runs()
    assert (unfinished.group, unfinished.algorithm, unfinished.steps, unfinished.budget) == (
        "mujoco-invertedpendulum", "SAC", 70, 120)
    assert unfinished.recent_return is not None and unfinished.recent_return > 0 and unfinished.seconds_left() > 0
    listed = CliRunner().invoke(app, ["demonstrator", "runs", "--episodes", "2"])
    assert listed.exit_code == 0 and "mujoco-invertedpendulum" in listed.output and "70 / 120" in listed.output
    assert "deterministic return (2 episodes)" in listed.output and "InvertedPendulum-v5: " in listed.output
    task, returns = evaluate_unfinished_run(unfinished, episodes=2)
    assert task == "InvertedPendulum-v5" and len(returns) == 2 and np.all(returns >= 1)  # whole episodes played
    np.testing.assert_array_equal(evaluate_unfinished_run(unfinished, episodes=2)[1], returns)  # deterministic
    with pytest.raises(VintixError, match="unfinished run with other settings"):
        train_demonstrator(task, out=tmp_path, progress_bar=False,
                           recipe=replace(recipe, hyperparameters={**recipe.hyperparameters, "batch_size": 32}))
    pickled = next(state.glob("steps-*/model.zip"))
    pickled.chmod(pickled.stat().st_mode | stat.S_IWOTH)  # anyone could have swapped in code to unpickle
    with pytest.raises(VintixError, match="model.zip is writable by other users; .* unpickled"):
        train_demonstrator(task, **run)
    with pytest.raises(VintixError, match="writable by other users"):
        evaluate_unfinished_run(unfinished, episodes=1)
    pickled.chmod(pickled.stat().st_mode & ~stat.S_IWOTH)
    saved_file = next(state.glob("steps-*/state.json"))  # as a vintix from before observation_dims saved it:
    saved["plan"]["recipe"].pop("observation_dims")      # a recipe field added since then takes its default
    saved["plan"]["recipe"]["stop_at_score"] = 0.5       # one that says when to stop is not matched
    saved["plan"]["recipe"]["action_noise_std"] = 0.0    # one removed since then resumes where it was unused
    saved_file.write_text(json.dumps(saved))
    started = RecordStart()
    path = train_demonstrator(task, timesteps=150, callback=started, **run)  # a budget only says where to stop
    steps_done, transitions = started.start
    assert steps_done == 70 and 0 < transitions <= 70  # model and replay buffer came back
    meta = json.loads(path.with_suffix(".json").read_text())
    assert (meta["resumed_at"], meta["timesteps"]) == (70, 150) and "obs_normalization" in meta
    assert not state.exists() and unfinished_runs() == []


def pendulum_sac(**fields) -> DemonstratorRecipe:
    """SAC on InvertedPendulum, small enough to train 200 steps in a test."""
    return DemonstratorRecipe("SAC", 200, {"learning_starts": 20, "batch_size": 16, "buffer_size": 1000}, **fields)


def test_a_run_with_a_target_score_stops_at_the_first_check_that_reaches_it(tmp_path):
    task = "InvertedPendulum-v5"
    with pytest.raises(KeyboardInterrupt):
        train_demonstrator(task, out=tmp_path, progress_bar=False, recipe=pendulum_sac(),
                           callback=InterruptAt(70, "ctrl-c"))
    lines = []  # a target decides when to stop, not how to train: the saved run resumes under it
    path = train_demonstrator(task, out=tmp_path, progress_bar=False, recipe=pendulum_sac(stop_at_score=-100.0),
                              report=lines.append)
    meta = json.loads(path.with_suffix(".json").read_text())
    assert (meta["resumed_at"], meta["timesteps"]) == (70, 75)  # checks every 2.5 % of 200 steps: the first at 75
    assert meta["stopped_at_score"]["step"] == 75 and meta["stopped_at_score"]["budget"] == 200
    assert len(lines) == 1 and lines[0].startswith("step 75: InvertedPendulum-v5 ")
    assert unfinished_runs() == []


def test_scoring_along_training_does_not_change_what_it_learns(tmp_path):
    task, lines = "InvertedPendulum-v5", []
    plain = train_demonstrator(task, out=tmp_path / "plain", progress_bar=False, recipe=pendulum_sac())
    scored = train_demonstrator(task, out=tmp_path / "scored", progress_bar=False,
                                recipe=pendulum_sac(stop_at_score=100.0), report=lines.append)
    meta = json.loads(scored.with_suffix(".json").read_text())
    assert len(lines) == 40 and "stopped_at_score" not in meta and meta["short_of_target"]["budget"] == 200
    assert plain.read_bytes() == scored.read_bytes()  # same weights: the checks play their own envs


def test_a_run_that_ends_short_of_its_target_stays_saved_for_a_larger_budget(tmp_path):
    task, lines, started = "InvertedPendulum-v5", [], RecordStart()
    run = dict(out=tmp_path, progress_bar=False, recipe=pendulum_sac(stop_at_score=100.0), report=lines.append)
    train_demonstrator(task, **run)
    [unfinished] = unfinished_runs()
    assert (unfinished.steps, unfinished.budget) == (200, 200) and len(lines) == 40
    assert [check["step"] for check in unfinished.score_checks] == list(range(5, 201, 5))
    listed = CliRunner().invoke(app, ["demonstrator", "runs"])
    assert listed.exit_code == 0 and "40 score checks: last step 200: " in listed.output
    folder, check = best_check(unfinished.folder)  # the best check's policy is kept, and scores as it did
    assert check == max(unfinished.score_checks, key=lambda check: check["normalized"])
    returns = episode_returns(task, load_demonstrator(task, folder), SCORE_EPISODES, SCORE_SEED)
    assert round(float(returns.mean()), 1) == check["mean"] and str(folder) in "".join(listed.output.split())
    scored = CliRunner().invoke(app, ["demonstrator", "eval", "--task", task, "--weights", str(folder),
                                      "--episodes", "2", "--out", str(tmp_path / "scores.csv")])
    assert scored.exit_code == 0 and f"--weights {folder}" in (tmp_path / "scores.csv").read_text()
    refused = CliRunner().invoke(app, ["demonstrator", "eval", "--task", task, "--weights", str(folder),
                                       "--update-package-table"])
    assert refused.exit_code == 2 and "copy its files into the package" in " ".join(refused.output.split())
    path = train_demonstrator(task, timesteps=210, callback=started, **run)
    assert started.start[0] == 200 and len(lines) == 42  # went on, checking at 205 and 210
    meta = json.loads(path.with_suffix(".json").read_text())
    assert (meta["resumed_at"], meta["timesteps"], meta["short_of_target"]["budget"]) == (200, 210, 210)
    assert [check["step"] for check in meta["score_checks"]] == list(range(5, 211, 5))  # the whole curve
    assert meta["short_of_target"]["best_check"]["normalized"] >= check["normalized"]  # compared with the kept one
    assert [run.steps for run in unfinished_runs()] == [210]


class RecordLearningRates(BaseCallback):
    """The optimizer's learning rate at each rollout's start: the one the last update used."""

    def __init__(self):
        super().__init__()
        self.rates = []

    def _on_rollout_start(self) -> None:
        self.rates.append(self.model.policy.optimizer.param_groups[0]["lr"])

    def _on_step(self) -> bool:
        return True


def test_a_learning_rate_that_decays_over_the_budget_ties_a_saved_run_to_that_budget(tmp_path):
    task, rates = "InvertedPendulum-v5", RecordLearningRates()
    recipe = DemonstratorRecipe("PPO", 256, {"n_steps": 32, "batch_size": 32, "n_epochs": 1, "learning_rate": 0.001},
                                normalize_observations=True, normalize_rewards=True, n_envs=2,
                                learning_rate_decay=True, stop_at_score=100.0)
    run = dict(out=tmp_path, progress_bar=False, recipe=recipe)
    with pytest.raises(KeyboardInterrupt):
        train_demonstrator(task, callback=InterruptAt(128, "ctrl-c"), **run)
    with pytest.raises(VintixError, match="unfinished run with other settings"):
        train_demonstrator(task, timesteps=512, **run)  # its schedule would jump
    path = train_demonstrator(task, callback=rates, **run)
    # 64 steps a rollout (2 envs x 32); the update after the one ending at step 192 used 0.001 x (1 - 192/256).
    assert rates.rates == sorted(rates.rates, reverse=True) and rates.rates[-1] == pytest.approx(0.00025)
    meta = json.loads(path.with_suffix(".json").read_text())
    assert (meta["n_envs"], meta["normalize_rewards"], meta["learning_rate_decay"]) == (2, True, True)
    # Short of its target, but a larger budget could not go on from here: nothing is kept.
    assert "state" not in meta["short_of_target"] and unfinished_runs() == []


def test_slow_saves_are_spaced_out_so_they_take_a_small_share_of_training(monkeypatch):
    clock = [0.0]
    monkeypatch.setattr(training.time, "perf_counter", lambda: clock[0])
    saved_at = []

    def save(seconds: float) -> None:
        saved_at.append(clock[0])
        clock[0] += seconds

    for save_seconds, expected in [(0.1, [300.0 + 300.1 * k for k in range(8)]), (20.0, [300.0, 1320.0, 2340.0])]:
        clock[0], saved_at[:] = 0.0, []
        saver = training._SaveEvery(lambda seconds=save_seconds: save(seconds), seconds=300.0, max_share=0.02)
        while clock[0] < 2500:
            saver._on_step()
            clock[0] += 1.0  # a training step
        # Fast saves keep the interval; a 20 s save waits 1,000 s after it, 2 % of the time.
        np.testing.assert_allclose(saved_at, expected)


@pytest.mark.parametrize("task", ["InvertedPendulum-v5", "Swimmer-v5", "Hopper-v5", "industrial-benchmark-40-v1"])
def test_demonstrator_acts_like_sb3_predict(task):
    """PPO (clipped Gaussian mean), PPO behind VecNormalize, SAC (squashed): the numpy forward gives
    SB3's actions up to float32 rounding."""
    demonstrator = load_demonstrator(task)
    assert demonstrator._mlp is not None  # the fast path, not predict
    env = make_env(task, seed=0)
    observations = np.stack([env.reset()[0]] + [np.clip(env.observation_space.sample(), -5, 5) for _ in range(7)])
    expected, _ = demonstrator.policy.predict(demonstrator.policy_input(observations), deterministic=True)
    np.testing.assert_allclose(demonstrator.act(observations, [env] * 8), expected, rtol=1e-5, atol=1e-5)


def test_industrial_benchmark_policy_normalizes_observations_like_its_training():
    demonstrator = load_demonstrator("industrial-benchmark-50-v1")
    assert demonstrator.metadata["env_options"] == {"reward_type": "delta"}
    raw = np.array([[50.0, 40.0, 60.0, 50.0, 30.0, 150.0]], dtype=np.float32)
    scaled = demonstrator.policy_input(raw)
    assert np.all(np.abs(scaled) < 10) and not np.allclose(scaled, raw)


@pytest.mark.parametrize("task, episodes", [
    ("InvertedPendulum-v5", 2), ("InvertedDoublePendulum-v5", 2), ("Swimmer-v5", 2), ("Reacher-v5", 10),
    ("Pusher-v5", 10), ("Hopper-v5", 2), ("HalfCheetah-v5", 2), ("Walker2d-v5", 5), ("Ant-v5", 3),
    ("HumanoidStandup-v5", 5),
    ("industrial-benchmark-35-v1", 3), ("industrial-benchmark-90-v1", 3),
])
def test_shipped_demonstrators_reach_80_percent_of_the_paper_expert(task, episodes):
    returns = episode_returns(task, load_demonstrator(task), episodes)
    assert normalized(task, returns.mean()) >= 0.8


@pytest.mark.parametrize("task", ["Ant-Dir-v5", "HalfCheetah-Vel-v5", "HalfCheetah-Dir-v5"])
def test_a_shipped_goal_aware_expert_goes_where_its_parameter_says(task):
    """A meta-RL task's shipped expert, on envs of other hidden parameters (both directions, four velocities): every
    episode scores most of what its table rows record (scores.csv), so it follows each env's own parameter."""
    seeds = [100, 101, 102, 103]
    assert len({float(make_env(task, seed=seed).unwrapped.true_goal[0]) for seed in seeds}) >= 2
    recorded = {s.policy: s.mean for s in read_scores() if s.task == task}
    returns = episode_returns(task, load_demonstrator(task), len(seeds), seeds[0])
    assert min((returns - recorded["random"]) / (recorded["demonstrator"] - recorded["random"])) > 0.7


def test_every_shipped_demonstrator_records_its_command_and_score():
    scored = {(s.task, s.policy) for s in read_scores()}
    shipped = sorted(shipped_weights_dir().glob("*.json"))
    assert len(shipped) >= 8
    for meta_path in shipped:
        meta = json.loads(meta_path.read_text())
        assert meta["command"].startswith("vintix demonstrator train --task ") and meta["train_seconds"] > 0
        task = meta["command"].split()[4]
        assert (expert_name(get_task(task)), meta["group"]) == (meta_path.stem, meta_path.stem)
        assert {(task, "demonstrator"), (task, "random")} <= scored, f"{task}: run vintix demonstrator eval"


def rewrite_json(name, change):
    """A damage to the weights folder: `change(metadata) -> metadata` applied to `name`.json."""
    def damage(folder):
        path = folder / f"{name}.json"
        path.write_text(json.dumps(change(json.loads(path.read_text()))))
    return damage


@pytest.mark.parametrize(("damage", "message"), [
    (lambda f: (f / "mujoco-reacher.json").write_text("{"), "mujoco-reacher.json: not valid JSON"),
    (lambda f: (f / "mujoco-reacher.json").write_text("[]"), "mujoco-reacher.json: expected a JSON object, got list"),
    (rewrite_json("mujoco-reacher", lambda m: {**m, "algorithm": "DQN"}), "algorithm 'DQN' is not one of PPO, SAC"),
    (rewrite_json("mujoco-reacher", lambda m: {**m, "policy_kwargs": {"net_arch": [10**9]}}),
     r"net_arch \[1000000000\] has layer widths that no tensor"),
    (lambda f: (f / "mujoco-reacher.safetensors").write_bytes((f / "mujoco-reacher.safetensors").read_bytes()[:100]),
     "mujoco-reacher.safetensors: not a readable safetensors file"),
    (lambda f: (f / "mujoco-reacher.safetensors").write_bytes((f / "mujoco-pusher.safetensors").read_bytes()),
     "does not fit the .* policy that mujoco-reacher.json describes"),
])
def test_damaged_demonstrator_weights_are_named_errors(tmp_path, damage, message):
    for name in ("mujoco-reacher", "mujoco-pusher"):
        for suffix in (".json", ".safetensors"):
            shutil.copy(shipped_weights_dir() / f"{name}{suffix}", tmp_path)
    damage(tmp_path)
    with pytest.raises(VintixError, match=message):
        load_demonstrator("Reacher-v5", tmp_path)
    result = CliRunner().invoke(app, ["demonstrator", "eval", "--task", "Reacher-v5", "--weights", str(tmp_path),
                                      "--episodes", "1", "--out", str(tmp_path / "scores.csv")])
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output


def test_task_without_shipped_weights_names_the_command_that_trains_them(without_shipped_weights):
    with pytest.raises(VintixError, match="vintix demonstrator train --task Hopper-v5"):
        load_demonstrator("Hopper-v5")


def test_metaworld_has_no_training_recipe_nor_trained_weights_to_load(tmp_path):
    with pytest.raises(VintixError, match="scripted"):
        recipe_for("reach-v3")
    with pytest.raises(VintixError, match="leave the weights out"):
        load_demonstrator("reach-v3", tmp_path)


def end_distances(task: str, demonstrator, seeds: range) -> np.ndarray:
    """The env's `obj_to_target` at the end of one episode per env seed (reach: the gripper centre to the goal)."""
    envs = [make_env(task, seed=seed) for seed in seeds]
    observations = np.stack([env.reset()[0] for env in envs])
    for _ in range(100):
        actions = demonstrator.act(observations, envs)
        steps = [env.step(action) for env, action in zip(envs, actions, strict=True)]
        observations = np.stack([step[0] for step in steps])
    return np.array([step[4]["obj_to_target"] for step in steps])


def test_a_reach_expert_aiming_its_gripper_centre_puts_it_on_the_goal_where_meta_worlds_leaves_it_4_cm_off():
    seeds = range(100, 105)
    hand_aimed = end_distances("reach-v3", load_demonstrator("reach-v3"), seeds)
    assert np.all((hand_aimed > 0.03) & (hand_aimed < 0.05))  # the hand is on the goal
    assert np.all(end_distances("reach-v3", load_demonstrator("reach-v3", aim="gripper-centre"), seeds) < 0.01)
    with pytest.raises(VintixError, match="unknown aim 'elbow'"):
        load_demonstrator("reach-v3", aim="elbow")
    with pytest.raises(VintixError, match="push-v3.*aim 'gripper-centre' is for"):
        load_demonstrator("push-v3", behaviour="probing", aim="gripper-centre")  # its goal is the puck's


def test_random_policy_scores_below_the_demonstrator_and_table_round_trips(tmp_path):
    table = tmp_path / "scores.csv"
    expert = measure("reach-v3", "demonstrator", load_demonstrator("reach-v3"), 3, 0, "cmd")
    random = measure("reach-v3", "random", UniformRandomPolicy(), 3, 0, "cmd")
    assert expert.mean > 2 * random.mean
    assert our_reference_scores("reach-v3", table) is None
    record_scores([expert], table)
    assert our_reference_scores("reach-v3", table) is None  # random missing: no half reference
    record_scores([random, replace(expert, mean=1.0)], table)
    assert read_scores(table) == [replace(expert, mean=1.0), random]
    random_ref, expert_ref = our_reference_scores("reach-v2", table)  # aliases resolve
    assert (random_ref.mean, expert_ref.mean) == (random.mean, 1.0) and "3 episodes" in expert_ref.provenance


def test_collection_with_a_trained_demonstrator_rises(tmp_path):
    plan = CollectionPlan("industrial-benchmark-35-v1", histories=1, steps=5000,
                          schedule=NoiseSchedule(noise_free_fraction=0.1))
    [summary] = collect(plan, tmp_path)
    returns = summary.episode_returns
    assert len(returns) == 20
    assert spearmanr(np.arange(len(returns)), returns).statistic >= 0.8
    assert normalized(plan.task, summary.mean_return(first=False)) >= 0.8


def test_demonstrator_eval_writes_to_the_users_folder_and_leaves_the_package_table_alone(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from vintix.cli import app
    from vintix.tasks import scores

    package_table = tmp_path / "package" / "scores.csv"  # a stand-in, so this test never touches the real one
    package_table.parent.mkdir()
    package_table.write_bytes(scores.scores_path().read_bytes())
    monkeypatch.setattr(scores, "scores_path", lambda: package_table)
    monkeypatch.chdir(tmp_path)
    before = package_table.read_bytes()
    (tmp_path / "before.csv").write_bytes(before)
    command = ["demonstrator", "eval", "--task", "reach-v3", "--episodes", "1"]
    result = CliRunner().invoke(app, command)
    assert result.exit_code == 0, result.output
    assert package_table.read_bytes() == before
    assert [(s.task, s.policy, s.episodes) for s in read_scores(tmp_path / "demonstrator-scores.csv")] == [
        ("reach-v3", "demonstrator", 1), ("reach-v3", "random", 1)]
    assert "demonstrator-scores.csv" in result.output
    asked = CliRunner().invoke(app, [*command, "--out", str(tmp_path / "mine.csv"), "--update-package-table"])
    assert asked.exit_code == 0, asked.output
    rows = {(s.task, s.policy): s.episodes for s in read_scores(package_table)}
    assert rows[("reach-v3", "demonstrator")] == rows[("reach-v3", "random")] == 1  # asked for: replaced
    assert len(rows) == len(read_scores(tmp_path / "before.csv"))
    assert str(package_table) in " ".join(asked.output.split())


def test_training_writes_to_the_users_folder_and_a_recipe_can_collect_with_those_weights(tmp_path):
    from vintix.demonstrators.base import external_demonstrator
    from vintix.demonstrators.trained import shipped_weights_dir
    from vintix.demonstrators.training import trained_weights_dir

    assert trained_weights_dir() == tmp_path / "user-cache" / "vintix" / "demonstrators"  # never the package
    demonstrator = external_demonstrator("InvertedPendulum-v5", f"weights:{shipped_weights_dir()}")
    env = make_env("InvertedPendulum-v5", seed=0)
    obs, _ = env.reset()
    assert demonstrator.act(obs[None], [env]).shape == (1, 1)


class CallLog:
    """A user-written demonstrator that reads its rewards (docs/demonstrators.md's protocol): it writes down every
    call the collector makes, and plays the Dark Room goal-blind, moving right until a reward, then staying."""

    def __init__(self):
        self.calls: list[tuple] = []

    def begin(self, envs, rngs):
        self.calls.append(("begin", len(envs)))
        self.paid = [False] * len(envs)

    def act(self, observations, envs):
        self.calls.append(("act", observations.copy()))
        return np.array([0 if paid else 4 for paid in self.paid])

    def observe(self, env_index, env, action, reward, episode_end):
        self.calls.append(("observe", env_index, int(action), reward, episode_end, tuple(env.unwrapped.true_goal)))
        self.paid[env_index] |= reward > 0

    def expert_act(self, observations, envs):
        actions = np.array([env.unwrapped.expert_action() for env in envs])
        self.calls.append(("expert_act", actions))
        return actions


def test_a_reward_reading_demonstrator_is_told_each_step_in_the_documented_order(tmp_path):
    """The protocol of docs/demonstrators.md, driven through collect: begin once per batch; then per step act (on
    the observations), expert_act (the recorded target), and per env observe(index, env, executed action, reward,
    episode end) right after its step, before the env resets; resets keep the history's hidden goal."""
    demonstrator = CallLog()
    plan = CollectionPlan("DarkRoom-v0", histories=2, steps=40, schedule=NoiseSchedule(noise_free_fraction=1.0),
                          envs_per_batch=2)
    collect(plan, tmp_path, demonstrator=demonstrator)
    kinds = [call[0] for call in demonstrator.calls]
    assert kinds == ["begin"] + ["act", "expert_act", "observe", "observe"] * 40
    assert demonstrator.calls[0] == ("begin", 2)
    observed = [call for call in demonstrator.calls if call[0] == "observe"]
    assert [call[1] for call in observed] == [0, 1] * 40
    assert [call[4] for call in observed[::2]] == ([False] * 19 + [True]) * 2  # the 20-step episodes' ends
    targets = [call[1] for call in demonstrator.calls if call[0] == "expert_act"]
    for index, path in enumerate(sorted(tmp_path.rglob("history-*.h5"))):
        history = LearningHistory(path)
        rows = history.read(0, history.num_steps, demonstrator_action=True)
        mine = observed[index::2]
        assert [call[2] for call in mine] == rows["action"].tolist()  # the executed actions, as stored
        assert [call[3] for call in mine] == rows["reward"].tolist()  # the rewards, as stored
        assert [t[index] for t in targets] == rows["demonstrator_action"].tolist()  # expert_act: the target
        assert len({call[5] for call in mine}) == 1  # the env's reset after an episode keeps its hidden goal


def call_log(task):
    """`CallLog` as a recipe or `--demonstrator` names a demonstrator: a callable of the task name."""
    return CallLog()


def test_the_cli_checks_a_users_own_demonstrator_per_episode_and_refuses_one_that_cannot_be_aimed():
    result = CliRunner().invoke(app, ["demonstrator", "histories", "--task", "DarkRoom-v0", "--demonstrator",
                                      "test_demonstrators:call_log", "--seeds", "3", "--episodes", "2"])
    assert result.exit_code == 0, result.output
    assert "test_demonstrators:call_log: 3 histories" in " ".join(result.output.split())
    refused = CliRunner().invoke(app, ["demonstrator", "goal-blind", "--task", "DarkRoom-v0", "--demonstrator",
                                       "test_demonstrators:call_log"])
    assert refused.exit_code == 2 and "has no act_toward(observations, goals)" in " ".join(refused.output.split())


def test_a_meta_rl_tasks_goal_aware_expert_trains_under_its_own_name_and_aims_where_it_is_told(tmp_path):
    """A meta-RL task's expert observes the hidden parameter: trained (briefly) under the task's own name, it acts on
    the env's true parameter, aims at any parameter it is given (`act_toward`), and a goal-inferring demonstrator
    plays it from the rewards alone."""
    from vintix.demonstrators.posterior import GoalInferringDemonstrator
    from vintix.demonstrators.scores import history_outcomes

    task = "HalfCheetah-Vel-v5"
    path = train_demonstrator(task, timesteps=300, out=tmp_path, state_dir=tmp_path / "state", progress_bar=False)
    assert path == tmp_path / "halfcheetah-vel.safetensors"
    assert json.loads(path.with_suffix(".json").read_text())["group"] == "halfcheetah-vel"
    expert = load_demonstrator(task, tmp_path)
    envs = [make_env(task, seed=seed) for seed in (1, 2)]
    observations = np.stack([env.reset()[0] for env in envs])
    goals = np.stack([env.unwrapped.true_goal for env in envs])
    np.testing.assert_allclose(expert.act(observations, envs), expert.act_toward(observations, goals), atol=1e-6)
    assert not np.allclose(expert.act_toward(observations, np.zeros((2, 1))),
                           expert.act_toward(observations, np.full((2, 1), 3.0)))
    inferring = load_demonstrator(task, tmp_path, behaviour="probe-then-sample")
    assert isinstance(inferring, GoalInferringDemonstrator)
    outcomes = history_outcomes(task, inferring, [100, 101], episodes=2)
    assert outcomes.returns.shape == (2, 2) and np.isfinite(outcomes.returns).all()


# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

# Demonstrators
cli_error("demonstrator", "eval an unknown task", ["demonstrator", "eval", "--task", "reech-v3"], "Did you mean")


@once
def weights_with_an_unknown_policy_kwarg() -> Path:
    """The shipped Hopper weights, their JSON's policy_kwargs given a keyword no SB3 policy takes."""
    from vintix.demonstrators.trained import shipped_weights_dir

    folder = work() / "weights-odd-kwarg"
    folder.mkdir()
    for suffix in ("json", "safetensors"):
        shutil.copy(shipped_weights_dir() / f"mujoco-hopper.{suffix}", folder)
    meta = json.loads((folder / "mujoco-hopper.json").read_text())
    meta["policy_kwargs"]["bogus_width"] = 3
    (folder / "mujoco-hopper.json").write_text(json.dumps(meta))
    return folder


cli_error("demonstrator", "eval with --weights whose policy_kwargs hold a keyword the policy does not take",
          lambda: ["demonstrator", "eval", "--task", "Hopper-v5", "--episodes", "1", "--weights",
                   weights_with_an_unknown_policy_kwarg(), "--out", work() / "scores-odd.csv"], "bogus_width")
cli_error("demonstrator", "eval a task without weights", ["demonstrator", "eval", "--task", "Humanoid-v5"],
          "no trained demonstrator")
cli_error("demonstrator", "eval with 0 episodes", ["demonstrator", "eval", "--task", "reach-v3", "--episodes", "0"],
          "--episodes")
cli_error("demonstrator", "eval only Bi-DexHands tasks", lambda: ["demonstrator", "eval", "--task", "Hand-Pen",
                                                                  "--out", work() / "d.csv"], "IsaacGym",
          after=not_written(lambda: work() / "d.csv"))
cli_error("demonstrator", "train a Meta-World task (scripted)", ["demonstrator", "train", "--task", "reach-v3"],
          "scripted")
cli_error("demonstrator", "train an unknown task", ["demonstrator", "train", "--task", "reech-v3"], "Did you mean")
cli_error("demonstrator", "train with 0 timesteps", lambda: ["demonstrator", "train", "--task", "InvertedPendulum-v5",
                                                            "--timesteps", "0", "--out", work() / "dw"], "--timesteps")


def package_table_untouched() -> str | None:
    from vintix.tasks.scores import scores_path

    before = scores_path().read_bytes()
    cwd = os.getcwd()
    os.chdir(work())
    try:
        code, output = invoke("demonstrator", "eval", "--task", "reach-v3", "--episodes", "1")
    finally:
        os.chdir(cwd)
    ok = code == 0 and scores_path().read_bytes() == before and (work() / "demonstrator-scores.csv").is_file()
    return None if ok else f"exit {code}, package table changed: {scores_path().read_bytes() != before}"


documented("demonstrator", "eval leaves the package's score table alone", package_table_untouched)
cli_error("demonstrator", "eval --out under a file (before measuring)", lambda: [
    "demonstrator", "eval", "--task", "reach-v3", "--episodes", "1", "--out", file_at("demo-file", "x")() / "s.csv"],
    "is a file, not a directory")
cli_error("demonstrator", "eval --out a directory", lambda: [
    "demonstrator", "eval", "--task", "reach-v3", "--episodes", "1", "--out", empty_dir("scores-dir")()],
    "it is a directory")
# A file of another kind where the scores go (issue 71's red team: an eval's episodes.csv was a KeyError at the end).
cli_error("demonstrator", "eval --out a file that is not a score table", lambda: [
    "demonstrator", "eval", "--task", "point-goal-v1", "--episodes", "1", "--out",
    file_at("scores-foreign", "task,shot,return\nreach-v3,1,0.5\n")()], "not a score table")


test_bad_input_ends_as_expected = bad_input_test("demonstrator")
