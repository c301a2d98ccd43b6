"""What `vintix eval` runs: its settings and their defaults, which the CLI's options take.

Kept apart from `run.py` (torch, the agent, the simulators) so that the CLI can read the defaults when it
starts without importing any of those.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vintix.errors import VintixError
from vintix.fields import check_field_types
from vintix.model.model import SAMPLE_NOISE

REWARD_INPUTS = ("true", "zero", "shuffled", "other-goal")
"""What `EvalConfig.reward_input` may feed back to the model."""
PLATEAU_SHOTS = 10
"""k of the best-k-shot plateau: the converged score that summaries and reports give (fewer when a run has
fewer shots)."""


ML1_ADAPTATION_SHOTS = 10
"""Meta-World's ML1 meta-test protocol: the episodes an agent adapts in before it is scored"""
ML1_SCORED_SHOTS = 3
"""... and the episodes it is scored on (success at any step of each)"""
ML1_SHOTS = ML1_ADAPTATION_SHOTS + ML1_SCORED_SHOTS
ML1_TEST_GOALS = 50
"""... on the test goals of `metaworld.ML1` (`vintix.tasks.metaworld.ml1_test_tasks`), 50 per task"""


class EvalConfigError(VintixError, ValueError):
    """An evaluation setting out of its range (the message names it)."""


@dataclass
class EvalConfig:
    """What `vintix eval` runs."""

    tasks: list[str] = field(default_factory=lambda: ["reach-v3"])
    """task names, domains or splits ('train', 'test'), repeated or comma-separated; domains and splits keep the
    tasks whose group the checkpoint has"""
    shots: int = 50
    """episodes per run: 50, or with ml1 ML1's 13 unless given"""
    seeds: int = 3
    """runs per task; run i's env is seeded first_seed + i (Meta-World: its own hidden goal)"""
    first_seed: int = 0
    """env seed of the first run (with ml1: the index of its ML1 test goal)"""
    variation: dict[str, float] = field(default_factory=dict)
    """MuJoCo physics variation of every env, NAME=VALUE on the command line, e.g. viscosity=0.05 (held-out
    evaluation)"""
    prompt_from: Path | None = None
    """dataset root: prompt run i with the first prompt_steps steps of its task's history i, and run it on
    that history's env (its env seed, so in Meta-World its hidden goal) instead of first_seed + i"""
    prompt_steps: int | None = None
    """prompt length in steps (default: half the model's window)"""
    batch_envs: int = 64
    """most envs stepped through one agent at once (the KV cache grows with it)"""
    reward_input: str = "true"
    """the reward fed back to the model: 'true' (the env's), 'zero' (0.0), 'shuffled' (at each step one
    drawn at random from the rewards the env's current episode has returned so far) or 'other-goal' (what each
    step would have earned under another env seed's hidden goal; hidden-goal tasks that can price a step under
    another goal); returns, success and scores always come from the true rewards (the reward-use ablation). A
    prompt keeps its stored rewards"""
    ml1: bool = False
    """Meta-World's ML1 meta-test protocol (docs/evaluation.md): run i plays ML1's test goal first_seed + i instead
    of a goal drawn from its seed, for 10 adaptation episodes then 3 scored ones (shots must be 13), its score the
    scored episodes' success rate. Meta-World tasks only"""
    greedy: bool = False
    """act on the argmax of a discrete group's logits (a gaussian policy's mean) instead of a draw; by default the
    policy samples, as AD and DPT evaluate (a greedy policy on a flat distribution never explores)"""
    sample_noise: str | None = None
    """how often a sampling head draws its noise, 'step' or 'episode' (`ModelConfig.sample_noise`: one draw held for
    an episode is one posterior sample an episode); None: the model's own setting"""

    def __post_init__(self) -> None:
        # Checked before any env runs: shots=0 used to crash only after the whole evaluation.
        check_field_types(self, EvalConfigError)
        counts = {"shots": self.shots, "seeds": self.seeds, "batch_envs": self.batch_envs,
                  "prompt_steps": 1 if self.prompt_steps is None else self.prompt_steps}  # None: half the context
        bad = [f"{k}={v}" for k, v in counts.items() if v < 1]
        bad += [f"first_seed={self.first_seed}"] if self.first_seed < 0 else []  # env seeds are unsigned
        if bad:
            raise EvalConfigError(f"{', '.join(bad)}: shots, seeds, batch_envs and prompt_steps must be >= 1, "
                                  "first_seed >= 0")
        if not [name for selector in self.tasks for name in selector.split(",") if name.strip()]:
            raise EvalConfigError("no tasks to evaluate; name task names, domains or splits")
        if self.ml1:
            self._check_ml1()
        if self.sample_noise not in (None, *SAMPLE_NOISE):
            raise EvalConfigError(f"sample_noise {self.sample_noise!r} is unknown; choose one of "
                                  f"{', '.join(SAMPLE_NOISE)}")
        if self.reward_input not in REWARD_INPUTS:
            raise EvalConfigError(f"reward_input {self.reward_input!r} is unknown; choose one of "
                                  f"{', '.join(map(repr, REWARD_INPUTS))}")

    def _check_ml1(self) -> None:
        if self.shots != ML1_SHOTS:
            raise EvalConfigError(f"ml1: ML1's protocol plays {ML1_ADAPTATION_SHOTS} adaptation and "
                                  f"{ML1_SCORED_SHOTS} scored episodes, so shots must be {ML1_SHOTS}, not {self.shots}")
        if self.first_seed + self.seeds > ML1_TEST_GOALS:
            raise EvalConfigError(f"ml1: runs play ML1's test goals first_seed to first_seed + seeds - 1, and there "
                                  f"are {ML1_TEST_GOALS} (0 to {ML1_TEST_GOALS - 1}); first_seed={self.first_seed} "
                                  f"with seeds={self.seeds} goes past them")
        if self.prompt_from is not None:
            raise EvalConfigError("ml1: a prompt brings its own history's goal; ML1's runs start cold on its test "
                                  "goals, so drop prompt_from")


@dataclass
class RunFile:
    """``run.json`` of a results folder, the fields its readers use (`vintix.fields.read_json_file` checks them; the
    file holds more: the model's config, the references, the time taken)."""

    checkpoint: str = ""
    """the model's name, as results name it (a shipped model's name, or its path)"""
    label: str | None = None
    """its name in reports"""
    weights_sha256: str | None = None
    """which weights played (`vintix.model.checkpoint.weights_sha256`); None in results from before it was kept"""
    config: dict[str, Any] = field(default_factory=dict)
    """the EvalConfig's fields"""
    custom_tasks: dict[str, dict[str, Any]] = field(default_factory=dict)
    """the specs of the tasks of your own it played"""
    goal_protocol: str | None = None
    """how hidden goals were drawn, where a task has one"""
    episodes_sha256: str | None = None
    """the sha256 of the episodes.csv it describes; None in results from before it was kept"""
