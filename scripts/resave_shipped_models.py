"""Write the shipped models in the current checkpoint layout (the Hub's: config.json, model.safetensors and a
README.md model card that carries the model's TRAINING.md). Weights and recorded training facts are kept
as they are; re-run after editing a TRAINING.md. From the repository root:

    python scripts/resave_shipped_models.py
"""

from vintix.agent.pretrained import resolve_checkpoint, shipped_models
from vintix.model import load_pretrained, read_metadata, save_pretrained


def main() -> None:
    for name in shipped_models():
        folder = resolve_checkpoint(name)
        training = (folder / "TRAINING.md").read_text()
        details = "#" + training if training.startswith("# ") else training  # its title becomes a section
        save_pretrained(load_pretrained(folder), folder, read_metadata(folder)["extra"], details, name=f"vintix {name}")
        print(f"{name}: {', '.join(sorted(p.name for p in folder.iterdir()))}")


if __name__ == "__main__":
    main()
