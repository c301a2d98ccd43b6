"""Write the shipped models in the current checkpoint layout (the Hub's: config.json, model.safetensors and a
README.md model card that carries the model's TRAINING.md). Weights and recorded training facts are kept
as they are, but for the paths the training machine recorded, which become relative to the run folder (a shipped
model it started from: its name), as `vintix train` records them now; re-run after editing a TRAINING.md. From
the repository root:

    python scripts/resave_shipped_models.py
"""

from pathlib import Path
from typing import Any

from vintix.agent.pretrained import resolve_checkpoint, shipped_models
from vintix.model import load_pretrained, read_metadata, save_pretrained
from vintix.train.checkpoint import portable_record


def shipped_init_name(extra: dict[str, Any]) -> str | None:
    """The shipped model a model was fine-tuned from, where its recorded init_from is a shipped model's folder."""
    init_from = (extra.get("train_config") or {}).get("init_from")
    if init_from is None:
        return None
    path = Path(init_from)
    return path.name if path.parent.name == "pretrained" and path.name in shipped_models() else None


def main() -> None:
    for name in shipped_models():
        folder = resolve_checkpoint(name)
        training = (folder / "TRAINING.md").read_text()
        details = "#" + training if training.startswith("# ") else training  # its title becomes a section
        extra = read_metadata(folder)["extra"]
        save_pretrained(load_pretrained(folder), folder, portable_record(extra, shipped_init_name(extra)), details,
                        name=f"vintix {name}")
        print(f"{name}: {', '.join(sorted(p.name for p in folder.iterdir()))}")


if __name__ == "__main__":
    main()
