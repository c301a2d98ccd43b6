"""Model checkpoints: safetensors + JSON round trip, and clear errors for damaged or foreign ones."""

import json
import re
import subprocess
import sys

import pytest
import torch

from conftest import HANG_GUARD_S
from test_model import make_batch, make_model
from vintix.errors import DeviceError
from vintix.memory import OutOfMemoryError
from vintix.model import CheckpointError, load_pretrained, read_metadata, save_pretrained


def test_save_then_load_gives_identical_outputs_and_keeps_extra(tmp_path):
    model = make_model()
    save_pretrained(model, tmp_path / "ckpt", extra={"step": 7})
    loaded = load_pretrained(tmp_path / "ckpt")
    for group, task in (("A", "a1"), ("B", "b0")):
        batch = make_batch(group, task, model)
        assert torch.equal(model(**batch), loaded(**batch))
    assert read_metadata(tmp_path / "ckpt")["extra"] == {"step": 7}
    # The Hugging Face Hub's layout, written by its mixin: pushable as it is
    assert sorted(p.name for p in (tmp_path / "ckpt").iterdir()) == ["README.md", "config.json", "model.safetensors"]


def test_the_hub_mixin_saves_a_model_card_and_loads_a_local_folder_strictly(tmp_path):
    from vintix.model import Vintix

    model = make_model()
    extra = {"step": 1200, "tokens": 4_000_000, "trained_tasks": ["a1"], "dataset_fingerprint": "abc",
             "in_context_score": 0.275, "select_metric": "success", "select_tasks": ["a1"], "reward_use_gap": 0.2,
             "train_config": {"lr": 0.001}}
    save_pretrained(model, tmp_path / "ckpt", extra=extra, details="## How it was made\n\nvintix train ...")
    card = (tmp_path / "ckpt" / "README.md").read_text()
    assert card.startswith("---\n") and "library_name: vintix" in card and "reinforcement-learning" in card
    assert "step 1,200, 4,000,000 tokens on a1" in card and "success 0.275" in card and "## How it was made" in card
    assert "(reward-use gap +0.200)" in card
    loaded = Vintix.from_pretrained(str(tmp_path / "ckpt"))  # the library's method, no download for a folder
    batch = make_batch("A", "a1", model)
    assert torch.equal(model(**batch), loaded(**batch)) and not loaded.training
    weights = tmp_path / "ckpt" / "model.safetensors"
    weights.write_bytes(weights.read_bytes()[:-100])  # strict: a damaged file is an error, not a partial load
    with pytest.raises(CheckpointError, match="truncated or damaged"):
        Vintix.from_pretrained(str(tmp_path / "ckpt"))


def test_the_mixins_own_save_pretrained_writes_a_filled_model_card(tmp_path):
    """What push_to_hub would publish: the model's size and facts, never the template's blanks."""
    from vintix.model.model import count_parameters

    model = make_model()
    model.checkpoint_extra = {"step": 30, "tokens": 900, "trained_tasks": ["a1"]}
    model.save_pretrained(tmp_path)  # huggingface_hub's method, no vintix arguments
    card = (tmp_path / "README.md").read_text()
    assert "{{" not in card and f"vintix: {count_parameters(model):,} parameters" in card
    assert "step 30, 900 tokens on a1" in card


def test_a_checkpoint_written_before_the_hub_layout_still_loads(tmp_path):
    model = make_model()
    save_pretrained(model, tmp_path, extra={"step": 3})
    (tmp_path / "config.json").rename(tmp_path / "model.json")  # the earlier layout: model.json, no card
    (tmp_path / "README.md").unlink()
    batch = make_batch("A", "a1", model)
    assert torch.equal(load_pretrained(tmp_path)(**batch), model(**batch))
    assert read_metadata(tmp_path)["extra"] == {"step": 3}


def test_missing_directory_or_weights_is_a_clear_error(tmp_path):
    with pytest.raises(CheckpointError, match="no config.json"):
        load_pretrained(tmp_path)
    save_pretrained(make_model(), tmp_path)
    (tmp_path / "model.safetensors").unlink()
    with pytest.raises(CheckpointError, match="model.safetensors is not"):
        load_pretrained(tmp_path)


def test_truncated_weights_are_reported(tmp_path):
    save_pretrained(make_model(), tmp_path)
    weights = tmp_path / "model.safetensors"
    weights.write_bytes(weights.read_bytes()[:100])
    with pytest.raises(CheckpointError, match="truncated or damaged"):
        load_pretrained(tmp_path)


def test_nan_weights_of_a_diverged_run_are_refused(tmp_path):
    model = make_model()
    with torch.no_grad():
        next(model.parameters()).view(-1)[0] = float("nan")
    save_pretrained(model, tmp_path)
    with pytest.raises(CheckpointError, match="1 of .* tensors hold NaN/inf .*use an earlier one"):
        load_pretrained(tmp_path)


def test_weights_of_another_config_are_refused(tmp_path):
    save_pretrained(make_model(), tmp_path / "small")
    save_pretrained(make_model(mlp_dim=32), tmp_path / "other")
    (tmp_path / "other" / "model.safetensors").replace(tmp_path / "small" / "model.safetensors")
    with pytest.raises(CheckpointError, match="wrong shape"):
        load_pretrained(tmp_path / "small")


def test_unknown_config_field_is_refused(tmp_path):
    save_pretrained(make_model(), tmp_path)
    meta = json.loads((tmp_path / "config.json").read_text())
    meta["config"]["rotary"] = True
    (tmp_path / "config.json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match="rotary"):
        load_pretrained(tmp_path)


def test_a_hand_edited_model_json_is_named_not_a_traceback(tmp_path):
    save_pretrained(make_model(), tmp_path)
    meta = json.loads((tmp_path / "config.json").read_text())
    for broken in ({**meta, "groups": [{"x": 1}]}, {**meta, "config": {**meta["config"], "n_heads": "2"}}):
        (tmp_path / "config.json").write_text(json.dumps(broken))
        with pytest.raises(CheckpointError, match="config.json: .*(no field 'groups.0..name'|n_heads must be int)"):
            load_pretrained(tmp_path)


def test_a_device_this_machine_lacks_is_named_before_loading(tmp_path):
    save_pretrained(make_model(), tmp_path)
    with pytest.raises(DeviceError, match="device 'tpu'"):
        load_pretrained(tmp_path, "tpu")


def test_a_model_json_that_asks_for_more_memory_than_the_machine_has_is_refused_before_allocating(tmp_path):
    save_pretrained(make_model(), tmp_path)
    meta = json.loads((tmp_path / "config.json").read_text())
    (tmp_path / "config.json").write_text(json.dumps({**meta, "config": {**meta["config"], "mlp_dim": 10**9}}))
    with pytest.raises(OutOfMemoryError,
                       match="the model this checkpoint describes needs [0-9,.]+ GiB; this machine has"):
        load_pretrained(tmp_path)


@pytest.mark.parametrize(("size", "refusal"), [
    ({"n_layers": 10**9}, "ModelConfigError: n_layers=1000000000, head_layers=.*: at most 256 each"),
    ({"n_layers": 200, "mlp_dim": 10**9}, "OutOfMemoryError: the model this checkpoint describes needs")])
def test_a_model_too_deep_or_too_big_is_refused_from_its_config_before_one_is_built(tmp_path, size, refusal):
    save_pretrained(make_model(), tmp_path)
    meta = json.loads((tmp_path / "config.json").read_text())
    (tmp_path / "config.json").write_text(json.dumps({**meta, "config": {**meta["config"], **size}}))
    # In a child with a deadline: building 10^9 blocks, even on the meta device, would never end.
    code = f"from vintix.model import load_pretrained; load_pretrained({str(tmp_path)!r})"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert re.search(refusal, result.stderr), result.stderr[-2000:]


def test_the_memory_a_process_may_use_counts_its_address_space_limit():
    """Clusters and containers set `ulimit -v`: a size that fits the machine but not the limit is refused too."""
    code = ("import resource; from vintix.memory import available_memory; "
            "resource.setrlimit(resource.RLIMIT_AS, (6 * 2**30, resource.RLIM_INFINITY)); print(available_memory())")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert result.returncode == 0, result.stderr
    assert 0 < int(result.stdout) < 6 * 2**30


def test_a_model_saved_by_the_mixin_alone_keeps_what_its_checkpoint_recorded(tmp_path):
    """``push_to_hub`` saves through the mixin's own save_pretrained: the folder must still be complete."""
    save_pretrained(make_model(), tmp_path / "a", extra={"step": 9})
    loaded = load_pretrained(tmp_path / "a")
    loaded.save_pretrained(tmp_path / "b")  # the library's method, as push_to_hub calls it
    assert read_metadata(tmp_path / "b")["extra"] == {"step": 9}
    batch = make_batch("A", "a1", loaded)
    assert torch.equal(load_pretrained(tmp_path / "b")(**batch), loaded(**batch))
