"""The agent as a policy: `Agent.predict` in a plain Gymnasium loop and in vector-env loops (both autoreset
modes) plays exactly what `vintix eval` plays, and a new episode never clears the context."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

from inference_model import one_torch_thread, tiny_model  # noqa: F401  (autouse fixture)
from vintix.agent import Agent
from vintix.agent.agent import AgentInputError, AgentStateError, ContextDiscardedWarning
from vintix.evaluate import EvalConfig, evaluate
from vintix.tasks import make_env


def eval_returns(model, task, seeds, shots):
    rows, _ = evaluate(Agent(model), EvalConfig(tasks=[task], shots=shots, seeds=len(seeds), first_seed=seeds[0]))
    return {(r["seed"], r["shot"]): r["return"] for r in rows}


def single_env_loop(agent, task, seed, shots):
    """The README's plain Gymnasium loop."""
    env = make_env(task, seed=seed)
    agent.reset([task], [env.action_space])
    obs, _ = env.reset()
    reward, start, episode_return, returns = 0.0, True, 0.0, []
    while len(returns) < shots:
        action, _ = agent.predict(obs, reward, start)
        obs, reward, terminated, truncated, _ = env.step(action)
        episode_return += reward
        start = terminated or truncated
        if start:
            returns.append(episode_return)
            episode_return = 0.0
            obs, _ = env.reset()
    return returns


def vector_loop(agent, task, seeds, shots, mode):
    """The README's vector-env loop, in either autoreset mode."""
    envs = gym.vector.SyncVectorEnv([lambda s=s: make_env(task, seed=s) for s in seeds], autoreset_mode=mode)
    agent.reset([task] * len(seeds), [envs.single_action_space] * len(seeds), discard_context=True)
    obs, _ = envs.reset()
    rewards, starts = np.zeros(len(seeds)), np.ones(len(seeds), dtype=bool)
    episode_returns, returns = np.zeros(len(seeds)), [[] for _ in seeds]
    while min(map(len, returns)) < shots:
        actions, _ = agent.predict(obs, rewards, starts, autoreset=mode)
        obs, rewards, terminated, truncated, _ = envs.step(actions)
        episode_returns += rewards
        starts = terminated | truncated
        for i in np.flatnonzero(starts):
            returns[i].append(float(episode_returns[i]))
            episode_returns[i] = 0.0
    envs.close()
    return returns, starts  # the episodes' returns per env, and which envs ended on the last step


@pytest.mark.parametrize("last_reward", [False, True])
def test_a_plain_gymnasium_loop_plays_exactly_what_eval_plays(last_reward):
    model = tiny_model(last_reward=last_reward)
    for task, seed in (("reach-v3", 7), ("InvertedPendulum-v5", 3)):
        expected = eval_returns(model, task, [seed], 4)
        assert single_env_loop(Agent(model), task, seed, 4) == [expected[(seed, shot)] for shot in range(1, 5)]


@pytest.mark.parametrize("last_reward", [False, True])
@pytest.mark.parametrize("mode", [gym.vector.AutoresetMode.SAME_STEP, gym.vector.AutoresetMode.NEXT_STEP])
def test_a_vector_env_loop_plays_exactly_what_eval_plays(mode, last_reward):
    model, seeds = tiny_model(last_reward=last_reward), [11, 12, 13]
    expected = eval_returns(model, "reach-v3", seeds, 3)
    returns, _ = vector_loop(Agent(model), "reach-v3", seeds, 3, mode)
    assert returns == [[expected[(s, shot)] for shot in (1, 2, 3)] for s in seeds]


@pytest.mark.parametrize("keep_first_steps", [0, 8])
def test_next_step_autoreset_feeds_no_token_for_a_finished_episodes_last_observation(keep_first_steps):
    # InvertedPendulum episodes end at different steps: envs sit out steps at different times, also in a
    # window that keeps the run's first steps.
    model, seeds = tiny_model(keep_first_steps=keep_first_steps), [1, 2, 3, 4]
    agent = Agent(model)
    same, _ = vector_loop(Agent(model), "InvertedPendulum-v5", seeds, 6, gym.vector.AutoresetMode.SAME_STEP)
    nxt, last_starts = vector_loop(agent, "InvertedPendulum-v5", seeds, 6, gym.vector.AutoresetMode.NEXT_STEP)
    assert agent.cache.length > 2 * agent.cache.window  # the ring has turned over
    # The same tokens in the same order per env: the episodes come out the same (up to float rounding of
    # a batch whose envs sit in other cache slots).
    np.testing.assert_allclose([r[:6] for r in nxt], [r[:6] for r in same], rtol=1e-4)
    # Each env took one token per step of its own episodes and sat out the step after each finished one
    # (but the last, whose next step never came).
    sat_out = [len(r) - int(ended) for r, ended in zip(nxt, last_starts, strict=True)]
    assert [agent.cache.length - c for c in agent.cache.clocks.tolist()] == sat_out


def test_a_new_episode_is_a_flag_and_reset_warns_before_clearing_a_context():
    agent = Agent(tiny_model())
    env = make_env("reach-v3", seed=0)
    agent.reset(["reach-v3"], [env.action_space])
    obs, _ = env.reset()
    agent.predict(obs)
    agent.predict(obs, 1.0, episode_start=True)  # a new episode: the context goes on
    assert agent.steps == 2
    with pytest.warns(ContextDiscardedWarning, match="episode_start=True"):
        agent.reset(["reach-v3"])
    assert agent.steps == 0
    agent.predict(obs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        agent.reset(["reach-v3"], discard_context=True)


def test_predict_shapes_and_errors():
    agent = Agent(tiny_model())
    with pytest.raises(AgentStateError, match="reset"):
        agent.predict(np.zeros(39))
    agent.reset(["reach-v3"])
    action, state = agent.predict(np.zeros(39))
    assert action.shape == (4,) and state is None
    agent.reset(["reach-v3", "InvertedPendulum-v5"], discard_context=True)
    with pytest.raises(AgentInputError, match="2 env"):
        agent.predict(np.zeros(39))
    with pytest.raises(AgentInputError, match="autoreset"):
        agent.predict([np.zeros(39), np.zeros(4)], autoreset="eventually")


@pytest.mark.parametrize("last_reward", [False, True])
def test_an_episodes_last_reward_reaches_only_a_last_reward_model(last_reward):
    """The reward passed with episode_start=True is the previous episode's last: the paper's layout never sees
    it (a success bonus paid at the end would be invisible), a last_reward model does."""
    def second_episode_action(last: float) -> np.ndarray:
        agent = Agent(tiny_model(last_reward=last_reward))
        agent.reset(["InvertedPendulum-v5"])
        for step in range(5):
            agent.predict(np.full(4, 0.1 * step), 1.0, step == 0)
        return agent.predict(np.zeros(4), last, True)[0]

    plus, minus = second_episode_action(1000.0), second_episode_action(-1000.0)
    assert np.array_equal(plus, minus) != last_reward
    agent = Agent(tiny_model(last_reward=last_reward))
    agent.reset(["InvertedPendulum-v5"])
    agent.predict(np.zeros(4))
    if last_reward:  # the start reads a reward: None there would feed a silent zero
        with pytest.raises(AgentInputError, match="previous episode's last reward"):
            agent.predict(np.zeros(4), None, True)
    else:
        agent.predict(np.zeros(4), None, True)


@pytest.mark.parametrize("last_action", [False, True])
def test_an_episodes_last_action_reaches_only_a_last_action_model(last_action):
    """The action that ended an episode (Key-to-Door's step onto the door) is seen at the next episode's start only
    by a last_action model; the prompt's rows shift across episodes as training windows do."""
    def second_episode_action(last: float) -> np.ndarray:
        agent = Agent(tiny_model(last_reward=True, last_action=last_action))
        agent.reset(["InvertedPendulum-v5"])
        actions = np.array([[0.1], [0.2], [0.3], [last]])
        agent.prompt([np.zeros((4, 4))], [actions], [np.ones(4)], [np.arange(4)])
        return agent.predict(np.zeros(4), 1.0, True)[0]

    assert np.array_equal(second_episode_action(2.0), second_episode_action(-2.0)) != last_action


def test_the_agent_never_feeds_a_reward_it_was_not_given_nor_spreads_one_over_several_envs():
    """A missing reward mid-episode would be the zero-reward ablation, run unasked; one reward for two envs,
    or flags of the wrong count, would silently be spread or cut."""
    agent = Agent(tiny_model())
    agent.reset(["reach-v3", "reach-v3"])  # a vector env of one task, as predict takes
    obs = np.zeros((2, 39))
    agent.predict(obs)  # the first step starts every episode: no reward to read
    with pytest.raises(AgentInputError, match=r"reward is None, but env\(s\) \[0, 1\] are mid-episode"):
        agent.predict(obs, None, [False, False])
    with pytest.raises(AgentInputError, match=r"reward is None, but env\(s\) \[1\]"):
        agent.predict(obs, None, [True, False])
    agent.predict(obs, None, [True, True])  # every env starts an episode: nothing to read
    with pytest.raises(AgentInputError, match="reward has 1 value"):
        agent.predict(obs, 0.5, [False, False])
    with pytest.raises(AgentInputError, match="episode_start has 3 value"):
        agent.predict(obs, [0.5, 0.5], [False, False, True])
    assert agent.steps == 2  # no refused call fed a token
