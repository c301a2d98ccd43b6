"""Importing and exporting the authors' released checkpoint (no download: a synthetic release).

The synthetic release has the release's key names, file format and metadata schema at a reduced width
and depth. `reference_forward` below is written from the release's published forward semantics in plain
torch, using nothing of vintix, so the parity tests check our model against an independent reading.
"""

import json
import math

import gymnasium as gym
import numpy as np
import pytest
import torch
import torch.nn.functional as F
from typer.testing import CliRunner

from conftest import fill_up
from vintix.agent import Agent
from vintix.agent.pretrained import resolve_checkpoint
from vintix.cli import app
from vintix.errors import UnknownTaskError
from vintix.model import load_pretrained, preset
from vintix.model.official import (
    OfficialFormatError,
    config_to_official,
    export_official,
    import_official,
    state_dict_from_official,
)
from vintix.tasks.layouts import legacy_layout

SMALL = {
    "observation_emb_dim": 31,
    "action_emb_dim": 31,
    "reward_emb_dim": 2,
    "hidden_dim": 64,
    "transformer_depth": 2,
    "transformer_heads": 16,
    "intermediate_size": 128,
    "context_len": 512,
}
RELEASE_MODEL_FIELDS = {
    "attn_dropout": 0.0,
    "residual_dropout": 0.0,
    "normalize_qk": True,
    "bias": True,
    "parallel_residual": False,
    "shared_attention_norm": False,
    "norm_class": "LayerNorm",
    "mlp_class": "GptNeoxMLP",
    "inner_ep_pos_enc": False,
    "norm_acs": False,
    "norm_obs": True,
}
TRAINING_FIELDS = {"data_dir": "/data/vintix", "lr": 3e-4, "epochs": 1, "ic_treshold": 0.5, "eval_every": 1000}

# release task name -> (group, obs dim, act dim)
TASKS = {
    "reach-v2": ("metaworld", 39, 4),
    "push-v2": ("metaworld", 39, 4),
    "industrial-benchmark-0-v1": ("industrial_benchmark_overall", 6, 3),
    "industrial-benchmark-40-v1": ("industrial_benchmark_overall", 6, 3),
    "industrial-benchmark-75-v1": ("industrial_benchmark_overall", 6, 3),
    "Humanoid-v4": ("humanoid_v4", 376, 17),
    "shadowhandpen": ("bidex_obs_417_acs_52", 417, 52),
}


def release_shapes(sizes, groups):
    """Key -> shape of a release state dict, from the release's module layout."""
    o, a, r, d = (sizes[k] for k in ("observation_emb_dim", "action_emb_dim", "reward_emb_dim", "hidden_dim"))
    shapes = {}
    for g, (obs_dim, act_dim) in groups.items():
        for kind, width, in_dim in (("obs_encoders", o, obs_dim), ("acs_encoders", a, act_dim)):
            shapes |= {
                f"encoder.{kind}.{g}.layers.0.weight": (width, in_dim),
                f"encoder.{kind}.{g}.layers.0.bias": (width,),
                f"encoder.{kind}.{g}.layers.2.weight": (width,),
                f"encoder.{kind}.{g}.layers.2.bias": (width,),
                f"encoder.{kind}.{g}.layers.3.weight": (width, width),
                f"encoder.{kind}.{g}.layers.3.bias": (width,),
                f"encoder.{kind}.{g}.layers.5.weight": (width,),
                f"encoder.{kind}.{g}.layers.5.bias": (width,),
            }
        shapes |= {
            f"encoder.rews_encoders.{g}.layers.0.weight": (r, 1),
            f"encoder.rews_encoders.{g}.layers.0.bias": (r,),
        }
        for n in (0, 2, 4):
            shapes |= {
                f"head.acs_decoders.{g}.layers.{n}.weight": (d, d),
                f"head.acs_decoders.{g}.layers.{n}.bias": (d,),
            }
        shapes |= {
            f"head.acs_decoders.{g}.layers.6.weight": (act_dim, d),
            f"head.acs_decoders.{g}.layers.6.bias": (act_dim,),
        }
    shapes |= {"encoder.prev_acs_padding": (1, a), "encoder.prev_rew_padding": (1, r)}
    head_dim, mlp = d // sizes["transformer_heads"], sizes["intermediate_size"]
    for i in range(sizes["transformer_depth"]):
        b = f"transformer.blocks.{i}"
        shapes |= {
            f"{b}.norm1.weight": (d,),
            f"{b}.norm1.bias": (d,),
            f"{b}.norm2.weight": (d,),
            f"{b}.norm2.bias": (d,),
            f"{b}.attention.in_proj.weight": (3 * d, d),
            f"{b}.attention.in_proj.bias": (3 * d,),
            f"{b}.attention.q_norm.weight": (head_dim,),
            f"{b}.attention.q_norm.bias": (head_dim,),
            f"{b}.attention.k_norm.weight": (head_dim,),
            f"{b}.attention.k_norm.bias": (head_dim,),
            f"{b}.attention.out_proj.weight": (d, d),
            f"{b}.attention.out_proj.bias": (d,),
            f"{b}.mlp.fc.weight": (mlp, d),
            f"{b}.mlp.fc.bias": (mlp,),
            f"{b}.mlp.proj.weight": (d, mlp),
            f"{b}.mlp.proj.bias": (d,),
        }
    return shapes | {"transformer.ln_f.weight": (d,), "transformer.ln_f.bias": (d,)}


def release_metadata(seed=0):
    rng = np.random.default_rng(seed)
    metadata = {}
    for name, (group, obs_dim, act_dim) in TASKS.items():
        mean, std = rng.normal(0, 1, obs_dim), rng.uniform(0.5, 2.0, obs_dim)
        std[rng.random(obs_dim) < 0.1] = 0.0  # constant channels: divided by 1e-6, no floor
        if group.startswith("industrial"):
            mean[0], std[0] = float(name.split("-")[2]), 0.0  # channel 0: the setpoint
        metadata[name] = {
            "action_type": "continuous",
            "action_dim": act_dim,
            "observation_shape": {"proprio": [obs_dim]},
            "group_name": group,
            "reward_scale": float(rng.choice([1.0, 0.1])),
            "obs_mean": mean.tolist(),
            "obs_std": std.tolist(),
            "acs_mean": rng.normal(0, 0.1, act_dim).tolist(),
            "acs_std": rng.uniform(0.5, 1, act_dim).tolist(),
        }
    return metadata


def write_release(folder, sizes=SMALL, metadata=None, mutate=None, config_changes=None, seed=0):
    """A release snapshot in `folder`: model.pth, config.json, metadata.json. Returns the state dict."""
    metadata = metadata or release_metadata(seed)
    groups = {e["group_name"]: (e["observation_shape"]["proprio"][0], e["action_dim"]) for e in metadata.values()}
    generator = torch.Generator().manual_seed(seed)
    # Linear weights at 1/sqrt(fan_in), so activations and actions stay O(1) as in a trained model.
    state = {
        k: torch.randn(shape, generator=generator) * (shape[1] ** -0.5 if len(shape) == 2 else 0.1)
        + (
            1.0
            if k.endswith(
                ("norm1.weight", "norm2.weight", "layers.2.weight", "layers.5.weight", "norm.weight", "ln_f.weight")
            )
            else 0.0
        )
        for k, shape in release_shapes(sizes, groups).items()
    }
    if mutate:
        mutate(state)
    folder.mkdir(parents=True, exist_ok=True)
    torch.save(state, folder / "model.pth")
    (folder / "config.json").write_text(
        json.dumps({**TRAINING_FIELDS, **sizes, **RELEASE_MODEL_FIELDS, **(config_changes or {})})
    )
    (folder / "metadata.json").write_text(json.dumps(metadata))
    return state


def reference_forward(state, config, metadata, task, obs, prev_action, prev_reward, step_num):
    """The release's forward for one sequence of `task` (plain torch): actions [T, act_dim]."""
    entry = metadata[task]
    g = entry["group_name"]
    d, heads = config["hidden_dim"], config["transformer_heads"]

    def linear(x, prefix):
        return F.linear(x, state[f"{prefix}.weight"], state[f"{prefix}.bias"])

    def layer_norm(x, prefix):
        return F.layer_norm(x, x.shape[-1:], state[f"{prefix}.weight"], state[f"{prefix}.bias"], eps=1e-5)

    def encoder(x, prefix):
        x = layer_norm(F.leaky_relu(linear(x, f"{prefix}.layers.0"), 0.01), f"{prefix}.layers.2")
        return layer_norm(F.leaky_relu(linear(x, f"{prefix}.layers.3"), 0.01), f"{prefix}.layers.5")

    mean, std = torch.tensor(entry["obs_mean"]), torch.tensor(entry["obs_std"])
    obs_emb = encoder((obs - mean) / (std + 1e-6), f"encoder.obs_encoders.{g}")
    act_emb = encoder(prev_action, f"encoder.acs_encoders.{g}")
    rew_emb = F.leaky_relu(
        linear(entry["reward_scale"] * prev_reward[:, None], f"encoder.rews_encoders.{g}.layers.0"), 0.01
    )
    start = (step_num == 0)[:, None]
    act_emb = torch.where(start, state["encoder.prev_acs_padding"][0], act_emb)
    rew_emb = torch.where(start, state["encoder.prev_rew_padding"][0], rew_emb)
    x = torch.cat([obs_emb, act_emb, rew_emb], -1)
    T, head_dim = x.shape[0], d // heads
    slopes = torch.tensor([2.0 ** (-8.0 * (h + 1) / heads) for h in range(heads)])
    distance = torch.arange(T)[:, None] - torch.arange(T)[None, :]
    bias = (-slopes[:, None, None] * distance).masked_fill(distance < 0, float("-inf"))
    for i in range(config["transformer_depth"]):
        b = f"transformer.blocks.{i}"
        q, k, v = linear(layer_norm(x, f"{b}.norm1"), f"{b}.attention.in_proj").view(T, 3, heads, head_dim).unbind(1)
        q, k = layer_norm(q, f"{b}.attention.q_norm"), layer_norm(k, f"{b}.attention.k_norm")
        scores = torch.einsum("qhd,khd->hqk", q, k) / math.sqrt(head_dim) + bias
        attended = torch.einsum("hqk,khd->qhd", scores.softmax(-1), v).reshape(T, d)
        x = x + linear(attended, f"{b}.attention.out_proj")
        x = x + linear(F.gelu(linear(layer_norm(x, f"{b}.norm2"), f"{b}.mlp.fc")), f"{b}.mlp.proj")
    x = layer_norm(x, "transformer.ln_f")
    for n in (0, 2, 4):
        x = F.leaky_relu(linear(x, f"head.acs_decoders.{g}.layers.{n}"), 0.01)
    return linear(x, f"head.acs_decoders.{g}.layers.6")


def random_inputs(metadata, task, steps, seed=0):
    """Observations at each task's scale (constant channels exactly at their mean), episodes of 60 steps."""
    rng = np.random.default_rng(seed)
    entry = metadata[task]
    mean, std = np.array(entry["obs_mean"]), np.array(entry["obs_std"])
    obs = torch.tensor(mean + std * rng.normal(0, 1, (steps, len(mean))), dtype=torch.float32)
    step_num = torch.arange(steps) % 60
    return obs, torch.tensor(rng.normal(0, 1, steps), dtype=torch.float32), step_num


@pytest.fixture(scope="module")
def release(tmp_path_factory):
    folder = tmp_path_factory.mktemp("release")
    state = write_release(folder)
    return (
        folder,
        state,
        json.loads((folder / "metadata.json").read_text()),
        json.loads((folder / "config.json").read_text()),
    )


@pytest.fixture(scope="module")
def imported(release, tmp_path_factory):
    out = tmp_path_factory.mktemp("imported")
    return import_official(release[0], out), load_pretrained(out)


def test_import_consumes_every_release_tensor_exactly_once(release, imported):
    _, state, _, _ = release
    result, model = imported
    ours = {
        k: v for k, v in model.state_dict().items() if k not in ("obs_mean", "obs_std", "reward_scale", "task_group")
    }
    assert len(ours) == len(state)
    remaining = {k: v.reshape(-1) for k, v in state.items()}
    for tensor in ours.values():
        match = [
            k
            for k, v in remaining.items()
            if v.shape == tensor.reshape(-1).shape and torch.equal(v, tensor.reshape(-1))
        ]
        assert len(match) == 1
        del remaining[match[0]]
    assert not remaining and result.directory.is_dir()


def test_import_maps_release_names_onto_our_envs_with_their_layouts(imported):
    result, model = imported
    assert result.renamed == {
        "reach-v2": "reach-v3",
        "push-v2": "push-v3",
        "Humanoid-v4": "Humanoid-v5",
        "shadowhandpen": "Hand-Pen",
    }
    humanoid = model.task_norms[model.task_index("Humanoid-v5")]
    assert humanoid.obs_layout == legacy_layout("Humanoid-v5", 376) and humanoid.obs_layout.env_dim == 348
    assert result.adapted == ["Humanoid-v5"] and not result.known_release


def test_industrial_benchmark_setpoints_80_to_100_get_derived_statistics(release, imported):
    _, _, metadata, _ = release
    result, model = imported
    assert result.derived_tasks == [f"industrial-benchmark-{p}-v1" for p in (80, 85, 90, 95, 100)]
    norm = model.task_norms[model.task_index("industrial-benchmark-90-v1")]
    assert norm.obs_mean[0] == pytest.approx(90.0) and norm.obs_std[0] == 0.0
    assert list(norm.obs_mean[1:]) == metadata["industrial-benchmark-75-v1"]["obs_mean"][1:]
    # The setpoint channel normalizes to 0 on its own task, as it did in training.
    normalized, _ = model.normalize(
        torch.tensor([model.task_index("industrial-benchmark-90-v1")]),
        torch.tensor([[[90.0, 0, 0, 0, 0, 0]]]),
        torch.zeros(1, 1),
    )
    assert normalized[0, 0, 0] == 0.0


@pytest.mark.parametrize("task", ["reach-v2", "industrial-benchmark-40-v1"])
def test_full_window_forward_matches_the_independent_reference(release, imported, task):
    _, state, metadata, config = release
    _, model = imported
    obs, reward, step_num = random_inputs(metadata, task, 300)
    prev_action = torch.randn(300, metadata[task]["action_dim"])
    expected = reference_forward(state, config, metadata, task, obs, prev_action, reward, step_num)
    index = model.task_index(task.replace("-v2", "-v3"))
    ours = model(
        metadata[task]["group_name"], torch.tensor([index]), obs[None], prev_action[None], reward[None], step_num[None]
    )[0]
    assert (ours - expected).abs().max() < 1e-4


def cached_agent_difference(model, state, config, metadata, tasks, steps):
    """Largest |difference| between the cached agent stepping one env per release task in `tasks` for
    `steps` steps and the reference forward over the same sequences."""
    inputs = [random_inputs(metadata, t, steps, seed=i) for i, t in enumerate(tasks)]
    agent = Agent(model)
    wide = [gym.spaces.Box(-1e3, 1e3, (metadata[t]["action_dim"],)) for t in tasks]  # nothing clipped
    agent.reset([t.replace("-v2", "-v3") for t in tasks], wide)
    actions = [[] for _ in tasks]
    for t in range(steps):
        step = agent.act([inp[0][t].numpy() for inp in inputs], [float(inp[1][t]) for inp in inputs],
                         [bool(inp[2][t] == 0) for inp in inputs])
        for i, a in enumerate(step):
            actions[i].append(torch.tensor(a))
    worst = 0.0
    for i, task in enumerate(tasks):
        taken = torch.stack(actions[i])
        prev_action = torch.cat([torch.zeros(1, taken.shape[1]), taken[:-1]])
        obs, reward, step_num = inputs[i]
        # reward[t] went to the agent with o_t as the reward of its previous action
        expected = reference_forward(state, config, metadata, task, obs, prev_action, reward, step_num)
        worst = max(worst, float((taken - expected).abs().max()))
    return worst


def test_cached_agent_steps_match_the_independent_reference(release, imported):
    _, state, metadata, config = release
    assert cached_agent_difference(imported[1], state, config, metadata, ["reach-v2", "industrial-benchmark-40-v1"],
                                   300) < 1e-4


def test_export_then_import_is_bit_identical_and_the_reference_reads_the_export(release, imported, tmp_path):
    _, _, metadata, config = release
    result, model = imported
    exported = export_official(result.directory, tmp_path / "exported")
    state = torch.load(exported / "model.pth", weights_only=True)
    assert json.loads((exported / "metadata.json").read_text()) == metadata
    assert json.loads((exported / "config.json").read_text()) == config
    again = load_pretrained(import_official(exported, tmp_path / "again").directory)
    for (name, a), (_, b) in zip(model.state_dict().items(), again.state_dict().items(), strict=True):
        assert torch.equal(a, b), name
    assert again.task_norms == model.task_norms
    obs, reward, step_num = random_inputs(metadata, "push-v2", 200)
    prev_action = torch.randn(200, 4)
    expected = reference_forward(state, config, metadata, "push-v2", obs, prev_action, reward, step_num)
    ours = model(
        "metaworld",
        torch.tensor([model.task_index("push-v3")]),
        obs[None],
        prev_action[None],
        reward[None],
        step_num[None],
    )[0]
    assert (ours - expected).abs().max() < 1e-4


@pytest.mark.parametrize(
    "damage, named",
    [
        (
            lambda s: s.__setitem__(
                "transformer.blocks.0.attention.qkv.weight", s.pop("transformer.blocks.0.attention.in_proj.weight")
            ),
            "in_proj.weight",
        ),
        (lambda s: s.pop("head.acs_decoders.metaworld.layers.4.bias"), "head.acs_decoders.metaworld.layers.4.bias"),
        (lambda s: s.__setitem__("transformer.ln_f.bias", torch.zeros(65)), "transformer.ln_f.bias (65,)"),
        (lambda s: s.__setitem__("encoder.obs_encoders.ghost.layers.0.bias", torch.zeros(31)), "ghost"),
    ],
)
def test_a_renamed_missing_reshaped_or_extra_key_is_refused_by_name(tmp_path, damage, named):
    write_release(tmp_path / "release", mutate=damage)
    with pytest.raises(OfficialFormatError, match="does not fit") as error:
        import_official(tmp_path / "release", tmp_path / "out")
    assert named in str(error.value) and not (tmp_path / "out" / "config.json").exists()


def test_a_model_field_we_do_not_implement_is_refused_by_name(tmp_path):
    write_release(tmp_path / "release", config_changes={"parallel_residual": True})
    with pytest.raises(OfficialFormatError, match="parallel_residual=True"):
        import_official(tmp_path / "release", tmp_path / "out")


def test_the_full_size_release_maps_onto_the_paper_preset_without_allocating(tmp_path):
    from vintix.model import GroupSpec, TaskNorm, Vintix, count_parameters
    from vintix.model.official import config_from_official

    sizes = {
        "observation_emb_dim": 511,
        "action_emb_dim": 511,
        "reward_emb_dim": 2,
        "hidden_dim": 1024,
        "transformer_depth": 20,
        "transformer_heads": 16,
        "intermediate_size": 4096,
        "context_len": 8192,
    }
    groups = {
        "metaworld": (39, 4),
        "industrial_benchmark_overall": (6, 3),
        "invertedpendulum_v4": (4, 1),
        "inverteddoublependulum_v4": (11, 1),
        "humanoid_v4": (376, 17),
        "walker2d_v4": (17, 6),
        "hopper_v4": (11, 3),
        "ant_v4": (27, 8),
        "humanoidstandup_v4": (376, 17),
        "swimmer_v4": (8, 2),
        "reacher_v4": (11, 2),
        "pusher_v5": (23, 7),
        "halfcheetah_v4": (17, 6),
    }
    # Eight Bi-DexHands groups (their dims are not in the facts we have; these are the ones for which
    # the parameter count comes out at the release's 332,100,768: two groups of 417/52 tasks).
    groups |= {
        f"bidex_obs_{o}_acs_{a}{suffix}": (o, a)
        for o, a, suffix in [
            (417, 52, "_1"),
            (417, 52, "_2"),
            (420, 52, ""),
            (422, 52, ""),
            (425, 52, ""),
            (428, 52, ""),
            (446, 52, ""),
            (422, 40, ""),
        ]
    }
    shapes = release_shapes(sizes, groups)
    assert len(groups) == 21 and len(shapes) == 870
    with torch.device("meta"):
        state = {k: torch.empty(shape) for k, shape in shapes.items()}
        model = Vintix(
            config_from_official({**sizes, **RELEASE_MODEL_FIELDS}),
            [GroupSpec(g, o, a) for g, (o, a) in groups.items()],
            [TaskNorm(g, g, [0.0] * o, [1.0] * o) for g, (o, _) in groups.items()],
        )
    assert len(state_dict_from_official(state, model)) == 870
    assert count_parameters(model) == sum(math.prod(s) for s in shapes.values()) == 332_100_768


def test_the_agent_refuses_shadowhandover_whose_group_the_release_lacks(imported):
    _, model = imported
    with pytest.raises(UnknownTaskError, match="bidexhands-398x40"):
        Agent(model).reset(["Hand-Over"], [gym.spaces.Box(-1, 1, (40,))])


def test_from_pretrained_imports_a_raw_snapshot_into_the_user_cache(release, tmp_path):
    agent = Agent.from_pretrained(release[0])
    assert agent.model.config.shared_padding and "reach-v3" in [n.task for n in agent.model.task_norms]
    cached = list((tmp_path / "user-cache" / "vintix" / "official").iterdir())
    assert len(cached) == 1 and (cached[0] / "config.json").is_file()
    Agent.from_pretrained(release[0])  # a second load reuses the import
    assert list((tmp_path / "user-cache" / "vintix" / "official").iterdir()) == cached


def test_export_refuses_a_model_the_release_code_cannot_express(tmp_path):
    with pytest.raises(OfficialFormatError, match="shared_padding=False"):
        export_official(resolve_checkpoint("point-goal"), tmp_path / "out")
    # The release's token layout drops an episode's last reward: a model that reads it has no place there.
    with pytest.raises(OfficialFormatError, match="last_reward=True"):
        config_to_official(preset("paper", last_reward=True))


def test_cli_imports_and_exports(release, tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["import-official", str(release[0]), "--out", str(tmp_path / "imported")])
    assert result.exit_code == 0, result.output
    assert "not the known release" in result.output and "reach-v2 -> reach-v3" in result.output
    result = runner.invoke(app, ["export-official", str(tmp_path / "imported"), "--out", str(tmp_path / "exported")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "exported" / "model.pth").is_file()


@pytest.mark.parametrize(
    "task, model_dim",
    [
        ("Humanoid-v5", 376),
        ("HumanoidStandup-v5", 376),
        ("Ant-v5", 27),
        ("Reacher-v5", 11),
        ("InvertedDoublePendulum-v5", 11),
    ],
)
def test_a_v5_env_seen_through_its_layout_is_the_v4_env(task, model_dim):
    layout = legacy_layout(task, model_dim)
    v5, v4 = gym.make(task), gym.make(task.replace("-v5", "-v4"))
    v5.reset(seed=0)
    v4.reset(seed=0)
    v4.unwrapped.set_state(v5.unwrapped.data.qpos.copy(), v5.unwrapped.data.qvel.copy())
    rng = np.random.default_rng(0)
    for _ in range(10):
        action = rng.uniform(-0.4, 0.4, v5.action_space.shape)
        np.testing.assert_allclose(layout.apply(v5.step(action)[0]), v4.step(action)[0], atol=1e-6)


def test_eval_runs_a_raw_release_snapshot_through_the_cli(release, tmp_path):
    result = CliRunner().invoke(app, ["eval", "--checkpoint", str(release[0]), "--tasks", "reach-v3,IB-p-40",
                                      "--shots", "1", "--seeds", "1", "--out", str(tmp_path / "results")])
    assert result.exit_code == 0, result.output
    rows = (tmp_path / "results" / "episodes.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[1].startswith("reach-v3") and rows[2].startswith("industrial-benchmark-40-v1")


def test_a_full_disk_is_said_before_a_release_export_writes(small_disk):
    fill_up(small_disk)
    with pytest.raises(OSError, match=r"the release snapshot would need about .* [kMGT]B free; free space, or write"):
        export_official(resolve_checkpoint("vintix-cpu"), small_disk / "out")
    assert sorted(p.name for p in small_disk.iterdir()) == ["ballast"]


def test_two_evals_of_one_release_snapshot_share_its_import(release):
    """The second of two imports at once into the user cache waits for the first and reuses it (the import's folder
    lock refused it)."""
    from concurrent.futures import ThreadPoolExecutor

    from vintix.agent.pretrained import imported_snapshot
    from vintix.model.checkpoint import is_checkpoint

    with ThreadPoolExecutor(2) as pool:
        first, second = pool.map(imported_snapshot, [release[0], release[0]])
    assert first == second and is_checkpoint(first)
