"""The Vintix model: per-group encoders -> causal ALiBi transformer -> per-group action heads.

One token per environment step t: ``[enc_obs(o_t) | enc_act(a_{t-1}) | enc_rew(r_{t-1})]``, and the
output at that token predicts ``a_t`` (paper §2.3). Tasks with the same observation/action space and
channel meaning share a *group*: one encoder set and one action head. The model sees the group and,
through normalization only, the task; it never gets a task identifier it could condition on.

A group acts in a continuous Box (its head gives the action, or a Gaussian's mean and log-std) or in a
Discrete space of n actions (AD's and DPT's home: Dark Room, bandits): its previous action comes in as an
index whose one-hot code the action encoder's first layer turns into an embedding, and its head gives n
logits, trained by cross-entropy on the target action. One model may hold groups of both kinds.

Read top to bottom: config and presets, attention with ALiBi, the transformer block, per-group
encoders and heads, the model, parameter counting.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F
from huggingface_hub import PyTorchModelHubMixin
from torch import nn

from vintix.errors import UnknownTaskError, VintixError
from vintix.fields import check_field_types
from vintix.tasks.layouts import ObsLayout

# ----------------------------------------------------------------------------------------------
# Configuration


_ACTIVATIONS = {"gelu": nn.GELU, "leaky_relu": nn.LeakyReLU}
REWARD_ENCODERS = ("linear", "mlp")
POLICIES = ("deterministic", "gaussian", "flow")
"""What a Box group's action head is (`ActionHead`); a Discrete group's is always categorical."""
SAMPLE_NOISE = ("step", "episode")
"""How often a sampling head draws the noise behind its action (`ModelConfig.sample_noise`)."""
LOG_STD_RANGE = (-5.0, 1.0)
"""Bounds of a gaussian policy's log-std: a likelihood can otherwise push the std to 0 on exact targets."""
MAX_FLOW_STEPS = 1000
"""The most integration steps a flow head may take at play (`ModelConfig.flow_steps`)."""


class ModelConfigError(VintixError, ValueError):
    """A model config with a field of the wrong type or out of range, or an unknown preset."""


MAX_LAYERS = 256
"""The most transformer (or head) layers a config may ask for: the paper's model has 20, and 25,000 layers of a
tiny width fit in memory yet take minutes to build in silence."""

MAX_FOURIER_BANDS = 12
"""The most Fourier bands a config may ask for (`ModelConfig.obs_fourier_bands`)."""


@dataclass
class ModelConfig:
    """Sizes of the model and how it treats its inputs; start from a preset (below)."""

    n_layers: int = 4
    """transformer blocks"""
    n_heads: int = 4
    """attention heads; d_model must divide evenly"""
    obs_emb_dim: int = 63
    """width of the observation part of a token"""
    act_emb_dim: int = 63
    """width of the previous-action part of a token"""
    rew_emb_dim: int = 2
    """width of the previous-reward part of a token (a scalar needs few dimensions)"""
    mlp_dim: int = 512
    """hidden width of the transformer's feed-forward layer"""
    head_layers: int = 3
    """hidden layers (width d_model) in each group's action head; 3 as in the official release"""
    context_len: int = 1024
    """longest window in steps (tokens) the model is trained on and attends over at inference"""
    keep_first_steps: int = 0
    """steps at the start of a run that the agent keeps in its window for good, sliding only the rest
    (`vintix.agent.cache`): for a model trained on windows that all begin at a history's first, exploring
    episode, so that its context still looks like one when the run outgrows the window; 0: a plain
    sliding window"""
    dropout: float = 0.0
    """dropout on attention probabilities and residual branches (the paper lists none; on CPU any
    attention dropout forces the unfused attention path, about 2x slower at 1024 steps)"""
    std_floor: float = 1e-2
    """lower bound on per-task observation std, so near-constant channels are not blown up (0: none)"""
    std_epsilon: float = 0.0
    """added to the (floored) std: observations are divided by ``max(std, std_floor) + std_epsilon``; the
    official release divides by ``std + 1e-6`` (std_floor 0, std_epsilon 1e-6)"""
    shared_padding: bool = False
    """one learned previous-action/previous-reward padding vector for all groups, as in the official
    release, instead of one per group"""
    mask_reward: bool = False
    """'AD without rewards' ablation: the reward embedding is always the padding vector"""
    last_reward: bool = False
    """an episode's first token carries the previous episode's last reward (its action part stays padding; a
    run's first token carries 0), so a reward paid only at an episode's end (a success bonus) reaches the
    model; False: the paper's token layout, where that reward is never seen and the release's format"""
    last_action: bool = False
    """with last_reward, an episode's first token also carries the previous episode's last action (a run's first
    token: zeros, action 0 of a discrete group), so the step that ends an episode is whole in the context: where
    an episode ends on reaching something (Key-to-Door's door), that step's cell is otherwise never seen, only its
    neighbour; False: padding, as in the paper"""
    episode_return: bool = False
    """each token also carries the return its episode earned before it (scaled as rewards, 0 at an episode start;
    `episode_returns_so_far`), so where a task pays for a subgoal and then for the goal (Key-to-Door's key, then its
    door) whether the subgoal is done is in the token itself, not in an earlier one the model must find; the agent
    keeps the sum. False: the paper's token layout"""
    activation: str = "gelu"
    """activation in encoders and heads: 'gelu', or 'leaky_relu' as in the official release"""
    policy: str = "deterministic"
    """a Box group's action head (`ActionHead`): 'deterministic', the action, trained by MSE (the paper);
    'gaussian', a mean and a log-std per action channel, trained by Gaussian likelihood; 'flow', a rectified flow
    from noise to the action (Vintix II), which can hold a posterior of several modes (left *or* right) where MSE
    averages them. The agent samples a sampling head's action: it explores as posterior sampling does, where the
    mean action of its histories stands still (a hidden goal equally likely on either side)"""
    flow_steps: int = 8
    """Euler steps a flow head integrates from noise to an action at play (training draws one time per target)"""
    sample_noise: str = "step"
    """how often the agent draws a sampling head's noise (a flow's start, a gaussian's z, a categorical's uniform):
    'step', a fresh draw every step; 'episode', one draw held for a whole episode, one posterior sample an episode as
    posterior-sampling RL commits to one hypothesis (measured worse on the toy hidden goal: docs/results/dpt); no
    weight depends on it"""
    reward_encoder: str = "linear"
    """'linear': Linear(1, rew_emb_dim) + activation, as in the official release; 'mlp': two layers, the
    first with biases spread over the reward range, so each unit bends at another reward value"""
    obs_fourier_bands: int = 0
    """also feed the observation encoder sin and cos of each normalized channel times pi * 2**k, k < this
    (`fourier_features`), so that nearby values (neighbouring grid cells) get distant codes; 0: raw only"""

    @property
    def pads_reward(self) -> bool:
        """Whether any token's reward part is the learned padding vector (episode starts, or all under
        mask_reward); a padding no token uses would be a parameter without a gradient, which DDP refuses."""
        return self.mask_reward or not self.last_reward

    @property
    def pads_action(self) -> bool:
        """Whether any token's action part is the learned padding vector (episode starts unless last_action)."""
        return not self.last_action

    @property
    def obs_codes_per_channel(self) -> int:
        """Inputs of the observation encoder per observation channel: the channel and its Fourier codes."""
        return 1 + 2 * self.obs_fourier_bands

    @property
    def d_model(self) -> int:
        """Transformer width: the three token parts side by side."""
        return self.obs_emb_dim + self.act_emb_dim + self.rew_emb_dim

    def __post_init__(self) -> None:
        check_field_types(self, ModelConfigError)
        sizes = {"n_layers": self.n_layers, "n_heads": self.n_heads, "obs_emb_dim": self.obs_emb_dim,
                 "act_emb_dim": self.act_emb_dim, "rew_emb_dim": self.rew_emb_dim, "mlp_dim": self.mlp_dim,
                 "context_len": self.context_len}
        counts = {"head_layers": self.head_layers, "obs_fourier_bands": self.obs_fourier_bands}
        small = [f"{k}={v}" for k, v in sizes.items() if v < 1] + [f"{k}={v}" for k, v in counts.items() if v < 0]
        divisor_ok = self.std_floor >= 0 and self.std_epsilon >= 0 and self.std_floor + self.std_epsilon > 0
        if small or not 0 <= self.dropout < 1 or not divisor_ok:
            raise ModelConfigError(
                "sizes must be >= 1 (head_layers, obs_fourier_bands >= 0), dropout in [0, 1), std_floor and "
                f"std_epsilon >= 0 and not both 0; got {', '.join(small) or f'dropout={self.dropout}, '}"
                f"{'' if small else f'std_floor={self.std_floor}, std_epsilon={self.std_epsilon}'}")
        if self.obs_fourier_bands > MAX_FOURIER_BANDS:
            raise ModelConfigError(f"obs_fourier_bands={self.obs_fourier_bands}: at most {MAX_FOURIER_BANDS}; past "
                                   "that a float32 observation has no digits left for the fastest band to read")
        if self.last_action and not self.last_reward:
            raise ModelConfigError("last_action needs last_reward: an episode's first token would carry the last "
                                   "action without the reward it earned")
        if self.n_layers > MAX_LAYERS or self.head_layers > MAX_LAYERS:
            raise ModelConfigError(f"n_layers={self.n_layers}, head_layers={self.head_layers}: at most {MAX_LAYERS} "
                                   "each (the paper's model has 20); more is a typo, and would take minutes to build")
        if not 0 <= self.keep_first_steps < self.context_len:
            raise ModelConfigError(f"keep_first_steps must lie in [0, context_len = {self.context_len}), got "
                                   f"{self.keep_first_steps}: the window needs room to slide")
        if self.d_model % self.n_heads:
            raise ModelConfigError(
                f"d_model = {self.obs_emb_dim}+{self.act_emb_dim}+{self.rew_emb_dim} = "
                f"{self.d_model} is not divisible by n_heads = {self.n_heads}"
            )
        if self.activation not in _ACTIVATIONS:
            raise ModelConfigError(f"activation must be one of {sorted(_ACTIVATIONS)}, got {self.activation!r}")
        if self.policy not in POLICIES:
            raise ModelConfigError(f"policy must be one of {list(POLICIES)}, got {self.policy!r}")
        if self.sample_noise not in SAMPLE_NOISE:
            raise ModelConfigError(f"sample_noise must be one of {list(SAMPLE_NOISE)}, got {self.sample_noise!r}")
        if not 1 <= self.flow_steps <= MAX_FLOW_STEPS:
            raise ModelConfigError(f"flow_steps must lie in [1, {MAX_FLOW_STEPS}], got {self.flow_steps}")
        if self.reward_encoder not in REWARD_ENCODERS:
            raise ModelConfigError(
                f"reward_encoder must be one of {list(REWARD_ENCODERS)}, got {self.reward_encoder!r}")

# tiny: ~0.8M backbone parameters, small enough to train on a laptop CPU in tens of minutes (the
#   shipped cpu-suite model); a 1024-step window holds 10 Meta-World or 4 Industrial Benchmark episodes.
#   Measured: ~4k training tokens/s on 2 cores (one group, fp32), ~14M tokens an hour; a 512-step
#   window roughly doubles that, since attention dominates at this width.
# small: a single-GPU model (~14M backbone parameters) with a 2048-step window.
# Both read an episode's last reward (last_reward), which the paper's layout drops; the models shipped before
#   that option existed pin last_reward: false in their training configs, so their commands still make them.
# paper: the paper's hyperparameter table (20 layers, 16 heads, 511+511+2, MLP 4096, 8192 steps) with the
#   official release's LeakyReLU encoders/heads, shared padding and ``std + 1e-6`` normalization, so a
#   model trained at this preset exports to the authors' format (`vintix.model.official`).
PRESETS: dict[str, ModelConfig] = {
    "tiny": ModelConfig(last_reward=True),
    "small": ModelConfig(
        n_layers=8, n_heads=8, obs_emb_dim=191, act_emb_dim=191, rew_emb_dim=2,
        mlp_dim=1536, context_len=2048, last_reward=True,
    ),
    "paper": ModelConfig(
        n_layers=20, n_heads=16, obs_emb_dim=511, act_emb_dim=511, rew_emb_dim=2,
        mlp_dim=4096, context_len=8192, activation="leaky_relu", std_floor=0.0, std_epsilon=1e-6,
        shared_padding=True,
    ),
}


def preset(name: str, **overrides: Any) -> ModelConfig:
    """A fresh copy of a preset config, with any field overridden (ModelConfig checks the values' types)."""
    if name not in PRESETS:
        raise ModelConfigError(f"unknown model preset {name!r}; choose one of {sorted(PRESETS)}")
    return replace(PRESETS[name], **overrides)


@dataclass
class GroupSpec:
    """Tasks sharing one observation/action space (and channel meaning) share encoders and a head."""

    name: str
    obs_dim: int
    act_dim: int
    """action channels, or a discrete group's number of actions"""
    discrete: bool = False
    """whether the group acts in a Discrete space: actions are indices, its head gives act_dim logits"""


@dataclass
class TaskNorm:
    """Per-task input normalization, computed once per dataset and stored in the checkpoint."""

    task: str
    group: str
    obs_mean: Sequence[float] | np.ndarray
    obs_std: Sequence[float] | np.ndarray
    reward_scale: float = 1.0
    obs_layout: ObsLayout | None = None
    """how this task's env observation maps onto the group's channels, where they differ (a model of
    Humanoid-v4's 376 channels acting on Humanoid-v5); None: the env's observation as it is"""


# ----------------------------------------------------------------------------------------------
# Attention with ALiBi: relative positions only, so a sliding KV-cache window needs no re-encoding.


def alibi_slopes(n_heads: int) -> torch.Tensor:
    """Per-head slopes of the ALiBi paper: a geometric sequence 2^(-8/n), 2^(-16/n), ... for n a power
    of two; otherwise the slopes for the closest lower power of two, topped up with every other slope
    of the next power of two (the paper's recipe, so the head count need not be a power of two)."""

    def power_of_2(n: int) -> list[float]:
        start = 2.0 ** (-8.0 / n)
        return [start ** (i + 1) for i in range(n)]

    if math.log2(n_heads).is_integer():
        slopes = power_of_2(n_heads)
    else:
        closest = 2 ** math.floor(math.log2(n_heads))
        slopes = power_of_2(closest) + power_of_2(2 * closest)[0::2][: n_heads - closest]
    return torch.tensor(slopes, dtype=torch.float32)


def alibi_bias(q_pos: torch.Tensor, k_pos: torch.Tensor, slopes: torch.Tensor) -> torch.Tensor:
    """Additive attention bias ``-slope * (q_pos - k_pos)``, ``-inf`` where ``k_pos > q_pos``.

    Positions are absolute step indices, ``[Tq]`` and ``[Tk]`` (or batched ``[B, Tq]``/``[B, Tk]``),
    so a KV cache whose key window starts anywhere uses the same function; a cache slot can be hidden
    by giving it a position larger than every query. Returns ``[..., H, Tq, Tk]`` in fp32.
    """
    rel = (q_pos.unsqueeze(-1) - k_pos.unsqueeze(-2)).unsqueeze(-3)  # [..., 1, Tq, Tk]
    bias = -slopes.view(-1, 1, 1) * rel.to(slopes.dtype)
    return bias.masked_fill(rel < 0, float("-inf"))


def attention(
    q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, bias: torch.Tensor, dropout_p: float = 0.0
) -> torch.Tensor:
    """Softmax(q kᵀ / √d + bias) v over ``[B, H, T, head_dim]`` tensors.

    Takes the bias rather than building it from positions so the backbone can build it once per
    forward and share it across layers: autograd keeps the bias for every layer's backward, and at
    the paper's size one copy is 2 GB (FlashAttention's built-in ALiBi, an optional GPU fast path,
    would avoid materializing it at all).
    """
    # A 3-D [H, Tq, Tk] mask sends CPU SDPA to its unfused math kernel; a 4-D one takes the fused
    # flash kernel (torch 2.13, T=1024: 4.6x faster forward + backward).
    if bias.dim() == 3:
        bias = bias.unsqueeze(0)
    bias = bias.to(q.dtype)
    if q.shape[-2] == 1 and q.device.type == "cpu" and dropout_p == 0.0:
        # One query per env (a cached agent step) is a batched matrix-vector product that reads the
        # whole cache once; the CPU flash kernel tiles for many queries and is ~1.5x slower here
        # (tiny, 16 envs, window full: 4.4 vs 2.8 ms for the 4 layers; `vintix bench infer`).
        scores = torch.matmul(q, k.transpose(-2, -1)) * q.shape[-1] ** -0.5 + bias
        return torch.matmul(scores.softmax(dim=-1), v)
    return F.scaled_dot_product_attention(q, k, v, attn_mask=bias, dropout_p=dropout_p)


# A KV cache's per-layer hook: new tokens' (k, v) in, the attended window's (k, v) out.
KVUpdate = Callable[[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]


class SelfAttention(nn.Module):
    """Multi-head self-attention with one packed qkv projection and qk-LayerNorm.

    qk-LayerNorm bounds the attention logits, which keeps long-context bf16 training stable.
    ``project_qkv`` and ``proj`` are public so a KV-cache step can project only the new tokens, append
    their k and v to the cache and call ``attention`` against the whole window.
    """

    def __init__(self, config: ModelConfig):
        super().__init__()
        self.n_heads = config.n_heads
        head_dim = config.d_model // config.n_heads
        self.qkv = nn.Linear(config.d_model, 3 * config.d_model)
        self.q_norm = nn.LayerNorm(head_dim)
        self.k_norm = nn.LayerNorm(head_dim)
        self.proj = nn.Linear(config.d_model, config.d_model)
        self.dropout = config.dropout

    def project_qkv(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """q, k, v as ``[B, H, T, head_dim]``, q and k LayerNorm-ed."""
        B, T, _ = x.shape
        q, k, v = self.qkv(x).view(B, T, 3, self.n_heads, -1).unbind(2)
        # LayerNorm runs in fp32 under autocast; cast back so q, k, v share v's (bf16) dtype.
        q = self.q_norm(q).to(v.dtype)
        k = self.k_norm(k).to(v.dtype)
        return q.transpose(1, 2), k.transpose(1, 2), v.transpose(1, 2)

    def forward(self, x: torch.Tensor, bias: torch.Tensor, kv_cache: KVUpdate | None = None) -> torch.Tensor:
        """``kv_cache`` (inference): stores the new tokens' k, v and returns the k, v of every token the
        queries attend to; ``bias`` then spans those keys (see `vintix.agent.KVCache`)."""
        B, T, D = x.shape
        q, k, v = self.project_qkv(x)
        if kv_cache is not None:
            k, v = kv_cache(k, v)
        y = attention(q, k, v, bias, self.dropout if self.training else 0.0)
        return self.proj(y.transpose(1, 2).reshape(B, T, D))


class MLP(nn.Module):
    """GPT-NeoX feed-forward: Linear, GELU, Linear."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        self.fc = nn.Linear(config.d_model, config.mlp_dim)
        self.proj = nn.Linear(config.mlp_dim, config.d_model)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.proj(F.gelu(self.fc(x)))


class Block(nn.Module):
    """Pre-LN transformer block."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        self.ln_1 = nn.LayerNorm(config.d_model)
        self.attn = SelfAttention(config)
        self.ln_2 = nn.LayerNorm(config.d_model)
        self.mlp = MLP(config)
        self.drop = nn.Dropout(config.dropout)

    def forward(self, x: torch.Tensor, bias: torch.Tensor, kv_cache: KVUpdate | None = None) -> torch.Tensor:
        x = x + self.drop(self.attn(self.ln_1(x), bias, kv_cache))
        return x + self.drop(self.mlp(self.ln_2(x)))


# ----------------------------------------------------------------------------------------------
# Per-group encoders and action heads (shapes as in the official release, so its checkpoint maps
# onto these modules).


def fourier_features(x: torch.Tensor, bands: int) -> torch.Tensor:
    """``x`` followed by sin and cos of ``pi * 2**k * x`` for each channel and k < `bands` (``x`` alone if 0)."""
    if bands == 0:
        return x
    angles = x.unsqueeze(-1) * (math.pi * 2.0 ** torch.arange(bands, dtype=x.dtype, device=x.device))
    return torch.cat([x, angles.sin().flatten(-2), angles.cos().flatten(-2)], dim=-1)


def _encoder_mlp(in_dim: int, out_dim: int, activation: str) -> nn.Sequential:
    # The LayerNorms keep the observation and action parts of a token at unit scale whatever the
    # raw channel scales of a group are.
    act = _ACTIVATIONS[activation]
    return nn.Sequential(
        nn.Linear(in_dim, out_dim), act(), nn.LayerNorm(out_dim),
        nn.Linear(out_dim, out_dim), act(), nn.LayerNorm(out_dim),
    )


class GroupEncoder(nn.Module):
    """Turns one group's (normalized obs, previous action, scaled previous reward) into tokens."""

    def __init__(self, spec: GroupSpec, config: ModelConfig):
        super().__init__()
        self.fourier_bands = config.obs_fourier_bands
        self.obs = _encoder_mlp(spec.obs_dim * config.obs_codes_per_channel, config.obs_emb_dim, config.activation)
        self.act = _encoder_mlp(spec.act_dim, config.act_emb_dim, config.activation)
        # No reward encoder at all under mask_reward: parameters that never get a gradient would
        # make DDP fail.
        self.rew = None if config.mask_reward else _reward_mlp(config)
        # Episode starts have no previous action/reward; a learned vector says so (the model's shared
        # pair under shared_padding: `Vintix.encode` hands the right pair in).
        self.act_pad = None if config.shared_padding or not config.pads_action else _padding(config.act_emb_dim)
        self.rew_pad = None if config.shared_padding or not config.pads_reward else _padding(config.rew_emb_dim)
        self.last_reward = config.last_reward
        self.reward_inputs = 2 if config.episode_return else 1

    def forward(
        self, obs: torch.Tensor, prev_action: torch.Tensor, prev_reward: torch.Tensor,
        episode_start: torch.Tensor, act_pad: torch.Tensor | None, rew_pad: torch.Tensor | None,
    ) -> torch.Tensor:
        start = episode_start.unsqueeze(-1)
        # [B, T] or, under episode_return, [B, T, 2]: the reward and the episode's return so far
        rewards = prev_reward.reshape(*obs.shape[:-1], self.reward_inputs)
        e_obs = self.obs(fourier_features(obs, self.fourier_bands))
        e_act = self.act(prev_action)
        if act_pad is not None:  # None under last_action: an episode start's action is the previous episode's last
            e_act = torch.where(start, act_pad, e_act)
        if self.rew is None:
            assert rew_pad is not None  # mask_reward pads every token
            e_rew = rew_pad.expand(*e_obs.shape[:-1], -1)
        elif self.last_reward:  # an episode start's reward is the previous episode's last
            e_rew = self.rew(rewards)
        else:
            assert rew_pad is not None
            e_rew = torch.where(start, rew_pad, self.rew(rewards))
        return torch.cat([e_obs, e_act, e_rew], dim=-1)


def _padding(dim: int) -> nn.Parameter:
    return nn.Parameter(torch.empty(dim))


def _reward_mlp(config: ModelConfig) -> nn.Sequential:
    # No LayerNorm here, unlike the obs/action encoders: one scalar times a weight vector has a single
    # direction, and LayerNorm would keep the direction and drop the scalar, the very thing to encode.
    act = _ACTIVATIONS[config.activation]
    layers: list[nn.Module] = [nn.Linear(2 if config.episode_return else 1, config.rew_emb_dim), act()]
    if config.reward_encoder == "mlp":
        layers += [nn.Linear(config.rew_emb_dim, config.rew_emb_dim), act()]
    return nn.Sequential(*layers)


class ActionHead(nn.Sequential):
    """A group's action head: what the backbone's output at step t says about a_t, as one interface.

    Each kind owns its output width, how the group's previous action enters its token (`encode_previous`), its
    training loss (`loss`) and how it acts (`act`: a draw, or its greedy choice). The model, the trainer and the agent
    call these and never branch on the kind; a new head is one subclass. The layers are the official release's
    (``hidden_layers`` of width d_model, then the output), children of this Sequential so that a checkpoint's
    ``heads.<group>.<i>.weight`` names map onto them unchanged.
    """

    noise_dim = 0
    """numbers a draw is made of (`draw_noise`; 0: the head acts deterministically); the agent draws them from each
    env's own stream, so an env's actions do not depend on its batch, and may hold them for an episode"""

    def __init__(self, in_dim: int, d_model: int, out_dim: int, hidden_layers: int, activation: str) -> None:
        layers: list[nn.Module] = []
        for i in range(hidden_layers):
            layers += [nn.Linear(in_dim if i == 0 else d_model, d_model), _ACTIVATIONS[activation]()]
        super().__init__(*layers, nn.Linear(in_dim if not hidden_layers else d_model, out_dim))

    def encode_previous(self, prev_action: torch.Tensor) -> torch.Tensor:
        """The previous action as the action encoder's input: a Box action as it is."""
        return prev_action

    def predict(self, h: torch.Tensor) -> torch.Tensor:
        """The head's point prediction from backbone outputs ``[..., d_model]``: the (mean) action, or logits."""
        return self(h)

    def loss(self, h: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Per-position loss ``[B, T]`` (mean over action channels) of the targets ``[B, T, act_dim]``."""
        raise NotImplementedError

    def draw_noise(self, generator: torch.Generator) -> torch.Tensor:
        """One env's draw ``[noise_dim]``: standard-normal numbers (a categorical head's: a uniform one)."""
        return torch.randn(self.noise_dim, generator=generator, device=generator.device)

    def act(self, h: torch.Tensor, noise: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """Actions ``[B, act_dim]`` (a discrete head: indices ``[B]``) from outputs ``[B, d_model]``, and whether each
        row's came from finite outputs ``[B]`` (a damaged model's do not). `noise` ``[B, noise_dim]``: the draws to act
        on (`draw_noise`); None: the greedy action."""
        actions = self.predict(h)
        return actions, torch.isfinite(actions).all(dim=-1)


class DeterministicHead(ActionHead):
    """The action itself, trained by MSE (the paper's head)."""

    def loss(self, h: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return F.mse_loss(self(h).float(), target, reduction="none").mean(dim=-1)


class GaussianHead(ActionHead):
    """A mean and a bounded log-std per channel, trained by Gaussian likelihood; acts on mean + std · noise."""

    def __init__(self, d_model: int, act_dim: int, hidden_layers: int, activation: str) -> None:
        super().__init__(d_model, d_model, 2 * act_dim, hidden_layers, activation)
        self.noise_dim = act_dim

    def distribution(self, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(mean, log-std), each ``[..., act_dim]``."""
        mean, log_std = self(h).chunk(2, dim=-1)
        return mean, log_std.clamp(*LOG_STD_RANGE)

    def predict(self, h: torch.Tensor) -> torch.Tensor:
        return self.distribution(h)[0]

    def loss(self, h: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        mean, log_std = self.distribution(h)  # negative log-likelihood, up to a constant
        variance = (2 * log_std.float()).exp()
        return F.gaussian_nll_loss(mean.float(), target, variance, reduction="none").mean(dim=-1)

    def act(self, h: torch.Tensor, noise: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        mean, log_std = self.distribution(h)
        actions = mean if noise is None else mean + log_std.exp() * noise
        return actions, torch.isfinite(actions).all(dim=-1)


class CategoricalHead(ActionHead):
    """n logits of a Discrete group, trained by cross-entropy on the target index; the previous action enters as the
    one-hot code of its index. AD and DPT sample: a greedy policy on a flat distribution never explores."""

    def __init__(self, d_model: int, actions: int, hidden_layers: int, activation: str) -> None:
        super().__init__(d_model, d_model, actions, hidden_layers, activation)
        self.actions = actions

    def encode_previous(self, prev_action: torch.Tensor) -> torch.Tensor:
        return F.one_hot(prev_action.long().clamp(0, self.actions - 1), self.actions).float()

    def loss(self, h: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return F.cross_entropy(self(h).float().transpose(1, 2), target.long(), reduction="none")

    noise_dim = 1

    def draw_noise(self, generator: torch.Generator) -> torch.Tensor:
        return torch.rand(1, generator=generator, device=generator.device)

    def act(self, h: torch.Tensor, noise: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        logits = self(h).float()
        finite = torch.isfinite(logits).all(dim=-1)
        if noise is None:
            return logits.argmax(dim=-1), finite
        # Inverse-CDF sampling: the action whose cumulative probability first passes the uniform draw.
        cumulative = torch.where(finite.unsqueeze(-1), logits, 0.0).softmax(dim=-1).cumsum(dim=-1)
        return (cumulative < noise.to(cumulative.dtype)).sum(dim=-1).clamp(max=self.actions - 1), finite


class FlowHead(ActionHead):
    """Rectified flow from standard-normal noise to the action (Vintix II), conditioned on the backbone's output: the
    network reads ``[h | x_τ | τ]`` and gives the velocity ``a − x₀`` that carries ``x₀`` (noise) along the straight
    line ``x_τ = (1 − τ) x₀ + τ a`` to the action. Trained on one (x₀, τ) draw per target; at play `steps` Euler
    steps from the noise. A draw is one sample of the action's distribution, so a posterior of several modes (a
    goal left *or* right) gives one of them, where MSE would average them; starting from zero noise is the greedy
    action."""

    def __init__(self, d_model: int, act_dim: int, hidden_layers: int, activation: str, steps: int) -> None:
        super().__init__(d_model + act_dim + 1, d_model, act_dim, hidden_layers, activation)
        self.noise_dim, self.steps = act_dim, steps

    def velocity(self, h: torch.Tensor, x: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
        return self(torch.cat([h, x.to(h.dtype), tau.to(h.dtype)], dim=-1))

    def predict(self, h: torch.Tensor) -> torch.Tensor:
        return self.integrate(h, torch.zeros(*h.shape[:-1], self.noise_dim, device=h.device, dtype=h.dtype))

    def loss(self, h: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        start = torch.randn_like(target)
        tau = torch.rand(*target.shape[:-1], 1, device=target.device, dtype=target.dtype)
        point = (1 - tau) * start + tau * target
        return F.mse_loss(self.velocity(h, point, tau).float(), target - start, reduction="none").mean(dim=-1)

    def integrate(self, h: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """The action the flow carries `noise` to: `steps` Euler steps from τ = 0 to 1."""
        x = noise.to(h.dtype)
        for k in range(self.steps):
            tau = torch.full((*h.shape[:-1], 1), k / self.steps, device=h.device, dtype=h.dtype)
            x = x + self.velocity(h, x, tau) / self.steps
        return x

    def act(self, h: torch.Tensor, noise: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        actions = self.predict(h) if noise is None else self.integrate(h, noise)
        return actions, torch.isfinite(actions).all(dim=-1)


def action_head(spec: GroupSpec, config: ModelConfig) -> ActionHead:
    """The head of a group: categorical for a Discrete one, else the config's `ModelConfig.policy`."""
    d, layers, activation = config.d_model, config.head_layers, config.activation
    if spec.discrete:
        return CategoricalHead(d, spec.act_dim, layers, activation)
    if config.policy == "gaussian":
        return GaussianHead(d, spec.act_dim, layers, activation)
    if config.policy == "flow":
        return FlowHead(d, spec.act_dim, layers, activation, config.flow_steps)
    return DeterministicHead(d, d, spec.act_dim, layers, activation)


def normalize_inputs(obs: torch.Tensor, reward: torch.Tensor, mean: torch.Tensor, divisor: torch.Tensor,
                     reward_scale: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """What the model sees of raw inputs ``obs [B, T, obs_dim]`` and ``reward [B, T]`` (or rewards and episode
    returns ``[B, T, 2]``, scaled alike), given each sequence's statistics ``mean, divisor [B, obs_dim]`` and
    ``reward_scale [B]``: the one place the normalization is written, for training (`Vintix.normalize`) and the
    agent alike."""
    scale = reward_scale.reshape(-1, *[1] * (reward.dim() - 1))
    return (obs - mean.unsqueeze(1)) / divisor.unsqueeze(1), reward * scale


def episode_returns_so_far(prev_reward: np.ndarray, episode_start: np.ndarray, first: np.ndarray) -> np.ndarray:
    """The return each token's episode earned before it (`ModelConfig.episode_return`), ``[B, T]``, from the rewards
    tokens carry ``prev_reward [B, T]`` and their ``episode_start [B, T]`` flags: 0 at a start, else the token
    before's plus the reward it carries. ``first [B]`` is the first token's where it is no start (a training window
    that opens mid-episode, an agent's next step): what the training data and the agent both compute."""
    earned = np.where(episode_start, 0.0, prev_reward).astype(np.float64)
    earned[:, 0] = np.where(episode_start[:, 0], 0.0, first)
    total = np.cumsum(earned, axis=1)
    steps = np.arange(total.shape[1])
    last_start = np.maximum.accumulate(np.where(episode_start, steps, 0), axis=1)
    # What the run had earned by its episode's start (its start's total, which the start's 0 leaves unchanged).
    before = np.where(np.cumsum(episode_start, axis=1) > 0, np.take_along_axis(total, last_start, axis=1), 0.0)
    return (total - before).astype(np.float32)


# ----------------------------------------------------------------------------------------------
# The model


MODEL_CARD = """---
{{ card_data }}
---

# {{ name }}

A [Vintix](https://arxiv.org/abs/2501.19400) action model: a causal ALiBi transformer over multi-episode
learning histories that improves in context, episode after episode, from the rewards it earns. Saved by
vintix: {{ parameters }} parameters, a {{ context_len }}-step context, {{ n_groups }} encoder group(s),
statistics for {{ n_tasks }} task(s).

```python
import vintix
agent = vintix.Agent.from_pretrained("path/to/this/folder")   # or: vintix eval --checkpoint path/to/this/folder
```

{{ training }}

{{ details }}
"""
"""The model card `Vintix.save_pretrained` writes as ``README.md`` (huggingface_hub's mixin renders it)."""


class Vintix(nn.Module, PyTorchModelHubMixin, library_name="vintix", model_card_template=MODEL_CARD,
             paper_url="https://arxiv.org/abs/2501.19400",
             tags=["reinforcement-learning", "in-context-learning", "algorithm-distillation"]):
    """Next-action model over multi-episode learning histories.

    Training: ``forward(group, task_idx, obs, prev_action, prev_reward, step_num)`` with every
    sequence of the batch from ``group``. To mix groups in one batch, ``embed`` each group's
    sub-batch, concatenate along the batch dim, run ``backbone`` once, split, and ``head`` each part.

    Saving and loading go through huggingface_hub's mixin: ``save_pretrained(folder)`` writes
    ``config.json``, ``model.safetensors`` and a ``README.md`` model card (use
    `vintix.model.save_pretrained` to record training facts beside the model), ``from_pretrained(folder)``
    loads a local folder strictly, and ``push_to_hub`` is the library's own.
    """

    # Buffers (set by register_buffer below), declared for the type checker: nn.Module's attribute
    # lookup would otherwise type them Tensor | Module.
    obs_mean: torch.Tensor
    obs_std: torch.Tensor
    reward_scale: torch.Tensor
    task_group: torch.Tensor
    alibi_slopes: torch.Tensor

    def __init__(self, config: ModelConfig, groups: Sequence[GroupSpec], task_norms: Sequence[TaskNorm]):
        super().__init__()
        self.config = config
        self.groups = {g.name: g for g in groups}
        if len(self.groups) != len(groups):
            raise ValueError("group names must be unique")
        self.task_norms = list(task_norms)
        self.checkpoint_extra: dict[str, Any] = {}
        """What a checkpoint of this model keeps beside it (training step, dataset fingerprint, ...)"""
        self._task_index = {t.task: i for i, t in enumerate(self.task_norms)}
        if len(self._task_index) != len(self.task_norms):
            raise ValueError("task names in task_norms must be unique")
        self._group_index = {name: i for i, name in enumerate(self.groups)}

        # Normalization lives in the model so training and inference cannot disagree. Statistics
        # are padded to the widest group; each group reads its first obs_dim columns.
        max_obs = max(g.obs_dim for g in groups)
        obs_mean = np.zeros((len(self.task_norms), max_obs), dtype=np.float32)
        obs_std = np.ones((len(self.task_norms), max_obs), dtype=np.float32)
        for i, t in enumerate(self.task_norms):
            if t.group not in self.groups:
                raise ValueError(f"task {t.task!r} names unknown group {t.group!r}")
            dim = self.groups[t.group].obs_dim
            mean, std = np.asarray(t.obs_mean, np.float32), np.asarray(t.obs_std, np.float32)
            if mean.shape != (dim,) or std.shape != (dim,):
                raise ValueError(
                    f"task {t.task!r}: obs_mean {mean.shape} / obs_std {std.shape} do not match "
                    f"group {t.group!r} obs_dim {dim}"
                )
            if t.obs_layout is not None and t.obs_layout.dim != dim:
                raise ValueError(f"task {t.task!r}: its obs_layout builds {t.obs_layout.dim} channels, group "
                                 f"{t.group!r} reads {dim}")
            obs_mean[i, :dim] = mean
            obs_std[i, :dim] = np.maximum(std, np.float32(config.std_floor)) + np.float32(config.std_epsilon)
        self.register_buffer("obs_mean", torch.tensor(obs_mean))
        self.register_buffer("obs_std", torch.tensor(obs_std))
        self.register_buffer(
            "reward_scale", torch.tensor([t.reward_scale for t in self.task_norms], dtype=torch.float32)
        )
        self.register_buffer(
            "task_group", torch.tensor([self._group_index[t.group] for t in self.task_norms], dtype=torch.long)
        )
        self.register_buffer("alibi_slopes", alibi_slopes(config.n_heads), persistent=False)

        self.encoders = nn.ModuleDict({g.name: GroupEncoder(g, config) for g in groups})
        self.act_pad = _padding(config.act_emb_dim) if config.shared_padding and config.pads_action else None
        self.rew_pad = _padding(config.rew_emb_dim) if config.shared_padding and config.pads_reward else None
        self.blocks = nn.ModuleList([Block(config) for _ in range(config.n_layers)])
        self.ln_f = nn.LayerNorm(config.d_model)
        self.heads = nn.ModuleDict({g.name: action_head(g, config) for g in groups})
        self.apply(self._init_weights)
        for name, p in self.named_parameters():
            if name.endswith(("attn.proj.weight", "mlp.proj.weight")):
                # GPT-2: each block adds two residual branches; keep the residual stream's variance
                # independent of depth.
                nn.init.normal_(p, mean=0.0, std=0.02 / math.sqrt(2 * config.n_layers))
            elif name.endswith(("act_pad", "rew_pad")):
                # Same unit scale as the LayerNorm-ed embeddings they stand in for.
                nn.init.normal_(p, mean=0.0, std=1.0)
            elif name.endswith("rew.0.weight"):
                # One input: std 0.02 would make the reward a whisper next to the unit-scale
                # obs/action parts; 1/sqrt(fan_in) = 1 keeps it audible from the first step.
                nn.init.normal_(p, mean=0.0, std=1.0)
            elif name.endswith("rew.0.bias") and config.reward_encoder == "mlp":
                # Kinks spread over a unit-scale reward range (see TrainConfig.normalize_rewards).
                nn.init.uniform_(p, -2.0, 2.0)
            elif name.endswith("rew.2.weight"):
                nn.init.normal_(p, mean=0.0, std=config.rew_emb_dim**-0.5)

    @staticmethod
    def _init_weights(module: nn.Module) -> None:
        if isinstance(module, nn.Linear):
            nn.init.normal_(module.weight, mean=0.0, std=0.02)
            nn.init.zeros_(module.bias)
        elif isinstance(module, nn.LayerNorm):
            nn.init.ones_(module.weight)
            nn.init.zeros_(module.bias)

    def _save_pretrained(self, save_directory: Path) -> None:
        """The mixin's hook (``save_pretrained``, ``push_to_hub``): the weights, then ``config.json`` with
        `checkpoint_extra`, each atomically; the mixin adds the model card."""
        from vintix.model.checkpoint import write_checkpoint

        write_checkpoint(self, save_directory)

    def generate_model_card(self, *args: Any, **kwargs: Any) -> Any:
        """The mixin's model card with every field filled, so that ``save_pretrained(folder)`` or ``push_to_hub``
        called directly shows this model's size and training facts, never the template's blanks; fields given
        (`vintix.model.save_pretrained`'s) win."""
        from vintix.model.checkpoint import model_card_fields

        fields = model_card_fields(self, self.checkpoint_extra, details="", name="A Vintix model")
        return super().generate_model_card(*args, **{**fields, **kwargs})

    @classmethod
    def _from_pretrained(cls, *, model_id: str, revision: str | None = None, cache_dir: str | Path | None = None,
                         force_download: bool = False, local_files_only: bool = False, token: str | bool | None = None,
                         map_location: str = "cpu", **model_kwargs: Any) -> Vintix:
        """The mixin's hook: a local folder is loaded strictly (`vintix.model.load_pretrained`); a Hub id is
        downloaded by huggingface_hub first, only when a user asks for one."""
        from vintix.model.checkpoint import load_pretrained

        folder = Path(model_id)
        if not folder.is_dir():
            from huggingface_hub import snapshot_download

            folder = Path(snapshot_download(repo_id=model_id, revision=revision, cache_dir=cache_dir,
                                            force_download=force_download, local_files_only=local_files_only,
                                            token=token))
        return load_pretrained(folder, map_location)

    def task_index(self, name: str) -> int:
        """Index of a task in ``task_norms``: what ``task_idx`` holds."""
        if name not in self._task_index:
            raise UnknownTaskError(f"task {name!r} has no normalization statistics in this model")
        return self._task_index[name]

    def normalize(
        self, task_idx: torch.Tensor, obs: torch.Tensor, reward: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-task z-scored observations ``[B, T, obs_dim]`` and scaled rewards ``[B, T]``. The ``obs_std``
        buffer holds the divisor, ``max(std, std_floor) + std_epsilon``."""
        dim = obs.shape[-1]
        return normalize_inputs(obs, reward, self.obs_mean[task_idx, :dim], self.obs_std[task_idx, :dim],
                                self.reward_scale[task_idx])

    def embed(
        self, group: str, task_idx: torch.Tensor, obs: torch.Tensor, prev_action: torch.Tensor,
        prev_reward: torch.Tensor, step_num: torch.Tensor, prev_return: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Tokens ``[B, T, d_model]``; at ``step_num == 0`` prev_action is ignored unless `ModelConfig.last_action`,
        and prev_reward unless `ModelConfig.last_reward` (there they are the previous episode's last).
        ``prev_return [B, T]``: what each token's episode earned before it, read by (and only by) an
        `ModelConfig.episode_return` model."""
        spec = self.groups.get(group)
        if spec is None:
            raise ValueError(f"unknown group {group!r}; the model has {sorted(self.groups)}")
        action_ok = prev_action.shape == obs.shape[:-1] if spec.discrete else prev_action.shape[-1] == spec.act_dim
        if obs.shape[-1] != spec.obs_dim or not action_ok:
            actions = f"{spec.act_dim} discrete actions (prev_action: one index per step)" if spec.discrete else \
                f"act_dim {spec.act_dim}"
            raise ValueError(
                f"group {group!r} expects obs_dim {spec.obs_dim} and {actions}, got "
                f"obs {tuple(obs.shape)} and prev_action {tuple(prev_action.shape)}"
            )
        if (self.task_group[task_idx] != self._group_index[group]).any():
            raise ValueError(f"task_idx {task_idx.tolist()} holds tasks outside group {group!r}")
        rewards = prev_reward
        if self.config.episode_return:
            if prev_return is None or prev_return.shape != prev_reward.shape:
                raise ValueError("this model reads each token's episode return so far (episode_return): pass "
                                 f"prev_return shaped as prev_reward {tuple(prev_reward.shape)}, got "
                                 f"{None if prev_return is None else tuple(prev_return.shape)}")
            rewards = torch.stack([prev_reward, prev_return], -1)
        obs, rewards = self.normalize(task_idx, obs, rewards)
        return self.encode(group, obs, prev_action, rewards, step_num == 0)

    def encode(
        self, group: str, obs: torch.Tensor, prev_action: torch.Tensor, prev_reward: torch.Tensor,
        episode_start: torch.Tensor,
    ) -> torch.Tensor:
        """Tokens of one group from already normalized observations and scaled rewards ``[B, T]`` (an
        `ModelConfig.episode_return` model's: ``[B, T, 2]``, each episode's scaled return so far beside them); a
        discrete group's `prev_action` holds indices ``[B, T]`` (any at an episode start: the padding replaces it)."""
        encoder = self.encoders[group]
        prev_action = self.action_head(group).encode_previous(prev_action).to(obs.dtype)
        owner = self if self.config.shared_padding else encoder
        # The owner has each padding its config uses (`ModelConfig.pads_action`, `pads_reward`).
        return encoder(obs, prev_action, prev_reward, episode_start, owner.act_pad, owner.rew_pad)

    def backbone(self, x: torch.Tensor) -> torch.Tensor:
        """Causal transformer over tokens ``[B, T, d_model]``, positions 0..T-1."""
        T = x.shape[1]
        if T > self.config.context_len:
            raise ValueError(f"{T} steps exceed context_len {self.config.context_len}")
        pos = torch.arange(T, device=x.device)
        # Build the bias in the dtype attention will run in, once: see `attention`.
        dev = x.device.type
        dtype = torch.get_autocast_dtype(dev) if torch.is_autocast_enabled(dev) else x.dtype
        bias = alibi_bias(pos, pos, self.alibi_slopes).to(dtype)
        for block in self.blocks:
            x = block(x, bias)
        return self.ln_f(x)

    def head(self, group: str, h: torch.Tensor) -> torch.Tensor:
        """Point predictions ``[B, T, act_dim]`` from backbone outputs: the (mean, or a flow's greedy) action, or a
        discrete group's logits (`ActionHead.predict`)."""
        return self.action_head(group).predict(h)

    def action_head(self, group: str) -> ActionHead:
        """The group's `ActionHead`: its loss and how it acts."""
        return cast(ActionHead, self.heads[group])

    def forward(
        self, group: str, task_idx: torch.Tensor, obs: torch.Tensor, prev_action: torch.Tensor,
        prev_reward: torch.Tensor, step_num: torch.Tensor, prev_return: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Predicted a_t for every step: ``obs [B,T,obs_dim]``, ``prev_action [B,T,act_dim]`` (a discrete group:
        indices ``[B,T]``, and the output is logits), ``prev_reward [B,T]``, ``step_num [B,T]`` (step within
        episode), ``task_idx [B]``; ``prev_return [B,T]`` for an `ModelConfig.episode_return` model (`embed`)."""
        x = self.embed(group, task_idx, obs, prev_action, prev_reward, step_num, prev_return)
        return self.head(group, self.backbone(x))


def estimated_parameters(config: ModelConfig, groups: Sequence[GroupSpec]) -> int:
    """The parameter count of a Vintix of `config` over `groups`, from the config's arithmetic alone (the
    weight matrices; biases and norms are a few percent more): a size checked before a single layer is
    built, since building a model of 10^9 layers, even on torch's meta device, never ends."""
    d = config.d_model
    per_block = 4 * d * d + 2 * d * config.mlp_dim  # attention's qkv and projection, the MLP's two layers
    per_group = sum(
        spec.obs_dim * config.obs_codes_per_channel * config.obs_emb_dim + config.obs_emb_dim ** 2
        + spec.act_dim * config.act_emb_dim + config.act_emb_dim ** 2 + config.head_layers * d * d + d * spec.act_dim
        for spec in groups)
    return config.n_layers * per_block + per_group


def count_parameters(model: nn.Module) -> int:
    """Number of parameters (buffers such as normalization statistics excluded); works on 'meta'."""
    return sum(p.numel() for p in model.parameters())
