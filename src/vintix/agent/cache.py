"""A sliding-window KV cache for a batch of envs: per layer, a ring buffer of the last `window` tokens.

Why a ring buffer: once the window is full, the new token's k and v overwrite the oldest token's
slot in place. Nothing is shifted (a shift-by-one copies the whole cache every step: about 1.2 s at
the paper's size on this CPU) and nothing is re-encoded, so a step costs the same after a million
steps as at the step where the window first fills.

Why ALiBi stays right: every slot remembers, per env, the position of the token it holds in that env's
own sequence, and the attention bias is built from those positions, ``-slope * (q_pos - k_pos)``. Slot
order is irrelevant to softmax attention, so a wrapped ring needs no reordering. An env can sit out a
step (`advance`'s ``skip``: a vector env's next-step autoreset, whose step ignores the action): its slot of
that step is hidden from its later tokens and its own clock does not move, so its sequence of tokens and
their distances are what they would have been without the hole; only its window holds one token less
until the hidden slot is overwritten.

A window can keep a run's first `keep_first` steps for good (`ModelConfig.keep_first_steps`): its first
`keep_first` slots are never overwritten and the ring turns over the others. A model trained only on
windows that begin at a history's first, exploring episode then keeps seeing such a window as the run
goes on. For ALiBi, the kept steps count as if they came right before the oldest sliding step, so
every distance within the window is one that a training window holds.

Semantics once the window is full (the paper's, and Mistral's sliding-window attention): cached
keys and values keep the hidden states they were computed with, when their token was new and saw
its own last `window` tokens. A cached run therefore equals one forward over the *whole* run with a
banded causal mask (each token attends to itself and the `window - 1` tokens before it, in every
layer; `banded_forward` below), so information from beyond the window still reaches the output
through the layers. It is not an exact recompute over only the last `window` tokens, which would
re-encode the whole window every step. Before the window is full the two coincide, and both equal
the model's ordinary forward.
"""

from __future__ import annotations

import torch

from vintix.memory import ensure_fits
from vintix.model.model import KVUpdate, Vintix, alibi_bias

HIDDEN = 2**62
"""The position of a slot an env sat out: later than every query, so `alibi_bias` masks it"""


class KVCache:
    """Keys and values of the last `window` tokens of `batch` envs stepped in lockstep, per layer.

    Usage per forward of ``T`` new tokens: ``bias = cache.advance(T, slopes)``, then each layer
    ``i`` calls ``cache.layer(i)(k, v)`` (through ``Block.forward(x, bias, kv_cache=...)``), which
    writes the new k, v into their slots and returns the filled part of the window.
    """

    def __init__(
        self, n_layers: int, batch: int, n_heads: int, head_dim: int, window: int,
        device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32, keep_first: int = 0,
    ) -> None:
        if not 0 <= keep_first < window:
            raise ValueError(f"keep_first={keep_first} must lie in [0, window={window})")
        shape = (n_layers, batch, n_heads, window, head_dim)
        # Allocated once: memory is fixed by (layers, batch, window), never by how long the run is.
        self.keys = torch.zeros(shape, device=device, dtype=dtype)
        self.values = torch.zeros(shape, device=device, dtype=dtype)
        self.window = window
        self.keep_first = keep_first
        """slots that keep the run's first steps for good; the ring turns over the rest"""
        self.positions = torch.zeros(batch, window, dtype=torch.long, device=device)
        """per env, the position in its own sequence of the token in each slot (meaningful for the first
        `filled` slots; `HIDDEN` for a slot the env sat out)"""
        self.clocks = torch.zeros(batch, dtype=torch.long, device=device)
        """per env, the tokens it has taken: the position of its next token"""
        self.length = 0
        """steps written so far (each fills one slot of every env)"""
        self._slots = torch.zeros(0, dtype=torch.long, device=device)

    @classmethod
    def for_model(cls, model: Vintix, batch: int) -> KVCache:
        """An empty cache shaped for `model`'s backbone and window, on its device and dtype."""
        config = model.config
        weight = model.ln_f.weight
        keys_and_values = 2 * config.n_layers * batch * config.context_len * config.d_model * weight.element_size()
        ensure_fits(keys_and_values, f"a KV cache for {batch} envs over a {config.context_len}-step context",
                    "Step fewer envs in one agent (vintix eval --seeds), or use a model with a shorter context_len",
                    weight.device)
        return cls(config.n_layers, batch, config.n_heads, config.d_model // config.n_heads,
                   config.context_len, weight.device, weight.dtype, config.keep_first_steps)

    @property
    def filled(self) -> int:
        """Slots holding a token: grows to `window`, then stays there."""
        return min(self.length, self.window)

    def advance(self, new_tokens: int, slopes: torch.Tensor, skip: torch.Tensor | None = None) -> torch.Tensor:
        """Claim slots for the next `new_tokens` tokens; return their ALiBi bias ``[B, H, T, filled]``.

        Several tokens at once (a prompt) only while they fit without wrapping: a wrapped chunk
        would overwrite keys its own earlier tokens still attend to. `skip` (bool ``[B]``, one token):
        envs sitting this step out; their token is computed (it sees itself, so it stays finite) but
        hidden from every later token, and their clocks stay.
        """
        if new_tokens != 1 and (self.length + new_tokens > self.window or skip is not None):
            raise ValueError(
                f"{new_tokens} tokens at once do not fit the {self.window}-step window after {self.length} "
                "steps (and cannot skip envs); feed them one at a time"
            )
        steps = torch.arange(new_tokens, device=self.positions.device)
        index, kept = self.length + steps, self.keep_first
        self._slots = torch.where(index < self.window, index, kept + (index - kept) % (self.window - kept))
        query_positions = self.clocks.unsqueeze(1) + steps  # [B, T]
        self.positions[:, self._slots] = query_positions
        self.length += new_tokens
        bias = alibi_bias(query_positions, self._attended_positions(), slopes)
        if skip is None:
            self.clocks += new_tokens
        else:
            self.clocks += (~skip).long()
            self.positions[skip.nonzero().squeeze(1).unsqueeze(1), self._slots] = HIDDEN
        return bias

    def _attended_positions(self) -> torch.Tensor:
        """Per env, the positions the bias is built from ``[B, filled]``: the slots' own, except that once
        the ring has overwritten a step, the kept first steps move up to just before the oldest sliding one."""
        positions = self.positions[:, : self.filled]
        if not self.keep_first or self.length <= self.window:
            return positions
        kept, sliding = positions[:, : self.keep_first], positions[:, self.keep_first:]
        oldest_sliding = sliding.min(dim=1).values  # a hidden slot's HIDDEN is never the least
        newest_kept = kept.masked_fill(kept == HIDDEN, -1).max(dim=1).values
        shift = (oldest_sliding - newest_kept - 1).unsqueeze(1)
        return torch.cat([torch.where(kept == HIDDEN, kept, kept + shift), sliding], dim=1)

    def keep(self, envs: torch.Tensor) -> None:
        """Keep only the batch rows `envs` (indices, in that order). The rows share one clock, so
        positions stay as they are; this copies the kept rows once, a cost paid per call, not per step."""
        self.keys = self.keys[:, envs]
        self.values = self.values[:, envs]
        self.positions = self.positions[envs]
        self.clocks = self.clocks[envs]

    def layer(self, index: int) -> KVUpdate:
        """Layer `index`'s hook: store the new k, v ``[B, H, T, head_dim]``, return the filled window."""
        keys, values, slots, filled = self.keys[index], self.values[index], self._slots, self.filled

        def update(k: torch.Tensor, v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            keys[:, :, slots] = k
            values[:, :, slots] = v
            return keys[:, :, :filled], values[:, :, :filled]  # views: no copy

        return update


def cached_backbone(model: Vintix, tokens: torch.Tensor, cache: KVCache, skip: torch.Tensor | None = None
                    ) -> torch.Tensor:
    """The backbone over the new tokens ``[B, T, d_model]`` only, attending to the cached window; `skip`:
    see `KVCache.advance`."""
    bias = cache.advance(tokens.shape[1], model.alibi_slopes, skip).to(tokens.dtype)
    x = tokens
    for i, block in enumerate(model.blocks):
        x = block(x, bias, kv_cache=cache.layer(i))
    return model.ln_f(x)


def banded_forward(model: Vintix, tokens: torch.Tensor, window: int, keep_first: int = 0) -> torch.Tensor:
    """Reference for the cache's semantics: the backbone over a whole run ``[B, T, d_model]`` (T may
    exceed the context) where every token attends to itself and the ``window - 1`` before it; with
    `keep_first`, to the run's first `keep_first` tokens and the ``window - keep_first - 1`` before it,
    the first ones counted as right before those once the ring has overwritten a step."""
    positions = torch.arange(tokens.shape[1], device=tokens.device)
    query, key = positions.view(-1, 1), positions.view(1, -1)
    kept = key < keep_first
    seen_at = torch.where(kept & (query >= window), key + query - window + 1, key)  # [T query, T key]
    bias = alibi_bias(positions.view(-1, 1), seen_at, model.alibi_slopes)[:, :, 0].transpose(0, 1)  # [H, T, T]
    too_old = ~kept & (query - key >= window - keep_first)
    bias = bias.masked_fill(too_old, float("-inf")).to(tokens.dtype)
    x = tokens
    for block in model.blocks:
        x = block(x, bias)
    return model.ln_f(x)
