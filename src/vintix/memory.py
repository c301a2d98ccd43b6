"""Sizes checked against the machine's memory before anything is allocated.

A model of billions of units, a context of 10^9 steps or thousands of envs in one agent would end in
a MemoryError deep inside torch, or in the kernel's OOM killer, after minutes of work; checked first,
they are an error that names the size, what asked for it and how to shrink it.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from typing import TypeVar

import torch

from vintix.errors import VintixError

M = TypeVar("M", bound=torch.nn.Module)


class OutOfMemoryError(VintixError, MemoryError):
    """What was asked for does not fit in this machine's memory."""


def available_memory() -> int:
    """Bytes of memory available to new allocations (Linux's MemAvailable; else all physical memory)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def tensor_bytes(tensors: Iterable[torch.Tensor]) -> int:
    return sum(t.numel() * t.element_size() for t in tensors)


def ensure_fits(nbytes: int, what: str, fix: str, device: torch.device | str = "cpu") -> None:
    """Raise OutOfMemoryError when `what` (`nbytes` of it) exceeds the memory available on `device`."""
    device = torch.device(device)
    if device.type == "cuda":
        available, where = torch.cuda.mem_get_info(device)[0], f"{device} has"
    else:
        available, where = available_memory(), "this machine has"
    if nbytes > available:
        raise OutOfMemoryError(f"{what} needs {nbytes / 2**30:,.1f} GiB; {where} {available / 2**30:,.1f} GiB "
                               f"available. {fix}")



def build_within_memory(build: Callable[[], M], copies: int, what: str, fix: str) -> M:
    """`build()`, once its tensors' size times `copies` (weights, gradients, optimizer moments...) is known
    to fit: it is built first on torch's meta device, which allocates nothing."""
    with torch.device("meta"):
        shape_only = build()
    ensure_fits(copies * tensor_bytes([*shape_only.parameters(), *shape_only.buffers()]), what, fix)
    return build()
