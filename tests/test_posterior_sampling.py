"""Histories whose improvement is caused by rewards: the toy hidden-goal task, the demonstrator that
infers the goal from rewards (posterior sampling), its collection, and the goal-blind baseline."""

import dataclasses

import numpy as np
import pytest
from typer.testing import CliRunner

from vintix.cli import app
from vintix.collect import CollectionError, CollectionPlan, CollectionSettingsError, NoiseSchedule, collect
from vintix.data import LearningHistory
from vintix.demonstrators import PosteriorSamplingDemonstrator, load_demonstrator
from vintix.demonstrators.goal_blind import (
    goal_blind_baseline,
    goal_blind_path,
    observation_spread_across_goals,
    read_goal_blind,
    write_goal_blind,
)
from vintix.demonstrators.posterior import FumblingExpert
from vintix.demonstrators.scores import episode_outcomes, history_outcomes
from vintix.errors import VintixError
from vintix.tasks import get_task, make_env
from vintix.tasks.toy import EPISODE_LENGTH, START, SUCCESS_RADIUS

NO_NOISE = NoiseSchedule(noise_free_fraction=1.0)


def play_episodes(task: str, seeds: range, episodes: int, behaviour: str = "posterior-sampling",
                  probe_margin: float = 0.0) -> np.ndarray:
    """Success per (env, episode) of a demonstrator that infers the goal, one history per env seed."""
    demonstrator = load_demonstrator(task, behaviour=behaviour, probe_margin=probe_margin)
    return history_outcomes(task, demonstrator, seeds, episodes).success


def test_toy_task_hides_its_goal_and_rewards_distance_to_it():
    env = make_env("point-goal-v1", seed=3)
    obs, _ = env.reset()
    goal = env.unwrapped.true_goal
    assert np.allclose(obs, START)  # the observation is the point, never the goal
    for _ in range(EPISODE_LENGTH):
        obs, reward, _, truncated, info = env.step(np.array([1.0]))
        assert reward == pytest.approx(env.unwrapped.rewards_under_goals(goal[None])[0])
        assert reward < env.unwrapped.rewards_under_goals(obs[None].astype(np.float64))[0]  # best where the point is
    assert truncated and info["success"] == float(np.linalg.norm(obs - goal) < SUCCESS_RADIUS)
    assert np.allclose(make_env("point-goal-v1", seed=3).unwrapped.true_goal, goal)
    assert not np.allclose(make_env("point-goal-v1", seed=4).unwrapped.true_goal, goal)


def test_posterior_sampling_starts_blind_and_finds_the_goal_from_rewards():
    success = play_episodes("point-goal-v1", range(100, 140), episodes=6)
    assert success[:, 0].mean() <= 0.4  # the first episode aims at a goal drawn from the prior
    assert success[:, -2:].mean() >= 0.7


def test_probing_on_metaworld_reach_finds_the_goal_after_its_first_episode_even_probing_outside_the_goal_box():
    inside = play_episodes("reach-v3", range(100, 110), episodes=1, behaviour="probing")
    outside = play_episodes("reach-v3", range(100, 110), episodes=3, behaviour="probing", probe_margin=0.06)
    assert outside[:, 0].mean() <= 0.4 < inside[:, 0].mean()  # fewer goals met by chance (0.2 vs 0.6)
    assert outside[:, 1:].mean() >= 0.8  # goal-blind: 0.15


def test_a_probing_first_episode_is_the_same_for_every_goal_and_later_ones_aim_at_the_likeliest_goal():
    demonstrator = load_demonstrator("point-goal-v1", behaviour="probing")
    envs = [make_env("point-goal-v1", seed=seed) for seed in (1, 2, 3)]
    demonstrator.begin(envs, [np.random.default_rng(seed) for seed in (7, 8, 9)])
    observations = np.stack([env.reset()[0] for env in envs])
    first = []
    for _ in range(EPISODE_LENGTH):
        actions = demonstrator.act(observations, envs)
        first.append(actions)
        for i, env in enumerate(envs):
            observations[i], reward, terminated, truncated, _ = env.step(actions[i])
            demonstrator.observe(i, env, actions[i], reward, terminated or truncated)
    assert all(np.array_equal(step[0], step[i]) for step in first for i in (1, 2))  # nothing about the goal yet
    guesses = np.stack([posterior.aim() for posterior in demonstrator._posteriors])
    goals = np.stack([env.unwrapped.true_goal for env in envs])
    assert np.abs(guesses - goals).max() < SUCCESS_RADIUS  # one probing episode's rewards tell each goal


def test_metaworld_rewards_under_the_true_goal_are_the_envs_rewards():
    env = make_env("reach-v3", seed=5)
    env.reset()
    goal = env.unwrapped.true_goal
    for _ in range(5):
        action = env.action_space.sample()
        _, reward, *_ = env.step(action)
        under = env.unwrapped.rewards_under_goals(np.stack([goal, goal + 0.1]), action)
        assert under[0] == pytest.approx(reward) and under[1] != pytest.approx(reward)
    assert np.array_equal(env.unwrapped.true_goal, goal)  # the swap is undone


def test_collected_posterior_sampling_histories_record_the_goal_aware_expert_action(tmp_path):
    plan = CollectionPlan("point-goal-v1", histories=2, steps=60, schedule=NO_NOISE, envs_per_batch=2,
                          behaviour="posterior-sampling")
    summaries = collect(plan, tmp_path)
    with LearningHistory(summaries[0].path) as history:
        rows = history.read(0, 60, demonstrator_action=True)
        assert history.attrs["behaviour"] == "posterior-sampling"
    env = make_env("point-goal-v1", seed=int(history.attrs["env_seed"]))
    expert = load_demonstrator("point-goal-v1").act_toward(rows["observation"], env.unwrapped.true_goal[None])
    assert np.allclose(rows["demonstrator_action"], expert, atol=1e-6)  # the target: aimed at the true goal
    assert not np.allclose(rows["action"][:10], rows["demonstrator_action"][:10])  # the behaviour: a guess
    again = collect(plan, tmp_path / "again")
    with LearningHistory(again[0].path) as first_again:
        assert np.array_equal(first_again.read(0, 60)["action"], rows["action"])  # reproducible
    with pytest.raises(CollectionSettingsError, match="behaviour"):
        collect(CollectionPlan("point-goal-v1", histories=2, steps=60, schedule=NO_NOISE, envs_per_batch=2), tmp_path)


def test_a_probe_margin_moves_the_probe_and_is_recorded_so_a_collection_cannot_mix_probes(tmp_path):
    plan = CollectionPlan("point-goal-v1", histories=1, steps=2 * EPISODE_LENGTH, schedule=NO_NOISE,
                          behaviour="probing")
    wide = dataclasses.replace(plan, probe_margin=0.5)
    with LearningHistory(collect(wide, tmp_path / "wide")[0].path) as history:
        assert history.attrs["probe_margin"] == 0.5
        wide_probe = history.read(0, EPISODE_LENGTH)["action"]
    with LearningHistory(collect(plan, tmp_path / "plain")[0].path) as history:
        assert "probe_margin" not in history.attrs  # the default is not recorded: earlier files keep their bytes
        assert not np.allclose(history.read(0, EPISODE_LENGTH)["action"], wide_probe)
    with pytest.raises(CollectionSettingsError, match="probe_margin"):
        collect(plan, tmp_path / "wide")
    for behaviour, margin in (("posterior-sampling", 0.05), ("probing", -0.05)):
        with pytest.raises(VintixError, match="probe_margin"):
            load_demonstrator("reach-v3", behaviour=behaviour, probe_margin=margin)


def test_an_expert_aiming_its_gripper_centre_is_recorded_so_a_collection_cannot_mix_aims(tmp_path):
    plan = CollectionPlan("reach-v3", histories=1, steps=100, schedule=NO_NOISE)
    aimed = dataclasses.replace(plan, aim="gripper-centre")
    with LearningHistory(collect(aimed, tmp_path)[0].path) as history:
        assert history.attrs["aim"] == "gripper-centre"
        aimed_actions = history.read(0, 100)["action"]
    with pytest.raises(CollectionSettingsError, match="aim 'gripper-centre' \\(now 'hand'\\)"):
        collect(plan, tmp_path)
    with LearningHistory(collect(plan, tmp_path / "hand")[0].path) as history:
        assert "aim" not in history.attrs
        assert not np.allclose(history.read(0, 100)["action"], aimed_actions)


def test_posterior_sampling_needs_a_task_whose_expert_can_aim_at_a_goal():
    with pytest.raises(VintixError, match="posterior-sampling"):
        load_demonstrator("industrial-benchmark-30-v1", behaviour="posterior-sampling")
    with pytest.raises(CollectionError, match="unknown behaviour"):
        CollectionPlan("reach-v3", histories=1, steps=10, behaviour="psrl")
    with pytest.raises(CollectionError, match="pilot_steps"):
        CollectionPlan("reach-v3", histories=1, steps=10, behaviour="posterior-sampling",
                       schedule=NoiseSchedule(pilot_steps=100))
    assert isinstance(load_demonstrator("reach-v3", behaviour="posterior-sampling"), PosteriorSamplingDemonstrator)


def test_goal_blind_baseline_separates_tasks_that_hide_their_goal():
    toy = goal_blind_baseline("point-goal-v1", seeds=20)
    assert toy.true_goal_success == 1.0 and toy.goal_blind_success <= 0.4
    button = goal_blind_baseline("button-press-v3", seeds=3)  # the goal follows from the observed button
    assert button.hidden_information == 0.0


def test_a_blind_expert_can_aim_at_the_best_constant_goal_and_rows_keep_a_random_policys_return(tmp_path):
    best = goal_blind_baseline("point-goal-v1", seeds=10, blind_aim="best")
    assert best.blind_aim == "best" and best.goal_blind_success <= 0.4 < best.true_goal_success
    assert best.random_return < best.true_goal_return and best.hidden_return > 0.5  # a blind aim earns no more
    written = write_goal_blind([best], tmp_path / "goal-blind.csv")
    assert read_goal_blind(written)["point-goal-v1"] == best
    old = tmp_path / "old.csv"  # a table measured before the blind_aim and random_return columns
    old.write_text(goal_blind_path().read_text())
    row = read_goal_blind(old)["reach-v3"]
    assert row.blind_aim == "mean" and np.isnan(row.random_return)
    with pytest.raises(VintixError, match="blind aim 'median'"):
        goal_blind_baseline("point-goal-v1", seeds=1, blind_aim="median")
    cli = CliRunner().invoke(app, ["demonstrator", "goal-blind", "--task", "point-goal-v1", "--seeds", "3",
                                   "--blind-aim", "best", "--out", str(tmp_path / "cli.csv")])
    assert cli.exit_code == 0, cli.output
    row = read_goal_blind(tmp_path / "cli.csv")["point-goal-v1"]
    assert row.blind_aim == "best" and row.command.endswith("--blind-aim best")


def test_only_rewards_tell_reach_goals_apart_but_plate_slide_shows_its_goal_to_a_probe_that_pushes_into_it():
    """The icrl suite's tasks must hide their goal from the observations whatever the agent does; plate-slide's
    goal is a net on the table: the probe pushes the plate into it, and the plate moves differently."""
    assert observation_spread_across_goals("reach-v3") == (0.0, 0.0, 0.0)
    probe, _, _ = observation_spread_across_goals("plate-slide-v3")
    assert probe > 0.05


def test_the_shipped_goal_blind_table_covers_every_metaworld_task():
    table = read_goal_blind()
    assert len([t for t in table if t.endswith("-v3")]) == 50
    assert table["reach-v3"].goal_blind_success <= 0.4 and table["reach-v3"].true_goal_success >= 0.9


def test_probe_then_sample_records_the_probe_then_the_expert_as_its_target_and_plays_guesses_after_the_probe(
        tmp_path):
    steps = 3 * EPISODE_LENGTH
    plan = CollectionPlan("point-goal-v1", histories=3, steps=steps, schedule=NO_NOISE, envs_per_batch=3,
                          behaviour="probe-then-sample")
    histories = []
    for summary in collect(plan, tmp_path):
        with LearningHistory(summary.path) as history:
            rows = history.read(0, steps, demonstrator_action=True)
            goal = make_env("point-goal-v1", seed=int(history.attrs["env_seed"])).unwrapped.true_goal
        histories.append((rows, goal))
    probe = slice(0, EPISODE_LENGTH)
    for rows, goal in histories:
        assert np.array_equal(rows["action"][probe], histories[0][0]["action"][probe])  # nothing known yet
        assert np.array_equal(rows["demonstrator_action"][probe], rows["action"][probe])  # the target: the probe
        later = slice(EPISODE_LENGTH, steps)
        expert = load_demonstrator("point-goal-v1").act_toward(rows["observation"][later], goal[None])
        assert np.allclose(rows["demonstrator_action"][later], expert, atol=1e-6)  # then: the goal-aware expert
    guesses = [rows["action"][EPISODE_LENGTH:] - rows["demonstrator_action"][EPISODE_LENGTH:] for rows, _ in histories]
    assert any(np.abs(miss).max() > 0 for miss in guesses)  # it plays a drawn goal, which may miss


def test_demonstrator_histories_prints_how_a_goal_inferring_demonstrator_does_episode_after_episode():
    runner = CliRunner()
    result = runner.invoke(app, ["demonstrator", "histories", "--task", "point-goal-v1", "--behaviour", "probing",
                                 "--seeds", "10", "--episodes", "2"])
    assert result.exit_code == 0, result.output
    rows = [line.split("│")[1:3] for line in result.output.splitlines() if line.count("│") == 5]
    success = {int(episode): float(rate) for episode, rate in rows if episode.strip().isdigit()}
    assert success[1] <= 0.4 and success[2] >= 0.9  # the probe, then the goal its rewards revealed
    result = runner.invoke(app, ["demonstrator", "histories", "--task", "point-goal-v1", "--behaviour", "expert"])
    assert result.exit_code == 2 and "does not learn within a history" in " ".join(result.output.split())


def check_setting_is_recorded_and_refused_where_wrong(tmp_path, name: str, value: float,
                                                      refused: list[tuple[str, float]]) -> None:
    """A demonstrator setting of a recipe: recorded in each history, so a collection will not add histories made
    without it to a folder of histories made with it; refused for each (behaviour, value) in `refused`."""
    plan = CollectionPlan("point-goal-v1", histories=1, steps=2 * EPISODE_LENGTH, schedule=NO_NOISE,
                          behaviour="probe-then-sample", **{name: value})
    with LearningHistory(collect(plan, tmp_path)[0].path) as history:
        assert history.attrs[name] == value
    with pytest.raises(CollectionSettingsError, match=name):
        collect(dataclasses.replace(plan, **{name: 0.0}), tmp_path)
    for behaviour, wrong in refused:
        with pytest.raises(VintixError, match=name):
            load_demonstrator("reach-v3", behaviour=behaviour, **{name: wrong})


def test_lapses_miss_after_the_goal_is_found_and_are_recorded_so_a_collection_cannot_mix_them(tmp_path):
    """With lapses, some episodes after the first aimed one aim at a prior draw: they end far from the goal the
    episodes before and after them reach, while the recorded target stays the goal-aware expert."""
    seeds, episodes, task = range(100, 120), 6, "Reacher-hidden-v5"
    steady = play_episodes(task, seeds, episodes, behaviour="probe-then-sample")
    lapsing = history_outcomes(task, load_demonstrator(task, behaviour="probe-then-sample", lapse_probability=0.5),
                               seeds, episodes).success
    assert np.array_equal(lapsing[:, :2], steady[:, :2])  # the probe and the first aimed episode never lapse
    assert steady[:, 2:].mean() >= 0.9 and lapsing[:, 2:].mean() <= steady[:, 2:].mean() - 0.2
    check_setting_is_recorded_and_refused_where_wrong(tmp_path, "lapse_probability", 0.5,
                                                      [("probing", 0.5), ("probe-then-sample", 1.5)])


def test_a_wider_reward_tolerance_makes_aimed_episodes_close_in_over_several_and_is_recorded(tmp_path):
    """reward_tolerance widens the likelihood: the aimed episodes of the hidden Reacher miss by centimetres at
    first and close in, where the default's end within a centimetre from the first aimed one on."""
    seeds, episodes, task = range(100, 120), 6, "Reacher-hidden-v5"
    default = history_outcomes(task, load_demonstrator(task, behaviour="probe-then-sample"), seeds, episodes)
    wide = history_outcomes(task, load_demonstrator(task, behaviour="probe-then-sample", reward_tolerance=0.2),
                            seeds, episodes)
    assert np.median(default.end_distance[:, 1:]) < 0.01
    assert np.median(wide.end_distance[:, 1]) > 2 * np.median(wide.end_distance[:, -1]) > 0.01
    check_setting_is_recorded_and_refused_where_wrong(tmp_path, "reward_tolerance", 0.2,
                                                      [("expert", 0.2), ("probing", -1.0)])


def test_a_fumbling_lapse_holds_the_gripper_open_so_pick_place_fails_where_the_expert_succeeds():
    """The other kind of lapse, for experts that handle an object: aimed right, the object never held."""
    expert = load_demonstrator("pick-place-v3")

    class Fumbled:
        def act(self, observations, envs):
            return expert.fumble(expert.act(observations, envs))

    assert isinstance(expert, FumblingExpert) and not isinstance(load_demonstrator("Reacher-hidden-v5"), FumblingExpert)
    assert episode_outcomes("pick-place-v3", expert, 3, 100)[1].mean() == 1.0
    assert episode_outcomes("pick-place-v3", Fumbled(), 3, 100)[1].mean() == 0.0
    demonstrator = load_demonstrator("pick-place-v3", behaviour="probe-then-sample", lapse_probability=1.0)
    outcomes = history_outcomes("pick-place-v3", demonstrator, range(100, 106), episodes=4)
    assert outcomes.success[:, 2:].mean() <= 0.5  # every episode from the third on lapses, half of them fumbling


def test_halfcheetah_vels_probe_stands_still_all_episode_and_its_rewards_place_the_target(tmp_path):
    """A model has no clock, so it cannot copy a probe that switches mid-episode with nothing in the observation
    saying when: HalfCheetah-Vel's probe stands still (its range's low end) for the whole first episode, each reward
    minus the target speed (less the control cost), and the episode after it runs at the target."""
    length = get_task("HalfCheetah-Vel-v5").episode_length
    plan = CollectionPlan("HalfCheetah-Vel-v5", histories=2, steps=2 * length, schedule=NO_NOISE, envs_per_batch=2,
                          behaviour="probe-then-sample")
    for summary in collect(plan, tmp_path):
        with LearningHistory(summary.path) as history:
            rows = history.read(0, 2 * length)
            target = float(make_env("HalfCheetah-Vel-v5", seed=int(history.attrs["env_seed"])).unwrapped.true_goal[0])
        speed = rows["observation"][:, 8]  # the root's x-velocity (qvel[0] after qpos[1:])
        probe, later = slice(20, length), slice(length + 100, 2 * length)
        assert np.abs(speed[probe]).mean() < 0.3  # through both halves of the first episode
        assert rows["reward"][probe].mean() == pytest.approx(-target, abs=0.3)
        assert speed[later].mean() == pytest.approx(target, abs=0.5)
