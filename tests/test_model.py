"""The model: ALiBi attention, causality, group routing, episode-start padding, normalization."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
import torch

from vintix.errors import UnknownTaskError
from vintix.model import (
    GroupSpec,
    ModelConfig,
    TaskNorm,
    Vintix,
    alibi_bias,
    alibi_slopes,
    attention,
    count_parameters,
    preset,
)
from vintix.model.model import LOG_STD_RANGE, action_head, fourier_features

GROUPS = [GroupSpec("A", obs_dim=5, act_dim=2), GroupSpec("B", obs_dim=7, act_dim=3)]
TASKS = [
    TaskNorm("a0", "A", obs_mean=[0.0] * 5, obs_std=[1.0] * 5, reward_scale=1.0),
    TaskNorm("a1", "A", obs_mean=[1.0, -2.0, 0.5, 3.0, 0.0], obs_std=[2.0, 0.5, 1.0, 4.0, 0.0], reward_scale=0.1),
    TaskNorm("b0", "B", obs_mean=[0.0] * 7, obs_std=[1.0] * 7, reward_scale=1.0),
]


def tiny_config(**overrides) -> ModelConfig:
    fields = dict(n_layers=2, n_heads=2, obs_emb_dim=14, act_emb_dim=14, rew_emb_dim=4, mlp_dim=64,
                  head_layers=1, context_len=32, dropout=0.0)
    return ModelConfig(**{**fields, **overrides})


def make_model(**overrides) -> Vintix:
    torch.manual_seed(0)
    return Vintix(tiny_config(**overrides), GROUPS, TASKS).eval()


def make_batch(group: str, task: str, model: Vintix, B: int = 2, T: int = 12, seed: int = 1) -> dict:
    g = torch.Generator().manual_seed(seed)
    spec = model.groups[group]
    step_num = torch.arange(T).remainder(5).expand(B, T).clone()  # episodes of 5 steps
    return dict(
        group=group,
        task_idx=torch.full((B,), model.task_index(task), dtype=torch.long),
        obs=torch.randn(B, T, spec.obs_dim, generator=g),
        prev_action=torch.rand(B, T, spec.act_dim, generator=g) * 2 - 1,
        prev_reward=torch.randn(B, T, generator=g),
        step_num=step_num,
    )


# --- attention -------------------------------------------------------------------------------


def test_alibi_slopes_follow_the_alibi_paper():
    assert torch.allclose(alibi_slopes(8), torch.tensor([2.0 ** -(i + 1) for i in range(8)]))
    # Non-power of 2: the 8-head slopes, then every other slope of the 16-head sequence.
    twelve = alibi_slopes(12)
    expected = [2.0 ** -(i + 1) for i in range(8)] + [2.0 ** -(0.5 + i) for i in range(4)]
    assert torch.allclose(twelve, torch.tensor(expected))
    assert len(set(twelve.tolist())) == 12 and bool((twelve > 0).all())


def reference_attention(q, k, v, q_pos, k_pos, slopes):
    scores = q @ k.transpose(-2, -1) / math.sqrt(q.shape[-1])
    rel = (q_pos[:, None] - k_pos[None, :]).float()
    scores = scores - slopes[:, None, None] * rel
    scores = scores.masked_fill(rel < 0, float("-inf"))
    return torch.softmax(scores, dim=-1) @ v


def test_alibi_attention_matches_explicit_softmax_with_key_window_offset():
    torch.manual_seed(0)
    B, H, d = 2, 4, 8
    q = torch.randn(B, H, 10, d)
    k, v = torch.randn(B, H, 15, d), torch.randn(B, H, 15, d)
    slopes = alibi_slopes(H)
    q_pos, k_pos = torch.arange(100, 110), torch.arange(95, 110)

    out = attention(q, k, v, alibi_bias(q_pos, k_pos, slopes))
    assert torch.allclose(out, reference_attention(q, k, v, q_pos, k_pos, slopes), atol=1e-5)
    # Only relative positions matter: what lets a sliding window keep its cache.
    shifted = attention(q, k, v, alibi_bias(q_pos - 95, k_pos - 95, slopes))
    assert torch.allclose(out, shifted, atol=1e-6)
    # Batched positions (one row per env) broadcast over heads.
    bias_b = alibi_bias(torch.stack([q_pos, q_pos + 7]), torch.stack([k_pos, k_pos + 7]), slopes)
    assert bias_b.shape == (B, H, 10, 15)
    assert torch.allclose(attention(q, k, v, bias_b), out, atol=1e-6)
    # A single query (a cached agent step) takes its own matrix-vector path: same answer.
    last = attention(q[:, :, -1:], k, v, alibi_bias(q_pos[-1:], k_pos, slopes))
    assert torch.allclose(last, out[:, :, -1:], atol=1e-6)


# --- the model ---------------------------------------------------------------------------------


def test_changing_step_t_never_changes_earlier_outputs():
    model = make_model()
    batch = make_batch("A", "a0", model)
    before = model(**batch)
    t = 6
    for key in ("obs", "prev_action", "prev_reward"):
        batch[key] = batch[key].clone()
        batch[key][:, t:] += 3.0
    after = model(**batch)
    assert torch.allclose(before[:, :t], after[:, :t], atol=1e-6)
    assert not torch.allclose(before[:, t:], after[:, t:], atol=1e-3)


def test_groups_use_their_own_encoders_and_heads():
    model = make_model()
    a, b = make_batch("A", "a0", model), make_batch("B", "b0", model)
    out_a, out_b = model(**a), model(**b)
    assert out_a.shape == (2, 12, 2) and out_b.shape == (2, 12, 3)

    with torch.no_grad():
        model.encoders["A"].obs[0].weight.add_(0.5)
    assert not torch.allclose(model(**a), out_a, atol=1e-4)
    assert torch.equal(model(**b), out_b)
    with torch.no_grad():
        model.heads["A"][-1].weight.add_(0.5)
    assert torch.equal(model(**b), out_b)


def test_mixing_groups_by_concatenating_embeddings_equals_per_group_forward():
    model = make_model()
    a, b = make_batch("A", "a1", model), make_batch("B", "b0", model)
    h = model.backbone(torch.cat([model.embed(**a), model.embed(**b)]))
    assert torch.allclose(model.head("A", h[:2]), model(**a), atol=1e-5)
    assert torch.allclose(model.head("B", h[2:]), model(**b), atol=1e-5)


def test_previous_action_and_reward_are_ignored_at_episode_starts():
    model = make_model()
    batch = make_batch("A", "a0", model)
    out = model(**batch)
    starts = batch["step_num"] == 0
    assert starts.sum() > 2
    changed = {**batch, "prev_action": batch["prev_action"].clone(), "prev_reward": batch["prev_reward"].clone()}
    changed["prev_action"][starts] = 5.0
    changed["prev_reward"][starts] = -7.0
    assert torch.equal(model(**changed), out)
    # Away from episode starts they do matter.
    changed["prev_reward"][~starts] += 1.0
    assert not torch.allclose(model(**changed), out, atol=1e-4)


def test_last_reward_reaches_an_episodes_first_token_and_every_parameter_learns():
    model = make_model(last_reward=True).train()
    batch = make_batch("A", "a0", model)
    out = model(**batch)
    starts = batch["step_num"] == 0
    changed = {**batch, "prev_action": batch["prev_action"].clone(), "prev_reward": batch["prev_reward"].clone()}
    changed["prev_action"][starts] = 5.0  # an episode start still has no previous action
    assert torch.equal(model(**changed), out)
    changed["prev_reward"][starts] = -7.0  # ... but the previous episode's last reward
    assert not torch.allclose(model(**changed)[starts], out[starts], atol=1e-4)
    # No reward padding is left unused: a parameter without a gradient would make DDP fail.
    assert all(enc.rew_pad is None for enc in model.encoders.values())
    out.square().mean().backward()
    unused = [n for n, p in model.named_parameters() if p.grad is None and ".B." not in n]  # the batch is group A's
    assert not unused


def test_an_episode_return_model_reads_what_the_episode_earned_and_others_do_not():
    """`episode_return`: the return so far reaches every token but the episode's first (where it is 0 anyway) and
    changes the outputs; a model without it is unchanged by it; one with it refuses to run without it."""
    batch = make_batch("A", "a0", make_model())
    starts = batch["step_num"] == 0
    earned = torch.rand(batch["prev_reward"].shape, generator=torch.Generator().manual_seed(2))
    model = make_model(episode_return=True)
    out = model(**batch, prev_return=earned)
    changed = earned.clone()
    changed[starts] += 3.0
    assert torch.equal(model(**batch, prev_return=changed), out)
    changed[~starts] += 1.0
    assert not torch.allclose(model(**batch, prev_return=changed)[~starts], out[~starts], atol=1e-4)
    plain = make_model()
    assert torch.equal(plain(**batch, prev_return=earned), plain(**batch))
    with pytest.raises(ValueError, match="episode_return.*pass prev_return"):
        model(**batch)


@pytest.mark.parametrize("shared_padding", [False, True])
def test_last_action_reaches_an_episodes_first_token_and_leaves_no_padding_unused(shared_padding):
    model = make_model(last_reward=True, last_action=True, shared_padding=shared_padding).train()
    batch = make_batch("A", "a0", model)
    out = model(**batch)
    starts = batch["step_num"] == 0
    changed = {**batch, "prev_action": batch["prev_action"].clone()}
    changed["prev_action"][starts] = 5.0  # the previous episode's last action, which ended it
    assert not torch.allclose(model(**changed)[starts], out[starts], atol=1e-4)
    out.square().mean().backward()
    unused = [n for n, p in model.named_parameters() if p.grad is None and ".B." not in n]
    assert not unused and not [n for n, _ in model.named_parameters() if n.endswith("act_pad")]
    with pytest.raises(ValueError, match="last_action needs last_reward"):
        tiny_config(last_action=True)


def test_observations_are_normalized_per_task_with_a_std_floor():
    model = make_model(std_floor=0.25)
    a1 = model.task_index("a1")
    obs = torch.randn(1, 3, 5)
    obs_n, rew = model.normalize(torch.tensor([a1]), obs, torch.ones(1, 3))
    mean = torch.tensor([1.0, -2.0, 0.5, 3.0, 0.0])
    std = torch.tensor([2.0, 0.5, 1.0, 4.0, 0.25])  # the zero std is floored
    assert torch.allclose(obs_n, (obs - mean) / std)
    assert torch.allclose(rew, torch.full((1, 3), 0.1))

    # Same raw inputs, different task statistics within a group -> different predictions.
    batch = make_batch("A", "a0", model)
    other = {**batch, "task_idx": torch.full((2,), a1)}
    assert not torch.allclose(model(**batch), model(**other), atol=1e-4)


def test_identical_statistics_make_tasks_indistinguishable():
    # The model has no task identity besides normalization.
    tasks = [TaskNorm("x", "A", [0.0] * 5, [1.0] * 5), TaskNorm("y", "A", [0.0] * 5, [1.0] * 5)]
    torch.manual_seed(0)
    model = Vintix(tiny_config(), GROUPS[:1], tasks).eval()
    batch = make_batch("A", "x", model)
    assert torch.equal(model(**batch), model(**{**batch, "task_idx": torch.ones(2, dtype=torch.long)}))


def test_mask_reward_makes_outputs_independent_of_rewards():
    model = make_model(mask_reward=True)
    assert all(enc.rew is None for enc in model.encoders.values())
    batch = make_batch("A", "a0", model)
    out = model(**batch)
    assert torch.equal(model(**{**batch, "prev_reward": batch["prev_reward"] * -10 + 3}), out)


def test_bad_inputs_are_refused_with_clear_errors():
    model = make_model()
    batch = make_batch("A", "a0", model)
    with pytest.raises(ValueError, match="outside group"):
        model(**{**batch, "task_idx": torch.full((2,), model.task_index("b0"))})
    with pytest.raises(ValueError, match="obs_dim"):
        model(**{**batch, "group": "B"})
    with pytest.raises(ValueError, match="context_len"):
        model(**make_batch("A", "a0", model, T=33))
    with pytest.raises(UnknownTaskError):
        model.task_index("nope")
    with pytest.raises(ValueError, match="obs_dim"):
        Vintix(tiny_config(), GROUPS, [TaskNorm("bad", "A", [0.0] * 4, [1.0] * 4)])


def test_a_few_optimizer_steps_fit_a_fixed_batch():
    model = make_model().train()
    batch = make_batch("A", "a0", model, T=16)
    target = torch.tanh(batch["obs"][..., :2] + batch["prev_reward"].unsqueeze(-1))
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3)
    losses = []
    for _ in range(40):
        loss = torch.nn.functional.mse_loss(model(**batch), target)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.3 * losses[0]


# --- size --------------------------------------------------------------------------------------

# The groups of the paper's 102 tasks: MuJoCo one per env (gymnasium v5 dims), Meta-World,
# Industrial Benchmark, and Bi-DexHands grouped by (obs, act) dims.
PAPER_GROUPS = [
    GroupSpec(name, obs, act)
    for name, obs, act in [
        ("Ant", 105, 8), ("HalfCheetah", 17, 6), ("Hopper", 11, 3), ("Humanoid", 348, 17),
        ("HumanoidStandup", 348, 17), ("InvertedDoublePendulum", 9, 1), ("InvertedPendulum", 4, 1),
        ("Pusher", 23, 7), ("Reacher", 10, 2), ("Swimmer", 8, 2), ("Walker2d", 17, 6),
        ("metaworld", 39, 4), ("industrial_benchmark", 6, 3),
        ("dex_428_52", 428, 52), ("dex_420_52", 420, 52), ("dex_422_52", 422, 52), ("dex_417_52", 417, 52),
        ("dex_425_52", 425, 52), ("dex_446_52", 446, 52), ("dex_422_40", 422, 40), ("dex_398_40", 398, 40),
    ]
]


def test_paper_preset_has_the_papers_parameter_count():
    with torch.device("meta"):
        model = Vintix(preset("paper"), PAPER_GROUPS, [])
    assert model.config.d_model == 1024
    assert abs(count_parameters(model) / 332_100_768 - 1) < 0.05


# --- reward encoder and policy ------------------------------------------------------------------


def test_the_mlp_reward_encoder_tells_rewards_apart_where_the_linear_one_can_go_flat():
    model = make_model(reward_encoder="mlp", rew_emb_dim=8, obs_emb_dim=10, act_emb_dim=10)
    encoder = model.encoders["A"].rew
    codes = encoder(torch.linspace(-1.5, 1.5, 7).unsqueeze(-1))
    assert codes.shape == (7, 8)
    distinct = torch.cdist(codes, codes)[~torch.eye(7, dtype=torch.bool)]
    assert distinct.min() > 1e-3  # every unit-scale reward gets its own code


def test_a_gaussian_policy_predicts_a_mean_and_a_bounded_log_std():
    model = make_model(policy="gaussian")
    batch = make_batch("B", "b0", model)
    h = model.backbone(model.embed(**batch))
    mean, log_std = model.action_head("B").distribution(h)
    assert mean.shape == log_std.shape == (2, 12, 3)
    assert torch.equal(model.head("B", h), mean) and torch.equal(model(**batch), mean)
    assert log_std.min() >= LOG_STD_RANGE[0] and log_std.max() <= LOG_STD_RANGE[1]


@pytest.mark.parametrize("policy", ["deterministic", "gaussian", "flow"])
def test_every_head_trains_and_acts_through_one_interface(policy):
    """The model, the trainer and the agent call the head's loss and act, whatever its kind."""
    model = make_model(policy=policy)
    batch = make_batch("B", "b0", model)
    h = model.backbone(model.embed(**batch))
    head = model.action_head("B")
    loss = head.loss(h, torch.rand(2, 12, 3))
    assert loss.shape == (2, 12) and torch.isfinite(loss).all()
    loss.mean().backward()  # every parameter of the head is trained
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in head.parameters())
    streams = [torch.Generator().manual_seed(i) for i in range(2)]
    actions, finite = head.act(h[:, -1].detach(), torch.stack([head.draw_noise(g) for g in streams]))
    assert actions.shape == (2, 3) and finite.all()
    greedy = head.act(h[:, -1].detach(), None)[0]
    assert torch.allclose(greedy, model.head("B", h[:, -1].detach()), atol=1e-6)


def test_a_discrete_group_has_a_categorical_head_whatever_the_policy():
    spec = GroupSpec("D", obs_dim=2, act_dim=5, discrete=True)
    head = action_head(spec, tiny_config(policy="flow"))
    h = torch.randn(3, tiny_config().d_model)
    probabilities = head(h).softmax(-1)
    uniform = torch.tensor([[0.0], [0.999999], [0.5]])
    indices = head.act(h, uniform)[0]  # inverse-CDF draws: the first action, the last, the median's
    assert indices.dtype == torch.long and indices[:2].tolist() == [0, 4]
    assert probabilities[2, :indices[2]].sum() < 0.5 <= probabilities[2, :indices[2] + 1].sum()
    assert head.encode_previous(torch.tensor([[4, 0]])).tolist() == [[[0, 0, 0, 0, 1], [1, 0, 0, 0, 0]]]


def test_a_flow_head_draws_one_of_two_modes_where_the_mse_head_averages_them():
    """A posterior of two goals (left or right, as on Ant-Dir): MSE learns their mean, standing still; the flow
    head's draws land on one mode or the other, each about half the time."""
    torch.manual_seed(0)
    spec, config = GroupSpec("B", obs_dim=1, act_dim=1), tiny_config(head_layers=2)
    heads = {policy: action_head(spec, replace(config, policy=policy)) for policy in ("deterministic", "flow")}
    h = torch.randn(1, 1, config.d_model).expand(64, 1, -1)  # one context, whose next action is -1 or +1
    for head in heads.values():
        optimizer = torch.optim.Adam(head.parameters(), lr=3e-3)
        for _ in range(400):
            target = torch.randint(0, 2, (64, 1, 1)).float() * 2 - 1
            optimizer.zero_grad()
            head.loss(h, target).mean().backward()
            optimizer.step()
    with torch.no_grad():
        assert abs(heads["deterministic"].predict(h[:1, 0]).item()) < 0.2
        draws = heads["flow"].act(h[:, 0], torch.randn(64, 1, generator=torch.Generator().manual_seed(1)))[0]
    assert (draws.abs() > 0.6).float().mean() > 0.8  # on a mode, not between them
    assert 0.25 < (draws > 0).float().mean() < 0.75  # both modes


def test_flow_noise_settings_are_checked():
    with pytest.raises(ValueError, match="sample_noise"):
        tiny_config(sample_noise="run")
    with pytest.raises(ValueError, match="flow_steps"):
        tiny_config(flow_steps=0)


@pytest.mark.parametrize("field, value", [("policy", "stochastic"), ("reward_encoder", "fourier")])
def test_unknown_policy_or_reward_encoder_is_a_named_error(field, value):
    with pytest.raises(ValueError, match=field):
        tiny_config(**{field: value})


# --- observation encoder ------------------------------------------------------------------------


def test_fourier_features_give_neighbouring_grid_cells_codes_as_far_apart_as_distant_ones():
    cells = (torch.arange(9.0) - 4) / 2.6  # a 9-cell row, z-scored as a task's statistics would
    raw = cells.unsqueeze(-1)
    codes = fourier_features(raw, 4)
    assert codes.shape == (9, 1 + 2 * 4) and torch.equal(codes[:, :1], raw)  # the raw channel comes first
    neighbours = (codes[1:] - codes[:-1]).norm(dim=-1)
    assert (raw[1:] - raw[:-1]).norm(dim=-1).max() < 0.4  # raw: neighbours sit at a tenth of the row's span
    assert neighbours.min() > 1.0  # coded: each neighbour is more than the row's whole raw span away
    assert torch.equal(fourier_features(raw, 0), raw)


def test_a_model_with_fourier_bands_feeds_them_to_its_observation_encoder_and_counts_them():
    model = make_model(obs_fourier_bands=3)
    assert model.encoders["A"].obs[0].in_features == 5 * (1 + 2 * 3)
    out = model(**make_batch("A", "a1", model))
    assert out.shape == (2, 12, 2) and torch.isfinite(out).all()
    plain = count_parameters(make_model())
    assert count_parameters(model) - plain == (5 + 7) * 2 * 3 * 14  # two groups' first encoder layers grow
    with pytest.raises(ValueError, match="obs_fourier_bands"):
        tiny_config(obs_fourier_bands=-1)
