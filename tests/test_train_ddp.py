"""Two-process DDP training on CPU through torchrun (gloo): it completes and the replicas stay identical."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
import yaml

from conftest import HANG_GUARD_S
from test_train import TEST_MODEL, metaworld_data  # noqa: F401  (the module-scoped data fixture)
from vintix.model import load_pretrained
from vintix.train.checkpoint import latest_checkpoint, read_training_state


@pytest.mark.slow
def test_torchrun_two_processes_on_cpu_keep_replicas_identical(metaworld_data, tmp_path):  # noqa: F811
    config = tmp_path / "ddp.yaml"
    config.write_text(yaml.safe_dump({
        "model": "tiny", "model_overrides": TEST_MODEL, "batch_size": 2, "max_steps": 4, "warmup_steps": 1,
        "checkpoint_every": 2, "log_every": 1, "tensorboard": False, "device": "cpu",
        "stats_cache_dir": str(tmp_path / "cache"),
    }))
    out = tmp_path / "run"
    command = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
               "-m", "vintix", "train", "--config", str(config), "--data", str(metaworld_data), "--out", str(out)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=HANG_GUARD_S,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "2 process(es) on cpu" in result.stdout
    state = read_training_state(latest_checkpoint(out))
    assert state["step"] == 4 and state["world_size"] == 2
    # Every rank's parameter checksum, gathered at the checkpoint: bitwise-equal replicas.
    first, second = state["replica_checksums"]
    assert first == second
    # 4 steps x 2 ranks x 2 windows x 128 steps.
    assert state["tokens"] == 4 * 2 * 2 * 128
    assert load_pretrained(latest_checkpoint(out)).config.n_layers == TEST_MODEL["n_layers"]
