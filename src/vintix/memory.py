"""Sizes checked against the machine's memory before anything is allocated.

A model of billions of units, a context of 10^9 steps or thousands of envs in one agent would end in
a MemoryError deep inside torch, or in the kernel's OOM killer, after minutes of work; checked first,
they are an error that names the size, what asked for it and how to shrink it.
"""

from __future__ import annotations

import os
import resource
from collections.abc import Callable, Iterable
from typing import TypeVar

import torch

from vintix.errors import VintixError

M = TypeVar("M", bound=torch.nn.Module)


class OutOfMemoryError(VintixError, MemoryError):
    """What was asked for does not fit in this machine's memory."""


def available_memory() -> int:
    """Bytes this process may still allocate: the least of the machine's available memory (Linux's MemAvailable;
    else all physical memory), what its address-space limit leaves (``ulimit -v``, as clusters and containers
    set) and what its cgroup's memory limit leaves (a container's)."""
    limits = [_machine_available()]
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        limits.append(soft - _address_space_used())
    cgroup = _cgroup_left()
    if cgroup is not None:
        limits.append(cgroup)
    return max(0, min(limits))


def _machine_available() -> int:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _address_space_used() -> int:
    """Bytes of this process's virtual address space (what ``ulimit -v`` counts)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


_CGROUP_FILES = (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),  # cgroup v2
                 ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"))


def _cgroup_left() -> int | None:
    """Bytes left under this process's cgroup memory limit, or None where there is none."""
    for limit_file, usage_file in _CGROUP_FILES:
        try:
            with open(limit_file) as f:
                limit = f.read().strip()
            with open(usage_file) as f:
                usage = int(f.read().strip())
        except (OSError, ValueError):
            continue
        if limit != "max" and int(limit) < 2**60:  # v1 writes a huge number for "no limit"
            return int(limit) - usage
    return None


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



def build_within_memory(build: Callable[[], M], copies: int, what: str, fix: str, parameters: int = 0) -> M:
    """`build()`, once its tensors' size times `copies` (weights, gradients, optimizer moments...) is known
    to fit: `parameters` (an estimate from the config's arithmetic, fp32) is checked first, before anything is
    built; then the model is built on torch's meta device, which allocates nothing, and checked exactly."""
    ensure_fits(copies * 4 * parameters, what, fix)
    with torch.device("meta"):
        shape_only = build()
    ensure_fits(copies * tensor_bytes([*shape_only.parameters(), *shape_only.buffers()]), what, fix)
    return build()
