"""Discrete actions end to end: the integer HDF5 layout, the categorical head, the agent's draws, and the errors.

A discrete group's actions are indices 0..n-1 everywhere: stored as int32 (n,), embedded as the previous action,
n logits out, cross-entropy in training, a draw (or the argmax) at play. One model may hold both kinds of group.
"""

import gymnasium as gym
import h5py
import numpy as np
import pytest
import torch

from vintix.agent import Agent
from vintix.agent.agent import AgentInputError
from vintix.data import LearningHistory, LearningHistoryWriter, write_task_metadata
from vintix.data.validate import validate_dataset
from vintix.errors import DatasetError
from vintix.evaluate import evaluate_shots
from vintix.model.model import GroupSpec, TaskNorm, Vintix, preset
from vintix.tasks import ActionSpaceError, action_space_of, make_env
from vintix.train.trainer import WindowLoss


def discrete_model(extra_groups=(), extra_norms=()):
    """An untrained tiny model with Dark Room's group (and any others)."""
    config = preset("tiny", n_layers=1, n_heads=2, obs_emb_dim=8, act_emb_dim=8, rew_emb_dim=4, mlp_dim=32,
                    context_len=64, head_layers=0)
    return Vintix(config, [GroupSpec("darkroom", 2, 5, discrete=True), *extra_groups],
                  [TaskNorm("DarkRoom-v0", "darkroom", [4.0, 4.0], [2.0, 2.0]), *extra_norms])


def write_history(path, actions, discrete=True, act_dim=5):
    rows = len(actions)
    with LearningHistoryWriter(path, obs_dim=2, act_dim=act_dim, discrete=discrete) as writer:
        writer.append(np.zeros((rows, 2)), actions, np.zeros(rows), np.arange(rows) % 20)
    return path


# ---------------------------------------------------------------------------------------------- the HDF5 layout


def test_discrete_actions_are_stored_as_int32_indices_and_read_back_unchanged(tmp_path):
    actions = np.array([0, 4, 2, 3, 1] * 8)
    path = write_history(tmp_path / "h.h5", actions)
    with h5py.File(path) as f:
        assert f["0-39/action"].dtype == np.int32 and f["0-39/action"].shape == (40,)
    history = LearningHistory(path)
    assert history.discrete and history.act_dim is None
    assert np.array_equal(history.read(0, 40)["action"], actions)


def test_the_writer_refuses_a_float_action_an_index_outside_the_space_and_a_vector_action(tmp_path):
    with pytest.raises(DatasetError, match="expected an integer one .a discrete task's actions are indices"):
        write_history(tmp_path / "a.h5", np.array([0.0, 1.0]))
    with pytest.raises(DatasetError, match="outside the task's 5 actions 0-4"):
        write_history(tmp_path / "b.h5", np.array([0, 5]))
    with pytest.raises(DatasetError, match="5 discrete actions: one integer per step"):
        write_history(tmp_path / "c.h5", np.zeros((2, 5), int))


def dataset_with(tmp_path, actions, discrete_json=True, discrete_file=True):
    task_dir = tmp_path / "data" / "icrl" / "DarkRoom-v0"
    write_task_metadata(task_dir, "DarkRoom-v0", 2, 5, discrete=discrete_json)
    if discrete_file:
        write_history(task_dir / "h.h5", actions)
    else:
        write_history(task_dir / "h.h5", np.zeros((len(actions), 5)), discrete=False)
    return tmp_path / "data"


def test_validation_flags_actions_outside_the_space_a_float_layout_and_a_kind_the_json_contradicts(tmp_path):
    root = dataset_with(tmp_path, np.array([0, 1, 2, 3, 4] * 4))
    assert validate_dataset(root) == []
    with h5py.File(root / "icrl" / "DarkRoom-v0" / "h.h5", "r+") as f:
        f["0-19/action"][3] = 7
    assert any("action 7 at row 3 is outside the task's 5 actions (0-4)" in p.message for p in validate_dataset(root))
    with h5py.File(root / "icrl" / "DarkRoom-v0" / "h.h5", "r+") as f:  # a float action in the integer layout
        del f["0-19/action"]
        f["0-19"].create_dataset("action", data=np.zeros(20, np.float32))
    assert any("stores one action per row as float32: a discrete task's actions are integer indices" in p.message
               for p in validate_dataset(root))
    other = dataset_with(tmp_path / "other", np.zeros(20, int), discrete_file=False)
    assert any("holds continuous actions but its task is discrete" in p.message for p in validate_dataset(other))


# ---------------------------------------------------------------------------------------------- the model


def test_a_discrete_group_gives_logits_and_cross_entropy_teaches_it_the_target_action():
    torch.manual_seed(0)
    model = discrete_model()
    batch = {"darkroom": {"task_idx": torch.zeros(4, dtype=torch.long), "obs": torch.randn(4, 16, 2),
                          "prev_action": torch.randint(0, 5, (4, 16)), "prev_reward": torch.zeros(4, 16),
                          "step_num": torch.arange(16).repeat(4, 1), "action": torch.full((4, 16), 3)}}
    logits = model("darkroom", batch["darkroom"]["task_idx"], *(batch["darkroom"][k] for k in
                   ("obs", "prev_action", "prev_reward", "step_num")))
    assert logits.shape == (4, 16, 5)
    loss = WindowLoss(model)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    first = float(loss(batch).mean().detach())
    assert first == pytest.approx(np.log(5), abs=0.3)  # near uniform at the start
    for _ in range(30):
        optimizer.zero_grad()
        loss(batch).mean().backward()
        optimizer.step()
    assert float(loss(batch).mean().detach()) < 0.05


def test_the_previous_action_is_embedded_so_different_indices_make_different_tokens():
    model = discrete_model()
    obs, reward, start = torch.zeros(1, 2, 2), torch.zeros(1, 2), torch.tensor([[True, False]])
    one = model.encode("darkroom", obs, torch.tensor([[0, 1]]), reward, start)
    other = model.encode("darkroom", obs, torch.tensor([[0, 3]]), reward, start)
    assert torch.equal(one[:, 0], other[:, 0])  # an episode start's action is the padding, whatever the index
    assert not torch.allclose(one[:, 1], other[:, 1])


# ---------------------------------------------------------------------------------------------- the agent


def test_predict_returns_a_valid_action_drawn_by_default_and_the_argmax_when_deterministic():
    agent = Agent(discrete_model(), seed=1)
    env = make_env("DarkRoom-v0", seed=0)
    agent.reset(["DarkRoom-v0"])
    observation, _ = env.reset()
    drawn = set()
    for step in range(40):
        action, _ = agent.predict(observation, 0.0, episode_start=step == 0)
        assert env.action_space.contains(action) and isinstance(action, np.integer)
        drawn.add(int(action))
    assert len(drawn) > 1  # an untrained model's logits are near flat: its draws vary
    agent.reset(["DarkRoom-v0"], discard_context=True)
    greedy = {int(agent.predict(observation, 0.0, episode_start=step == 0, deterministic=True)[0])
              for step in range(5)}
    assert len(greedy) == 1


def test_a_vector_env_gets_one_action_per_env_and_one_model_holds_both_kinds_of_group():
    reacher = GroupSpec("mujoco-reacher", 10, 2)
    model = discrete_model([reacher], [TaskNorm("Reacher-v5", "mujoco-reacher", [0.0] * 10, [1.0] * 10)])
    agent = Agent(model)
    agent.reset(["DarkRoom-v0", "DarkRoom-v0", "Reacher-v5"])
    envs = [make_env("DarkRoom-v0", seed=0), make_env("DarkRoom-v0", seed=1), make_env("Reacher-v5", seed=0)]
    actions = agent.act([env.reset()[0] for env in envs], np.zeros(3), np.ones(3, bool))
    assert actions[0].shape == actions[1].shape == () and actions[2].shape == (2,)
    for env, action in zip(envs, actions, strict=True):
        env.step(action)
    vector = gym.vector.SyncVectorEnv([lambda s=s: make_env("DarkRoom-v0", seed=s) for s in range(3)])
    agent = Agent(discrete_model())
    agent.reset(["DarkRoom-v0"] * 3)
    observations, _ = vector.reset()
    actions, _ = agent.predict(observations)
    assert actions.shape == (3,) and vector.action_space.contains(actions)


def test_a_discrete_model_refuses_a_box_task_and_a_continuous_model_a_discrete_one():
    with pytest.raises(AgentInputError, match="task 'Reacher-v5' acts in Box.*group 'mujoco-reacher' is discrete"):
        Agent(discrete_model([GroupSpec("mujoco-reacher", 10, 2, discrete=True)])).reset(["Reacher-v5"])
    continuous = discrete_model([GroupSpec("darkroom-box", 2, 5)])
    continuous.task_norms.append(TaskNorm("DarkRoom-heldout-v0", "darkroom-box", [0.0, 0.0], [1.0, 1.0]))
    model = Vintix(continuous.config, list(continuous.groups.values()), continuous.task_norms)
    with pytest.raises(AgentInputError, match="acts in Discrete.5., but the checkpoint's group 'darkroom-box' is "
                                              "continuous"):
        Agent(model).reset(["DarkRoom-heldout-v0"])


def test_discrete_spaces_not_starting_at_0_and_multidiscrete_are_refused_with_the_way_round():
    with pytest.raises(ActionSpaceError, match="starts at 1; vintix's discrete actions are 0 to n - 1"):
        action_space_of(gym.spaces.Discrete(5, start=1))
    with pytest.raises(ActionSpaceError, match="MultiDiscrete, which vintix does not support: flatten it into one "
                                               "Discrete of 6 actions"):
        action_space_of(gym.spaces.MultiDiscrete([2, 3]))
    agent = Agent(discrete_model())
    with pytest.raises(AgentInputError, match="starts at 1"):
        agent.reset(["DarkRoom-v0"], [gym.spaces.Discrete(5, start=1)])
    with pytest.raises(AgentInputError, match="has 4 actions, group 'darkroom' chooses among 5"):
        agent.reset(["DarkRoom-v0"], [gym.spaces.Discrete(4)])


def test_a_prompt_of_stored_discrete_actions_is_fed_as_indices():
    agent = Agent(discrete_model())
    agent.reset(["DarkRoom-v0"])
    steps = 10
    agent.prompt([np.full((steps, 2), 4.0)], [np.arange(steps) % 5], [np.zeros(steps)], [np.arange(steps)])
    assert agent.steps == steps
    with pytest.raises(AgentInputError, match="indices 0-4"):
        agent.reset(["DarkRoom-v0"], discard_context=True)
        agent.prompt([np.full((2, 2), 4.0)], [np.array([0, 9])], [np.zeros(2)], [np.arange(2)])


def test_the_shipped_darkroom_model_reads_its_rewards_on_goals_it_never_saw():
    """`darkroom` (its TRAINING.md): on AD^ε's 16 held-out goals its episodes 5-6 earn about half the optimum with its
    rewards fed back, nothing fed zeros."""
    agent = Agent.from_pretrained("darkroom", threads=1)
    runs = {feed: evaluate_shots(agent, "DarkRoom-heldout-v0", shots=6, seeds=16, first_seed=100, reward_input=feed)
            for feed in ("true", "zero")}
    late = {feed: float(np.nanmean(r.scores[:, 4:])) for feed, r in runs.items()}
    assert late["true"] > late["zero"] + 0.3 and late["zero"] < 0.1, late


def test_the_shipped_keytodoor_model_reads_its_rewards_on_pairs_it_never_saw():
    """`keytodoor` (its TRAINING.md): on 16 held-out (key, door) pairs its episodes 9-12 earn about 0.6 of the
    optimum with its rewards fed back, about a quarter fed zeros (it walks, and finds the key now and then)."""
    agent = Agent.from_pretrained("keytodoor", threads=1)
    runs = {feed: evaluate_shots(agent, "KeyToDoor-heldout-v0", shots=12, seeds=16, first_seed=100, reward_input=feed)
            for feed in ("true", "zero")}
    late = {feed: float(np.nanmean(r.scores[:, 8:])) for feed, r in runs.items()}
    assert late["true"] > late["zero"] + 0.2 and late["true"] > 0.4, late


def test_the_shipped_bandit_model_reads_its_rewards_on_bandits_it_never_saw():
    """`bandit` (its TRAINING.md): on 16 new bandits its episodes 11-20 earn about 0.9 of the best arm with its
    rewards fed back, about a random policy's 0.6 fed zeros."""
    agent = Agent.from_pretrained("bandit", threads=1)
    runs = {feed: evaluate_shots(agent, "BernoulliBandit-v0", shots=20, seeds=16, first_seed=100, reward_input=feed)
            for feed in ("true", "zero")}
    late = {feed: float(np.nanmean(r.scores[:, 10:])) for feed, r in runs.items()}
    assert late["true"] > late["zero"] + 0.15 and late["true"] > 0.8, late
