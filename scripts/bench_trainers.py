"""Env steps per second while learning, for the off-policy trainers a MuJoCo demonstrator could use.

    OMP_NUM_THREADS=1 python scripts/bench_trainers.py --task Humanoid-v5 --steps 3000

Stable-Baselines3's SAC against sb3-contrib's TQC and CrossQ (`pip install sb3-contrib`) and sbx-rl's SAC
and CrossQ (its JAX sibling; `pip install sbx-rl`), installed into the same environment: neither is a
vintix dependency, and trainers that are not installed are skipped. CrossQ runs with its library's
default critics and, as `CrossQ 256`, with critics as wide as SAC's. Each learns
`--warmup` steps first (random actions, then the first updates and JAX's compilation), and only the
next `--steps` are timed. The table of trainer speeds in docs/demonstrators.md comes from this
script.
"""

from __future__ import annotations

import argparse
import importlib.util
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import torch

from vintix.tasks import make_env


def trainers() -> dict[str, Callable[..., Any]]:
    from stable_baselines3 import SAC

    found: dict[str, Callable[..., Any]] = {"SB3 SAC": SAC}
    if importlib.util.find_spec("sb3_contrib") is not None:
        import sb3_contrib

        narrow = {"net_arch": {"pi": [256, 256], "qf": [256, 256]}}
        found |= {"sb3-contrib TQC": sb3_contrib.TQC, "sb3-contrib CrossQ": sb3_contrib.CrossQ,
                  "sb3-contrib CrossQ 256": partial(sb3_contrib.CrossQ, policy_kwargs=narrow)}
    if importlib.util.find_spec("sbx") is not None:
        import sbx

        found |= {"sbx-rl SAC": sbx.SAC, "sbx-rl CrossQ": sbx.CrossQ}
    return found


def steps_per_second(algorithm: Callable[..., Any], task: str, warmup: int, steps: int) -> float:
    model = algorithm("MlpPolicy", make_env(task), learning_starts=warmup // 2, seed=0, verbose=0)
    model.learn(warmup)
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--task", default="Walker2d-v5")
    parser.add_argument("--steps", type=int, default=3000, help="timed env steps per trainer")
    parser.add_argument("--warmup", type=int, default=1000, help="untimed env steps first")
    args = parser.parse_args()
    torch.set_num_threads(1)  # one core per run, as demonstrator training runs
    found = trainers()
    for module, package in (("sb3_contrib", "sb3-contrib"), ("sbx", "sbx-rl")):
        if importlib.util.find_spec(module) is None:
            print(f"{package} is not installed (`pip install {package}`): its trainers are skipped")
    for name, algorithm in found.items():
        speed = steps_per_second(algorithm, args.task, args.warmup, args.steps)
        print(f"{args.task}  {name:22s} {speed:6.0f} env steps/s")


if __name__ == "__main__":
    main()
