"""The framework of the bad-input cases, which each stage's test file holds (test_collect.py, test_train.py, ...;
test_bad_inputs.py: the cases that cross stages), and the fixtures they share.

Bad input, as a careless or hostile user gives it: bad CLI arguments, damaged datasets, runs and
checkpoints, bad agent inputs, interrupted runs. One parametrized case each: a test file registers its cases with
`cli_error`, `api_error` and `documented`, then runs them with ``test_bad_input_ends_as_expected =
bad_input_test(AREA, ...)``.

A case expects either
- an error: it passes when the CLI exits non-zero with a message (no traceback), or the Python API raises
  a `VintixError`, and the message contains the case's key phrase (the thing it names). It fails as
  *confusing* when the error does not name it, *traceback* when an unexpected exception escapes, and
  *silent* when the command exits 0 (or the call returns), or leaves a file it should not have written;
- documented behaviour: it passes when the case's check of that behaviour holds.

The fixtures are small real datasets, runs and checkpoints, made once in a temporary folder on first
use (per test module: `once`) and then damaged in copies, so each file's cases take well under a minute.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from conftest import child_env
from vintix.cli import app
from vintix.errors import VintixError

WORK = Path()
"""The folder every fixture and output of this module lives in (set by `workspace` before any case runs)."""


@pytest.fixture(scope="module", autouse=True)
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """The module's folder; the cases register tasks, put a module on sys.path and set variables, which the
    modules after this one must not see."""
    from vintix.tasks import registry

    global WORK
    WORK = tmp_path_factory.mktemp("bad-inputs")
    custom, path, environ = dict(registry._custom), list(sys.path), dict(os.environ)
    yield
    registry._custom.clear()
    registry._custom.update(custom)
    sys.path[:] = path
    os.environ.clear()
    os.environ.update(environ)


# A model small enough to train a few steps in a second.
TINY = ("{n_layers: 1, n_heads: 2, obs_emb_dim: 15, act_emb_dim: 15, rew_emb_dim: 2, mlp_dim: 32, head_layers: 1, "
        "context_len: 64}")
QUICK = {"model_overrides": TINY, "max_steps": 2, "batch_size": 2, "warmup_steps": 1, "log_every": 1,
         "checkpoint_every": 1, "tensorboard": "false"}


def quick_train(**changes: object) -> list[str]:
    """--set arguments that train the tiny model a few steps, each field once (a repeated --set is an error);
    `changes` replace or add fields."""
    return [arg for key, value in {**QUICK, **changes}.items() for arg in ("--set", f"{key}={value}")]


QUICK_TRAIN = quick_train()


# ---------------------------------------------------------------------------------------------
# Outcomes


@dataclass
class Outcome:
    category: str  # clear, confusing, traceback, silent, documented
    detail: str


@dataclass
class Case:
    area: str
    name: str
    expect: str  # "error" or "documented"
    run: Callable[[], Outcome]


CASES: list[Case] = []


def one_line(text: str, width: int = 110) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= width else text[: width - 1] + "…"


def cli_error(area: str, name: str, args: list[str] | Callable[[], list[str]], needle: str,
              setup: Callable[[], object] | None = None, after: Callable[[], str | None] | None = None) -> None:
    """A CLI call that must end in a clear error whose message contains `needle` (case-insensitive).
    `after` may return a complaint (e.g. a file that should not have been written)."""

    def run() -> Outcome:
        if setup is not None:
            setup()
        argv = args() if callable(args) else args
        result = CliRunner().invoke(app, [str(a) for a in argv])
        output = " ".join(result.output.split())
        if result.exception is not None and not isinstance(result.exception, SystemExit):
            kind = type(result.exception).__name__
            return Outcome("traceback", f"{kind}: {one_line(result.exception)}")
        if result.exit_code == 0:
            return Outcome("silent", f"exit 0: {one_line(output[-200:])}")
        if "Traceback" in output:
            return Outcome("traceback", one_line(output))
        complaint = after() if after is not None else None
        if complaint:
            return Outcome("silent", complaint)
        if needle.lower() not in output.lower():
            return Outcome("confusing", f"exit {result.exit_code}, lacks {needle!r}: {one_line(output)}")
        return Outcome("clear", f"exit {result.exit_code}: {one_line(output)}")

    CASES.append(Case(area, name, "error", run))


def api_error(area: str, name: str, call: Callable[[], object], needle: str) -> None:
    """A Python API call that must raise a VintixError naming `needle`."""

    def run() -> Outcome:
        try:
            value = call()
        except VintixError as error:
            if needle.lower() not in " ".join(str(error).split()).lower():
                return Outcome("confusing", f"{type(error).__name__} lacks {needle!r}: {one_line(error)}")
            return Outcome("clear", f"{type(error).__name__}: {one_line(error)}")
        except Exception as error:  # noqa: BLE001 - classifying is the point
            return Outcome("traceback", f"{type(error).__name__}: {one_line(error)}")
        return Outcome("silent", f"returned {one_line(repr(value))}")

    CASES.append(Case(area, name, "error", run))


def documented(area: str, name: str, check: Callable[[], str | None]) -> None:
    """Documented behaviour: `check` returns None when it holds, else what happened instead."""

    def run() -> Outcome:
        try:
            problem = check()
        except VintixError as error:
            return Outcome("silent", f"unexpected {type(error).__name__}: {one_line(error)}")
        except Exception as error:  # noqa: BLE001
            return Outcome("traceback", f"{type(error).__name__}: {one_line(error)}\n"
                           + textwrap.indent(traceback.format_exc(limit=-3), "    "))
        return Outcome("documented", "as documented") if problem is None else Outcome("silent", problem)

    CASES.append(Case(area, name, "documented", run))


def invoke(*argv: object) -> tuple[int, str]:
    result = CliRunner().invoke(app, [str(a) for a in argv])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, " ".join(result.output.split())


# ---------------------------------------------------------------------------------------------
# Fixtures: small real datasets, runs and checkpoints, and damaged copies of them


def work() -> Path:
    """The test module's folder (`WORK`), as a case reads it when it runs."""
    return WORK


def once(make: Callable[[], Path]) -> Callable[[], Path]:
    """`make` run once per test module: what it made lives in that module's folder, and the tasks and variables it
    set are undone when the module ends (`workspace`)."""
    cache: dict[Path, Path] = {}

    def get() -> Path:
        if WORK not in cache:
            cache[WORK] = make()
        return cache[WORK]

    return get


def write_dataset(root: Path, task: str = "reach-v3", histories: int = 2, steps: int = 300, obs_dim: int | None = None,
                  act_dim: int | None = None, domain: str | None = None, seed: int = 0) -> Path:
    """Synthetic histories of a registry task (100-step episodes), written by the package's writer."""
    from vintix.data import LearningHistoryWriter, task_directory, write_task_metadata
    from vintix.tasks import get_task

    spec = get_task(task)
    obs_dim, act_dim = obs_dim or spec.obs_dim, act_dim or spec.act_dim
    folder = task_directory(root, domain or spec.domain, task)
    write_task_metadata(folder, task, obs_dim, act_dim, noise_free_fraction=0.1)
    rng = np.random.default_rng(seed)
    for i in range(histories):
        with LearningHistoryWriter(folder / f"history-{i:04d}.h5", obs_dim, act_dim, chunk_size=128) as writer:
            writer.append(rng.normal(size=(steps, obs_dim)), rng.uniform(-1, 1, size=(steps, act_dim)),
                          rng.normal(size=steps), np.arange(steps) % 100)
    return root


@once
def clean_data() -> Path:
    return write_dataset(WORK / "data-clean")


def damaged_copy(source: Callable[[], Path], name: str, damage: Callable[[Path], object]) -> Callable[[], Path]:
    """A copy of `source()` under WORK/name with `damage` applied to it, made on first use."""

    @once
    def make() -> Path:
        copy = WORK / name
        shutil.copytree(source(), copy)
        damage(copy)
        return copy

    return make


def damaged_data(name: str, damage: Callable[[Path], object]) -> Callable[[], Path]:
    """A copy of the clean dataset with one damage applied to its reach-v3 folder."""
    return damaged_copy(clean_data, f"data-{name}", lambda root: damage(root / "metaworld" / "reach-v3"))


def set_value(key: str, row: int, value: float) -> Callable[[Path], None]:
    def damage(folder: Path) -> None:
        with h5py.File(folder / "history-0000.h5", "r+") as f:
            data = f["0-127"][key][()]
            data[row] = value
            f["0-127"][key][...] = data

    return damage


def truncate_file(path: Path, keep: float = 0.5) -> None:
    path.write_bytes(path.read_bytes()[: int(path.stat().st_size * keep)])


def flip_data_byte(folder: Path) -> None:
    path = folder / "history-0000.h5"
    with h5py.File(path) as f:
        chunk = f["0-127/reward"].id.get_chunk_info(0)
    data = bytearray(path.read_bytes())
    data[chunk.byte_offset + chunk.size // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def break_step_num(folder: Path) -> None:
    with h5py.File(folder / "history-0000.h5", "r+") as f:
        f["0-127/step_num"][50] = 77


DATA = {
    "nan-reward": damaged_data("nan-reward", set_value("reward", 30, np.nan)),
    "inf-obs": damaged_data("inf-obs", set_value("proprio_observation", 40, np.inf)),
    "nan-action": damaged_data("nan-action", set_value("action", 41, np.nan)),
    "truncated": damaged_data("truncated", lambda f: truncate_file(f / "history-0000.h5", 0.6)),
    "corrupted-block": damaged_data("corrupted-block", flip_data_byte),
    "step-break": damaged_data("step-break", break_step_num),
    "garbage-json": damaged_data("garbage-json", lambda f: (f / "reach-v3.json").write_text("{not json")),
    "missing-json": damaged_data("missing-json", lambda f: (f / "reach-v3.json").unlink()),
    "partial-leftover": damaged_data("partial-leftover", lambda f: (f / "history-0009.h5.partial").write_bytes(b"x")),
    "empty-h5": damaged_data("empty-h5", lambda f: (f / "history-0005.h5").write_bytes(b"")),
    "foreign-entry": damaged_data("foreign-entry", lambda f: h5py.File(f / "history-0001.h5", "r+").close()
                                  or _add_entry(f / "history-0001.h5")),
}


def _add_entry(path: Path) -> None:
    with h5py.File(path, "r+") as f:
        f.create_dataset("notes", data=np.zeros(3))


def rewrite_json(change: Callable[[dict], object]) -> Callable[[Path], None]:
    def damage(folder: Path) -> None:
        meta = json.loads((folder / "reach-v3.json").read_text())
        change(meta)
        (folder / "reach-v3.json").write_text(json.dumps(meta))

    return damage


def float64_history(folder: Path) -> None:
    """A history whose reward was stored as float64 (what a hand-rolled writer does)."""
    with h5py.File(folder / "history-0001.h5", "r+") as f:
        reward = f["0-127/reward"][()]
        del f["0-127/reward"]
        f["0-127"].create_dataset("reward", data=reward.astype(np.float64))


def bytes_reward_history(folder: Path) -> None:
    """A history whose reward was stored as byte strings (a writer that formatted numbers as text)."""
    with h5py.File(folder / "history-0001.h5", "r+") as f:
        reward = f["0-127/reward"][()]
        del f["0-127/reward"]
        f["0-127"].create_dataset("reward", data=np.array([f"{r:.3f}".encode() for r in reward]))


def unchecksummed_copy(folder: Path) -> None:
    """Rewrite a history the way the published dataset stores it: no chunks, no checksums."""
    path = folder / "history-0000.h5"
    with h5py.File(path) as f:
        groups = {g: {k: f[g][k][()] for k in f[g]} for g in f}
    path.unlink()
    with h5py.File(path, "w") as f:
        for name, datasets in groups.items():
            for key, data in datasets.items():
                f.create_group(name) if name not in f else None
                f[name].create_dataset(key, data=data)


def add_demonstrator_actions(nan_row: int | None = None, groups: int | None = None) -> Callable[[Path], None]:
    """Give history-0000 a demonstrator_action dataset (a copy of its actions) in its first `groups`
    groups (default all), with a NaN at `nan_row` of the first."""
    def damage(folder: Path) -> None:
        with h5py.File(folder / "history-0000.h5", "r+") as f:
            for name in sorted(f, key=lambda g: int(g.split("-")[0]))[:groups]:
                proposed = f[name]["action"][()]
                if nan_row is not None and name == "0-127":
                    proposed[nan_row] = np.nan
                f[name].create_dataset("demonstrator_action", data=proposed)

    return damage


def declare_a_billion_rows(folder: Path) -> None:
    """A history of a few KB that declares 10^9 rows it never stores (chunked datasets, no chunk written):
    a reader that trusted the shape would try to allocate 145 GiB."""
    rows = 10**9
    with h5py.File(folder / "history-0002.h5", "w") as f:
        group = f.create_group(f"0-{rows - 1}")
        for key, width, dtype in [("proprio_observation", 39, "f4"), ("action", 4, "f4"), ("reward", None, "f4"),
                                  ("step_num", None, "i4")]:
            group.create_dataset(key, shape=(rows, width) if width else (rows,), dtype=dtype, chunks=True)


DATA.update({
    "declares-a-billion-rows": damaged_data("declares-a-billion-rows", declare_a_billion_rows),
    "nan-demonstrator-action": damaged_data("nan-demonstrator-action", add_demonstrator_actions(nan_row=41)),
    "demonstrator-action-in-one-group": damaged_data("demonstrator-action-in-one-group",
                                                     add_demonstrator_actions(groups=1)),
    "discrete-json": damaged_data("discrete-json", rewrite_json(lambda m: m.update(action_type="discrete"))),
    "text-dims-json": damaged_data("text-dims-json", rewrite_json(lambda m: m.update(action_dim="4"))),
    "json-list": damaged_data("json-list", lambda f: (f / "reach-v3.json").write_text("[1, 2]")),
    "shape-list-json": damaged_data("shape-list-json", rewrite_json(lambda m: m.update(observation_shape=[39]))),
    "json-not-utf8": damaged_data("json-not-utf8", lambda f: (f / "reach-v3.json").write_bytes(b"\xff\xfe{")),
    "float64-reward": damaged_data("float64-reward", float64_history),
    "bytes-reward": damaged_data("bytes-reward", bytes_reward_history),
    "not-hdf5": damaged_data("not-hdf5", lambda f: (f / "history-0001.h5").write_text("just text")),
    "published-layout": damaged_data("published-layout", unchecksummed_copy),
    "json-only-task": damaged_data("json-only-task", lambda f: (f.parent / "push-v3").mkdir()
                                   or (f.parent / "push-v3" / "push-v3.json").write_text(
                                       (f / "reach-v3.json").read_text().replace("reach-v3", "push-v3"))),
})


@once
def ib7_data() -> Path:
    return write_dataset(WORK / "data-ib7", task="industrial-benchmark-10-v1", obs_dim=7, histories=1, steps=500)


unknown_task_data = damaged_data("unknown-task", rewrite_json(lambda m: m.update(task_name="my-own-task-v1")))
no_fraction_data = damaged_data("no-fraction", rewrite_json(lambda m: m.pop("noise_free_fraction")))


@once
def pusher_v4_data() -> Path:
    """A folder named and labelled like the published dataset's Pusher."""
    root = WORK / "data-pusher-v4"
    write_dataset(root, task="Pusher-v5", histories=1, steps=300)
    folder = root / "mujoco" / "Pusher-v5"
    published = root / "mujoco" / "Pusher-v4"
    folder.rename(published)
    (published / "Pusher-v5.json").rename(published / "Pusher-v4.json")
    meta = json.loads((published / "Pusher-v4.json").read_text())
    (published / "Pusher-v4.json").write_text(json.dumps({**meta, "task_name": "Pusher-v4"}))
    return root


@once
def trained_run() -> Path:
    """A real training run: checkpoints at steps 1 and 2."""
    out = WORK / "run-clean"
    code, output = invoke("train", "--data", clean_data(), "--out", out, *QUICK_TRAIN)
    assert code == 0, output
    return out


def damaged_run(name: str, damage: Callable[[Path], object]) -> Callable[[], Path]:
    """A copy of the trained run with one damage applied to its checkpoints folder."""
    return damaged_copy(trained_run, f"run-{name}", lambda out: damage(out / "checkpoints"))


def newest(checkpoints: Path) -> Path:
    return checkpoints / "step-00000002"


RUNS = {
    "truncated-optimizer": damaged_run("truncated-optimizer",
                                       lambda c: truncate_file(newest(c) / "optimizer.safetensors")),
    "truncated-rng": damaged_run("truncated-rng", lambda c: truncate_file(newest(c) / "rng.safetensors")),
    "garbage-trainer-json": damaged_run("garbage-trainer-json",
                                        lambda c: (newest(c) / "trainer.json").write_text("]{")),
    "trainer-json-wrong-step": damaged_run("trainer-json-wrong-step", lambda c: (newest(c) / "trainer.json").write_text(
        json.dumps({**json.loads((newest(c) / "trainer.json").read_text()), "step": "two"}))),
    "truncated-weights": damaged_run("truncated-weights", lambda c: truncate_file(newest(c) / "model.safetensors")),
    "truncated-weights-eval": damaged_run("truncated-weights-eval",
                                          lambda c: truncate_file(newest(c) / "model.safetensors")),
    "garbage-model-json": damaged_run("garbage-model-json", lambda c: (newest(c) / "config.json").write_text("nope")),
    "all-damaged": damaged_run("all-damaged", lambda c: [truncate_file(d / "optimizer.safetensors")
                                                        for d in c.glob("step-*")]),
    "partial-leftover": damaged_run("partial-leftover",
                                    lambda c: shutil.copytree(newest(c), c / "step-00000003.partial")),
}


@once
def model_checkpoint() -> Path:
    directory = WORK / "ckpt"
    shutil.copytree(newest(trained_run() / "checkpoints"), directory)
    for name in ("optimizer.safetensors", "rng.safetensors", "trainer.json"):
        (directory / name).unlink()
    return directory


def damaged_checkpoint(name: str, damage: Callable[[Path], object]) -> Callable[[], Path]:
    """A copy of the model-only checkpoint with one damage applied to it."""
    return damaged_copy(model_checkpoint, f"ckpt-{name}", damage)


@once
def other_model() -> Path:
    """A model of another size over the same task."""
    from vintix.model import load_pretrained, save_pretrained
    from vintix.model.model import Vintix, preset

    model = load_pretrained(model_checkpoint())
    config = preset("tiny", n_layers=1, n_heads=2, obs_emb_dim=15, act_emb_dim=15, rew_emb_dim=2, mlp_dim=16,
                    head_layers=1, context_len=64)
    return save_pretrained(Vintix(config, list(model.groups.values()), model.task_norms), WORK / "other-model")


def nan_weights(directory: Path) -> None:
    from safetensors.torch import load_file, save_file

    weights = load_file(str(directory / "model.safetensors"))
    weights = {k: v.fill_(float("nan")) if v.is_floating_point() else v for k, v in weights.items()}
    save_file(weights, str(directory / "model.safetensors"))


CHECKPOINTS = {
    "truncated-weights": damaged_checkpoint("truncated-weights", lambda d: truncate_file(d / "model.safetensors")),
    "garbage-json": damaged_checkpoint("garbage-json", lambda d: (d / "config.json").write_text("{")),
    "json-missing-keys": damaged_checkpoint("json-missing-keys", lambda d: (d / "config.json").write_text("{}")),
    "nan-weights": damaged_checkpoint("nan-weights", nan_weights),
    "no-weights": damaged_checkpoint("no-weights", lambda d: (d / "model.safetensors").unlink()),
    "future-format": damaged_checkpoint("future-format", lambda d: (d / "config.json").write_text(
        json.dumps({**json.loads((d / "config.json").read_text()), "format_version": 99}))),
    "groups-malformed": damaged_checkpoint("groups-malformed", lambda d: (d / "config.json").write_text(
        json.dumps({**json.loads((d / "config.json").read_text()), "groups": [{"x": 1}]}))),
    # One typed loader (issue 71, class 4): fields of the wrong JSON type were tracebacks.
    **{f"{field}-is-{kind}": damaged_checkpoint(f"{field}-is-{kind}", lambda d, field=field, value=value: (
        d / "config.json").write_text(json.dumps({**json.loads((d / "config.json").read_text()), field: value})))
       for field, kind, value in [("custom_tasks", "a-list", ["reach-v3"]), ("config", "a-list", [1, 2]),
                                  ("groups", "an-object", {"metaworld": 1}), ("task_norms", "text", "none")]},
    # ...and each group's (issue 71's red team: a text obs_dim was "does not describe a model", no field named)
    "group-text-obs-dim": damaged_checkpoint("group-text-obs-dim", lambda d: (d / "config.json").write_text(json.dumps(
        {**json.loads((d / "config.json").read_text()), "groups": [
            {**g, "obs_dim": str(g["obs_dim"])} for g in json.loads((d / "config.json").read_text())["groups"]]}))),
    # ...and the record the model card shows (issue 71, class 4): a text step was a traceback at the next save.
    "extra-step-is-text": damaged_checkpoint("extra-step-is-text", lambda d: (d / "config.json").write_text(json.dumps(
        {**json.loads((d / "config.json").read_text()),
         "extra": {**json.loads((d / "config.json").read_text())["extra"], "step": "many"}}))),
    "config-text-heads": damaged_checkpoint("config-text-heads", lambda d: (d / "config.json").write_text(json.dumps(
        {**json.loads((d / "config.json").read_text()),
         "config": {**json.loads((d / "config.json").read_text())["config"], "n_heads": "2"}}))),
    "weights-of-another-model": damaged_checkpoint("weights-of-another-model", lambda d: shutil.copy(
        other_model() / "model.safetensors", d / "model.safetensors")),
}


@once
def eval_results() -> Path:
    out = WORK / "results-clean"
    code, output = invoke("eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "2",
                          "--seeds", "1", "--out", out)
    assert code == 0, output
    return out


@once
def collected() -> Path:
    out = WORK / "collected"
    code, output = invoke("collect", "--task", "reach-v3", "--histories", "1", "--steps", "150", "--out", out)
    assert code == 0, output
    return out


def file_at(name: str, text: str) -> Callable[[], Path]:
    @once
    def make() -> Path:
        path = WORK / name
        path.write_text(text)
        return path

    return make


def empty_dir(name: str) -> Callable[[], Path]:
    @once
    def make() -> Path:
        path = WORK / name
        path.mkdir(exist_ok=True)
        return path

    return make


def missing(name: str) -> Path:
    return WORK / "does-not-exist" / name


def not_written(path_of: Callable[[], Path]) -> Callable[[], str | None]:
    return lambda: f"wrote {path_of()} although it failed" if path_of().exists() else None


def straight_and_killed_runs(args: list[str], name: str, marker: str) -> tuple[Path, Path, int, str]:
    """Run `vintix *args` straight into WORK/name-straight, and as a real process into WORK/name-killed
    that gets kill -9 once `marker` (a path in its --out) exists, then re-run it there. Returns both
    folders and the re-run's exit code and output."""
    straight, killed = WORK / f"{name}-straight", WORK / f"{name}-killed"
    code, output = invoke(*args, "--out", straight)
    assert code == 0, output
    # The process computes with as many threads as this one (an earlier test's `eval` may have set 1):
    # float sums over another thread count differ in their last bits.
    env = child_env(OMP_NUM_THREADS=str(torch.get_num_threads()))
    process = subprocess.Popen([sys.executable, "-m", "vintix", *args, "--out", str(killed)], env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and not (killed / marker).exists():
        time.sleep(0.05)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    code, output = invoke(*args, "--out", killed)
    return straight, killed, code, output
# What vintix data validate, then vintix train, names in each damaged dataset. Training runs the same
# checks, but its reader names a truncated file rather than the damage; None: not probed against
# training (a .partial leftover it ignores is a documented case below; the metadata cases are validation's).
DAMAGE_NAMES = {
    "nan-reward": ("NaN/inf in reward",) * 2, "inf-obs": ("NaN/inf in proprio_observation",) * 2,
    "nan-action": ("NaN/inf in action",) * 2, "truncated": ("truncated or corrupted", "history-0000.h5"),
    "corrupted-block": ("failed its checksum",) * 2, "step-break": ("step_num jumps",) * 2,
    "garbage-json": ("not valid JSON",) * 2, "missing-json": ("missing task metadata", None),
    "partial-leftover": ("leftover of an interrupted write", None), "empty-h5": ("history-0005.h5",) * 2,
    "foreign-entry": ("'notes' is not a step group",) * 2, "discrete-json": ("action_type",) * 2,
    "text-dims-json": ("field 'action_dim' must be int", None), "json-list": ("expected a JSON object, got list", None),
    "shape-list-json": ("field 'observation_shape' must be dict", None),
    "json-not-utf8": ("not valid JSON",) * 2, "float64-reward": ("reward is float64",) * 2,
    "bytes-reward": ("reward is |S",) * 2,
    "not-hdf5": ("history-0001.h5",) * 2, "nan-demonstrator-action": ("NaN/inf in demonstrator_action",) * 2,
    "demonstrator-action-in-one-group": ("groups disagree on their demonstrator-action dataset",) * 2,
    "declares-a-billion-rows": ("declares 1,000,000,000 rows but stores no data",) * 2,
}

# Training
TRAIN = ["train", "--out"]

# Output folders (issue 47, class 2): a command never writes over its own input, into another kind of output,
# or over files already there (another model's results, checkpoint or release) unless told --overwrite.
@once
def release_snapshot() -> Path:
    from test_official_checkpoint import write_release

    folder = WORK / "release"
    folder.mkdir()
    write_release(folder)
    return folder


# Damaged releases (issue 47, class 4): a non-finite weight or statistic is refused at import, named.
def damaged_release(name: str, damage: Callable[[Path], object]) -> Callable[[], list[object]]:
    def args() -> list[object]:
        folder = WORK / f"release-{name}"
        shutil.copytree(release_snapshot(), folder)
        damage(folder)
        return ["import-official", folder, "--out", WORK / f"imported-{name}"]
    return args
# Issue 55, class 6: JSON nested 10^5 deep (300 KB) is malformed JSON to every reader, not a RecursionError.
DEEP_JSON = "[" * 100_000 + "]" * 100_000


def bad_input_test(*areas: str) -> Callable[[Case], None]:
    """The parametrized test of the cases of `areas` (each area's cases live in one test file)."""
    cases = [case for case in CASES if case.area in areas]

    @pytest.mark.parametrize("case", cases, ids=[f"{c.area}: {c.name}" for c in cases])
    def test_bad_input_ends_as_expected(case: Case) -> None:
        outcome = case.run()
        assert outcome.category in ("clear", "documented"), f"{outcome.category}: {outcome.detail}"

    return test_bad_input_ends_as_expected
