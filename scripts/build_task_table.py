"""Build src/vintix/tasks/paper_tasks.csv from the paper's appendix tables.

Run once when the reference tables change:
    python scripts/build_task_table.py REFERENCE_DIR src/vintix/tasks/paper_tasks.csv
REFERENCE_DIR holds two CSV files transcribed by hand from the paper's appendix, which the repository
does not ship (the table built from them is what it ships):
    paper_dataset_metadata.csv  domain, task, obs_dim, act_dim, reward_scale, trajectory_length,
                                n_trajectories, mean_episode_length (the dataset table, one row per task)
    paper_task_scores.csv       task, random_mean, random_std, expert_mean, expert_std, vintix_norm_mean,
                                vintix_norm_std (the 'Task-Level Performance' tables)
The package reads only the CSV it ships; nothing reads the reference folder at run time.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

META_WORLD_TEST = {"bin-picking", "box-close", "door-lock", "door-unlock", "hand-insert"}
BIDEXHANDS_TEST = {"Hand-Door-Close-Outward", "Hand-Door-Open-Inward", "Hand-Door-Open-Outward", "Hand-Kettle",
                   "Hand-Over"}
# gymnasium's max_episode_steps for the v5 MuJoCo tasks.
MUJOCO_EPISODE_LENGTH = {"Reacher": 50, "Pusher": 100}


def canonical(domain: str, paper_name: str) -> tuple[str, list[str]]:
    """Our task name and the aliases users (and the paper's tables) may use for it."""
    if domain == "mujoco":
        env = paper_name.split("-")[0]
        # The published dataset names its tasks -v4 (Pusher too, although gymnasium's Pusher-v4 does
        # not load on mujoco 3): every -v4 name reads as the -v5 task, whose dims the data has.
        return f"{env}-v5", [f"{env}-v4"]
    if domain == "metaworld":
        return f"{paper_name}-v3", [paper_name, f"{paper_name}-v2"]
    if domain == "industrial_benchmark":
        setpoint = paper_name.split("-")[-1]
        return f"industrial-benchmark-{setpoint}-v1", [paper_name]
    return paper_name, ["shadowhand" + paper_name.removeprefix("Hand-").replace("-", "").lower()]


def main(reference: Path, out: Path) -> None:
    scores = {row["task"]: row for row in csv.DictReader(open(reference / "paper_task_scores.csv"))}
    rows = []
    for meta in csv.DictReader(open(reference / "paper_dataset_metadata.csv")):
        domain = meta["domain"]
        name, aliases = canonical(domain, meta["task"])
        score = next(scores[k] for k in [meta["task"], name, *aliases] if k in scores)
        obs_dim, act_dim = int(meta["obs_dim"]), int(meta["act_dim"])
        if domain == "mujoco":
            group = "mujoco-" + name.split("-")[0].lower()
            length = MUJOCO_EPISODE_LENGTH.get(name.split("-")[0], 1000)
            split = "train"
        elif domain == "metaworld":
            group, length = "metaworld", 100
            split = "test" if meta["task"] in META_WORLD_TEST else "train"
        elif domain == "industrial_benchmark":
            group, length = "industrial_benchmark", 250
            split = "train" if int(name.split("-")[2]) <= 75 else "test"
        else:  # Bi-DexHands: tasks share encoders only when their dims agree; lengths are the paper's means
            group, length = f"bidexhands-{obs_dim}x{act_dim}", round(float(meta["mean_episode_length"]))
            split = "test" if meta["task"] in BIDEXHANDS_TEST else "train"
        rows.append({
            "name": name, "domain": domain, "group": group, "obs_dim": obs_dim, "act_dim": act_dim,
            "episode_length": length, "reward_scale": meta["reward_scale"], "split": split,
            "random_mean": score["random_mean"], "random_std": score["random_std"],
            "expert_mean": score["expert_mean"], "expert_std": score["expert_std"],
            "paper_vintix_mean": score["vintix_norm_mean"], "paper_vintix_std": score["vintix_norm_std"],
            "paper_history_length": meta["trajectory_length"], "paper_histories": meta["n_trajectories"],
            "aliases": " ".join(aliases),
        })
    with open(out, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f"wrote {len(rows)} tasks to {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
