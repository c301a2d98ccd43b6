"""The discrete benchmarks (`vintix.tasks.discrete_benchmarks`) as AD, AD^ε and DPT define them, and their
demonstrators."""

import numpy as np
import pytest

from vintix.collect import CollectionPlan, NoiseSchedule, collect
from vintix.data import LearningHistory
from vintix.demonstrators import load_demonstrator
from vintix.demonstrators.discrete_benchmarks import WALK_PERSISTENCE
from vintix.errors import VintixError
from vintix.tasks import get_task, list_tasks, make_env
from vintix.tasks.discrete_benchmarks import MOVES, SIZE, START, goal_split, pair_split


def play(env, actions):
    """Rewards of `actions` from a reset, and whether the last step ended the episode."""
    env.reset()
    rewards, done = [], False
    for action in actions:
        _, reward, terminated, truncated, _ = env.step(action)
        rewards.append(reward)
        done = terminated or truncated
    return rewards, done


def path_to(target, start=START):
    """Actions from `start` to `target`: along x, then y (0 stay, 1 up, 2 down, 3 left, 4 right)."""
    dx, dy = target[0] - start[0], target[1] - start[1]
    return [4 if dx > 0 else 3] * abs(dx) + [1 if dy > 0 else 2] * abs(dy)


def test_the_domain_registers_nine_discrete_tasks_whose_held_out_goals_are_a_split_task():
    tasks = {t.name: t for t in list_tasks(domain="icrl")}
    assert set(tasks) == {"DarkRoom-v0", "DarkRoom-heldout-v0", "DarkRoomHard-v0", "DarkRoomHard-heldout-v0",
                          "KeyToDoor-v0", "KeyToDoor-heldout-v0", "KeyToDoorRandomStart-v0",
                          "KeyToDoorRandomStart-heldout-v0", "BernoulliBandit-v0"}
    assert all(t.discrete for t in tasks.values())
    assert (tasks["DarkRoom-v0"].act_dim, tasks["DarkRoom-v0"].episode_length) == (5, 20)
    assert tasks["DarkRoom-heldout-v0"].split == "test" and tasks["DarkRoom-v0"].split == "train"
    assert get_task("Reacher-v5").action_type == "continuous"


def test_dark_room_splits_its_81_goals_65_to_16_and_key_to_door_holds_out_a_fifth_of_the_pairs():
    train, test = goal_split()
    assert (len(train), len(test)) == (65, 16)
    assert len({tuple(g) for g in np.concatenate([train, test])}) == 81
    train_pairs, test_pairs = pair_split()
    assert len(test_pairs) == int(0.2 * 81 * 80)
    assert not {tuple(p) for p in train_pairs} & {tuple(p) for p in test_pairs}
    held_out_goals = {tuple(make_env("DarkRoom-heldout-v0", seed=s).unwrapped.true_goal) for s in range(200)}
    assert held_out_goals <= {tuple(g) for g in test}


def test_dark_room_pays_one_on_every_step_on_the_goal_from_the_centre_and_its_optimum_counts_them():
    env = make_env("DarkRoom-v0", seed=7)
    goal = env.unwrapped.true_goal
    observation, _ = env.reset()
    assert tuple(observation) == START
    route = path_to(goal)
    rewards, done = play(env, route + [0] * (20 - len(route)))
    assert done and sum(rewards) == env.unwrapped.optimal_return() == 20 - len(route) + 1
    assert rewards[len(route) - 1:] == [1.0] * (21 - len(route))


def test_dark_room_hard_pays_once_and_key_to_door_pays_the_key_then_the_door_which_ends_the_episode():
    hard = make_env("DarkRoomHard-v0", seed=7)
    route = path_to(hard.unwrapped.true_goal)
    rewards, _ = play(hard, route + [0] * (20 - len(route)))
    assert sum(rewards) == 1.0 == hard.unwrapped.optimal_return()
    env = make_env("KeyToDoor-v0", seed=3)
    key, door = env.unwrapped.true_goal
    rewards, done = play(env, path_to(door))  # the door without the key pays nothing
    assert sum(rewards) == 0 and not done
    rewards, done = play(env, path_to(key) + path_to(door, key))
    assert rewards.count(1.0) == 2 and sum(rewards) == 2.0 and done


def test_key_to_door_with_random_starts_starts_each_episode_elsewhere_never_on_the_key_as_its_seed_says():
    """AD^ε's Key-to-Door: the same pairs as KeyToDoor-v0, a start drawn anew each episode from the env's seed."""
    env = make_env("KeyToDoorRandomStart-v0", seed=3)
    key, door = env.unwrapped.true_goal
    np.testing.assert_array_equal([key, door], make_env("KeyToDoor-v0", seed=3).unwrapped.true_goal)
    starts = [tuple(env.reset()[0]) for _ in range(30)]
    assert len(set(starts)) > 10 and tuple(key) not in starts
    again = make_env("KeyToDoorRandomStart-v0", seed=3)
    assert [tuple(again.reset()[0]) for _ in range(30)] == starts
    rewards, done = play(make_env("KeyToDoorRandomStart-v0", seed=3),  # its first episode starts at starts[0]
                         path_to(key, np.array(starts[0], dtype=int)) + path_to(door, key))
    assert sum(rewards) == 2.0 and done


def test_a_hidden_goal_is_drawn_from_the_seed_and_kept_across_resets():
    for task in ("DarkRoom-v0", "KeyToDoor-v0", "BernoulliBandit-v0"):
        env = make_env(task, seed=11)
        first = env.unwrapped.true_goal
        env.reset()
        env.reset()
        assert np.array_equal(env.unwrapped.true_goal, first)
        assert np.array_equal(make_env(task, seed=11).unwrapped.true_goal, first)
    goals = {tuple(make_env("DarkRoom-v0", seed=s).unwrapped.true_goal) for s in range(100)}
    assert len(goals) > 30


def test_the_bandit_pays_each_arm_at_its_hidden_mean():
    env = make_env("BernoulliBandit-v0", seed=5)
    means = env.unwrapped.true_goal
    env.reset()
    pulls = {arm: [] for arm in range(5)}
    for step in range(5000):
        arm = step % 5
        _, reward, _, truncated, _ = env.step(arm)
        pulls[arm].append(reward)
        if truncated:
            env.reset()
    assert np.allclose([np.mean(pulls[a]) for a in range(5)], means, atol=0.05)


def test_an_action_outside_the_space_is_an_error_naming_it():
    env = make_env("DarkRoom-v0", seed=0)
    env.reset()
    with pytest.raises(ValueError, match="not in Discrete"):
        env.step(5)


def normalized_returns(root, task, episodes=25):
    """[histories, episodes] returns of the first `episodes` episodes of a collected task's histories, each divided
    by its goal's optimum (Key-to-Door's episodes end at the door, so its histories hold more of them)."""
    rows = []
    for path in sorted((root / "icrl" / task).glob("*.h5")):
        history = LearningHistory(path)
        optimal = make_env(task, seed=history.env_seed).unwrapped.optimal_return()
        rows.append(history.episode_returns()[:episodes] / optimal)
    return np.array(rows)


@pytest.mark.parametrize(("task", "behaviour"), [
    ("DarkRoom-v0", "posterior-sampling"), ("DarkRoomHard-v0", "posterior-sampling"),
    ("KeyToDoor-v0", "posterior-sampling"), ("BernoulliBandit-v0", "posterior-sampling"),
    ("DarkRoom-heldout-v0", "posterior-search"), ("KeyToDoor-v0", "posterior-search")])
def test_the_reward_inferring_demonstrator_reaches_the_optimum_within_a_few_episodes_without_the_goal(task, behaviour,
                                                                                                     tmp_path):
    steps = 30 * get_task(task).episode_length
    collect(CollectionPlan(task, histories=10, steps=steps, behaviour=behaviour,
                           schedule=NoiseSchedule(noise_free_fraction=1.0)), tmp_path)
    returns = normalized_returns(tmp_path, task)
    assert returns[:, 0].mean() < 0.7  # it has to search first...
    assert returns[:, 15:].mean() >= (0.85 if task == "BernoulliBandit-v0" else 0.99)  # ...then it has found it


def test_the_walk_search_moves_as_its_position_and_last_move_say_then_goes_straight_to_what_it_found(tmp_path):
    """`walk-search`: until a reward shows the key, every move leaves the cell (no wall bumped, never staying) and
    repeats the last one about `WALK_PERSISTENCE` of the time; once the key and the door are found, episodes are
    optimal. Slower than the spiral search, but no move depends on how far earlier episodes got."""
    task = "KeyToDoor-heldout-v0"
    collect(CollectionPlan(task, histories=20, steps=40 * 50, behaviour="walk-search",
                           schedule=NoiseSchedule(noise_free_fraction=1.0)), tmp_path)
    returns = normalized_returns(tmp_path, task, 40)
    assert returns[:, 0].mean() < 0.5 and returns[:, 25:40].mean() >= 0.95
    repeats = []
    for path in sorted((tmp_path / "icrl" / task).glob("*.h5")):
        rows = LearningHistory(path).read(0, 50)
        searching = slice(0, int(np.argmax(rows["reward"] > 0)) or 50)  # the first episode, up to the key
        positions, actions = rows["observation"][searching], rows["action"][searching]
        after = np.clip(positions + MOVES[actions], 0, SIZE - 1)
        assert (actions != 0).all() and (after != positions).any(axis=1).all()  # every move leaves the cell
        repeats.extend(actions[1:] == actions[:-1])
    assert abs(np.mean(repeats) - WALK_PERSISTENCE) < 0.1  # turns forced at walls add to the random ones


def test_ad_eps_histories_rise_from_random_to_optimal_and_record_the_experts_action(tmp_path):
    collect(CollectionPlan("DarkRoom-v0", histories=10, steps=1200, schedule=NoiseSchedule(noise_free_fraction=0.1)),
            tmp_path)
    returns = normalized_returns(tmp_path, "DarkRoom-v0", 59)
    assert returns[:, :5].mean() < 0.2 and returns[:, -5:].mean() == 1.0
    history = LearningHistory(next((tmp_path / "icrl" / "DarkRoom-v0").glob("*.h5")))
    rows = history.read(0, 1200, demonstrator_action=True)
    assert rows["action"].dtype == np.int32 and rows["action"].shape == (1200,)
    tail = slice(1100, 1200)  # noise-free: the executed action is the expert's
    assert np.array_equal(rows["action"][tail], rows["demonstrator_action"][tail])
    assert (rows["action"][:100] != rows["demonstrator_action"][:100]).mean() > 0.5  # ε near 1: mostly random


def test_ads_learner_improves_over_its_history(tmp_path):
    collect(CollectionPlan("DarkRoom-v0", histories=10, steps=2000, behaviour="learner",
                           schedule=NoiseSchedule(noise_free_fraction=1.0)), tmp_path)
    returns = normalized_returns(tmp_path, "DarkRoom-v0", 99)
    assert returns[:, :10].mean() < 0.3 and returns[:, -10:].mean() > 0.7


def test_the_discrete_benchmarks_take_their_own_behaviours_only():
    with pytest.raises(VintixError, match="discrete benchmark"):
        load_demonstrator("DarkRoom-v0", behaviour="probe-then-sample")
    with pytest.raises(VintixError, match="'learner'"):
        load_demonstrator("reach-v3", behaviour="learner")
    with pytest.raises(VintixError, match="on a bandit use posterior-sampling"):
        load_demonstrator("BernoulliBandit-v0", behaviour="posterior-search")


def test_a_searchers_proposals_can_be_its_targets_under_noise(tmp_path):
    """`target: proposal`: the rows record what the search would have done before the noise (DART's targets), not
    the goal-aware expert's action, and the files say so."""
    agreement = {}
    for target in ("expert", "proposal"):
        collect(CollectionPlan("DarkRoom-v0", histories=4, steps=200, behaviour="posterior-search", target=target,
                               schedule=NoiseSchedule(noise_free_fraction=0.0, knots=(0.2, 0.2, 0.0))),
                tmp_path / target)
        history = LearningHistory(next((tmp_path / target / "icrl" / "DarkRoom-v0").glob("*.h5")))
        rows = history.read(0, 40, demonstrator_action=True)  # the first two episodes: mostly searching
        agreement[target] = float((rows["action"] == rows["demonstrator_action"]).mean())
        assert (target == "proposal") == (history.attrs.get("target") == "proposal")
    # ε about 0.2: the executed action is the proposal but for the noise; the expert heads elsewhere while searching.
    assert agreement["proposal"] >= 0.75 > agreement["expert"]
