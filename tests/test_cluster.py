"""`--ray`: collection and evaluation fanned out as Ray tasks, on a local Ray instance, give what the
same commands give in local processes; without Ray installed, `--ray` says how to install it."""

from __future__ import annotations

import re
import shutil
import socket
import sys
import tempfile

import numpy as np
import pytest
from typer.testing import CliRunner

from conftest import HANG_GUARD_S
from vintix.cli import app
from vintix.data import LearningHistory

runner = CliRunner()


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray instance for the module (starting one takes seconds); `--ray auto` joins it. Its session
    folder sits under a short path of its own, not TMPDIR: Ray's sockets live there, and a Unix socket's path
    may not exceed 107 bytes, which a long TMPDIR breaks."""
    ray = pytest.importorskip("ray")
    folder = tempfile.mkdtemp(prefix="vx-ray-", dir="/tmp")
    ray.init(num_cpus=2, include_dashboard=False, _temp_dir=folder)
    yield
    ray.shutdown()
    shutil.rmtree(folder, ignore_errors=True)


def test_collection_on_ray_equals_the_local_collection(tmp_path, local_ray):
    common = ["collect", "--task", "reach-v3", "--histories", "3", "--steps", "300", "--envs-per-batch", "1"]
    local = runner.invoke(app, [*common, "--out", str(tmp_path / "local")])
    on_ray = runner.invoke(app, [*common, "--ray", "auto", "--out", str(tmp_path / "ray")])  # 3 batches: 3 Ray tasks
    assert local.exit_code == 0, local.output
    assert on_ray.exit_code == 0, on_ray.output
    assert f"wrote 3 histories (900 steps) under {tmp_path / 'ray'}" in on_ray.output
    task = "metaworld/reach-v3"
    assert ((tmp_path / "ray" / task / "reach-v3.json").read_text()
            == (tmp_path / "local" / task / "reach-v3.json").read_text())
    for index in range(3):
        name = f"{task}/history-{index:04d}.h5"
        with LearningHistory(tmp_path / "local" / name) as local, LearningHistory(tmp_path / "ray" / name) as on_ray:
            assert on_ray.attrs == local.attrs and on_ray.num_steps == local.num_steps == 300
            expected, got = local.read(0, 300), on_ray.read(0, 300)
            assert got.keys() == expected.keys()
            for key in expected:
                np.testing.assert_array_equal(got[key], expected[key], err_msg=f"{name} {key}")


def test_evaluation_on_ray_writes_the_local_episodes(tmp_path, local_ray):
    common = ["eval", "--checkpoint", "cpu-suite", "--tasks", "reach-v3,Reacher-v5", "--shots", "2", "--seeds", "2",
              "--batch-envs", "1"]  # four runs, one a batch: four Ray tasks
    local = runner.invoke(app, [*common, "--out", str(tmp_path / "local")])
    on_ray = runner.invoke(app, [*common, "--ray", "auto", "--out", str(tmp_path / "ray")])
    assert local.exit_code == 0, local.output
    assert on_ray.exit_code == 0, on_ray.output
    assert f"wrote 8 episodes to {tmp_path / 'ray' / 'episodes.csv'}" in on_ray.output
    episodes = (tmp_path / "ray" / "episodes.csv").read_text()
    assert episodes == (tmp_path / "local" / "episodes.csv").read_text()
    assert len({line.split(",")[4] for line in episodes.splitlines()[1:]}) == 2  # both seeds, in the local order


@pytest.mark.parametrize("command", [
    ["collect", "--task", "reach-v3", "--histories", "1", "--steps", "100"],
    ["eval", "--checkpoint", "cpu-suite", "--tasks", "reach-v3", "--shots", "1", "--seeds", "1"],
])
def test_ray_without_ray_installed_says_how_to_install_it_before_any_work(tmp_path, monkeypatch, command):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now fails as it does where Ray is not installed
    result = runner.invoke(app, [*command, "--ray", "auto", "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    assert "pip install 'vintix[cluster]'" in result.output
    assert not (tmp_path / "out").exists()


def a_closed_port() -> int:
    """A local TCP port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("where, named", [("--ray", "(from --ray)"), ("RAY_ADDRESS", "(from RAY_ADDRESS)"),
                                          ("stale ray start", "(from the latest `ray start` on this machine)")])
def test_a_cluster_address_where_nothing_runs_is_named_not_retried_for_minutes(tmp_path, monkeypatch, where, named):
    """ray.init retries such an address for minutes, printing warnings (a one-episode `eval --ray auto`
    never ended); `--ray` refuses it before any work, naming where the address came from."""
    ray = pytest.importorskip("ray")
    ray.shutdown()  # a connected process never looks at an address (the module's local instance)
    port = a_closed_port()
    address = f"127.0.0.1:{port}"
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path / "ray-tmp"))  # where `ray start` records its cluster
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    if where == "RAY_ADDRESS":
        monkeypatch.setenv("RAY_ADDRESS", address)
    elif where == "stale ray start":  # the file `ray start` leaves when its cluster dies without `ray stop`
        (tmp_path / "ray-tmp" / "ray").mkdir(parents=True)
        (tmp_path / "ray-tmp" / "ray" / "ray_current_cluster").write_text(address)
    result = runner.invoke(app, ["eval", "--checkpoint", "point-goal", "--tasks", "point-goal-v1", "--shots", "1",
                                 "--seeds", "1", "--ray", address if where == "--ray" else "auto",
                                 "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    # Ray's own lookup of a recorded cluster names this machine by its network address, not 127.0.0.1.
    assert re.search(rf"no Ray cluster answers at [\d.]+:{port} {re.escape(named)}", " ".join(result.output.split()))
    assert not (tmp_path / "out").exists()


def test_an_address_space_limit_ends_in_a_named_error_not_a_crash_inside_ray(tmp_path):
    """Under `ulimit -v` (clusters and containers set one) Ray cannot map its object store: it aborted in C++
    or its workers never started. `--ray` refuses first, in seconds, naming the limit."""
    pytest.importorskip("ray")
    import subprocess

    command = (f"ulimit -v 8000000; {sys.executable} -m vintix eval --checkpoint point-goal --tasks point-goal-v1 "
               f"--shots 1 --seeds 1 --ray auto --out {tmp_path / 'results'}")
    result = subprocess.run(["bash", "-c", command], capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert result.returncode != 0
    output = " ".join((result.stdout + result.stderr).split())
    assert "address-space limit (ulimit -v 8000000)" in output, output[-2000:]
    assert not (tmp_path / "results").exists()
