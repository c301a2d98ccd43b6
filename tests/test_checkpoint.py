"""Model checkpoints: safetensors + JSON round trip, and clear errors for damaged or foreign ones."""

import json

import pytest
import torch

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
    assert sorted(p.name for p in (tmp_path / "ckpt").iterdir()) == ["model.json", "model.safetensors"]


def test_missing_directory_or_weights_is_a_clear_error(tmp_path):
    with pytest.raises(CheckpointError, match="no model.json"):
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
    meta = json.loads((tmp_path / "model.json").read_text())
    meta["config"]["rotary"] = True
    (tmp_path / "model.json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match="rotary"):
        load_pretrained(tmp_path)


def test_a_hand_edited_model_json_is_named_not_a_traceback(tmp_path):
    save_pretrained(make_model(), tmp_path)
    meta = json.loads((tmp_path / "model.json").read_text())
    for broken in ({**meta, "groups": [{"x": 1}]}, {**meta, "config": {**meta["config"], "n_heads": "2"}}):
        (tmp_path / "model.json").write_text(json.dumps(broken))
        with pytest.raises(CheckpointError, match="model.json: .*(does not describe a model|n_heads must be int)"):
            load_pretrained(tmp_path)


def test_a_device_this_machine_lacks_is_named_before_loading(tmp_path):
    save_pretrained(make_model(), tmp_path)
    with pytest.raises(DeviceError, match="device 'tpu'"):
        load_pretrained(tmp_path, "tpu")


def test_a_model_json_that_asks_for_more_memory_than_the_machine_has_is_refused_before_allocating(tmp_path):
    save_pretrained(make_model(), tmp_path)
    meta = json.loads((tmp_path / "model.json").read_text())
    (tmp_path / "model.json").write_text(json.dumps({**meta, "config": {**meta["config"], "mlp_dim": 10**9}}))
    with pytest.raises(OutOfMemoryError,
                       match="the model this checkpoint describes needs [0-9,.]+ GiB; this machine has"):
        load_pretrained(tmp_path)
