"""Env steps per second while learning, for the off-policy trainers a MuJoCo demonstrator could use.

    OMP_NUM_THREADS=1 python scripts/bench_trainers.py --task Humanoid-v5 --steps 3000

Stable-Baselines3's SAC against sbx-rl's SAC and CrossQ (its JAX sibling; `pip install sbx-rl` into the
same environment, it is not a vintix dependency: trainers it lacks are skipped). Each learns
`--warmup` steps first (random actions, then the first updates and JAX's compilation), and only the
next `--steps` are timed. The README's table of trainer speeds comes from this script.
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import torch

from vintix.tasks import make_env


def trainers() -> dict[str, type]:
    from stable_baselines3 import SAC

    found: dict[str, type] = {"SB3 SAC": SAC}
    if importlib.util.find_spec("sbx") is not None:
        import sbx

        found |= {"sbx-rl SAC": sbx.SAC, "sbx-rl CrossQ": sbx.CrossQ}
    return found


def steps_per_second(algorithm: type, task: str, warmup: int, steps: int) -> float:
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
    if "sbx-rl SAC" not in found:
        print("sbx-rl is not installed (`pip install sbx-rl`): only SB3 is measured")
    for name, algorithm in found.items():
        print(f"{args.task}  {name:14s} {steps_per_second(algorithm, args.task, args.warmup, args.steps):6.0f} env steps/s")


if __name__ == "__main__":
    main()
