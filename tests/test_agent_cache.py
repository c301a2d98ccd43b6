"""The sliding-window KV cache: exact before the window fills, banded (streaming) semantics after,
fixed memory, prompt chunks equal single steps."""

from __future__ import annotations

import pytest
import torch

from inference_model import one_torch_thread, tiny_model  # noqa: F401  (autouse fixture)
from vintix.agent import KVCache, banded_forward, cached_backbone
from vintix.model.model import ModelConfigError

WINDOW = 16


def cached_outputs(model, tokens: torch.Tensor, chunk: int = 0) -> torch.Tensor:
    """Backbone outputs of every token, fed through a fresh cache (the first `chunk` at once)."""
    cache = KVCache.for_model(model, tokens.shape[0])
    outputs = [cached_backbone(model, tokens[:, :chunk], cache)] if chunk else []
    outputs += [cached_backbone(model, tokens[:, t : t + 1], cache) for t in range(chunk, tokens.shape[1])]
    return torch.cat(outputs, dim=1)


def make(steps: int, batch: int = 3, **overrides: int):
    model = tiny_model(context_len=WINDOW, **overrides)
    torch.manual_seed(1)
    with torch.no_grad():
        # At init the residual branches whisper (GPT-2 scaling); louder weights let every token
        # influence the others, so the comparisons below can tell the semantics apart.
        for weight in model.blocks.parameters():
            if weight.dim() == 2:
                weight.normal_(0.0, 0.2)
    return model, torch.randn(batch, steps, model.config.d_model)


@torch.inference_mode()
def test_cached_steps_equal_full_recompute_until_the_window_is_full():
    model, tokens = make(WINDOW)
    cached = cached_outputs(model, tokens)
    for t in range(WINDOW):
        recomputed = model.backbone(tokens[:, : t + 1])[:, -1]
        torch.testing.assert_close(cached[:, t], recomputed, rtol=1e-5, atol=1e-5)


@torch.inference_mode()
def test_after_the_window_is_full_the_cache_is_a_banded_forward_over_the_whole_run():
    model, tokens = make(3 * WINDOW + 5)
    cached = cached_outputs(model, tokens)
    torch.testing.assert_close(cached, banded_forward(model, tokens, WINDOW), rtol=1e-5, atol=1e-5)
    # ...which is not an exact recompute over the last WINDOW tokens: cached keys of deeper layers
    # keep what they saw when they were new (streaming semantics, as the paper's FlashAttention cache).
    t = 2 * WINDOW
    exact_window = model.backbone(tokens[:, t - WINDOW + 1 : t + 1])[:, -1]
    assert (cached[:, t] - exact_window).abs().max() > 1e-3


@torch.inference_mode()
def test_a_window_that_keeps_the_first_steps_slides_only_the_rest():
    keep = 5
    model, tokens = make(3 * WINDOW + 5, keep_first_steps=keep)
    cache = KVCache.for_model(model, tokens.shape[0])
    cached = torch.cat([cached_backbone(model, tokens[:, t : t + 1], cache) for t in range(tokens.shape[1])], dim=1)
    torch.testing.assert_close(cached, banded_forward(model, tokens, WINDOW, keep_first=keep), rtol=1e-5, atol=1e-5)
    end = tokens.shape[1]
    assert all(sorted(row) == [*range(keep), *range(end - WINDOW + keep, end)] for row in cache.positions.tolist())
    # the kept steps are heard: the outputs differ from a plain sliding window's once the run outgrows it
    plain = banded_forward(model, tokens, WINDOW)
    torch.testing.assert_close(cached[:, :WINDOW], plain[:, :WINDOW], rtol=1e-5, atol=1e-5)
    assert (cached[:, -1] - plain[:, -1]).abs().max() > 1e-3


def test_a_window_must_have_room_to_slide_past_the_steps_it_keeps():
    with pytest.raises(ModelConfigError, match="keep_first_steps"):
        tiny_model(context_len=WINDOW, keep_first_steps=WINDOW)


@torch.inference_mode()
def test_cache_memory_is_fixed_however_long_the_run():
    model, tokens = make(4 * WINDOW)
    cache = KVCache.for_model(model, tokens.shape[0])
    keys, values = cache.keys.data_ptr(), cache.values.data_ptr()
    size = cache.keys.numel() + cache.values.numel() + cache.positions.numel()
    for t in range(tokens.shape[1]):
        cached_backbone(model, tokens[:, t : t + 1], cache)
    assert cache.length == 4 * WINDOW and cache.filled == WINDOW
    assert (cache.keys.data_ptr(), cache.values.data_ptr()) == (keys, values)
    assert cache.keys.numel() + cache.values.numel() + cache.positions.numel() == size
    # the ring holds exactly the last WINDOW positions
    assert all(sorted(row) == list(range(3 * WINDOW, 4 * WINDOW)) for row in cache.positions.tolist())


@torch.inference_mode()
def test_a_prompt_chunk_equals_the_same_tokens_one_by_one():
    model, tokens = make(WINDOW + 6)
    torch.testing.assert_close(cached_outputs(model, tokens, chunk=10), cached_outputs(model, tokens),
                               rtol=1e-5, atol=1e-5)


def test_a_chunk_that_would_wrap_the_ring_is_refused():
    model, tokens = make(WINDOW)
    cache = KVCache.for_model(model, 3)
    cache.advance(WINDOW - 2, model.alibi_slopes)
    try:
        cache.advance(3, model.alibi_slopes)
    except ValueError as error:
        assert "one at a time" in str(error)
    else:
        raise AssertionError("a wrapping chunk was accepted")


def test_bench_infer_runs_and_prints_its_table():
    from typer.testing import CliRunner

    from vintix.cli import app

    result = CliRunner().invoke(app, ["bench", "infer", "tiny", "--envs", "2", "--repeats", "2", "--no-recompute",
                                      "--threads", "1"])
    assert result.exit_code == 0, result.output
    assert "tiny" in result.output and "literal run check" in result.output
