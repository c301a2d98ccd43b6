"""Time one layer's single-query attention over a full KV cache, the step of a cached agent, in the
precisions and kernels a CPU offers: why batching envs cannot make that step ≥ 8× cheaper per env here.

    python scripts/bench_cached_attention.py                  # the tiny preset: 16 envs x 4 heads x 1,024 keys
    python scripts/bench_cached_attention.py --envs 16 --heads 8 --keys 2048 --head-dim 48   # small

Every env attends over its own cache, so the step reads all of it whatever the batching; a cheaper
step would need fewer bytes per key (half precision) or a kernel that reads them faster. The model
uses the first row (fp32 matmul, `vintix.model.model.attention`); docs/benchmarks.md quotes this table.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from functools import partial

import torch
import torch.nn.functional as F


def milliseconds(work: Callable[[], object], repeats: int) -> float:
    work()  # warm-up
    started = time.perf_counter()
    for _ in range(repeats):
        work()
    return (time.perf_counter() - started) / repeats * 1e3


def matmul_attention(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    scores = torch.matmul(q, k.transpose(-2, -1)) * q.shape[-1] ** -0.5 + bias
    return torch.matmul(scores.softmax(dim=-1), v)


def sdpa_attention(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    return F.scaled_dot_product_attention(q, k, v, attn_mask=bias)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", type=int, default=16)
    parser.add_argument("--heads", type=int, default=4)
    parser.add_argument("--keys", type=int, default=1024, help="cached steps attended over (the window)")
    parser.add_argument("--head-dim", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"one query per env, {args.envs} envs x {args.heads} heads x {args.keys} keys x {args.head_dim} dims, "
          "1 thread")
    for dtype in (torch.float32, torch.bfloat16, torch.float16):
        shape = (args.envs, args.heads)
        q = torch.randn(*shape, 1, args.head_dim, dtype=dtype)
        k, v = (torch.randn(*shape, args.keys, args.head_dim, dtype=dtype) for _ in range(2))
        bias = torch.randn(*shape, 1, args.keys, dtype=dtype)
        cache_mb = 2 * k.numel() * k.element_size() / 2**20
        times = [milliseconds(partial(attend, q, k, v, bias), args.repeats) for attend in (matmul_attention,
                                                                                           sdpa_attention)]
        print(f"{str(dtype):15} cache {cache_mb:6.1f} MB   matmul {times[0]:6.2f} ms   SDPA {times[1]:6.2f} ms")


if __name__ == "__main__":
    main()
