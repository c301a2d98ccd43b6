"""The package's folders are pipeline stages; a stage imports only itself, earlier stages and the shared modules.

Every import counts, at module level or inside a function, and so does a package named by string to
``importlib.import_module`` or ``importlib.resources.files`` (which imports it): an import that runs
upward, however late, hides a loop between two stages.
"""

from __future__ import annotations

import ast
from pathlib import Path

import vintix

STAGES = ("tasks", "demonstrators", "data", "collect", "model", "train", "agent", "evaluate", "report")
"""Lower to higher. collect writes its histories through data's format, so data comes first."""
TOP = ("__main__", "cli")
"""python -m vintix and the command line (and vintix/__init__.py, the package's face): above every stage."""

PACKAGE = Path(vintix.__file__).parent
# Every other module directly under src/vintix (errors, atomic, memory, fields, userdirs, cluster) is shared:
# anything may import it, so it may import no stage.


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def level(module: str) -> int | None:
    """The stage's index, len(STAGES) for the top, None for a shared module."""
    parts = module.split(".")
    if len(parts) == 1:  # vintix/__init__.py
        return len(STAGES)
    if parts[1] in STAGES:
        return STAGES.index(parts[1])
    if len(parts) == 2 and parts[1] in TOP:
        return len(STAGES)
    return None


def imported(module: str, path: Path) -> list[tuple[int, str]]:
    """(line, module) of every vintix module `module` imports anywhere in its source."""
    found = []
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:  # `from vintix import cluster` imports the module vintix.cluster
                found.append((node.lineno, f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base))
        elif isinstance(node, ast.Call) and _called(node) in ("files", "import_module") and node.args:
            if isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str):
                found.append((node.lineno, node.args[0].value))
    return sorted((line, name) for line, name in found if name == "vintix" or name.startswith("vintix."))


def _called(call: ast.Call) -> str | None:
    """The called function's own name: ``files`` of ``resources.files(...)`` and of ``files(...)``."""
    if isinstance(call.func, ast.Attribute):
        return call.func.attr
    return call.func.id if isinstance(call.func, ast.Name) else None


def stage_name(index: int | None) -> str:
    return "shared" if index is None else STAGES[index] if index < len(STAGES) else "top"


def test_every_folder_is_a_stage_in_the_order():
    folders = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    assert folders == set(STAGES), "a new folder needs its place in STAGES"


def test_no_module_imports_a_later_stage():
    upward = []
    for module, path in MODULES.items():
        own = level(module)
        for line, name in imported(module, path):
            # `import vintix` (or `from vintix import __version__`) runs nothing every other import does not.
            target = None if name == "vintix" else level(name)
            if target is None:
                continue  # a shared module: anything may import it
            if own is None or target > own:  # a shared module imports no stage
                upward.append(f"{path.relative_to(PACKAGE.parent)}:{line} ({stage_name(own)}) imports {name} "
                              f"({stage_name(target)})")
    assert not upward, "imports that run up the pipeline:\n" + "\n".join(upward)


def test_the_checker_sees_every_kind_of_import(tmp_path):
    path = tmp_path / "sample.py"
    path.write_text("from vintix import cluster, errors\n"
                    "from importlib import resources\n"
                    "def f():\n"
                    "    if True:\n"
                    "        from vintix.collect.calibrate import noise_free_return\n"
                    "    import vintix.report\n"
                    "    return resources.files('vintix.agent')\n")
    assert imported("vintix.data.sample", path) == [
        (1, "vintix.cluster"), (1, "vintix.errors"), (5, "vintix.collect.calibrate"), (6, "vintix.report"),
        (7, "vintix.agent")]
