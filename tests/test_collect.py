"""Collecting noise-distilled learning histories on a real simulator with a real demonstrator."""

import filecmp
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.stats import spearmanr

from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    bad_input_test,
    cli_error,
    collected,
    documented,
    file_at,
    invoke,
    not_written,
    straight_and_killed_runs,
    truncate_file,
    work,
    workspace,
)
from conftest import HANG_GUARD_S, child_env, fill_up
from vintix.atomic import FolderInUseError, folder_lock
from vintix.collect import CollectionError, CollectionPlan, CollectionSettingsError, NoiseSchedule, collect
from vintix.collect.bench import benchmark_collection
from vintix.data import LearningHistory, read_task_metadata, validate_dataset
from vintix.demonstrators import ScriptedMetaWorldDemonstrator
from vintix.tasks import make_env

PLAN = CollectionPlan("reach-v3", histories=3, steps=300, envs_per_batch=2)


class InterruptedAfter:
    """The real demonstrator, until the process is interrupted (Ctrl-C) after `calls` steps."""

    def __init__(self, task: str, calls: int) -> None:
        self.inner, self.calls = ScriptedMetaWorldDemonstrator(task), calls

    def act(self, observations, envs):
        self.calls -= 1
        if self.calls < 0:
            raise KeyboardInterrupt
        return self.inner.act(observations, envs)


def test_history_rises_from_random_to_expert(tmp_path):
    plan = CollectionPlan("reach-v3", histories=1, steps=3000, schedule=NoiseSchedule(noise_free_fraction=0.1))
    [summary] = collect(plan, tmp_path)
    returns = summary.episode_returns
    assert len(returns) == 30
    assert spearmanr(np.arange(len(returns)), returns).statistic >= 0.8
    assert summary.mean_return(first=False) > 3 * summary.mean_return(first=True)


def test_histories_follow_the_format_and_the_episode_structure(tmp_path):
    summaries = collect(PLAN, tmp_path)
    assert validate_dataset(tmp_path) == []
    meta = read_task_metadata(tmp_path / "metaworld" / "reach-v3")
    assert meta["noise_free_fraction"] == PLAN.schedule.noise_free_fraction  # expert distillation reads it
    for summary in summaries:
        with LearningHistory(summary.path) as history:
            assert history.num_steps == 300
            np.testing.assert_array_equal(history.episode_starts, [0, 100, 200])  # 100-step episodes
            rows = history.read(0, 300)
            assert np.all(np.abs(rows["action"]) <= 1)


def test_histories_store_what_the_demonstrator_proposed_before_noise(tmp_path):
    plan = CollectionPlan("reach-v3", histories=1, steps=300, schedule=NoiseSchedule(noise_free_fraction=0.5))
    [summary] = collect(plan, tmp_path)
    with LearningHistory(summary.path) as history:
        rows, env_seed = history.read(0, 300, demonstrator_action=True), history.env_seed
    executed, proposed = rows["action"], rows["demonstrator_action"]
    np.testing.assert_array_equal(executed[150:], proposed[150:])  # the noise-free half plays the demonstrator
    assert np.abs(executed[:50] - proposed[:50]).mean() > 0.2  # where ε ≈ 1 the executed action is noise
    # The stored proposal is the scripted policy's action on the stored observation (same env: same goal),
    # inside the action bounds.
    env = make_env("reach-v3", seed=env_seed)
    env.reset()
    policy = ScriptedMetaWorldDemonstrator("reach-v3")
    np.testing.assert_allclose(np.clip(policy.act(rows["observation"][:20], [env] * 20), -1, 1), proposed[:20],
                               atol=1e-6)
    env.close()


def test_a_folder_collected_without_demonstrator_actions_is_refused(tmp_path):
    plan = CollectionPlan("reach-v3", histories=1, steps=100)
    [summary] = collect(plan, tmp_path)
    with h5py.File(summary.path, "r+") as f:
        for group in f:
            del f[group]["demonstrator_action"]
    with pytest.raises(CollectionSettingsError, match="no demonstrator actions \\(now stored\\)"):
        collect(plan, tmp_path)


def test_a_folder_played_by_another_demonstrator_is_refused_both_ways(tmp_path):
    """A history records a demonstrator named from outside the package, so neither the package's own nor a named
    one adds histories to a folder the other played."""
    named = CollectionPlan("reach-v3", histories=1, steps=100, demonstrator="vintix.demonstrators:load_demonstrator")
    collect(named, tmp_path / "named")
    with pytest.raises(CollectionSettingsError, match="demonstrator 'vintix.demonstrators:load_demonstrator' "
                                                      "\\(now None\\)"):
        collect(replace(named, demonstrator=None), tmp_path / "named")
    collect(replace(named, demonstrator=None), tmp_path / "own")
    with pytest.raises(CollectionSettingsError, match="demonstrator None"):
        collect(named, tmp_path / "own")


def test_same_seed_same_bytes_other_seed_other_data(tmp_path):
    collect(PLAN, tmp_path / "a")
    collect(PLAN, tmp_path / "b")
    collect(CollectionPlan("reach-v3", histories=1, steps=300, seed=1), tmp_path / "c")
    name = "metaworld/reach-v3/history-0000.h5"
    assert filecmp.cmp(tmp_path / "a" / name, tmp_path / "b" / name, shallow=False)
    with LearningHistory(tmp_path / "a" / name) as a, LearningHistory(tmp_path / "c" / name) as c:
        assert not np.array_equal(a.read(0, 300)["action"], c.read(0, 300)["action"])


def test_histories_do_not_depend_on_how_many_steps_are_buffered(tmp_path, monkeypatch):
    plan = CollectionPlan("InvertedPendulum-v5", histories=2, steps=250, envs_per_batch=2)
    collect(plan, tmp_path / "default")
    monkeypatch.setattr("vintix.collect.collector.BLOCK_STEPS", 7)  # blocks that straddle episodes and the end
    collect(plan, tmp_path / "small-blocks")
    for name in ["history-0000.h5", "history-0001.h5"]:
        assert filecmp.cmp(tmp_path / "default/mujoco/InvertedPendulum-v5" / name,
                           tmp_path / "small-blocks/mujoco/InvertedPendulum-v5" / name, shallow=False)


def test_collection_benchmark_replays_what_it_collected():
    [result] = benchmark_collection(["InvertedPendulum-v5"], steps=400, envs_per_batch=4, repeats=1)
    assert result.task == "InvertedPendulum-v5" and result.envs_per_batch == 4
    assert result.raw_steps_per_s > 0 and result.collect_steps_per_s > 0
    assert result.ratio == result.collect_steps_per_s / result.raw_steps_per_s


def test_interrupted_collection_resumes_to_identical_files(tmp_path):
    collect(PLAN, tmp_path / "straight")
    with pytest.raises(KeyboardInterrupt):
        # The first batch (histories 0, 1) completes; the second (history 2) dies halfway.
        collect(PLAN, tmp_path / "resumed", demonstrator=InterruptedAfter("reach-v3", calls=300 + 150))
    task_dir = tmp_path / "resumed" / "metaworld" / "reach-v3"
    assert sorted(p.name for p in task_dir.iterdir()) == ["history-0000.h5", "history-0001.h5", "reach-v3.json"]
    collect(PLAN, tmp_path / "resumed")
    for name in ["history-0000.h5", "history-0001.h5", "history-0002.h5", "reach-v3.json"]:
        assert filecmp.cmp(tmp_path / "straight/metaworld/reach-v3" / name, task_dir / name, shallow=False), name


def test_a_folder_finished_with_other_settings_is_refused_not_reported_as_done(tmp_path):
    first = CollectionPlan("reach-v3", histories=2, steps=100, envs_per_batch=2)
    collect(first, tmp_path)
    task_dir = tmp_path / "metaworld" / "reach-v3"
    before = {p.name: p.read_bytes() for p in task_dir.iterdir()}
    for other, difference in [(dict(steps=50), "steps 100 (now 50)"), (dict(seed=1), "collection_seed 0 (now 1)"),
                              (dict(schedule=NoiseSchedule(curvature=2.0)), "curvature 1.0 (now 2.0)"),
                              (dict(schedule=NoiseSchedule(knots=[1.0, 0.5, 0.0])), "knots [] (now [1.0, 0.5, 0.0])")]:
        with pytest.raises(CollectionSettingsError, match="holds histories made with other settings") as error:
            collect(CollectionPlan("reach-v3", **{**dict(histories=2, steps=100, envs_per_batch=2), **other}), tmp_path)
        assert difference in str(error.value) and "history-0000.h5" in str(error.value)
    assert {p.name: p.read_bytes() for p in task_dir.iterdir()} == before  # JSON included: nothing rewritten
    again = collect(CollectionPlan("reach-v3", histories=3, steps=100, envs_per_batch=2), tmp_path)
    assert [s.collected_now for s in again] == [False, False, True]  # same settings: only the new one


def test_a_folder_collected_with_knots_resumes_with_the_same_knots(tmp_path):
    plan = CollectionPlan("reach-v3", histories=1, steps=100, schedule=NoiseSchedule(knots=[1.0, 0.2, 0.0]))
    collect(plan, tmp_path)
    [again] = collect(plan, tmp_path)  # the knots read back from the file match the plan's
    assert not again.collected_now
    with LearningHistory(again.path) as history:
        np.testing.assert_array_equal(history.attrs["knots"], [1.0, 0.2, 0.0])


def test_a_pilot_fits_each_history_its_own_knots_and_resumes_with_them(tmp_path):
    plan = CollectionPlan("handle-pull-v3", histories=3, steps=300, envs_per_batch=3,
                          schedule=NoiseSchedule(noise_free_fraction=0.1, pilot_steps=2000))
    summaries = collect(plan, tmp_path)
    knots = []
    for summary in summaries:
        with LearningHistory(summary.path) as history:
            assert history.attrs["pilot_steps"] == 2000 and history.num_steps == 300  # the pilot is not stored
            knots.append(tuple(history.attrs["knots"]))
    assert all(k[0] == 1 and k[-1] == 0 and np.all(np.diff(k) <= 0) for k in knots)
    assert len(set(knots)) == 3  # each goal answers noise its own way (seed 0: three different fits)
    assert not any(s.collected_now for s in collect(plan, tmp_path))  # each file's own knots are not a difference
    without = CollectionPlan("handle-pull-v3", 3, 300, envs_per_batch=3,
                             schedule=NoiseSchedule(noise_free_fraction=0.1))
    for other, folder, difference in [(replace(plan, schedule=replace(plan.schedule, pilot_steps=1000)), tmp_path,
                                       "pilot_steps 2000 (now 1000)"), (without, tmp_path, "pilot_steps 2000 (now 0)"),
                                      (plan, tmp_path / "plain", "pilot_steps 0 (now 2000)")]:
        if folder.name == "plain":
            collect(without, folder)
        with pytest.raises(CollectionSettingsError, match="other settings") as error:
            collect(other, folder)
        assert difference in str(error.value)
    with pytest.raises(CollectionError, match="reach-v3: a pilot of 50 steps completed 0 episode"):
        collect(CollectionPlan("reach-v3", 1, 100, schedule=NoiseSchedule(pilot_steps=50)), tmp_path / "short")
    assert not list((tmp_path / "short").rglob("*.h5"))
    with pytest.raises(CollectionError, match="give knots or pilot_steps, not both"):
        CollectionPlan("reach-v3", 1, 100, NoiseSchedule(knots=(1.0, 0.0), pilot_steps=100))


@pytest.mark.parametrize(("settings", "message"), [
    (dict(envs_per_batch=0), "envs_per_batch=0"), (dict(histories=0), "histories=0"), (dict(steps=-5), "steps=-5"),
    (dict(seed=-1), "seed=-1"), (dict(steps="100"), "CollectionPlan.steps must be int, got '100'"),
])
def test_plan_settings_out_of_range_are_named(settings, message):
    with pytest.raises(CollectionError, match=message):
        CollectionPlan("reach-v3", **{"histories": 1, "steps": 100, **settings})


def test_a_second_collection_into_a_folder_in_use_is_refused_at_once(tmp_path):
    plan = CollectionPlan("reach-v3", histories=1, steps=10)
    with folder_lock(tmp_path, "vintix collect"):  # as another process collecting there would hold it
        with pytest.raises(FolderInUseError, match=rf"is in use by vintix collect \(pid {os.getpid()}\)"):
            collect(plan, tmp_path)
        assert not list(tmp_path.rglob("*.h5"))
    assert len(collect(plan, tmp_path)) == 1  # released with the block: the kernel's lock, no stale file to delete


def test_a_collection_the_disk_cannot_hold_is_refused_before_anything_is_written(tmp_path):
    plan = CollectionPlan("reach-v3", histories=1, steps=10**12)
    with pytest.raises(CollectionError, match=r"need about [\d,.]+ [kMGT]B, and .* [kMGT]B free; free space"):
        collect(plan, tmp_path / "data")
    assert not (tmp_path / "data").exists()


def test_a_seed_an_hdf5_attribute_cannot_hold_is_refused():
    with pytest.raises(CollectionError, match=r"0 <= seed < 2\*\*63"):
        CollectionPlan("reach-v3", histories=1, steps=10, seed=2**64)


def _children(pid: int) -> set[int]:
    """The live processes whose parent is `pid` (Linux /proc)."""
    children = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # the process ended while we looked
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            children.add(int(stat.parent.name))
    return children


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def start_collection(args: list[str], out: Path) -> subprocess.Popen:
    """`python -m vintix *args --out out` as a real process, its output (stdout and stderr) piped."""
    env = child_env()
    return subprocess.Popen([sys.executable, "-m", "vintix", *args, "--out", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def wait_for_partial_files(task_dir: Path, count: int) -> None:
    """Until `count` histories are being written in `task_dir` (or two minutes have passed)."""
    deadline = time.monotonic() + 120
    while len(list(task_dir.glob("*.partial"))) < count and time.monotonic() < deadline:
        time.sleep(0.02)


def assert_rerun_gives_the_uninterrupted_bytes(args: list[str], interrupted: Path, straight: Path,
                                               histories: int) -> None:
    for out in (interrupted, straight):
        output, _ = (process := start_collection(args, out)).communicate(timeout=HANG_GUARD_S)
        assert process.returncode == 0, output
    for name in ["reach-v3.json"] + [f"history-{i:04d}.h5" for i in range(histories)]:
        assert filecmp.cmp(straight / "metaworld/reach-v3" / name, interrupted / "metaworld/reach-v3" / name,
                           shallow=False), name


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGKILL], ids=["kill", "kill -9"])
def test_a_killed_multi_worker_collection_ends_its_workers_and_the_rerun_is_identical(tmp_path, signum):
    """`kill` (SIGTERM) or `kill -9` of `vintix collect --workers 2` mid-run: the collection and both
    workers end (SIGTERM: the parent ends them and says so; kill -9: the kernel tells them their parent
    died), no unfinished file is left, and the re-run completes to the bytes of an uninterrupted one."""
    args = ["collect", "--task", "reach-v3", "--histories", "4", "--steps", "2000", "--envs-per-batch", "1",
            "--workers", "2"]
    killed = tmp_path / "killed"
    process = start_collection(args, killed)
    wait_for_partial_files(killed / "metaworld" / "reach-v3", 2)
    workers = _children(process.pid)
    try:
        assert len(workers) >= 2, "both workers should be writing by now"
        process.send_signal(signum)
        # Orphaned workers would hold the output pipe open: this would time out.
        output, _ = process.communicate(timeout=60)
        assert process.returncode != 0 and "Traceback" not in output, output
        assert "interrupted" in output or signum == signal.SIGKILL, output
        deadline = time.monotonic() + 30
        while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(pid) for pid in workers), "a worker outlived the collection"
    finally:
        for pid in workers | {process.pid}:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
    assert not list(killed.rglob("*.partial"))
    assert_rerun_gives_the_uninterrupted_bytes(args, killed, tmp_path / "straight", histories=4)


def test_a_disk_that_fills_up_mid_collection_ends_it_with_the_fix_and_no_unfinished_file(tmp_path, small_disk):
    """Another program fills the disk while `vintix collect` writes (the check before it starts passed):
    a named error with the fix, exit 2, no traceback, no .partial left; once there is room, the re-run
    completes to the bytes of an uninterrupted collection."""
    args = ["collect", "--task", "reach-v3", "--histories", "2", "--steps", "2000", "--envs-per-batch", "1"]
    out = small_disk / "data"
    process = start_collection(args, out)
    wait_for_partial_files(out / "metaworld" / "reach-v3", 1)
    ballast = fill_up(small_disk)
    output, _ = process.communicate(timeout=HANG_GUARD_S)
    assert process.returncode == 2, output
    assert "No space left on device" in output and "the disk is full" in output and "Traceback" not in output, output
    assert "the same `vintix collect` resumes from them" in " ".join(output.split()), output
    assert not list(out.rglob("*.partial"))
    ballast.unlink(missing_ok=True)
    assert_rerun_gives_the_uninterrupted_bytes(args, out, tmp_path / "straight", histories=2)


def test_the_summary_has_one_row_per_task_and_leaves_out_episodes_the_historys_end_cut_short(tmp_path):
    """Reacher's episodes run 50 steps: a 120-step history holds 2 complete ones and 20 steps of a third,
    whose return (20 steps' worth) would pull the last 10 % of the history toward zero."""
    from typer.testing import CliRunner

    from vintix.cli import app

    result = CliRunner().invoke(app, ["collect", "--task", "Reacher-v5", "--histories", "3", "--steps", "120",
                                      "--noise-free-fraction", "1.0", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    [row] = [line for line in result.output.splitlines() if line.startswith("│ Reacher-v5")]
    cells = [c.strip() for c in row.strip("│").split("│")]
    assert cells[1:4] == ["3", "360", "6"] and "history-0000" not in result.output
    complete = []
    for path in sorted((tmp_path / "mujoco" / "Reacher-v5").glob("*.h5")):
        with LearningHistory(path) as history:
            complete.append(history.episode_returns()[-2])  # the last complete episode
    assert float(cells[5]) == pytest.approx(np.mean(complete), abs=0.05)


# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

# Collection
cli_error("collect", "--plan with a damaged rates table", lambda: [
    "collect", "--recipe", "tiny", "--plan", "--rates", file_at("rates.csv", "task,speed\nreach-v3,fast\n")()],
    "not a readable rates table")
cli_error("collect", "--plan with --workers 0", ["collect", "--recipe", "paper", "--plan", "--workers", "0"],
          "workers must be >= 1")
cli_error("collect", "neither --task nor --recipe", lambda: ["collect", "--out", work() / "c1"],
          "exactly one of --task")
cli_error("collect", "both --task and --recipe", lambda: ["collect", "--task", "reach-v3", "--recipe", "tiny",
                                                          "--out", work() / "c2"], "exactly one of --task")
cli_error("collect", "unknown task", lambda: ["collect", "--task", "reech-v3", "--out", work() / "c3"], "Did you mean")
cli_error("collect", "task without a demonstrator",
          lambda: ["collect", "--task", "Humanoid-v5", "--out", work() / "c4"],
          "no trained demonstrator")
cli_error("collect", "Bi-DexHands task", lambda: ["collect", "--task", "Hand-Pen", "--out", work() / "c5"], "Hand-Pen")
for option, value, needle in [("--envs-per-batch", "0", "envs_per_batch=0"), ("--histories", "0", "histories=0"),
                              ("--steps", "0", "steps=0"), ("--steps", "-5", "steps=-5"), ("--seed", "-1", "seed=-1"),
                              ("--curvature", "0", "curvature"),
                              ("--noise-free-fraction", "1.5", "noise_free_fraction"),
                              ("--workers", "0", "workers")]:
    cli_error("collect", f"{option} {value}", lambda o=option, v=value: ["collect", "--task", "reach-v3", o, v,
                                                                         "--out", work() / "c6"], needle,
              after=not_written(lambda: work() / "c6"))
cli_error("collect", "unknown recipe", lambda: ["collect", "--recipe", "nosuch", "--out", work() / "c7"],
          "no recipe file")
cli_error("collect", "recipe: invalid YAML", lambda: ["collect", "--recipe", file_at("bad.yaml", "tasks: [a, : b")(),
                                                      "--out", work() / "c8"], "not valid YAML")
for name, recipe, needle in [
    ("unknown setting", "tasks:\n  reach-v3: {stpes: 100}\n", "unknown setting"),
    ("steps is text", "tasks:\n  reach-v3: {histories: 1, steps: many}\n", "steps must be int"),
    ("no histories anywhere", "tasks:\n  reach-v3: {steps: 100}\n", "no histories"),
    ("tasks is a list", "tasks: [reach-v3]\n", "non-empty 'tasks:' mapping"),
    ("task settings are a number", "tasks:\n  reach-v3: 5\n", "must be mappings"),
    ("unknown task", "tasks:\n  reech-v3: {}\n", "reech-v3"),
    ("rising knots", "tasks:\n  reach-v3: {histories: 1, steps: 10, knots: [1, 0.2, 0.5, 0]}\n", "never rising"),
    ("knots and a curvature", "tasks:\n  reach-v3: {histories: 1, steps: 10, knots: [1, 0], curvature: 2}\n",
     "not both"),
    ("knots are text", "tasks:\n  reach-v3: {histories: 1, steps: 10, knots: steep}\n", "knots must be"),
    ("knots and a pilot", "tasks:\n  reach-v3: {histories: 1, steps: 10, knots: [1, 0], pilot_steps: 500}\n",
     "not both"),
    ("negative pilot", "tasks:\n  reach-v3: {histories: 1, steps: 10, pilot_steps: -1}\n", "pilot_steps must be >= 0"),
    ("pilot shorter than two episodes", "tasks:\n  reach-v3: {histories: 1, steps: 10, pilot_steps: 150}\n",
     "too few to fit knots to"),
]:
    slug = name.replace(" ", "-")
    cli_error("collect", f"recipe: {name}", lambda r=recipe, f=f"{slug}.yaml": [
        "collect", "--recipe", file_at(f, r)(), "--out", work() / f"c-{f}"], needle)
cli_error("collect", "--out is a file", lambda: ["collect", "--task", "reach-v3", "--steps", "10", "--out",
                                                 file_at("out-file", "x")()], "not a directory")
cli_error("collect", "folder finished with other --steps", lambda: ["collect", "--task", "reach-v3", "--histories", "1",
                                                                    "--steps", "100", "--out", collected()],
          "made with other settings")
cli_error("collect", "folder finished with other --seed", lambda: [
    "collect", "--task", "reach-v3", "--histories", "1", "--steps", "150", "--seed", "4", "--out", collected()],
          "made with other settings")


def truncated_history_in_collection() -> list[str]:
    out = work() / "collected-truncated"
    shutil.copytree(collected(), out, dirs_exist_ok=True)
    truncate_file(out / "metaworld" / "reach-v3" / "history-0000.h5")
    return ["collect", "--task", "reach-v3", "--histories", "1", "--steps", "150", "--out", out]


cli_error("collect", "a finished history was truncated since", truncated_history_in_collection, "history-0000.h5")


def rerun_collects_nothing() -> str | None:
    code, output = invoke("collect", "--task", "reach-v3", "--histories", "1", "--steps", "150", "--out", collected())
    return None if code == 0 and "collected 0 steps" in output else f"exit {code}: {output[-200:]}"


documented("collect", "re-running a finished collection collects nothing", rerun_collects_nothing)


def partial_leftover_is_overwritten() -> str | None:
    out = work() / "collected-partial"
    folder = out / "metaworld" / "reach-v3"
    folder.mkdir(parents=True)
    (folder / "history-0000.h5.partial").write_bytes(b"left by kill -9")
    code, output = invoke("collect", "--task", "reach-v3", "--histories", "1", "--steps", "50", "--out", out)
    left = sorted(p.name for p in folder.iterdir())
    return None if code == 0 and left == ["history-0000.h5", "reach-v3.json"] else f"exit {code}, files {left}"


documented("collect", "a .partial left by kill -9 is replaced by the finished file", partial_leftover_is_overwritten)


def killed_collection_resumes_identically() -> str | None:
    """kill -9 a real `python -m vintix collect` mid-run; the re-run equals an uninterrupted one."""
    args = ["collect", "--task", "reach-v3", "--histories", "4", "--steps", "400", "--envs-per-batch", "2"]
    straight, killed, code, _ = straight_and_killed_runs(args, "kill", "metaworld/reach-v3/history-0000.h5")
    names = ["reach-v3.json"] + [f"history-{i:04d}.h5" for i in range(4)]
    folders = [run / "metaworld" / "reach-v3" for run in (straight, killed)]
    same = all((folders[0] / n).read_bytes() == (folders[1] / n).read_bytes() for n in names)
    return None if code == 0 and same else f"exit {code}, identical files: {same}"


documented("collect", "kill -9 mid-collection, then re-run: identical bytes", killed_collection_resumes_identically)


test_bad_input_ends_as_expected = bad_input_test("collect")
