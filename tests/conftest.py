"""Shared helpers for tests that drive real environments."""

import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

HANG_GUARD_S = 3600
"""The timeout of every subprocess a test runs: a guard against a hang only, never a speed check. The longest such
command (tests/test_icrl_your_env.py's page: about 6.5 minutes on 2 idle cores) runs four times slower with the other
core busy, and an hour is still twice that."""


def child_env(**extra: str) -> dict[str, str]:
    """The environment of a `python -m vintix` child process: this one's, with its import path, so the
    child runs the same vintix (the source tree may be first on the path, not installed), plus `extra`."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), **extra}


@pytest.fixture(autouse=True)
def own_user_cache(tmp_path, monkeypatch):
    """Tests never read or delete the user's ~/.cache/vintix (norm stats, unfinished demonstrator runs)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "user-cache"))


@pytest.fixture
def without_shipped_weights(tmp_path, monkeypatch):
    """The package as if it shipped no trained demonstrator, so a test of a missing one does not hang on
    which tasks ship one."""
    monkeypatch.setattr("vintix.demonstrators.trained.shipped_weights_dir", lambda: tmp_path / "no-weights")


def rollout(env, steps: int, action_seed: int = 0, reset_seed: int | None = None):
    """Reset (with `reset_seed`), then take `steps` uniform-random actions drawn from a generator of
    our own (not the env's action space), resetting at episode ends.
    Returns (observations, rewards) stacked, the reset observations included."""
    rng = np.random.default_rng(action_seed)
    low, high = env.action_space.low, env.action_space.high
    obs, _ = env.reset(seed=reset_seed)
    observations, rewards = [obs], []
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(rng.uniform(low, high).astype(env.action_space.dtype))
        observations.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            observations.append(env.reset()[0])
    return np.array(observations), np.array(rewards)


def flip_a_byte_of_data(path, dataset: str = "0-6/proprio_observation") -> None:
    """Damage one data block in place, leaving the file's structure (and so its openability) intact."""
    with h5py.File(path) as f:
        chunk = f[dataset].id.get_chunk_info(0)
    with open(path, "r+b") as f:
        f.seek(chunk.byte_offset + chunk.size // 2)
        byte = f.read(1)
        f.seek(-1, 1)
        f.write(bytes([byte[0] ^ 0xFF]))


def mounted_tmpfs(folder: Path, options: str):
    """A real tmpfs file system mounted at `folder` (created) while the generator runs; the test is
    skipped where mounting is not allowed."""
    folder.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)], capture_output=True).returncode:
        pytest.skip("mounting a tmpfs needs root (or CAP_SYS_ADMIN)")
    yield folder
    subprocess.run(["umount", "--lazy", str(folder)], check=True)  # lazy: a file a failed test left open


@pytest.fixture
def small_disk(tmp_path):
    """An 8 MB file system, for a disk that fills up."""
    yield from mounted_tmpfs(tmp_path / "disk", "size=8m")


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder on a read-only file system (permission bits would not stop the root user tests run as)."""
    yield from mounted_tmpfs(tmp_path / "read-only", "size=1m,ro")


def fill_up(disk: Path) -> Path:
    """Write zeros into `disk` until it is full, as another program would; returns the ballast file (which may
    be empty, or absent: on a loaded machine the writer being tested can fill the disk first)."""
    ballast = disk / "ballast"
    try:
        with open(ballast, "wb") as f:
            while True:
                f.write(bytes(1 << 16))
                f.flush()
    except OSError:
        pass
    return ballast


def pytest_collection_modifyitems(config, items):
    """The minutes-long end-to-end tests (marked slow) first: with a pytest worker per core (`make test`), each file
    on one worker, they then run side by side from the start instead of one of them alone at the end."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)  # stable: the rest keep their order
