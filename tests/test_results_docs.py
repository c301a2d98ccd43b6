"""docs/results/ is a results folder a reader can navigate: an index by question, one entry README.md of one shape
per experiment, and no link into it that leads nowhere."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

ROOT = Path(__file__).parents[1]
RESULTS = ROOT / "docs" / "results"
SHAPE = ("**Question", "**Answer", "**Command", "**Table", "**Records")
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def prose(text: str) -> str:
    """The text outside fenced code blocks and inline code, where a link is a link."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.M | re.S)
    return re.sub(r"`[^`\n]*`", "", text)


def anchors(markdown: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation and symbols dropped, spaces to hyphens, repeats numbered."""
    seen: dict[str, int] = {}
    found = set()
    text = re.sub(r"^```.*?^```", "", markdown.read_text(), flags=re.M | re.S)
    for heading in re.findall(r"^#{1,6}\s+(.+?)\s*#*$", text, flags=re.M):
        heading = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "").lower()
        slug = "".join(c for c in heading if c in " -_" or unicodedata.category(c)[0] in "LMN").replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        found.add(slug if count == 0 else f"{slug}-{count}")
    return found


def broken_links(markdown: Path) -> list[str]:
    broken = []
    for target in LINK.findall(prose(markdown.read_text())):
        if re.match(r"[a-z][a-z+.-]*:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        resolved = (markdown.parent / path).resolve() if path else markdown
        if not resolved.exists():
            broken.append(f"{markdown.relative_to(ROOT)}: {target} (no such file)")
        elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
            broken.append(f"{markdown.relative_to(ROOT)}: {target} (no such heading)")
    return broken


def pages_linking_into_results() -> list[Path]:
    pages = sorted(RESULTS.rglob("*.md")) + [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
    return [page for page in pages if page.is_relative_to(RESULTS) or "results/" in page.read_text()]


def test_every_link_in_and_into_the_results_resolves():
    broken = [line for page in pages_linking_into_results() for line in broken_links(page)]
    assert broken == []


def test_every_results_folder_has_an_entry_readme_of_one_shape_and_the_index_names_it():
    index = (RESULTS / "README.md").read_text()
    for folder in sorted(p for p in RESULTS.iterdir() if p.is_dir()):
        readme = folder / "README.md"
        assert readme.is_file(), f"{folder.name} has no README.md"
        text = readme.read_text()
        positions = [text.find(label) for label in SHAPE]
        assert -1 not in positions and positions == sorted(positions), f"{folder.name}: {SHAPE} in that order"
        assert f"]({folder.name}/README.md)" in index, f"the index does not link {folder.name}"
    assert not list(RESULTS.rglob("HOW.md"))


def test_the_results_keep_no_checkpoint_and_no_bulky_per_episode_file():
    checkpoints = [p for p in RESULTS.rglob("*") if p.suffix in (".safetensors", ".pt", ".pth", ".ckpt")]
    assert checkpoints == []
    # The per-episode files still kept are traces a README quotes, or runs no run.sh rebuilds (recorded here).
    quoted = {"vintix-cpu/results/ad-true/episodes.csv", "vintix-cpu/first-run/results/ad-true/episodes.csv",
              "vintix-cpu-meta/step-6000/results/ad-true/episodes.csv",
              "vintix-cpu-meta/step-12000-keep300/results/ad-true/episodes.csv",
              "meta-rl/switching-probe/results/true/episodes.csv", "meta-rl/switching-probe/results/zero/episodes.csv",
              "meta-rl/switching-probe/results/shuffled/episodes.csv",
              "vintix-cpu-meta/training-log.csv"}  # the run's log: its in-context selections
    bulky = {p.relative_to(RESULTS).as_posix() for p in RESULTS.rglob("*.csv") if p.stat().st_size > 200_000}
    assert bulky <= quoted, sorted(bulky - quoted)
