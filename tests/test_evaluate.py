"""Evaluation: a real cold-start eval through the CLI, normalization edge cases, task selection,
prompts, the reward-use ablation, the training callback, and clear errors."""

from __future__ import annotations

import csv
import json
import shutil
from collections.abc import Callable

import h5py
import numpy as np
import pytest
from gymnasium.wrappers import RecordEpisodeStatistics
from typer.testing import CliRunner

from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    CHECKPOINTS,
    DEEP_JSON,
    RUNS,
    api_error,
    bad_input_test,
    clean_data,
    cli_error,
    collected,
    damaged_checkpoint,
    empty_dir,
    file_at,
    missing,
    model_checkpoint,
    not_written,
    work,
    workspace,
)
from inference_model import one_torch_thread, tiny_model  # noqa: F401  (autouse fixture)
from vintix.agent import Agent
from vintix.cli import app
from vintix.collect import CollectionPlan, NoiseSchedule, collect
from vintix.data import LearningHistory, LearningHistoryWriter, task_directory, write_task_metadata
from vintix.errors import UnknownTaskError, VintixError
from vintix.evaluate import (
    EvalConfig,
    EvalConfigError,
    Reference,
    ReferenceScoreError,
    evaluate,
    evaluate_shots,
    in_context_score,
    in_context_scorer,
    ml1_success,
    parse_variation,
    reference,
    select_tasks,
    shots_to_show,
)
from vintix.evaluate.run import RewardFeed, other_goal, other_goal_reward, play_shots
from vintix.model import save_pretrained
from vintix.tasks import make_env
from vintix.train import ConfigError, TrainConfig


def test_cold_start_eval_on_real_envs_writes_every_episode(tmp_path):
    save_pretrained(tiny_model(), tmp_path / "ckpt")
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tmp_path / "ckpt"), "--tasks",
                                      "reach-v3,InvertedPendulum-v5", "--shots", "2", "--seeds", "2",
                                      "--out", str(tmp_path / "results")])
    assert result.exit_code == 0, result.output
    assert "wrote 8 episodes" in result.output
    # Off a terminal (a log file; here the runner's capture) tqdm's bars are off: a line per batch says it is alive.
    assert "1/1 batches of runs done" in result.output
    # The per-shot table: one row per domain, a column per shot.
    assert "at each shot" in result.output and "metaworld train" in result.output and "shot 2" in result.output
    # Meta-World's success rate beside its score, in both tables; MuJoCo has no success flag.
    assert "success shot 1" in result.output and "success rate" in result.output
    rows = list(csv.DictReader((tmp_path / "results" / "episodes.csv").open()))
    assert sorted({(r["task"], r["seed"], r["shot"]) for r in rows}) == sorted(
        (t, s, k) for t in ("reach-v3", "InvertedPendulum-v5") for s in "01" for k in "12")
    for row in rows:
        for table in ("paper", "ours"):
            ref = reference(row["task"], table)
            if ref is None:  # the package's score table has not measured this task: empty, and said so
                assert row[f"normalized_{table}"] == "" and f"no '{table}' reference score" in result.output
            else:
                expected = (float(row["return"]) - ref.random) / (ref.expert - ref.random)
                assert float(row[f"normalized_{table}"]) == pytest.approx(expected)
    assert {r["reward_input"] for r in rows} == {"true"}
    reach = [r for r in rows if r["task"] == "reach-v3"]
    assert {r["length"] for r in reach} == {"100"} and {r["success"] for r in reach} <= {"0.0", "1.0"}
    # different seeds are different hidden goals, so different returns
    assert len({r["return"] for r in reach if r["shot"] == "1"}) == 2
    run = json.loads((tmp_path / "results" / "run.json").read_text())
    assert run["label"] == "ckpt" and "one hidden goal" in run["goal_protocol"]


def test_evaluate_shots_returns_what_vintix_eval_writes_per_seed_and_shot(tmp_path):
    """The Python helper (SB3's evaluate_policy habit) plays the same runs as `vintix eval`: same returns, success
    and scores, as [seeds, shots] arrays."""
    save_pretrained(tiny_model(), tmp_path / "ckpt")
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tmp_path / "ckpt"), "--tasks", "reach-v3",
                                      "--shots", "3", "--seeds", "2", "--first-seed", "7",
                                      "--out", str(tmp_path / "results")])
    assert result.exit_code == 0, result.output
    runs = evaluate_shots(Agent.from_pretrained(tmp_path / "ckpt"), "reach-v3", shots=3, seeds=2, first_seed=7)
    assert runs.task == "reach-v3" and runs.seeds == [7, 8] and runs.returns.shape == (2, 3)
    for row in csv.DictReader((tmp_path / "results" / "episodes.csv").open()):
        i, j = runs.seeds.index(int(row["seed"])), int(row["shot"]) - 1
        assert runs.returns[i, j] == pytest.approx(float(row["return"]))
        assert runs.success[i, j] == float(row["success"])
        assert runs.scores[i, j] == pytest.approx(float(row["normalized_ours"]))
    assert runs.per_shot("success").shape == (3,)
    with pytest.raises(UnknownTaskError, match="Hopper"):
        evaluate_shots(Agent.from_pretrained(tmp_path / "ckpt"), "Hopper-v5", shots=1, seeds=1)


@pytest.mark.parametrize(("option", "message"), [
    (["--shots", "0"], "shots=0"), (["--seeds", "0"], "seeds=0"), (["--seeds", "-1"], "seeds=-1"),
    (["--batch-envs", "0"], "batch_envs=0"), (["--first-seed", "-1"], "first_seed=-1"),
    (["--prompt-steps", "-5"], "prompt_steps=-5"), (["--threads", "0"], "Invalid value for '--threads'"),
    (["--reference", "bogus"], "unknown reference table 'bogus'"), (["--device", "tpu"], "device 'tpu'"),
    (["--variation", "viscosity=nan"], "variation"),
    (["--reward-input", "none"], "reward_input 'none' is unknown; choose one of 'true', 'zero', 'shuffled'"),
    (["--ml1", "--shots", "5"], "scored episodes, so shots must be 13, not 5"),
    (["--ml1", "--first-seed", "48", "--seeds", "3"], "goes past them"),
])
def test_eval_settings_out_of_range_are_named_before_any_env_runs(tmp_path, option, message):
    save_pretrained(tiny_model(), tmp_path / "ckpt")
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tmp_path / "ckpt"), "--tasks", "reach-v3",
                                      "--out", str(tmp_path / "results"), *option])
    assert result.exit_code == 2 and not isinstance(result.exception, Exception), result.output  # no traceback
    assert message in " ".join(result.output.split())
    assert not (tmp_path / "results").exists()


def test_ml1_plays_metaworlds_test_goals_and_scores_the_three_episodes_after_ten(tmp_path):
    save_pretrained(tiny_model(), tmp_path / "ckpt")
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tmp_path / "ckpt"), "--tasks", "reach-v3", "--ml1",
                                      "--seeds", "2", "--first-seed", "5", "--out", str(tmp_path / "results")])
    assert result.exit_code == 0, result.output
    assert "Meta-World ML1 meta-test" in result.output and "wrote 26 episodes" in result.output  # 13 per run
    rows = list(csv.DictReader((tmp_path / "results" / "episodes.csv").open()))
    assert {(r["seed"], r["shot"]) for r in rows} == {(s, str(k)) for s in ("5", "6") for k in range(1, 14)}
    run = json.loads((tmp_path / "results" / "run.json").read_text())
    assert "ML1 meta-test" in run["goal_protocol"] and run["config"]["ml1"]
    # Runs 5 and 6 play ML1's test goals 5 and 6: the same goal as an env that was told it directly.
    env = make_env("reach-v3", seed=5)
    env.unwrapped.use_ml1_test_goal(5)
    runs = evaluate_shots(Agent.from_pretrained(tmp_path / "ckpt"), "reach-v3", shots=1, seeds=1, first_seed=5)
    ml1_first = next(r for r in rows if r["seed"] == "5" and r["shot"] == "1")
    assert float(ml1_first["return"]) != pytest.approx(runs.returns[0, 0])  # not the goal seed 5 draws
    # A task that is not Meta-World's is refused, by name.
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tmp_path / "ckpt"), "--tasks", "InvertedPendulum-v5",
                                      "--ml1", "--seeds", "1", "--out", str(tmp_path / "pendulum")])
    assert result.exit_code == 2 and "not InvertedPendulum-v5" in " ".join(result.output.split())


def test_ml1_success_is_the_mean_over_goals_of_the_scored_episodes():
    rows = [{"task": "reach-v3", "seed": seed, "shot": shot, "success": float(shot > 10 if seed else shot == 12)}
            for seed in (0, 1) for shot in range(1, 14)]
    (summary,) = ml1_success(rows)
    assert summary["goals"] == 2 and summary["success"] == pytest.approx((1 / 3 + 1) / 2)
    assert summary["adaptation_first"] == 0 and summary["adaptation_last"] == 0
    assert summary["low"] <= summary["success"] <= summary["high"]


def test_an_unwritable_out_is_named_before_the_run_not_after(tmp_path, monkeypatch):
    save_pretrained(tiny_model(), tmp_path / "ckpt")
    (tmp_path / "a-file").write_text("x")

    def no_env_yet(*args, **kwargs):
        raise AssertionError("the evaluation made an env before it checked where its results go")

    monkeypatch.setattr("vintix.evaluate.run.make_env", no_env_yet)  # a tripwire: the check comes first
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tmp_path / "ckpt"), "--tasks", "reach-v3",
                                      "--shots", "50", "--out", str(tmp_path / "a-file" / "results")])
    assert result.exit_code == 2 and "a-file is a file, not a directory" in " ".join(result.output.split())


def test_eval_config_checks_types_and_ranges_in_python_too():
    with pytest.raises(EvalConfigError, match="shots=0"):
        EvalConfig(shots=0)
    with pytest.raises(EvalConfigError, match="EvalConfig.seeds must be int, got '3'"):
        EvalConfig(seeds="3")
    with pytest.raises(EvalConfigError, match="no tasks to evaluate"):
        EvalConfig(tasks=[",", ""])
    with pytest.raises(EvalConfigError,
                       match="reward_input 'masked' is unknown; choose one of 'true', 'zero', 'shuffled'"):
        EvalConfig(reward_input="masked")


def test_normalization_formula_and_expert_not_above_random_raises():
    ref = Reference(random=10.0, expert=110.0, provenance="test")
    np.testing.assert_allclose(ref.normalize([10.0, 60.0, 110.0, 160.0]), [0.0, 0.5, 1.0, 1.5])
    for expert in (10.0, 5.0):
        with pytest.raises(ReferenceScoreError, match="not above random"):
            Reference(random=10.0, expert=expert, provenance="test")
    with pytest.raises(ValueError, match="unknown reference table"):
        reference("reach-v3", "jat")


def test_domains_and_splits_keep_the_checkpoints_groups_but_a_named_foreign_task_is_an_error():
    specs, notes = select_tasks(["metaworld,InvertedPendulum-v5"], ["metaworld", "mujoco-invertedpendulum"])
    assert len(specs) == 51 and not notes
    specs, notes = select_tasks(["test"], ["metaworld"])  # held-out: ML45 test tasks of the checkpoint's group
    assert sorted(s.name for s in specs) == ["bin-picking-v3", "box-close-v3", "door-lock-v3", "door-unlock-v3",
                                             "hand-insert-v3"]
    assert "industrial-benchmark-80-v1" in notes[0]
    with pytest.raises(UnknownTaskError, match="industrial_benchmark"):
        select_tasks(["reach-v3", "industrial-benchmark-90-v1"], ["metaworld"])
    with pytest.raises(UnknownTaskError, match="reach"):
        select_tasks(["reach-v9"], ["metaworld"])


def test_a_variation_only_applies_where_the_env_has_it():
    assert parse_variation(["viscosity=0.05", "gravity_scale=1.1"]) == {"viscosity": 0.05, "gravity_scale": 1.1}
    with pytest.raises(VintixError, match="NAME=NUMBER"):
        parse_variation(["viscosity"])
    agent = Agent(tiny_model())
    rows, _ = evaluate(agent, EvalConfig(tasks=["InvertedPendulum-v5"], shots=1, seeds=1, variation={"viscosity": 0.1}))
    assert rows[0]["variation"] == "viscosity=0.1"
    with pytest.raises(VintixError, match="viscosity"):
        evaluate(agent, EvalConfig(tasks=["reach-v3"], shots=1, seeds=1, variation={"viscosity": 0.1}))


def test_a_prompted_run_starts_after_the_stored_steps_on_the_prompting_historys_goal(tmp_path):
    collect([CollectionPlan("reach-v3", 2, 300, NoiseSchedule(1.0, 0.05), 0, 2)], tmp_path / "data")
    histories = sorted((tmp_path / "data" / "metaworld" / "reach-v3").glob("*.h5"))
    agent = Agent(tiny_model())
    config = EvalConfig(tasks=["reach-v3"], shots=1, seeds=2, prompt_from=tmp_path / "data", prompt_steps=12)
    rows, _ = evaluate(agent, config)
    assert [r["prompt_steps"] for r in rows] == [12, 12]
    assert agent.steps == 12 + 100  # the prompt, then one 100-step episode
    # Run i plays on history i's env, so its hidden goal is the one the prompt's rewards point to.
    seeds = [LearningHistory(path).env_seed for path in histories]
    assert [r["seed"] for r in rows] == seeds and len(set(seeds)) == 2
    with pytest.raises(VintixError, match="has 2 histories, but prompting run 3"):
        evaluate(agent, EvalConfig(tasks=["reach-v3"], shots=1, seeds=3, prompt_from=tmp_path / "data"))
    with pytest.raises(VintixError, match="no learning history of push-v3"):
        evaluate(agent, EvalConfig(tasks=["push-v3"], shots=1, seeds=1, prompt_from=tmp_path / "data"))


def test_a_meta_world_history_without_its_env_seed_cannot_prompt(tmp_path):
    """Published files do not say their goal: prompting with one would chase another goal."""
    folder = task_directory(tmp_path / "data", "metaworld", "reach-v3")
    write_task_metadata(folder, "reach-v3", 39, 4)
    with LearningHistoryWriter(folder / "history-0000.h5", 39, 4) as writer:
        writer.append(np.zeros((20, 39)), np.zeros((20, 4)), np.zeros(20), np.arange(20))
    with pytest.raises(VintixError, match="hidden goal is unknown"):
        evaluate(Agent(tiny_model()), EvalConfig(tasks=["reach-v3"], shots=1, seeds=1, prompt_from=tmp_path / "data",
                                                 prompt_steps=10))


def test_a_feed_tells_the_model_zeros_or_the_episodes_own_rewards_out_of_order():
    rewards = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert [RewardFeed("true", 0)(r) for r in rewards] == rewards
    assert [RewardFeed("zero", 0)(r) for r in rewards] == [0.0] * 6
    shuffled = RewardFeed("shuffled", 0)
    fed = [shuffled(r) for r in rewards]
    # Each step: one of the rewards the episode has returned so far (the first step has only its own).
    assert fed[0] == 1.0 and all(f in rewards[: i + 1] for i, f in enumerate(fed)) and fed != rewards
    again = RewardFeed("shuffled", 0)
    assert [again(r) for r in rewards] == fed  # seeded by the env seed: reproducible
    shuffled.new_episode()
    assert shuffled(7.0) == 7.0  # a new episode draws from its own rewards only


def test_an_other_goal_feed_tells_the_model_what_each_step_would_earn_under_another_seeds_goal():
    """Rewards as consistent as the true ones, pointing elsewhere: a direction task's feed is the other direction's
    reward, HalfCheetah-Vel's another seed's target speed's, to the episode's last step (priced before a reset)."""
    env = make_env("HalfCheetah-Dir-v5", seed=100)
    assert other_goal("HalfCheetah-Dir-v5", 100, env)[0] == -env.unwrapped.true_goal[0]
    for task in ("HalfCheetah-Dir-v5", "HalfCheetah-Vel-v5"):
        env = make_env(task, seed=100)
        other = float(other_goal(task, 100, env)[0])
        assert other == float(make_env(task, seed=101).unwrapped.true_goal[0]) != env.unwrapped.true_goal[0]
        feed = RewardFeed("other-goal", 100, other_goal_reward(task, 100, env))
        env.reset()
        for action in np.random.default_rng(0).uniform(-1, 1, (200, 6)):
            _, reward, terminated, truncated, info = env.step(action)
            fed = feed(reward, action)
            velocity = info["x_velocity"]
            earned = other * velocity if task == "HalfCheetah-Dir-v5" else -abs(velocity - other)
            assert fed == pytest.approx(earned + info["reward_ctrl"]) and fed != reward
        assert truncated
    agent = Agent(tiny_model(("point-goal-v1",)))
    rows, _ = evaluate(agent, EvalConfig(tasks=["point-goal-v1"], shots=2, seeds=2, reward_input="other-goal"))
    assert {r["reward_input"] for r in rows} == {"other-goal"} and len(rows) == 4
    with pytest.raises(VintixError, match="InvertedPendulum-v5: reward_input 'other-goal'.*use 'zero' or 'shuffled'"):
        evaluate(Agent(tiny_model()), EvalConfig(tasks=["InvertedPendulum-v5"], shots=1, seeds=1,
                                                 reward_input="other-goal"))


def test_zero_and_shuffled_rewards_change_what_the_model_sees_but_returns_stay_the_envs():
    agent = Agent(tiny_model())

    def returns(reward_input: str) -> list[float]:
        rows, _ = evaluate(agent, EvalConfig(tasks=["reach-v3"], shots=2, seeds=1, reward_input=reward_input))
        assert {r["reward_input"] for r in rows} == {reward_input}
        return [r["return"] for r in rows]

    true, zero, shuffled = returns("true"), returns("zero"), returns("shuffled")
    assert zero != true and shuffled != true  # other rewards fed back: other actions, other episodes
    assert returns("shuffled") == shuffled
    # What is recorded is what the env paid, not what the model was fed (zeros would sum to 0).
    env = RecordEpisodeStatistics(make_env("reach-v3", seed=0))
    agent.reset(["reach-v3"], [env.action_space], discard_context=True)
    episodes = play_shots(agent, [env], [RewardFeed("zero", 0)], shots=2)
    assert [e.episode_return for e in episodes[0]] == pytest.approx(list(env.return_queue)) == zero
    assert min(zero) > 10  # reach-v3 pays a dense positive reward every step


def test_selection_by_success_needs_a_task_with_a_success_flag_and_measures_the_reward_use_gap():
    model = tiny_model()
    assert 0.0 <= in_context_score(model, ["reach-v3"], shots=2, seeds=1, metric="success") <= 1.0
    with pytest.raises(ConfigError,
                       match=r"none of \['InvertedPendulum-v5'\] has a success flag.*select_metric 'score'"):
        in_context_score(model, ["InvertedPendulum-v5"], shots=2, seeds=1, metric="success")
    config = TrainConfig(select_every=10, select_shots=2, select_seeds=2)
    selection = in_context_scorer(config)(model, ["InvertedPendulum-v5"])
    zero = in_context_score(model, ["InvertedPendulum-v5"], shots=2, seeds=2, first_seed=1000, reward_input="zero")
    assert selection.reward_use_gap == pytest.approx(selection.score - zero)
    unmeasured = in_context_scorer(TrainConfig(select_every=10, select_shots=2, select_seeds=2,
                                               select_reward_gap=False))
    assert np.isnan(unmeasured(model, ["InvertedPendulum-v5"]).reward_use_gap)


def test_in_context_score_is_a_training_callback_that_restores_train_mode():
    model = tiny_model().train()
    score = in_context_score(model, ["InvertedPendulum-v5"], shots=2, seeds=2)
    assert model.training and np.isfinite(score) and -1.0 < score < 1.0


def test_the_console_names_tasks_whole_says_which_shots_it_shows_and_compares_like_with_like(tmp_path):
    """Full task names, the shots a per-shot table skips said, the paper's Vintix scores only beside scores
    normalized by the paper's table, and no hidden-goal protocol recorded for tasks that hide nothing."""
    save_pretrained(tiny_model(("InvertedPendulum-v5", "industrial-benchmark-30-v1")), tmp_path / "ckpt")
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(tmp_path / "ckpt"), "--tasks",
                                      "industrial-benchmark-30-v1", "--shots", "13", "--seeds", "1",
                                      "--reference", "ours", "--out", str(tmp_path / "results")])
    assert result.exit_code == 0, result.output
    assert "industrial-benchmark-30-v1" in result.output and "paper's Vintix" not in result.output
    assert f"at shots {', '.join(map(str, shots_to_show(13)))} of 13" in result.output
    assert "goal_protocol" not in json.loads((tmp_path / "results" / "run.json").read_text())


def test_the_per_shot_table_shows_every_shot_or_a_spread_that_keeps_the_first_and_last():
    assert shots_to_show(10) == list(range(1, 11))
    many = shots_to_show(100)
    assert many[:3] == [1, 2, 3] and many[-1] == 100 and len(many) <= 12 and many == sorted(set(many))


@pytest.mark.parametrize("model", ["darkroom", "gaussian"])
def test_a_sampled_seed_plays_the_same_alone_in_a_batch_and_through_predict(model):
    """Each env draws from its own stream, seeded from its env seed: seed 103's episodes are the same in a batch of
    8 (batches of 3, so it sits in the middle of one), alone, and through `Agent.predict` after
    ``reset([task], seeds=[103])``: exactly for a discrete model; a continuous one's batched matmuls round their
    last float bits differently, which moves Meta-World's returns by about 1e-5 of themselves here."""
    from vintix.tasks import make_env

    agent = Agent.from_pretrained("darkroom") if model == "darkroom" else Agent(tiny_model(policy="gaussian"))
    task = "DarkRoom-heldout-v0" if model == "darkroom" else "reach-v3"
    batch = evaluate_shots(agent, task, shots=3, seeds=8, first_seed=100, batch_envs=3)
    alone = evaluate_shots(agent, task, shots=3, seeds=1, first_seed=103)
    tolerance = 0 if model == "darkroom" else 1e-4
    np.testing.assert_allclose(batch.returns[3], alone.returns[0], rtol=tolerance)
    env = make_env(task, seed=103)
    agent.reset([task], seeds=[103], discard_context=True)
    obs, _ = env.reset()
    reward, start, returns = 0.0, True, [0.0]
    while len(returns) <= 3:
        action, _ = agent.predict(obs, reward, episode_start=start)
        obs, reward, terminated, truncated, _ = env.step(action)
        returns[-1] += reward
        start = terminated or truncated
        if start:
            obs, _ = env.reset()
            returns.append(0.0)
    np.testing.assert_allclose(returns[:3], alone.returns[0], rtol=tolerance)


def test_eval_may_hold_a_sampling_heads_noise_for_an_episode_whatever_the_model_says():
    from vintix.evaluate import EvalConfig
    from vintix.evaluate.config import EvalConfigError

    agent = Agent(tiny_model(policy="flow"))
    held = evaluate_shots(agent, "reach-v3", shots=2, seeds=1, first_seed=100, sample_noise="episode")
    assert agent.sample_noise == "episode"
    fresh = evaluate_shots(agent, "reach-v3", shots=2, seeds=1, first_seed=100)
    assert agent.sample_noise == "step" and not np.allclose(held.returns, fresh.returns)
    with pytest.raises(EvalConfigError, match="sample_noise 'run' is unknown"):
        EvalConfig(sample_noise="run")


# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

# Evaluation
EVAL = ["eval", "--tasks", "reach-v3", "--shots", "1", "--seeds", "1"]


def without(argv: list[str], option: str) -> list[str]:
    """`argv` without `option` and its value (a case that gives the option its own value gives it once)."""
    if option not in argv:
        return argv
    at = argv.index(option)
    return argv[:at] + argv[at + 2:]


for option, value, needle in [("--shots", "0", "shots=0"), ("--seeds", "0", "seeds=0"), ("--seeds", "-1", "seeds=-1"),
                              ("--threads", "0", "--threads"), ("--batch-envs", "0", "batch_envs=0"),
                              ("--first-seed", "-1", "first_seed=-1"), ("--prompt-steps", "-3", "prompt_steps=-3"),
                              ("--reference", "bogus", "bogus"), ("--device", "cuda", "no GPU"),
                              ("--device", "tpu", "tpu"), ("--variation", "viscosity=abc", "NAME=NUMBER"),
                              ("--variation", "viscosity=0.05", "viscosity"),
                              ("--variation", "viscosity=-1", "viscosity")]:
    cli_error("eval", f"{option} {value}", lambda o=option, v=value: [
        *without(EVAL, o), "--checkpoint", model_checkpoint(), o, v, "--out", work() / f"e-bad{o}{v}"], needle,
        after=not_written(lambda o=option, v=value: work() / f"e-bad{o}{v}"))
cli_error("eval", "--checkpoint missing", lambda: [*EVAL, "--checkpoint", missing("ckpt")], "no such checkpoint")
cli_error("eval", "--checkpoint a file", lambda: [*EVAL, "--checkpoint", file_at("ckpt-file", "x")()],
          "neither a model checkpoint")
cli_error("eval", "--out under a file (before the run, not after)", lambda: [
    *EVAL, "--checkpoint", model_checkpoint(), "--out", file_at("eval-out-file", "x")() / "results"],
    "is a file, not a directory")
cli_error("eval", "a shipped model's name this checkout lacks", ["eval", "--checkpoint", "no-such-model", "--tasks",
                                                                 "Hopper-v5"], "no shipped model of that name")


def nan_prompt() -> list[object]:
    root = work() / "prompt-nan"
    if not root.exists():
        shutil.copytree(collected(), root)
        with h5py.File(root / "metaworld" / "reach-v3" / "history-0000.h5", "r+") as f:
            group = next(iter(f))
            f[group]["reward"][3] = np.nan
    return [*EVAL, "--checkpoint", model_checkpoint(), "--prompt-from", root, "--prompt-steps", "10",
            "--out", work() / "e-nan-prompt"]


cli_error("eval", "--prompt-from a history with a NaN reward", nan_prompt, "NaN")
cli_error("eval", "--checkpoint an empty folder", lambda: [*EVAL, "--checkpoint", empty_dir("empty3")()],
          "neither a model checkpoint")
for damage, needle in [("truncated-weights", "truncated or damaged"), ("garbage-json", "not valid JSON"),
                       ("json-missing-keys", "no field 'format_version' (int)"), ("nan-weights", "NaN/inf"),
                       ("custom_tasks-is-a-list", "field 'custom_tasks' must be dict[str, dict[str, Any]], got"),
                       ("config-is-a-list", "field 'config' must be dict[str, Any], got [1, 2]"),
                       ("groups-is-an-object", "field 'groups' must be list[dict[str, Any]]"),
                       ("task_norms-is-text", "field 'task_norms' must be list[dict[str, Any]], got \"none\""),
                       ("extra-step-is-text", "field 'extra.step' must be int, got \"many\""),
                       ("no-weights", "model.safetensors is not"), ("future-format", "checkpoint format 99"),
                       ("groups-malformed", "no field 'groups[0].name' (str)"),
                       ("group-text-obs-dim", "field 'groups[0].obs_dim' must be int"),
                       ("config-text-heads", "n_heads must be int"),
                       ("weights-of-another-model", "does not fit the model")]:
    cli_error("eval", f"checkpoint: {damage}", lambda d=damage: [*EVAL, "--checkpoint", CHECKPOINTS[d](), "--out",
                                                                 work() / "e-ckpt"], needle)
cli_error("eval", "a run whose newest checkpoint is truncated", lambda: [
    *EVAL, "--checkpoint", RUNS["truncated-weights-eval"](), "--out", work() / "e-run"], "newest intact checkpoint is",
    after=not_written(lambda: work() / "e-run"))
cli_error("eval", "unknown task", lambda: ["eval", "--checkpoint", model_checkpoint(), "--tasks", "reech-v3"],
          "Did you mean")
cli_error("eval", "task of a group the checkpoint lacks", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "industrial-benchmark-35-v1"], "no encoder")
cli_error("eval", "empty --tasks", lambda: ["eval", "--checkpoint", model_checkpoint(), "--tasks", ","], "no tasks")
cli_error("eval", "--prompt-from missing", lambda: [*EVAL, "--checkpoint", model_checkpoint(), "--prompt-from",
                                                    missing("data")], "not a directory")
cli_error("eval", "--prompt-from a dataset without the task", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "push-v3", "--shots", "1", "--seeds", "1",
    "--prompt-from", clean_data()], "no learning history of push-v3")
cli_error("eval", "--prompt-steps longer than the window", lambda: [
    *EVAL, "--checkpoint", model_checkpoint(), "--prompt-from", collected(), "--prompt-steps", "100"], "window")
cli_error("eval", "--prompt-from with more seeds than histories", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "1", "--seeds", "3",
    "--prompt-from", collected(), "--prompt-steps", "10"], "histories")


def eval_config(**fields: object) -> Callable[[], object]:
    from vintix.evaluate import EvalConfig

    return lambda: EvalConfig(**fields)


api_error("eval", "EvalConfig(shots=0)", eval_config(shots=0), "shots=0")
api_error("eval", "EvalConfig(seeds='3')", eval_config(seeds="3"), "seeds must be int")
cli_error("eval", "a checkpoint whose config.json is nested 10^5 deep", lambda: [
    "eval", "--checkpoint", damaged_checkpoint("deep-json", lambda c: (c / "config.json").write_text(DEEP_JSON))(),
    "--tasks", "reach-v3"], "config.json")

# Provenance (issue 71, class 3): evaluate_shots' rows are one task's, so it takes one task's name.
for given, needle in [("metaworld", "'metaworld' is 50 tasks"), ("reach-v3,push-v3", "not the list"),
                      ("reach-v3,reach-v3", "not the list"), ("reach-v3,", "not the list"),
                      (["reach-v3"], "give one task's name"), ("reech-v3", "Did you mean")]:
    api_error("eval", f"evaluate_shots on {given!r}", lambda given=given: __import__("vintix.evaluate").evaluate
              .evaluate_shots(__import__("vintix").Agent.from_pretrained(model_checkpoint()), given), needle)


test_bad_input_ends_as_expected = bad_input_test("eval")
