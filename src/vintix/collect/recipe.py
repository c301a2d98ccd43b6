"""Collection recipes: a YAML file naming tasks and their per-task collection settings.

    defaults:            # any CollectionPlan field except `task`
      histories: 4
      steps: 10000
      curvature: 1.0
      noise_free_fraction: 0.05
    tasks:
      reach-v3: {}
      door-open-v3: {curvature: 2.0}
      InvertedPendulum-v5: {knots: [1.0, 0.4, 0.3, 0.0]}   # see `vintix data fit-schedule`
      handle-pull-v3: {pilot_steps: 30000}   # knots fitted per history to a pilot on its own goal
      metaworld: {}      # a domain or split name expands to all its tasks

A recipe may build on another (`vintix.configfiles`): ``base: darkroom-search`` and only what differs (``defaults:``
and ``tasks:`` merge key by key, so a task added, or one setting of a task changed, is one line).

Shipped recipes (`vintix collect --recipe NAME`): see `src/vintix/collect/recipes/`.
"""

from __future__ import annotations

import dataclasses
from importlib import resources
from pathlib import Path
from typing import Any

from vintix.atomic import not_a_file
from vintix.collect.collector import CollectionError, CollectionPlan
from vintix.collect.noise import NoiseSchedule
from vintix.configfiles import read_layered
from vintix.errors import local_or_shipped
from vintix.tasks import resolve_tasks

SCHEDULE_KEYS = {f.name for f in dataclasses.fields(NoiseSchedule)}
PLAN_KEYS = {f.name for f in dataclasses.fields(CollectionPlan)} - {"task", "schedule"}


def shipped_recipes() -> list[str]:
    """Names of the recipes the package ships (`vintix collect --recipe NAME`)."""
    return sorted(p.name.removesuffix(".yaml") for p in resources.files("vintix.collect").joinpath("recipes").iterdir()
                  if p.name.endswith(".yaml"))


def shipped_recipe(name: str) -> Path | None:
    """The file of the recipe the package ships as `name`, or None."""
    shipped = resources.files("vintix.collect").joinpath("recipes").joinpath(f"{name}.yaml")
    return Path(str(shipped)) if shipped.is_file() else None


def recipe_path(name_or_path: str | Path) -> Path:
    """A recipe file, or the name of one the package ships ('tiny', 'metaworld-cpu', ...); a bare name that is both
    is refused (`vintix.errors.local_or_shipped`)."""
    path = Path(name_or_path)
    shipped = shipped_recipe(str(name_or_path))
    if shipped is not None and not local_or_shipped(name_or_path, True, "recipe", a_file=True):
        return shipped
    if path.is_file():
        return path
    if why := not_a_file(path):
        raise CollectionError(f"--recipe {why}")
    raise FileNotFoundError(
        f"no recipe file {str(name_or_path)!r} and no shipped recipe of that name; shipped: {shipped_recipes()}")


def _plan(task: str, settings: dict[str, Any], where: str) -> CollectionPlan:
    unknown = set(settings) - PLAN_KEYS - SCHEDULE_KEYS
    if unknown:
        raise CollectionError(
            f"{where}: unknown setting(s) {sorted(unknown)}; known: {sorted(PLAN_KEYS | SCHEDULE_KEYS)}")
    needed = sorted({"histories", "steps"} - set(settings))
    if needed:
        raise CollectionError(f"{where}: no {' or '.join(needed)} (set them under 'defaults:' or the task)")
    try:  # the plan and schedule check their own types and ranges (no int() that would truncate 2.5)
        schedule = NoiseSchedule(**{k: v for k, v in settings.items() if k in SCHEDULE_KEYS})
        return CollectionPlan(task=task, schedule=schedule, **{k: v for k, v in settings.items() if k in PLAN_KEYS})
    except ValueError as error:
        raise CollectionError(f"{where}: {error}") from error


def resolved_recipe(name_or_path: str | Path) -> dict[str, Any]:
    """A recipe's settings with its base's underneath (`vintix.configfiles`): what `vintix collect --print-config`
    shows."""
    return _read_recipe(recipe_path(name_or_path))


def _read_recipe(path: Path) -> dict[str, Any]:
    return read_layered(path, shipped_recipe, CollectionError, "recipe")


def load_recipe(name_or_path: str | Path) -> list[CollectionPlan]:
    """The collection plans of a recipe, one per task, task settings overriding the defaults."""
    path = recipe_path(name_or_path)
    recipe = _read_recipe(path)
    if not isinstance(recipe.get("tasks"), dict) or not recipe["tasks"]:
        raise CollectionError(f"{path}: a recipe needs a non-empty 'tasks:' mapping (and optionally 'defaults:')")
    defaults = recipe.get("defaults") or {}
    if not isinstance(defaults, dict) or not all(isinstance(v, dict) or v is None for v in recipe["tasks"].values()):
        raise CollectionError(
            f"{path}: 'defaults:' and each task's settings must be mappings, e.g. reach-v3: {{steps: 500}}")
    plans: dict[str, CollectionPlan] = {}
    for selector, settings in recipe["tasks"].items():
        for spec in resolve_tasks([selector]):
            plans[spec.name] = _plan(spec.name, {**defaults, **(settings or {})}, f"{path}: {selector}")
    return list(plans.values())
