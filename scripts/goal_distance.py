"""Does a model end its Meta-World episodes at its own hidden goal, or somewhere every goal shares?

Plays a model cold on `--seeds` envs of `--task` (default reach-v3; one hidden goal each, seeds training
never used) for `--shots` episodes, then compares, per episode, how far the hand ended from its own env's
goal with how far it ended from the other envs' goals. A model that reads its rewards ends nearer its
own goal (ratio well below 1); one that heads for a place every goal shares, such as the goal box's
middle, ends as near to all of them (ratio about 1). The project's target for reach-v3 at convergence:
a ratio of 0.5 or less (docs/in-context-rl.md).

    python scripts/goal_distance.py CHECKPOINT [--task reach-v3] [--shots 50] [--seeds 3] [--first-seed 100]
        [--reward-input true|zero|shuffled] [--point hand|gripper-centre|object] [--out FILE.csv]

`--point gripper-centre` measures from the gripper centre (4.5 cm below the hand), which reach's success
measures: the point a model trained on an expert aiming it (`aim: gripper-centre`) puts on the goal.
`--point object` measures from the task's object (observation[4:7]), which push's and pick-place's success
measures. Every row also says how far the hand ended from the object: a model that holds the object
ends a few centimetres from it, one that lost or never grasped it far away.

Prints per shot the median distance to the own goal, to the other goals, their ratio, the hand's to the
object and the success rate; `--out` writes one row per episode.
"""

from __future__ import annotations

import argparse
import csv
import io
from pathlib import Path

import numpy as np

from vintix.agent import Agent
from vintix.atomic import atomic_write_text
from vintix.evaluate.config import REWARD_INPUTS, EvalConfig
from vintix.evaluate.run import RewardFeed, play_shots
from vintix.tasks import action_box, get_task, make_env
from vintix.tasks.metaworld import hand_to_gripper_centre

OBJECT = slice(4, 7)
"""Where a Meta-World observation holds the first object's position."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint")
    parser.add_argument("--task", default="reach-v3", help="a Meta-World task with a hidden goal")
    parser.add_argument("--shots", type=int, default=EvalConfig.shots)
    parser.add_argument("--seeds", type=int, default=EvalConfig.seeds)
    parser.add_argument("--first-seed", type=int, default=100, help="env seed of the first goal (default 100: goals "
                        "the shipped recipes' histories never used, as in the docs' reward-ablation commands)")
    parser.add_argument("--reward-input", choices=REWARD_INPUTS, default=EvalConfig.reward_input)
    parser.add_argument("--point", choices=("hand", "gripper-centre", "object"), default="hand",
                        help="the point whose distance to the goals is measured")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    if get_task(args.task).domain != "metaworld":
        parser.error(f"--task {args.task}: not a Meta-World task; this script measures Meta-World's hidden goals")

    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    envs = [make_env(args.task, seed=seed) for seed in seeds]
    agent = Agent.from_pretrained(args.checkpoint)
    agent.reset([args.task] * len(envs), [action_box(env.action_space) for env in envs], discard_context=True)
    feeds = [RewardFeed(args.reward_input, seed) for seed in seeds]
    episodes = play_shots(agent, envs, feeds, args.shots, progress=True)
    goals = np.stack([env.unwrapped.true_goal for env in envs])  # fixed for an env's life (ML45 protocol)
    offset = hand_to_gripper_centre(args.task) if args.point == "gripper-centre" else np.zeros(3)
    for env in envs:
        env.close()

    rows = []
    for run, (seed, runs_episodes) in enumerate(zip(seeds, episodes, strict=True)):
        others = np.delete(goals, run, axis=0)
        for shot, episode in enumerate(runs_episodes, start=1):
            hand, obj = episode.last_observation[:3], episode.last_observation[OBJECT]
            point = obj if args.point == "object" else hand - offset
            rows.append({"seed": seed, "shot": shot, "success": episode.success,
                         "own_goal": float(np.linalg.norm(point - goals[run])),
                         "other_goals": float(np.median(np.linalg.norm(others - point, axis=1))),
                         "hand_to_object": float(np.linalg.norm(hand - obj))})

    print(f"{args.task}, {args.checkpoint}, {args.reward_input} rewards fed back, {len(seeds)} goals (seeds {seeds[0]}–"
          f"{seeds[-1]}); the {args.point}'s distances, medians over goals, in metres")
    print("shot  own goal  other goals  ratio  hand to object  success")
    for shot in range(1, args.shots + 1):
        at_shot = [row for row in rows if row["shot"] == shot]
        own, other, hand_to_object = (float(np.median([row[key] for row in at_shot]))
                                      for key in ("own_goal", "other_goals", "hand_to_object"))
        success = np.mean([row["success"] for row in at_shot])
        print(f"{shot:4d}  {own:8.3f}  {other:11.3f}  {own / other:5.2f}  {hand_to_object:14.3f}  {success:6.0%}")
    if args.out is not None:
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        atomic_write_text(args.out, buffer.getvalue())
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
