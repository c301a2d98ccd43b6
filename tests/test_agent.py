"""The agent: cold start equals the model's forward, mixed-group batches, action bounds, held-out
tasks, and clear errors for inputs it cannot take."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable

import numpy as np
import pytest
import torch
from gymnasium.spaces import Box

import vintix
from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    api_error,
    bad_input_test,
    model_checkpoint,
    work,
    workspace,
)
from inference_model import one_torch_thread, random_inputs, tiny_model  # noqa: F401  (autouse fixture)
from vintix.agent import Agent, AgentInputError, AgentOutputError, AgentStateError
from vintix.errors import UnknownTaskError
from vintix.memory import OutOfMemoryError
from vintix.model import save_pretrained

UNBOUNDED = {dim: Box(-np.inf, np.inf, (dim,)) for dim in (1, 4)}


def play(agent: Agent, inputs: list[dict], steps: int) -> list[np.ndarray]:
    """Feed each env's stored obs/reward/starts step by step; actions [steps, act_dim] per env."""
    actions = [[] for _ in inputs]
    for t in range(steps):
        out = agent.act([x["obs"][0, t] for x in inputs], [x["prev_reward"][0, t] for x in inputs],
                        [x["step_num"][0, t] == 0 for x in inputs])
        for i, a in enumerate(out):
            actions[i].append(a)
    return [np.stack(a) for a in actions]


def test_from_pretrained_cold_start_equals_the_models_forward_over_the_same_history(tmp_path):
    save_pretrained(tiny_model(), tmp_path / "ckpt")
    agent = vintix.Agent.from_pretrained(tmp_path / "ckpt")
    model = agent.model
    inputs = random_inputs(model, "metaworld", 1, steps=20, episode=6)
    agent.reset(["push-v3"], [UNBOUNDED[4]])  # no clipping to hide a difference
    actions = play(agent, [inputs], 20)[0]
    # the model sees the agent's own previous actions
    prev_action = np.concatenate([np.zeros((1, 4), np.float32), actions[:-1]])[None]
    with torch.inference_mode():
        expected = model("metaworld", torch.tensor([model.task_index("push-v3")]), torch.tensor(inputs["obs"]),
                         torch.tensor(prev_action), torch.tensor(inputs["prev_reward"]),
                         torch.tensor(inputs["step_num"]))[0].numpy()
    np.testing.assert_allclose(actions, expected, rtol=1e-5, atol=1e-5)


def test_an_episode_return_model_acting_equals_its_forward_given_each_episodes_return_so_far():
    """The agent keeps what each episode earned, stepping and prompting alike: the actions of a run equal the
    model's forward over it with the returns summed here, step by step, from the rewards."""
    model = tiny_model(episode_return=True)
    inputs = random_inputs(model, "metaworld", 1, steps=20, episode=6)
    rewards, steps = inputs["prev_reward"][0], inputs["step_num"][0]
    earned = np.zeros(20, np.float32)
    for t in range(1, 20):
        earned[t] = 0.0 if steps[t] == 0 else earned[t - 1] + rewards[t]
    agent = Agent(model)
    agent.reset(["push-v3"], [UNBOUNDED[4]])
    actions = play(agent, [inputs], 20)[0]
    prev_action = np.concatenate([np.zeros((1, 4), np.float32), actions[:-1]])[None]
    with torch.inference_mode():
        expected = model("metaworld", torch.tensor([model.task_index("push-v3")]), torch.tensor(inputs["obs"]),
                         torch.tensor(prev_action), torch.tensor(inputs["prev_reward"]),
                         torch.tensor(inputs["step_num"]), torch.tensor(earned[None]))[0].numpy()
    np.testing.assert_allclose(actions, expected, rtol=1e-5, atol=1e-5)
    # Prompted with the first 14 steps (rows: the reward after each action), then stepped: the same actions.
    agent.reset(["push-v3"], [UNBOUNDED[4]], discard_context=True)
    agent.prompt([inputs["obs"][0, :14]], [actions[:14]], [rewards[1:15]], [steps[:14]])
    tail = [agent.act([inputs["obs"][0, t]], [rewards[t]], [steps[t] == 0])[0] for t in range(14, 20)]
    np.testing.assert_allclose(tail, expected[14:], rtol=1e-5, atol=1e-5)


def test_a_mixed_group_batch_acts_like_each_env_alone():
    model = tiny_model()
    tasks = ["reach-v3", "InvertedPendulum-v5", "push-v3"]
    spaces = [UNBOUNDED[4], UNBOUNDED[1], UNBOUNDED[4]]
    inputs = [random_inputs(model, model.task_norms[model.task_index(t)].group, 1, steps=12, seed=i)
              for i, t in enumerate(tasks)]
    agent = Agent(model)
    agent.reset(tasks, spaces)
    together = play(agent, inputs, 12)
    for i, task in enumerate(tasks):
        agent.reset([task], [spaces[i]], discard_context=True)
        np.testing.assert_allclose(together[i], play(agent, [inputs[i]], 12)[0], rtol=1e-5, atol=1e-5)


def test_envs_dropped_mid_run_leave_the_others_acting_as_before():
    model = tiny_model()
    tasks = ["reach-v3", "InvertedPendulum-v5", "push-v3", "InvertedPendulum-v5"]
    spaces = [UNBOUNDED[4], UNBOUNDED[1], UNBOUNDED[4], UNBOUNDED[1]]
    inputs = [random_inputs(model, model.task_norms[model.task_index(t)].group, 1, steps=12, seed=i)
              for i, t in enumerate(tasks)]
    agent = Agent(model)
    agent.reset(tasks, spaces)
    together = play(agent, inputs, 12)
    agent.reset(tasks, spaces, discard_context=True)
    first = play(agent, inputs, 5)
    agent.keep([3, 0])  # reordered, and a group (push's) loses a member
    rest = play(agent, [{k: v[:, 5:] for k, v in inputs[i].items()} for i in (3, 0)], 7)
    for env, after in zip((3, 0), rest, strict=True):
        np.testing.assert_allclose(np.concatenate([first[env], after]), together[env], rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="keep needs indices"):
        agent.keep([2])


def test_actions_are_clipped_to_each_envs_bounds():
    model = tiny_model()
    with torch.no_grad():
        for head in model.heads.values():
            head[-1].weight.mul_(1000.0)  # a head that shouts far outside every action space
    agent = Agent(model)
    agent.reset(["reach-v3", "InvertedPendulum-v5"])  # bounds from the real envs: [-1, 1]^4, [-3, 3]
    inputs = [random_inputs(model, "metaworld", 1, 10), random_inputs(model, "mujoco-invertedpendulum", 1, 10)]
    reach, pendulum = play(agent, inputs, 10)
    assert np.abs(reach).max() == pytest.approx(1.0) and np.all(np.abs(reach) <= 1.0)
    assert np.abs(pendulum).max() == pytest.approx(3.0) and np.all(np.abs(pendulum) <= 3.0)


def test_a_model_that_computes_nan_raises_instead_of_returning_nan_actions():
    model = tiny_model()
    with torch.no_grad():
        model.heads["mujoco-invertedpendulum"][-1].bias.fill_(float("nan"))  # a diverged head
    agent = Agent(model)
    agent.reset(["reach-v3", "InvertedPendulum-v5"])
    with pytest.raises(AgentOutputError, match="env 1 \\(InvertedPendulum-v5\\): the model's action is NaN/inf"):
        agent.act([np.zeros(39), np.zeros(4)], [0.0, 0.0], [True, True])


def test_a_held_out_task_uses_its_groups_pooled_normalization():
    agent = Agent(tiny_model())
    agent.reset(["door-lock-v3", "reach-v3"])  # ML45 test task: no statistics in the checkpoint
    assert [t.norm_source for t in agent.tasks] == ["group-pooled", "task"]
    reach, push = (agent.model.task_norms[agent.model.task_index(t)] for t in ("reach-v3", "push-v3"))
    expected_mean = (np.array(reach.obs_mean) + np.array(push.obs_mean)) / 2
    np.testing.assert_allclose(agent.tasks[0].obs_mean.numpy(), expected_mean, rtol=1e-5, atol=1e-5)
    assert len(agent.act([np.zeros(39), np.zeros(39)], [0.0, 0.0], [True, True])) == 2


def test_unknown_task_or_group_is_a_clear_error():
    agent = Agent(tiny_model())
    with pytest.raises(UnknownTaskError, match="reach-v3"):
        agent.reset(["reech-v3"])
    with pytest.raises(UnknownTaskError, match="group 'industrial_benchmark'.*no encoder"):
        agent.reset(["industrial-benchmark-35-v1"])


def test_wrong_observation_dim_or_non_finite_input_is_a_clear_error():
    agent = Agent(tiny_model())
    with pytest.raises(RuntimeError, match="reset"):
        agent.act([np.zeros(39)], [0.0], [True])
    agent.reset(["reach-v3", "InvertedPendulum-v5"])
    with pytest.raises(AgentInputError, match="env 1 .*InvertedPendulum-v5.*shape \\(39,\\).*expects \\(4,\\)"):
        agent.act([np.zeros(39), np.zeros(39)], [0.0, 0.0], [True, True])
    observation = np.zeros(39)
    observation[3] = np.nan
    with pytest.raises(AgentInputError, match="env 0 .*NaN or inf"):
        agent.act([observation, np.zeros(4)], [0.0, 0.0], [True, True])
    with pytest.raises(AgentInputError, match="previous reward contains NaN or inf"):
        agent.act([np.zeros(39), np.zeros(4)], [0.0, np.inf], [False, False])
    # a reward at an episode start is ignored, whatever it is
    assert len(agent.act([np.zeros(39), np.zeros(4)], [np.nan, 0.0], [True, True])) == 2


@pytest.mark.parametrize(("observation", "reward", "start", "message"), [
    (np.full(39, "1.5"), 0.0, True, "observation of env 0 must be real numbers, got <U3"),
    (np.zeros(39) + 1j, 0.0, True, "observation of env 0 must be real numbers, got complex128"),
    (np.zeros(39), None, False, "prev_rewards must be real numbers, got object"),
    (np.zeros(39), 0.0, "yes", "episode_starts must be booleans"),
    (np.zeros(39), 0.0, 2, r"episode_starts must be booleans \(or 0/1\), got \[2\]"),
])
def test_text_complex_or_non_flag_inputs_are_refused_not_converted(observation, reward, start, message):
    agent = Agent(tiny_model())
    agent.reset(["reach-v3"])
    with pytest.raises(AgentInputError, match=message):
        agent.act([observation], [reward], [start])


def test_an_empty_contexts_first_step_must_be_an_episode_start():
    agent = Agent(tiny_model())
    agent.reset(["reach-v3", "reach-v3"])
    with pytest.raises(AgentInputError,
                       match=r"env\(s\) \[1\]: the first step of an empty context must be an episode start"):
        agent.act([np.zeros(39)] * 2, [0.0, 0.0], [True, False])
    agent.act([np.zeros(39)] * 2, [0.0, 0.0], [True, True])
    agent.act([np.zeros(39)] * 2, [1.0, 0.0], [False, True])  # later steps: any mix


def test_keep_takes_distinct_indices_not_a_mask():
    agent = Agent(tiny_model())
    agent.reset(["reach-v3", "push-v3", "reach-v3"])
    with pytest.raises(AgentInputError, match=r"not a mask.*np.flatnonzero\(mask\)"):
        agent.keep([True, False, True])
    with pytest.raises(AgentInputError, match="an index twice"):
        agent.keep([0, 0])
    with pytest.raises(AgentInputError, match="indices in 0..2"):
        agent.keep([0.5])
    agent.keep(np.array([2, 0]))
    assert [t.task for t in agent.tasks] == ["reach-v3", "reach-v3"]


def test_one_agent_stepped_from_two_threads_at_once_is_a_named_error():
    agent = Agent(tiny_model())
    agent.reset(["reach-v3"])
    inside, release = threading.Event(), threading.Event()
    hook = agent.model.ln_f.register_forward_hook(lambda *_: (inside.set(), release.wait(10)) and None)
    first = threading.Thread(target=agent.act, args=([np.zeros(39)], [0.0], [True]))
    first.start()
    assert inside.wait(10)  # the first thread is inside act, in the model's forward
    with pytest.raises(AgentStateError, match="agent.act while another thread is inside this agent"):
        agent.act([np.zeros(39)], [0.0], [True])
    release.set()
    first.join()
    hook.remove()
    assert agent.steps == 1  # only the first thread's step went in


def test_misuse_of_the_agent_is_a_named_error():
    agent = Agent(tiny_model())
    for call in (lambda: agent.act([np.zeros(39)], [0.0], [True]), lambda: agent.keep([0]),
                 lambda: agent.prompt([np.zeros((2, 39))], [np.zeros((2, 4))], [np.zeros(2)], [np.arange(2)])):
        with pytest.raises(AgentStateError, match="call agent.reset"):
            call()
    with pytest.raises(AgentInputError, match="at least one task"):
        agent.reset([])
    with pytest.raises(AgentInputError, match="2 tasks but 1 action spaces"):
        agent.reset(["reach-v3", "push-v3"], [UNBOUNDED[4]])
    agent.reset(["reach-v3"], [UNBOUNDED[4]])
    with pytest.raises(AgentInputError, match="prev_rewards must be real numbers"):
        agent.act([np.zeros(39)], ["lots"], [False])
    window = agent.model.config.context_len
    with pytest.raises(AgentInputError, match=f"a prompt of {window + 1} steps after 0 does not fit the model's "
                                              f"{window}-step window"):
        agent.prompt([np.zeros((window + 1, 39))], [np.zeros((window + 1, 4))], [np.zeros(window + 1)],
                     [np.arange(window + 1)])


def test_a_gaussian_policy_samples_reproducibly_from_its_seed():
    model = tiny_model(policy="gaussian")
    inputs = random_inputs(model, "metaworld", 1, steps=10)

    def run(seed: int) -> np.ndarray:
        agent = Agent(model, seed=seed)
        agent.reset(["reach-v3"], [UNBOUNDED[4]])
        return play(agent, [inputs], 10)[0]

    first = run(0)
    np.testing.assert_array_equal(first, run(0))  # reset restarts the draws
    assert not np.allclose(first, run(1))


@pytest.mark.parametrize("sample_noise", ["step", "episode"])
def test_a_flow_heads_noise_is_drawn_each_step_or_held_for_an_episode(sample_noise):
    """'episode': one draw at each episode start, held to its end (one posterior sample an episode); 'step': a
    fresh draw every step. The action is the flow of that noise, reproducible from the seed."""
    model = tiny_model(policy="flow", sample_noise=sample_noise)
    inputs = random_inputs(model, "metaworld", 1, steps=14)  # two episodes of 7 steps
    agent = Agent(model)
    agent.reset(["reach-v3"], [UNBOUNDED[4]])
    noises = []
    for t in range(14):
        agent.act([inputs["obs"][0, t]], [inputs["prev_reward"][0, t]], [inputs["step_num"][0, t] == 0])
        noises.append(agent._held_noise["metaworld"][0].clone())
    same_as_last = [torch.equal(a, b) for a, b in zip(noises, noises[1:], strict=False)]
    if sample_noise == "episode":
        assert same_as_last == [t % 7 != 6 for t in range(13)]  # a new draw at step 7 only
    else:
        assert not any(same_as_last)
    agent.reset(["reach-v3"], [UNBOUNDED[4]], discard_context=True)
    again = play(agent, [inputs], 14)[0]
    agent.reset(["reach-v3"], [UNBOUNDED[4]], discard_context=True)
    np.testing.assert_array_equal(again, play(agent, [inputs], 14)[0])


def test_a_context_or_batch_beyond_the_machines_memory_is_refused_before_allocating(tmp_path):
    model = tiny_model()
    save_pretrained(model, tmp_path)
    meta = json.loads((tmp_path / "config.json").read_text())
    (tmp_path / "config.json").write_text(json.dumps({**meta, "config": {**meta["config"], "context_len": 10**9}}))
    agent = Agent.from_pretrained(tmp_path)  # the weights do not depend on the context's length
    with pytest.raises(OutOfMemoryError, match="a KV cache for 1 envs over a 1000000000-step context needs"):
        agent.reset(["reach-v3"])


def test_threads_sets_torchs_cpu_threads_when_asked_and_leaves_them_otherwise():
    before = torch.get_num_threads()
    try:
        Agent(tiny_model(), threads=2)
        assert torch.get_num_threads() == 2
        Agent(tiny_model())
        assert torch.get_num_threads() == 2  # None: left as it is
        with pytest.raises(AgentInputError, match="threads must be a whole number of CPU threads from 1 to 1024"):
            Agent(tiny_model(), threads=0)
    finally:
        torch.set_num_threads(before)


# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

def agent(tasks: list[str] | None = None) -> object:
    from vintix.agent import Agent

    a = Agent.from_pretrained(model_checkpoint())
    if tasks is not None:
        a.reset(tasks)
    return a


api_error("agent", "act before reset", lambda: agent().act([np.zeros(39)], [0.0], [True]), "reset")
api_error("agent", "reset with no tasks", lambda: agent([]), "at least one task")
# Issue 55, class 6: every Python entry point checks its arguments' types and ranges.
api_error("agent", "reset with a None task", lambda: agent([None]), "must be task names")  # type: ignore[list-item]
api_error("agent", "reset with one name, not a list", lambda: agent("reach-v3"), "a list of task names")  # type: ignore[arg-type]
for threads in (1.5, "2", True, 2**40, 100000, 0, -1):
    api_error("agent", f"Agent(threads={threads!r})",
              lambda threads=threads: __import__("vintix").Agent.from_pretrained(model_checkpoint(), threads=threads),
              "whole number of CPU threads from 1 to 1024")
api_error("agent", "reset with an unknown task", lambda: agent(["reech-v3"]), "Did you mean")
api_error("agent", "reset with a task of another group", lambda: agent(["Hopper-v5"]), "no encoder")
api_error("agent", "reset with too few action spaces", lambda: agent().reset(["reach-v3", "push-v3"], []),
          "action spaces")
api_error("agent", "act with a NaN observation", lambda: agent(["reach-v3"]).act([np.full(39, np.nan)], [0.0], [True]),
          "NaN or inf")
api_error("agent", "act with an inf reward", lambda: agent(["reach-v3"]).act([np.zeros(39)], [np.inf], [False]),
          "NaN or inf")
api_error("agent", "act with a wrong observation size", lambda: agent(["reach-v3"]).act([np.zeros(11)], [0.0], [True]),
          "shape (11,)")
api_error("agent", "act with two observations for one env", lambda: agent(["reach-v3"]).act(
    [np.zeros(39), np.zeros(39)], [0.0, 0.0], [True, True]), "reset with 1 envs")
api_error("agent", "keep an index out of range", lambda: agent(["reach-v3"]).keep([3]), "keep needs indices")
api_error("agent", "act with a text reward", lambda: agent(["reach-v3"]).act([np.zeros(39)], ["lots"], [False]),
          "reward")
api_error("agent", "act with a None observation", lambda: agent(["reach-v3"]).act([None], [0.0], [True]),
          "real numbers")
api_error("agent", "from_pretrained on a device this machine lacks", lambda: __import__("vintix").Agent.from_pretrained(
    model_checkpoint(), device="cuda" if not torch.cuda.is_available() else "tpu"), "device")
api_error("agent", "reset with an action space of the wrong size", lambda: agent().reset(
    ["reach-v3"], [__import__("gymnasium").spaces.Box(-1, 1, (7,))]), "action space has shape (7,)")


def nan_model_acts() -> object:
    from vintix.agent import Agent

    a = Agent.from_pretrained(model_checkpoint())
    with torch.no_grad():
        for parameter in a.model.heads.parameters():
            parameter.fill_(float("nan"))
    a.reset(["reach-v3"])
    return a.act([np.zeros(39)], [0.0], [True])


api_error("agent", "act with a NaN model", nan_model_acts, "NaN/inf")
api_error("agent", "prompt with NaN rewards", lambda: agent(["reach-v3"]).prompt(
    [np.zeros((5, 39))], [np.zeros((5, 4))], [np.full(5, np.nan)], [np.arange(5)]), "NaN or inf")
api_error("agent", "prompt longer than the window", lambda: agent(["reach-v3"]).prompt(
    [np.zeros((100, 39))], [np.zeros((100, 4))], [np.zeros(100)], [np.arange(100)]), "window")
api_error("agent", "prompts of different lengths", lambda: agent(["reach-v3", "push-v3"]).prompt(
    [np.zeros((5, 39)), np.zeros((4, 39))], [np.zeros((5, 4)), np.zeros((4, 4))], [np.zeros(5), np.zeros(4)],
    [np.arange(5), np.arange(4)]), "same number of steps")
api_error("agent", "from_pretrained of a missing name",
          lambda: __import__("vintix").Agent.from_pretrained("no-such-model"), "no shipped model")

# The agent never changes the experiment silently (issue 47, class 5).
def predict_after(first: dict[str, object], then: dict[str, object], envs: int = 1) -> Callable[[], object]:
    def call() -> object:
        import vintix

        agent = vintix.Agent.from_pretrained(model_checkpoint())
        agent.reset(["reach-v3"] * envs)
        obs = np.zeros(39) if envs == 1 else np.zeros((envs, 39))
        agent.predict(obs, **first)
        return agent.predict(obs, **then)
    return call


api_error("agent", "predict with no reward mid-episode (it would feed zeros)",
          predict_after({}, {"reward": None, "episode_start": False}), "reward is None")
api_error("agent", "predict with one reward for two envs", predict_after({}, {"reward": 0.5, "episode_start": [False,
          False]}, envs=2), "reward has 1 value")
api_error("agent", "predict with three episode_start flags for two envs", predict_after(
    {}, {"reward": [0.5, 0.5], "episode_start": [False, False, True]}, envs=2), "episode_start has 3 value")


test_bad_input_ends_as_expected = bad_input_test("agent")
