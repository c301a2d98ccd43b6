"""Recipes and training configs that build on another (`base:`): how they merge, their errors, --print-config,
and that no shipped file repeats another's settings instead of naming it as its base."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from vintix.cli import app
from vintix.collect.collector import CollectionError
from vintix.collect.recipe import load_recipe, resolved_recipe, shipped_recipe, shipped_recipes
from vintix.configfiles import BASE_KEY, read_layered
from vintix.train.config import ConfigError, load_config, shipped_config, shipped_configs


def _resolved_config(name: str) -> dict:
    return read_layered(shipped_config(name), shipped_config, ConfigError, "training config")  # type: ignore[arg-type]


KINDS = {"recipe": (shipped_recipes(), shipped_recipe, resolved_recipe),
         "config": (shipped_configs(), shipped_config, _resolved_config)}


def _leaves(settings: dict, prefix: tuple[str, ...] = ()) -> dict[tuple[str, ...], str]:
    found = {}
    for key, value in settings.items():
        if isinstance(value, dict) and value:
            found.update(_leaves(value, (*prefix, key)))
        else:
            found[(*prefix, key)] = repr(value)
    return found


def _ancestry(name: str, find) -> list[str]:
    """The file and the shipped bases under it, nearest first."""
    chain = [name]
    while (base := yaml.safe_load(find(chain[-1]).read_text()).get(BASE_KEY)) is not None:
        chain.append(base)
    return chain


@pytest.mark.parametrize("kind", KINDS)
def test_no_shipped_file_repeats_another_instead_of_naming_it_as_its_base(kind):
    """Two files whose resolved settings differ in at most two values, or one of which holds all the other's, are
    near-copies: one must build on the other, or both on a common base. Files for different tasks that share a
    behaviour's few settings are not near-copies (their tasks differ in name, histories and steps)."""
    names, find, resolve = KINDS[kind]
    leaves = {name: _leaves(resolve(name)) for name in names}
    unrelated = []
    for a, b in itertools.combinations(names, 2):
        differ = [key for key in leaves[a].keys() | leaves[b].keys() if leaves[a].get(key) != leaves[b].get(key)]
        contains = leaves[a].items() <= leaves[b].items() or leaves[b].items() <= leaves[a].items()
        if (len(differ) <= 2 or contains) and not set(_ancestry(a, find)) & set(_ancestry(b, find)):
            unrelated.append(f"{a} / {b} differ only in {sorted('.'.join(k) for k in differ)}")
    assert unrelated == []


@pytest.mark.parametrize("kind", KINDS)
def test_a_file_with_a_base_states_only_what_differs_from_it(kind):
    names, find, resolve = KINDS[kind]
    restated = []
    for name in names:
        own = yaml.safe_load(find(name).read_text())
        base = own.pop(BASE_KEY, None)
        if base is None:
            continue
        underneath = _leaves(resolve(base))
        restated += [f"{name}: {'.'.join(key)}" for key, value in _leaves(own).items() if underneath.get(key) == value]
    assert restated == []


def test_a_base_is_read_first_and_mappings_merge_key_by_key(tmp_path):
    mine = tmp_path / "configs" / "mine.yaml"
    mine.parent.mkdir()
    mine.write_text("base: darkroom-search\nmodel_overrides: {context_len: 900}\nbatch_size: 3\n")
    (tmp_path / "configs" / "tuned.yaml").write_text("base: mine.yaml\nlr: 0.0003\n")
    config = load_config(str(tmp_path / "configs" / "tuned.yaml"))
    shipped = load_config("darkroom-search")
    assert (config.lr, config.batch_size, config.window_len) == (0.0003, 3, shipped.window_len)
    assert config.model_overrides == {**shipped.model_overrides, "context_len": 900}  # merged, not replaced


def test_a_recipe_with_a_base_adds_a_task_or_changes_one_setting_of_one(tmp_path):
    recipe = tmp_path / "recipe.yaml"
    recipe.write_text("base: darkroom-ad\ntasks:\n  DarkRoom-v0: {steps: 200}\n"
                      "  KeyToDoor-v0: {histories: 2, steps: 100}\n")
    plans = {plan.task: plan for plan in load_recipe(recipe)}
    base = load_recipe("darkroom-ad")[0]
    assert (plans["DarkRoom-v0"].histories, plans["DarkRoom-v0"].steps) == (base.histories, 200)
    assert plans["KeyToDoor-v0"].behaviour == base.behaviour == "learner"  # the base's defaults apply to it too


@pytest.mark.parametrize(("text", "message"), [
    ("base: no-such-config\n", "base: no-such-config is no shipped training config; name a file of your own as a "
                               "path relative to this one"),
    ("base: ./missing.yaml\n", "base: ./missing.yaml: no such file"),
    ("base: ./self.yaml\n", "comes back to a file already read"),
    ("base: [darkroom]\n", "base: names the training config this one builds on"),
])
def test_a_base_that_cannot_be_read_is_named_with_the_fix(tmp_path, text, message):
    path = tmp_path / "self.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(".", r"\.")):
        load_config(str(path))


def test_a_recipe_base_loop_through_two_files_is_refused(tmp_path):
    (tmp_path / "a.yaml").write_text("base: b.yaml\n")
    (tmp_path / "b.yaml").write_text("base: a.yaml\ntasks: {DarkRoom-v0: {histories: 1, steps: 20}}\n")
    with pytest.raises(CollectionError, match="a.yaml -> .*b.yaml -> .*a.yaml"):
        load_recipe(tmp_path / "a.yaml")


def test_print_config_shows_the_resolved_whole_and_runs_nothing(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["train", "--config", "keytodoor-walk", "--out", str(tmp_path / "run"),
                                 "--set", "max_steps=7", "--print-config"])
    assert result.exit_code == 0, result.output
    printed = yaml.safe_load(result.output)
    assert printed["max_steps"] == 7 and printed["window_len"] == 800  # --set, and the base's
    assert printed["model_overrides"]["episode_return"] is True and printed["model_overrides"]["n_layers"] == 3
    assert not (tmp_path / "run").exists()
    result = runner.invoke(app, ["collect", "--recipe", "vintix-cpu-meta", "--print-config"])
    assert result.exit_code == 0, result.output
    tasks = yaml.safe_load(result.output)["tasks"]
    assert {"reach-v3", "window-open-v3", "Ant-Dir-v5"} <= set(tasks) and len(tasks) == 15
    result = runner.invoke(app, ["collect", "--task", "DarkRoom-v0", "--print-config"])
    assert result.exit_code != 0 and "give --recipe" in result.output


def test_every_shipped_file_resolves_to_a_valid_recipe_or_config():
    for name in shipped_recipes():
        assert load_recipe(name), name
    for name in shipped_configs():
        load_config(name)
    assert Path(shipped_config("darkroom")).read_text().count("\n") > 5  # type: ignore[arg-type]
