"""Parity of an imported synthetic release with the independent reference forward of
tests/test_official_checkpoint.py, over longer runs than the test: python scripts/official-parity.py"""

import json
import sys
import tempfile
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_official_checkpoint import (  # noqa: E402
    cached_agent_difference,
    random_inputs,
    reference_forward,
    write_release,
)
from vintix.model import load_pretrained  # noqa: E402
from vintix.model.official import export_official, import_official  # noqa: E402

STEPS = 500


def ours(model, metadata, task, obs, prev_action, reward, step_num):
    index = torch.tensor([model.task_index(task.replace("-v2", "-v3"))])
    with torch.no_grad():
        return model(metadata[task]["group_name"], index, obs[None], prev_action[None], reward[None], step_num[None])[0]


def main() -> None:
    torch.manual_seed(0)
    root = Path(tempfile.mkdtemp())
    state = write_release(root / "release")
    metadata = json.loads((root / "release" / "metadata.json").read_text())
    config = json.loads((root / "release" / "config.json").read_text())
    model = load_pretrained(import_official(root / "release", root / "imported").directory)
    tasks = ["reach-v2", "push-v2", "industrial-benchmark-0-v1", "industrial-benchmark-40-v1",
             "industrial-benchmark-75-v1"]

    full = 0.0
    for task in tasks:
        obs, reward, step_num = random_inputs(metadata, task, STEPS)
        prev_action = torch.randn(STEPS, metadata[task]["action_dim"])
        expected = reference_forward(state, config, metadata, task, obs, prev_action, reward, step_num)
        diff = ours(model, metadata, task, obs, prev_action, reward, step_num) - expected
        full = max(full, float(diff.abs().max()))
    print(f"full-window forward, {STEPS} steps, {len(tasks)} tasks: max |diff| {full:.2e}")

    stepped = tasks[:4]
    cached = cached_agent_difference(model, state, config, metadata, stepped, STEPS)
    print(f"cached agent, {len(stepped)} envs of 2 groups, {STEPS} steps: max |diff| {cached:.2e}")

    exported = export_official(root / "imported", root / "exported")
    again = load_pretrained(import_official(exported, root / "again").directory)
    same = all(torch.equal(a, b) for a, b in zip(model.state_dict().values(), again.state_dict().values(), strict=True))
    exported_state = torch.load(exported / "model.pth", weights_only=True)
    obs, reward, step_num = random_inputs(metadata, "push-v2", STEPS)
    prev_action = torch.randn(STEPS, 4)
    expected = reference_forward(exported_state, config, metadata, "push-v2", obs, prev_action, reward, step_num)
    worst = float((ours(model, metadata, "push-v2", obs, prev_action, reward, step_num) - expected).abs().max())
    print(f"export -> import bit-identical: {same}; reference forward on the exported files: max |diff| {worst:.2e}")


if __name__ == "__main__":
    main()
