"""Bad input that crosses the stages, as a careless or hostile user gives it: output folders and planted files,
values checked the same way wherever they arrive, names that shadow shipped ones, code that files name (trust) and
plug-ins that fail. Each stage's own bad-input cases are in its test file (test_collect.py, test_train.py, ...);
the cases' framework and shared fixtures: tests/bad_inputs.py."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import vintix
from bad_inputs import (  # noqa: F401  (workspace: autouse fixture)
    api_error,
    bad_input_test,
    clean_data,
    cli_error,
    damaged_data,
    damaged_release,
    documented,
    empty_dir,
    eval_results,
    invoke,
    model_checkpoint,
    not_written,
    once,
    release_snapshot,
    rewrite_json,
    trained_run,
    work,
    workspace,
)
from conftest import HANG_GUARD_S, child_env
from vintix.atomic import MAX_NAME_BYTES, file_name
from vintix.cli import app

# ---------------------------------------------------------------------------------------------
# Bad input: one case each, a clear error or the documented behaviour (framework and shared fixtures:
# tests/bad_inputs.py)

# ---------------------------------------------------------------------------------------------
# The cases

# Top-level and task registry
cli_error("cli", "unknown command", ["frobnicate"], "No such command")
for flag in ("false", 1, "yes"):
    api_error("trust", f"load_pretrained(trust_code={flag!r})",
              lambda flag=flag: __import__("vintix.model").model.load_pretrained(model_checkpoint(), trust_code=flag),
              "trust_code must be True or False")


def other_release() -> list[object]:
    code, output = invoke("import-official", release_snapshot(), "--out", work() / "imported")
    assert code == 0, output
    target = work() / "another-release"
    shutil.copytree(release_snapshot(), target, dirs_exist_ok=True)
    return ["export-official", work() / "imported", "--out", target]


cli_error("outputs", "import-official --out its own snapshot",
          lambda: ["import-official", release_snapshot(), "--out", release_snapshot()], "own input")
cli_error("outputs", "import-official --out over an existing checkpoint",
          lambda: ["import-official", release_snapshot(), "--out", model_checkpoint()], "--overwrite")
cli_error("outputs", "import-official --out into a training run",
          lambda: ["import-official", release_snapshot(), "--out", trained_run()], "a training run")
cli_error("outputs", "export-official --out over another release", other_release, "--overwrite")
cli_error("outputs", "export-official --out its own checkpoint",
          lambda: ["export-official", model_checkpoint(), "--out", model_checkpoint()], "own input")
cli_error("outputs", "eval --out over another checkpoint's results", lambda: [
    "eval", "--checkpoint", "point-goal", "--tasks", "point-goal-v1", "--shots", "1", "--seeds", "1",
    "--out", eval_results()], "--overwrite")


def rerun_and_overwrite() -> str | None:
    again = invoke("eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "1", "--seeds", "1",
                   "--out", eval_results())
    forced = invoke("import-official", release_snapshot(), "--out", work() / "imported", "--overwrite")
    return None if again[0] == forced[0] == 0 else f"re-run: {again}; --overwrite: {forced}"


documented("outputs", "eval re-run into its own results, and import-official --overwrite, write", rerun_and_overwrite)


def integer_key(folder: Path) -> None:
    weights = torch.load(folder / "model.pth", weights_only=True)
    weights[7] = weights.pop(next(iter(weights)))
    torch.save(weights, folder / "model.pth")


cli_error("outputs", "import-official of a release whose model.pth has an integer key", damaged_release(
    "integer-key", integer_key), "with the key 7")


def nan_weight(folder: Path) -> None:
    weights = torch.load(folder / "model.pth", weights_only=True)
    key = next(k for k in weights if k.endswith("weight"))
    weights[key][0] = float("nan")
    torch.save(weights, folder / "model.pth")


def edit_metadata(field: str, value: object) -> Callable[[Path], None]:
    def damage(folder: Path) -> None:
        metadata = json.loads((folder / "metadata.json").read_text())
        entry = next(iter(metadata.values()))
        if field == "obs_std":
            entry[field][0] = value
        else:
            entry[field] = value
        (folder / "metadata.json").write_text(json.dumps(metadata))
    return damage


cli_error("outputs", "import-official of a release with a NaN weight", damaged_release("nan-weight", nan_weight),
          "hold NaN or inf")
cli_error("outputs", "import-official of a release with a NaN obs_std",
          damaged_release("nan-std", edit_metadata("obs_std", float("nan"))), ".obs_std' must be list[float]")
cli_error("outputs", "import-official of a release with reward_scale -1e308",
          damaged_release("scale", edit_metadata("reward_scale", -1e308)), "reward_scale")


def edit_config(field: str, value: object) -> Callable[[Path], None]:
    def damage(folder: Path) -> None:
        config = json.loads((folder / "config.json").read_text())
        (folder / "config.json").write_text(json.dumps({**config, field: value}))
    return damage


# Issue 71's red team: a text where the release writes a number was named by the wrong field, or by none.
cli_error("outputs", "import-official of a release whose obs_mean is a text",
          damaged_release("text-mean", edit_metadata("obs_mean", "0.1")), ".obs_mean' must be list[float]")
cli_error("outputs", "import-official of a release whose transformer_depth is a text",
          damaged_release("text-depth", edit_config("transformer_depth", "4")), "'transformer_depth' must be int")

# Benchmarks (invalid ones must fail before timing anything)
cli_error("bench", "train an unknown preset", ["bench", "train", "huge"], "huge")
cli_error("bench", "train with batch size 0", ["bench", "train", "tiny", "--batch-size", "0"], "--batch-size")
cli_error("bench", "infer with 0 envs", ["bench", "infer", "tiny", "--envs", "0", "--no-recompute"], "--envs")
cli_error("bench", "infer an unknown preset", ["bench", "infer", "huge"], "huge")


# Trust (issue 47, class 1): code that a checkpoint's or dataset's file names runs only when the user says so.
PROBE_TASK = {"env_factory": "trust_probe:make", "obs_dim": 39, "act_dim": 4, "episode_length": 500,
              "group": "metaworld"}


@once
def probe_code() -> Path:
    """A module whose factory leaves a mark when it runs (and makes a real env), importable here."""
    folder = work() / "probe-code"
    folder.mkdir()
    (folder / "trust_probe.py").write_text(
        "from pathlib import Path\n\nimport vintix\n\n\ndef make(**kwargs):\n"
        "    Path(__file__).with_name('ran').touch()\n    return vintix.make_env('reach-v3', seed=0)\n\n\n"
        "def broken(*args, **kwargs):\n    raise RuntimeError('boom in user code')\n\n\n"
        "def exits(*args, **kwargs):\n    raise SystemExit(0)\n\n\n"
        "class ActsBroken:\n    def __init__(self, task):\n        pass\n\n"
        "    def act(self, observations, envs):\n        raise ZeroDivisionError('boom in act')\n")
    sys.path.insert(0, str(folder))
    return folder


@once
def code_naming_checkpoint() -> Path:
    """The model-only checkpoint, its config naming three custom tasks whose env a factory makes."""
    probe_code()
    directory = work() / "ckpt-names-code"
    shutil.copytree(model_checkpoint(), directory)
    config = json.loads((directory / "config.json").read_text())
    config["custom_tasks"] = {name: PROBE_TASK for name in ("probe-refused", "probe-yours", "probe-trusted")}
    (directory / "config.json").write_text(json.dumps(config))
    return directory


def probe_ran() -> str | None:
    ran = probe_code() / "ran"
    if ran.exists():
        ran.unlink()
        return "the factory ran"
    return None


def eval_probe(task: str, *options: object) -> list[object]:
    return [*options, "eval", "--checkpoint", code_naming_checkpoint(), "--tasks", task, "--shots", "1", "--seeds",
            "1", "--out", work() / f"results-{task}"]


cli_error("trust", "eval of a checkpoint whose custom task names an env factory", lambda: eval_probe("probe-refused"),
          "--trust-code", after=probe_ran)


def yours_or_trusted_runs(task: str, *options: object) -> Callable[[], str | None]:
    def check() -> str | None:
        try:
            code, output = invoke(*eval_probe(task, *options))
        finally:
            os.environ.pop("VINTIX_TRUST_CODE", None)  # --trust-code sets it for the process
        if code != 0:
            return f"exit {code}: {output[-300:]}"
        return None if probe_ran() else "exit 0, but the factory never ran"
    return check


@once
def probe_tasks_file() -> Path:
    path = work() / "probe-tasks.yaml"
    path.write_text(json.dumps({"tasks": {"probe-yours": PROBE_TASK}}))  # JSON is YAML
    return path


documented("trust", "a task you registered yourself (tasks file) runs its factory without --trust-code",
           lambda: yours_or_trusted_runs("probe-yours", "--tasks-file", probe_tasks_file())())
documented("trust", "--trust-code runs the factory a checkpoint names",
           yours_or_trusted_runs("probe-trusted", "--trust-code"))


def dataset_naming_code() -> object:
    """make_env of a task that a dataset's task JSON registered, its spec naming a factory."""
    import vintix
    from vintix.data import read_task_metadata, register_dataset_task, write_task_metadata

    probe_code()
    folder = write_task_metadata(work() / "data-names-code" / "custom" / "probe-data", "probe-data", 39, 4,
                                 custom_task=PROBE_TASK).parent
    register_dataset_task(folder, read_task_metadata(folder))
    return vintix.make_env("probe-data", seed=0)


api_error("trust", "make_env of a task a dataset's task JSON names, with a factory", dataset_naming_code,
          "VINTIX_TRUST_CODE=1")


@once
def dataset_naming_an_env_module() -> Path:
    """A dataset whose task JSON names ``env_id: trust_probe_env:ProbeEnv-v0``, the module shipped beside it (in the
    folder a command runs from): importing it leaves a mark."""
    from vintix.data import LearningHistoryWriter, write_task_metadata
    from vintix.data.layout import TRUNCATED

    root = work() / "data-names-env-module"
    task = {"env_id": "trust_probe_env:ProbeEnv-v0", "obs_dim": 2, "act_dim": 1, "episode_length": 5}
    folder = write_task_metadata(root / "custom" / "probe-env", "probe-env", 2, 1, custom_task=task).parent
    with LearningHistoryWriter(folder / "history-0000.h5", 2, 1, episode_ends=True) as writer:
        writer.append(np.zeros((5, 2)), np.zeros((5, 1)), np.zeros(5), np.arange(5),
                      episode_end=np.array([0, 0, 0, 0, TRUNCATED]), final_observation=np.zeros((5, 2)))
    (root / "trust_probe_env.py").write_text(
        "from pathlib import Path\n\nPath(__file__).with_name('imported').touch()\n")
    sys.path.insert(0, str(root))  # as if run from the dataset's folder, where Python imports from
    return root


def env_module_imported() -> str | None:
    mark = work() / "data-names-env-module" / "imported"
    return "the dataset's module was imported" if mark.exists() else None


cli_error("trust", "export-minari of a dataset whose task JSON names a module:EnvId shipped beside it", lambda: [
    "data", "export-minari", dataset_naming_an_env_module(), "--dataset-id", "probe/probe-env-v0"], "--trust-code",
    after=env_module_imported)


def test_every_import_of_named_code_passes_the_trust_gate():
    """`vintix.tasks.custom.import_code` is the one place code named by a file is imported: an ``import_module`` (or
    ``__import__``) anywhere else in the package could import what a checkpoint or dataset names, past the gate."""
    allowed = {"tasks/custom.py": 1,  # the gate itself
               "evaluate/__init__.py": 1,  # the package's own lazy submodules, a fixed table
               "demonstrators/base.py": 1}  # stable_baselines3 or sbx, a fixed table (_MODEL_LIBRARIES)
    package = Path(vintix.__file__).parent
    found = {str(path.relative_to(package)): len(re.findall(r"\bimport_module\(|__import__\(", path.read_text()))
             for path in package.rglob("*.py")}
    assert {name: count for name, count in found.items() if count} == allowed


# Output folders (issue 55, class 2): a link or special file planted in a folder a command writes never carries a
# write outside it, nor hangs a read; a second writer into a folder is refused, not mixed.
def victim() -> Path:
    """A file outside every output folder that a planted link points at; it must stay as it is."""
    path = work() / "victim.txt"
    if not path.exists():
        path.write_text("precious\n")
    return path


def victim_changed() -> str | None:
    return None if victim().read_text() == "precious\n" else f"{victim()} was written: {victim().read_text()[:60]!r}"


def planted(name: str, folder: Callable[[], Path], relative: str, target: Callable[[], Path] = victim
            ) -> Callable[[], Path]:
    """A copy of `folder` (a dataset or run) with `relative` a symbolic link to `target`."""
    @once
    def make() -> Path:
        copy = work() / f"planted-{name}"
        shutil.copytree(folder(), copy, symlinks=True)
        link = copy / relative
        link.parent.mkdir(parents=True, exist_ok=True)
        link.unlink(missing_ok=True)
        link.symlink_to(target())
        return copy
    return make


cli_error("outputs", "collect into a dataset whose .vintix-lock is a link to a file of yours", lambda: [
    "collect", "--task", "reach-v3", "--histories", "1", "--steps", "50", "--out",
    planted("lock", clean_data, ".vintix-lock")()], "symbolic link", after=victim_changed)
cli_error("outputs", "collect into a dataset with a history's temporary planted as a link", lambda: [
    "collect", "--task", "reach-v3", "--histories", "3", "--steps", "50", "--out",
    planted("partial", clean_data, "metaworld/reach-v3/history-0002.h5.partial")()], "symbolic link",
    after=victim_changed)
cli_error("outputs", "resume training in a run whose log.csv is a link to a file of yours", lambda: [
    "train", "--data", clean_data(), "--out", planted("log", trained_run, "log.csv")()], "symbolic link",
    after=victim_changed)
cli_error("outputs", "resume training in a run with a checkpoint's temporary folder planted as a link", lambda: [
    "train", "--data", clean_data(), "--out",
    planted("step-partial", trained_run, "checkpoints/step-00000099.partial", lambda: work())()], "symbolic link")


def results_with_a_fifo_as(name: str) -> Callable[[], Path]:
    """A results folder whose file `name` is a FIFO (a read of it would hang)."""
    @once
    def make() -> Path:
        folder = work() / f"results-fifo-{name}"
        folder.mkdir()
        os.mkfifo(folder / name)
        return folder

    return make


results_with_a_fifo, results_with_a_fifo_run_json = results_with_a_fifo_as("episodes.csv"), results_with_a_fifo_as(
    "run.json")


def eval_one_episode(checkpoint: object, out: object, *options: object) -> tuple[int, str]:
    return invoke("eval", "--checkpoint", checkpoint, "--tasks", "reach-v3", "--shots", "1", "--seeds", "1",
                  "--out", out, *options)


def zero_rewards_into_the_true_ones() -> str | None:
    """A results folder belongs to one run (issue 71, class 2): the same model fed zeros may not replace its true
    rewards' results, a re-run of the very same run may."""
    out = work() / "results-one-run"
    code, output = eval_one_episode(model_checkpoint(), out)
    assert code == 0, output
    code, again = eval_one_episode(model_checkpoint(), out)
    if code != 0:
        return f"the same run again was refused: {again[-300:]}"
    code, output = eval_one_episode(model_checkpoint(), out, "--reward-input", "zero")
    if code == 0 or not all(words in output for words in ("holds the results of", "true rewards", "zero rewards")):
        return f"exit {code}: {output[-300:]}"
    return None


def two_models_of_one_name() -> str | None:
    """Two different models both called `model` (each relative to its working folder), evaluated into one --out:
    the weights' sha256 tells them apart, so the second is refused."""
    from safetensors.torch import load_file, save_file

    first, second = work() / "name-a" / "model", work() / "name-b" / "model"
    shutil.copytree(model_checkpoint(), first)
    shutil.copytree(model_checkpoint(), second)
    weights = load_file(str(second / "model.safetensors"))
    name = sorted(weights)[0]
    weights[name] = weights[name] + 1.0
    save_file(weights, str(second / "model.safetensors"), metadata={"format": "pt"})
    out, cwd = work() / "results-of-model", os.getcwd()
    try:
        os.chdir(first.parent)
        code, output = eval_one_episode("model", out)
        assert code == 0, output
        os.chdir(second.parent)
        code, output = eval_one_episode("model", out)
    finally:
        os.chdir(cwd)
    if code == 0 or "holds the results of 'model'" not in output:
        return f"exit {code}: {output[-300:]}"
    return None


documented("outputs", "eval with zero rewards into the same model's true-reward results is refused, naming both",
           zero_rewards_into_the_true_ones)
documented("outputs", "two models both called `model` into one --out: the second is refused", two_models_of_one_name)
cli_error("outputs", "eval into a folder whose run.json is a FIFO (it was read before the lock and hung)", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "1", "--seeds", "1", "--out",
    results_with_a_fifo_run_json()], "a FIFO")
cli_error("outputs", "eval into a folder whose episodes.csv is a FIFO (a read would hang)", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "1", "--seeds", "1", "--out",
    results_with_a_fifo(), "--overwrite"], "a FIFO")


LOCK = ".vintix-lock"


def held(folder: Callable[[], Path], argv: Callable[[Path], list[object]]) -> Callable[[], str | None]:
    """Run `argv(folder)` while another process holds `folder`'s lock: refused at once, naming the holder, and
    nothing of the folder changed."""
    def check() -> str | None:
        from vintix.atomic import folder_lock

        target = folder()
        before = sorted((p.name, p.stat().st_size) for p in target.rglob("*") if p.is_file() and p.name != LOCK)
        holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from vintix.atomic import folder_lock\n"
                                   "with folder_lock(sys.argv[1], 'a test holding it'):\n    print('held', flush=True)"
                                   "\n    time.sleep(3600)", str(target)], stdout=subprocess.PIPE, text=True,
                                  env=child_env())
        try:
            assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
            code, output = invoke(*argv(target))
        finally:
            holder.kill()
            holder.wait()
        with folder_lock(target, "the test, after"):  # released when its holder died
            pass
        after = sorted((p.name, p.stat().st_size) for p in target.rglob("*") if p.is_file() and p.name != LOCK)
        if code != 2 or "in use by a test holding it" not in output:
            return f"exit {code}: {output[-300:]}"
        return None if after == before else f"the folder changed: {before} -> {after}"
    return check


documented("outputs", "eval into a results folder another eval holds: refused, not mixed", held(
    eval_results, lambda out: ["eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "1",
                               "--seeds", "1", "--out", out, "--overwrite"]))
documented("outputs", "report into a folder another report holds: refused", held(
    lambda: empty_dir("report-held")(), lambda out: ["report", eval_results(), "--out", out]))
documented("outputs", "import-official into a folder another import holds: refused", held(
    lambda: empty_dir("import-held")(), lambda out: ["import-official", release_snapshot(), "--out", out]))
documented("outputs", "export-official into a folder another export holds: refused", held(
    lambda: empty_dir("export-held")(), lambda out: ["export-official", model_checkpoint(), "--out", out]))


# Values (issue 55, class 5): every CLI value is checked once, the same way wherever it arrives.
cli_error("values", "eval --reward-input given twice", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--reward-input", "zero", "--reward-input",
    "true"], "--reward-input is given 2 times")
cli_error("values", "eval --variation of one name twice", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "HalfCheetah-v5", "--variation", "viscosity=0.1",
    "--variation", "viscosity=0.2"], "'viscosity' is given twice")
cli_error("values", "train --out given twice", lambda: [
    "train", "--data", clean_data(), "--out", work() / "a", "--out=" + str(work() / "b")], "--out is given 2 times")
cli_error("values", "eval --prompt-steps 0 (it used to mean 512)", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--prompt-from", clean_data(),
    "--prompt-steps", "0"], "prompt_steps=0")
cli_error("values", "report --plateau-shots beyond the run's shots", lambda: [
    "report", eval_results(), "--plateau-shots", "50", "--out", work() / "r-plateau"], "more shots than the runs have")

# Options mean one thing (issue 71, class 7).
cli_error("values", "train --set of one field twice", lambda: [
    "train", "--data", clean_data(), "--out", work() / "set-twice", "--set", "max_steps=1", "--set", "max_steps=2"],
    "--set max_steps given more than once", after=not_written(lambda: work() / "set-twice"))
cli_error("values", "train --set init_from= (empty: it trained from scratch without a word)", lambda: [
    "train", "--data", clean_data(), "--out", work() / "set-empty", "--set", "init_from="],
    "gives init_from no value", after=not_written(lambda: work() / "set-empty"))
cli_error("values", "train --set 'init_from=\"\"' (an empty text: it was read as the working folder)", lambda: [
    "train", "--data", clean_data(), "--out", work() / "set-empty-text", "--set", 'init_from=""'],
    "init_from given as an empty text", after=not_written(lambda: work() / "set-empty-text"))
cli_error("values", "report --gap-shots with one results folder", lambda: [
    "report", eval_results(), "--gap-shots", "1-2", "--out", work() / "r-gap-one"], "give both folders",
    after=not_written(lambda: work() / "r-gap-one"))


def threads_beyond_the_cores_are_capped() -> str | None:
    code, output = invoke("eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "1",
                          "--seeds", "1", "--threads", "1024", "--out", work() / "threads-1024")
    cores = len(os.sched_getaffinity(0))
    if code != 0 or f"--threads 1024 is more than the {cores} cores this process may use: using {cores}" not in output:
        return f"exit {code}: {output[-300:]}"
    return None


def escape_codes_from_a_name_are_printed_escaped() -> str | None:
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(model_checkpoint()), "--tasks", "\x1b[2Jreach-v3"])
    if result.exit_code == 0 or "\x1b" in result.output or "\\x1b[2Jreach-v3" not in result.output:
        return f"exit {result.exit_code}: {result.output!r}"
    return None


def a_dataset_task_name_is_printed_as_it_is() -> str | None:
    """Issue 71's red team: `data stats` sent a task JSON's escape codes to the terminal, and rich read its
    ``[bold]`` as markup (the name printed was not the name)."""
    name = "\x1b[31mRED\x1b[0m[bold]B[/bold]\nline"
    root = damaged_data("marked-up-name", rewrite_json(lambda m: m.update(task_name=name)))()
    code, output = invoke("data", "stats", root)
    if code != 0 or "\x1b" in output or "\\x1b[31mRED\\x1b[0m[bold]B[/bold]\\nline" not in output:
        return f"exit {code}: {output!r}"
    return None


documented("values", "--threads 1024 runs on the machine's cores, with a note", threads_beyond_the_cores_are_capped)
documented("values", "a dataset's task name holding escape codes and markup is printed as it is",
           a_dataset_task_name_is_printed_as_it_is)
documented("values", "an escape code in a name is printed as \\x1b, never sent to the terminal",
           escape_codes_from_a_name_are_printed_escaped)


def lr_in_the_docs_spelling() -> str | None:
    from vintix.train import load_config

    config = load_config("tiny", None, ["lr=3e-4", "min_lr_fraction=1e-1"])
    return None if (config.lr, config.min_lr_fraction) == (3e-4, 0.1) else f"read as {config.lr}"


documented("values", "--set lr=3e-4 (YAML 1.1 reads it as a string) is the float the docs mean",
           lr_in_the_docs_spelling)


def rates_table(kind: str, row: str) -> Callable[[], list[object]]:
    def argv() -> list[object]:
        path = work() / f"rates-{kind}.csv"
        path.write_text("task,envs_per_batch,raw_steps_per_s,collect_steps_per_s\n" + row + "\n")
        return ["collect", "--task", "reach-v3", "--histories", "2", "--steps", "100", "--plan", "--rates", path]
    return argv


for kind, row in (("zero", "reach-v3,16,0,0"), ("nan", "reach-v3,16,nan,nan"), ("negative", "reach-v3,16,-5,-5"),
                  ("no-envs", "reach-v3,0,100,100")):
    cli_error("values", f"collect --plan with a rates table of {kind} rates", rates_table(kind, row),
              "rates must be positive numbers")
cli_error("values", "collect --plan refuses what collect refuses (posterior-search on a trained-expert task)",
          lambda: ["collect", "--plan", "--recipe", recipe_file("plan-refused", {
              "defaults": {"behaviour": "posterior-search"}, "tasks": {"Hopper-v5": {"histories": 1, "steps": 10}}})],
          "needs a hidden-goal task")


def recipe_file(name: str, content: dict[str, object]) -> Path:
    path = work() / f"{name}.yaml"
    path.write_text(json.dumps(content))  # JSON is YAML
    return path


# More of class 2 and 5, of our own: what a planted file or a typo does to each command.
cli_error("values", "eval --threads 5000", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--threads", "5000"], "--threads")
cli_error("values", "train --threads 5000", lambda: ["train", "--data", clean_data(), "--threads", "5000"],
          "--threads")
cli_error("values", "report --gap-shots backwards", lambda: [
    "report", eval_results(), "--gap-shots", "3-1", "--out", work() / "r-gap-back"], "first <= last")
cli_error("values", "report --gap-shots not a range", lambda: [
    "report", eval_results(), "--gap-shots", "all", "--out", work() / "r-gap-all"], "give FIRST-LAST")
cli_error("outputs", "eval into a folder whose episodes.csv is a link to a file of yours", lambda: [
    "eval", "--checkpoint", model_checkpoint(), "--tasks", "reach-v3", "--shots", "1", "--seeds", "1", "--out",
    planted("results", eval_results, "episodes.csv")(), "--overwrite"], "symbolic link", after=victim_changed)
cli_error("outputs", "report into a folder whose report.md is a link to a file of yours", lambda: [
    "report", eval_results(), "--out", planted("report", lambda: empty_dir("report-planted")(), "report.md")()],
    "symbolic link", after=victim_changed)


@once
def dataset_with_a_fifo() -> Path:
    folder = work() / "data-fifo"
    shutil.copytree(clean_data(), folder)
    os.mkfifo(folder / "metaworld" / "reach-v3" / "history-0009.h5")
    return folder


cli_error("outputs", "collect into a dataset holding a FIFO named like a history (a read would hang)", lambda: [
    "collect", "--task", "reach-v3", "--histories", "1", "--steps", "50", "--out", dataset_with_a_fifo()], "a FIFO")


def fifo_in_place_of(name: str, source: Callable[[], Path], relative: str) -> Callable[[], Path]:
    """A copy of `source()` whose file `relative` is a FIFO."""
    @once
    def make() -> Path:
        folder = work() / f"fifo-{name}"
        shutil.copytree(source(), folder)
        (folder / relative).unlink()
        os.mkfifo(folder / relative)
        return folder
    return make


def bare_fifo(name: str) -> Path:
    path = work() / name
    if not path.exists():
        os.mkfifo(path)
    return path


# Issue 71's red team: a FIFO where a file is read was called missing ("no recipe file", "missing task metadata"):
# it is named for what it is.
for what, args in [
    ("the task JSON", lambda: ["data", "validate", fifo_in_place_of("task-json", clean_data,
                                                                     "metaworld/reach-v3/reach-v3.json")()]),
    ("episodes.csv", lambda: ["report", fifo_in_place_of("episodes", eval_results, "episodes.csv")(), "--out",
                              work() / "r-fifo"]),
    ("model.safetensors", lambda: ["eval", "--checkpoint", fifo_in_place_of("weights", model_checkpoint,
                                                                            "model.safetensors")(),
                                   "--tasks", "reach-v3", "--out", work() / "e-fifo"]),
    ("the recipe", lambda: ["collect", "--recipe", bare_fifo("recipe.yaml"), "--out", work() / "c-fifo"]),
    ("the training config", lambda: ["train", "--config", bare_fifo("config.yaml"), "--data", clean_data()]),
]:
    cli_error("outputs", f"a FIFO in place of {what}", args, ": not a regular file")


# Names (issue 55, class 3): a bare name means one thing; a local path shadowing a shipped name is refused.
def in_shadowing_folder(*argv: object) -> Callable[[], tuple[int, str]]:
    """Run `argv` from a folder holding ./vintix-cpu (a folder), ./tiny (a file) and ./darkroom (a file)."""
    def run() -> tuple[int, str]:
        folder = work() / "shadowing"
        (folder / "vintix-cpu").mkdir(parents=True, exist_ok=True)
        for name in ("tiny", "darkroom"):
            (folder / name).write_text("tasks: {}\n")
        here = Path.cwd()
        os.chdir(folder)
        try:
            return invoke(*argv)
        finally:
            os.chdir(here)
    return run


def refused_as_shadowed(*argv: object) -> Callable[[], str | None]:
    def check() -> str | None:
        code, output = in_shadowing_folder(*argv)()
        return None if code == 2 and "write ./" in output and "is both the shipped" in output else \
            f"exit {code}: {output[-300:]}"
    return check


documented("names", "eval --checkpoint vintix-cpu beside a folder ./vintix-cpu: refused, not the folder",
           refused_as_shadowed("eval", "--checkpoint", "vintix-cpu", "--tasks", "reach-v3", "--shots", "1"))
documented("names", "collect --recipe tiny beside a file ./tiny: refused, not the file",
           refused_as_shadowed("collect", "--recipe", "tiny", "--plan"))
documented("names", "train --config darkroom beside a file ./darkroom: refused, not the file",
           refused_as_shadowed("train", "--config", "darkroom", "--data", "nowhere"))


def dot_slash_means_the_local_file() -> str | None:
    code, output = in_shadowing_folder("collect", "--recipe", "./tiny", "--plan")()
    return None if code == 2 and "a recipe needs a non-empty 'tasks:'" in output else f"exit {code}: {output[-200:]}"


documented("names", "collect --recipe ./tiny reads the local file", dot_slash_means_the_local_file)


def a_folder_shadows_no_file() -> str | None:
    """Issue 71's red team: a model folder ./vintix-cpu stopped `--config vintix-cpu` with advice (./vintix-cpu)
    that named no config."""
    code, output = in_shadowing_folder("train", "--config", "vintix-cpu", "--data", "nowhere")()
    return None if code == 2 and "is both the shipped" not in output and "nowhere" in output else \
        f"exit {code}: {output[-300:]}"


documented("names", "train --config vintix-cpu beside a model folder ./vintix-cpu: the shipped config",
           a_folder_shadows_no_file)


# Plug-ins (issue 47, class 6): code vintix is told to call that fails ends in one line naming it and the fix.
def plugin_task(name: str, **fields: object) -> Callable[[], object]:
    def call() -> object:
        import vintix

        probe_code()
        vintix.register_task(name, obs_dim=39, act_dim=4, episode_length=500, **fields)
        return vintix.make_env(name, seed=0)
    return call


def plugin_demonstrator(source: str) -> Callable[[], object]:
    def call() -> object:
        from vintix.demonstrators.base import external_demonstrator

        probe_code()
        demonstrator = external_demonstrator("reach-v3", source)
        import vintix

        env = vintix.make_env("reach-v3", seed=0)
        return demonstrator.act(env.reset()[0][None], [env])
    return call


@once
def sac_zip() -> Path:
    import gymnasium as gym
    from stable_baselines3 import SAC

    path = work() / "pendulum-sac.zip"
    SAC("MlpPolicy", gym.make("Pendulum-v1"), learning_starts=0, buffer_size=100).save(path)
    path.chmod(0o600)
    return path


def collect_with_demonstrator(source: str) -> list[object]:
    probe_code()
    recipe = work() / f"recipe-{source.replace(':', '-')}.yaml"
    recipe.write_text(json.dumps({"tasks": {"reach-v3": {"histories": 1, "steps": 20, "demonstrator": source}}}))
    return ["collect", "--recipe", recipe, "--out", work() / f"data-{source.replace(':', '-')}"]


api_error("plugins", "a task whose env factory raises", plugin_task("plugin-broken", env_factory="trust_probe:broken"),
          "env_factory 'trust_probe:broken' raised RuntimeError: boom in user code")
api_error("plugins", "a task whose env factory calls sys.exit(0)", plugin_task("plugin-exits",
          env_factory="trust_probe:exits"), "env_factory 'trust_probe:exits' raised SystemExit")
api_error("plugins", "a task whose env factory names a relative module", plugin_task(
    "plugin-relative", env_factory=".trust_probe:make"), "is not a module name")
cli_error("plugins", "collect with a demonstrator that calls sys.exit(0) (it used to exit 0, having done nothing)",
          lambda: collect_with_demonstrator("trust_probe:exits"), "raised SystemExit")
api_error("plugins", "a custom task in a built-in group with other dims", lambda: __import__("vintix").register_task(
    "plugin-wide", env_id="Pendulum-v1", obs_dim=3, act_dim=1, episode_length=200, group="metaworld"),
    "group 'metaworld' has obs_dim 39")
api_error("plugins", "a demonstrator whose constructor raises", plugin_demonstrator("trust_probe:broken"),
          "demonstrator 'trust_probe:broken' raised RuntimeError")
cli_error("plugins", "collect with a demonstrator whose act raises", lambda: collect_with_demonstrator(
    "trust_probe:ActsBroken"), "the demonstrator's act raised ZeroDivisionError")
api_error("plugins", "sb3:PPO: on a SAC model file", lambda: plugin_demonstrator(f"sb3:PPO:{sac_zip()}")(),
          "Name the algorithm it was saved with")
api_error("plugins", "sbx: without sbx installed", lambda: plugin_demonstrator(f"sbx:SAC:{sac_zip()}")(),
          "pip install sbx-rl")


def clash_with_a_tasks_file() -> object:
    from vintix.tasks.custom import register_specs, register_tasks_file

    path = work() / "clash-tasks.yaml"
    path.write_text(json.dumps({"tasks": {"plugin-clash": {"env_id": "Pendulum-v1", "obs_dim": 3, "act_dim": 1,
                                                           "episode_length": 200}}}))
    register_tasks_file(path)
    return register_specs({"plugin-clash": {"env_id": "Pendulum-v1", "obs_dim": 3, "act_dim": 1,
                                            "episode_length": 100}}, "some-checkpoint/config.json")


api_error("plugins", "a checkpoint's task whose name a tasks file's task has", clash_with_a_tasks_file,
          "is already task 'plugin-clash' (from tasks file")

def python_dash_m() -> str | None:
    env = child_env()
    result = subprocess.run([sys.executable, "-m", "vintix", "tasks", "--domain", "industrial_benchmark"],
                            capture_output=True, text=True, env=env, timeout=HANG_GUARD_S)
    listed = len(result.stdout.splitlines()) - 1  # under a header line
    return None if result.returncode == 0 and listed == 21 else f"exit {result.returncode}, {listed} tasks"


documented("cli", "python -m vintix runs the CLI", python_dash_m)
cli_error("cli", "python -m vintix with a bad option", ["tasks", "--domian", "mujoco"], "No such option")


test_bad_input_ends_as_expected = bad_input_test("outputs", "values", "trust", "names", "plugins", "cli", "bench")


# Names from files are never paths: a task, label, group or dataset id that a file supplies becomes one file name.
@pytest.mark.parametrize("name", ["../../escaped", "/tmp/absolute", "nul\x00in-it", "x" * 300, "..", ".hidden",
                                  "tab\tand\nnewline", "ünïcödé"])
def test_names_from_files_are_never_paths(name):
    made = file_name(name)
    assert made and "/" not in made and "\x00" not in made and made not in (".", "..") and not made.startswith(".")
    assert len(made.encode()) <= MAX_NAME_BYTES and made.isascii() and made.isprintable()
    assert file_name(name + "!") != made  # two names, two files
    assert file_name("reach-v3") == "reach-v3" and file_name("HalfCheetah-Vel-v5") == "HalfCheetah-Vel-v5"


def test_names_from_files_are_never_paths_data_plot_and_collect_write_inside_their_folder(tmp_path, monkeypatch):
    """A task of your own whose name climbs out (a tasks file or a dataset's task JSON names it): its histories and
    its figure stay under the folder the command was given."""
    from vintix.tasks import registry

    monkeypatch.setattr(registry, "_custom", dict(registry._custom))
    vintix.register_task("../../../escaped-v0", env_id="Pendulum-v1", obs_dim=3, act_dim=1, episode_length=50,
                         reference_random=-400, reference_expert=-50)
    (tmp_path / "run").mkdir()
    monkeypatch.chdir(tmp_path / "run")
    (tmp_path / "run" / "still.py").write_text(
        "import numpy as np\n\n\nclass Still:\n    def __init__(self, task):\n        pass\n\n"
        "    def act(self, observations, envs):\n        return np.zeros((len(envs), 1), np.float32)\n")
    monkeypatch.syspath_prepend(str(tmp_path / "run"))
    recipe = tmp_path / "run" / "recipe.yaml"
    recipe.write_text('tasks:\n  "../../../escaped-v0": {histories: 1, steps: 100, demonstrator: "still:Still"}\n')
    code, output = invoke("collect", "--recipe", recipe, "--out", "data")
    assert code == 0, output
    code, output = invoke("data", "plot", "data", "--out", "figures")
    assert code == 0, output
    assert {p.name for p in tmp_path.iterdir()} - {"user-cache"} == {"run"}  # run/data/custom/../../.. is tmp_path
    assert len(list((tmp_path / "run" / "figures").rglob("*.png"))) == 2  # the task's and its domain's
