"""docs/icrl-your-env.md, followed as a user would: its files written out as the page shows them, its shell
commands run as they are written, and the model they make must read its rewards (success from shot 2 on with
the true rewards fed back, not with zeros). A page that drifts from what works fails here."""

from __future__ import annotations

import csv
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import HANG_GUARD_S

PAGE = Path(__file__).parents[1] / "docs" / "icrl-your-env.md"


def page_blocks(page: Path = PAGE) -> tuple[dict[str, str], list[str]]:
    """The page's files, by the name on their first line (``# hidden_target.py ...``), and its shell blocks in
    page order (a page of two routes has one each)."""
    files, shells = {}, []
    for language, body in re.findall(r"```(\w+)\n(.*?)```", page.read_text(), flags=re.S):
        if language == "bash":
            shells.append(body)
        else:
            files[body.splitlines()[0].split()[1].rstrip(":")] = body
    return files, shells


def mean_by_shot(folder: Path, column: str = "success") -> dict[int, float]:
    """A results folder's `column` of episodes.csv, averaged over runs, by shot."""
    with (folder / "episodes.csv").open() as file:
        rows = list(csv.DictReader(file))
    return {shot: float(np.mean([float(r[column]) for r in rows if int(r["shot"]) == shot]))
            for shot in sorted({int(r["shot"]) for r in rows})}



def follow_page(page: Path, folder: Path) -> set[str]:
    """Write `page`'s files into `folder` and run its shell blocks there, one after the other, with this
    environment's vintix; the names of the files it wrote."""
    files, shells = page_blocks(page)
    for name, text in files.items():
        (folder / name).write_text(text)
    env = {**os.environ, "PYTHONPATH": str(folder),
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}  # this environment's vintix
    for shell in shells:
        run = subprocess.run(["bash", "-euo", "pipefail", "-c", shell], cwd=folder, env=env, capture_output=True,
                             text=True, timeout=HANG_GUARD_S)
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return set(files)


@pytest.mark.slow
def test_following_the_page_gives_a_model_that_finds_the_hidden_target_from_its_rewards(tmp_path):
    assert follow_page(PAGE, tmp_path) == {"hidden_target.py", "tasks.yaml", "recipe.yaml", "train.yaml"}
    true, zero = mean_by_shot(tmp_path / "results" / "true"), mean_by_shot(tmp_path / "results" / "zero")
    later = [2, 3, 4]
    assert true[1] <= 0.3  # the probe
    assert np.mean([true[s] for s in later]) >= 0.8
    assert np.mean([true[s] - zero[s] for s in later]) >= 0.5  # the rewards, not the context's length, do it
    assert (tmp_path / "report" / "report.md").is_file()
